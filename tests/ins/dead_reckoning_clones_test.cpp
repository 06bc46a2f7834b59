// SPDX-License-Identifier: MIT
// DeadReckoningClones against the textbook reference: one augmented Kalman filter whose state
// holds the current error and every cloned position error explicitly, propagated with the full
// block transition and updated with a linear measurement of the clones.
#include "trailmark/ins/dead_reckoning_clones.h"

#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <cmath>
#include <stdexcept>
#include <vector>

namespace trailmark {
namespace {

/// The reference: state [current error (6); clone errors (2 each)], mean and covariance.
struct AugmentedFilter {
  DeadReckoning dr;
  Eigen::VectorXd mean = Eigen::VectorXd::Zero(DeadReckoning::kErrors);
  Eigen::MatrixXd cov;
  std::vector<Vec2> clone_n;

  /// With a considered heading offset (the dead reckoning's own covariance excludes it): the
  /// true error covariance of this filter's estimate, of [the state above; the offset], the
  /// offset last. The gain stays the one computed without it (Joseph form with that gain).
  Eigen::MatrixXd with_offset;

  explicit AugmentedFilter(const DeadReckoning& d) : dr(d), cov(d.error_covariance()) {
    const double sigma = d.considered_offset_sigma_rad();
    with_offset = Eigen::MatrixXd::Zero(7, 7);
    with_offset.topLeftCorner<6, 6>() = cov;
    // The heading error at the start is the stated one plus the offset.
    with_offset(2, 2) += sigma * sigma;
    with_offset(2, 6) = with_offset(6, 2) = with_offset(6, 6) = sigma * sigma;
  }
  void AddStep(const Step& s) {
    const DeadReckoning::ErrorCovariance before = dr.error_covariance();
    dr.AddStep(s);
    const auto& phi = dr.last_transition();
    // The step's own noise, from the dead reckoning's two covariances.
    const DeadReckoning::ErrorCovariance q = dr.error_covariance() - phi * before * phi.transpose();
    const Eigen::Index n = cov.rows();
    Eigen::MatrixXd F = Eigen::MatrixXd::Identity(n, n);
    F.topLeftCorner<6, 6>() = phi;
    Eigen::MatrixXd Q = Eigen::MatrixXd::Zero(n, n);
    Q.topLeftCorner<6, 6>() = q;
    mean = F * mean;
    cov = F * cov * F.transpose() + Q;
    Eigen::MatrixXd Fo = Eigen::MatrixXd::Identity(n + 1, n + 1);
    Fo.topLeftCorner(n, n) = F;
    Eigen::MatrixXd Qo = Eigen::MatrixXd::Zero(n + 1, n + 1);
    Qo.topLeftCorner(n, n) = Q;
    with_offset = Fo * with_offset * Fo.transpose() + Qo;
  }
  void Clone(double own_variance) {
    const Eigen::Index n = cov.rows();
    Eigen::MatrixXd J = Eigen::MatrixXd::Zero(n + 2, n);
    J.topRows(n).setIdentity();
    J(n, 0) = J(n + 1, 1) = 1;
    mean = J * mean;
    cov = J * cov * J.transpose();
    cov.bottomRightCorner<2, 2>() += Mat2::Identity() * own_variance;
    clone_n.push_back(dr.position_n().head<2>());
    // The offset stays last: the new clone goes before it.
    Eigen::MatrixXd Jo = Eigen::MatrixXd::Zero(n + 3, n + 1);
    Jo.topLeftCorner(n, n).setIdentity();
    Jo(n, 0) = Jo(n + 1, 1) = Jo(n + 2, n) = 1;
    with_offset = Jo * with_offset * Jo.transpose();
    with_offset.block<2, 2>(n, n) += Mat2::Identity() * own_variance;
  }
  /// y = H p + v, p the clones' true positions = DR - e.
  void Measure(const Eigen::MatrixXd& H, const Eigen::VectorXd& y, const Eigen::MatrixXd& R) {
    const Eigen::Index n = cov.rows(), k = static_cast<Eigen::Index>(clone_n.size());
    Eigen::VectorXd dr_c(2 * k);
    for (Eigen::Index i = 0; i < k; ++i) dr_c.segment<2>(2 * i) = clone_n[i];
    Eigen::MatrixXd He = Eigen::MatrixXd::Zero(H.rows(), n);
    He.rightCols(2 * k) = -H;
    const Eigen::VectorXd innovation = y - (H * dr_c + He * mean);
    const Eigen::MatrixXd S = He * cov * He.transpose() + R;
    const Eigen::MatrixXd K = cov * He.transpose() * S.inverse();
    mean += K * innovation;
    cov = cov - K * S * K.transpose();
    Eigen::MatrixXd Ko = Eigen::MatrixXd::Zero(n + 1, H.rows());
    Ko.topRows(n) = K;
    Eigen::MatrixXd Heo = Eigen::MatrixXd::Zero(H.rows(), n + 1);
    Heo.leftCols(n) = He;
    const Eigen::MatrixXd IKH = Eigen::MatrixXd::Identity(n + 1, n + 1) - Ko * Heo;
    with_offset = IKH * with_offset * IKH.transpose() + Ko * R * Ko.transpose();
  }
  Vec2 position() const { return dr.position_n().head<2>() - mean.head<2>(); }
  Mat2 position_cov() const { return cov.topLeftCorner<2, 2>(); }
  /// The clones' positions' posterior (mean, covariance), as a solver would give them.
  std::pair<Eigen::VectorXd, Eigen::MatrixXd> ClonePosterior() const {
    const Eigen::Index k = static_cast<Eigen::Index>(clone_n.size());
    Eigen::VectorXd m(2 * k);
    for (Eigen::Index i = 0; i < k; ++i)
      m.segment<2>(2 * i) = clone_n[i] - mean.segment<2>(6 + 2 * i);
    return {m, cov.bottomRightCorner(2 * k, 2 * k)};
  }
};

/// A measurement of three clones: two position fixes and a distance-like combination.
std::pair<Eigen::MatrixXd, Eigen::VectorXd> ThreeClonesMeasured() {
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(5, 6);
  H(0, 0) = H(1, 1) = 1;
  H(2, 4) = H(3, 5) = 1;
  H(4, 2) = 0.6, H(4, 3) = -0.8, H(4, 0) = -0.6;
  Eigen::VectorXd y(5);
  y << 1.0, -2.0, 9.0, 1.5, 0.4;
  return {H, y};
}

/// A walk with turns, pauses (standing: the drift rate integrates) and a step scale.
Step WalkStep(int k) {
  const double heading = 0.3 * std::sin(0.15 * k) + (k > 30 ? 1.4 : 0.0);
  const double len = (k % 17 == 0) ? 0.0 : 0.7;
  const double t0 = 0.6 * k + (k > 20 ? 8.0 : 0.0);
  return Step{t0, t0 + 0.5, "ff1", Vec3(len * std::cos(heading), len * std::sin(heading), 0)};
}

/// Steps k, k + 1, ... (n of them) into both; k ends after them.
void Walk(DeadReckoningClones& clones, AugmentedFilter& ref, int* k, int n) {
  for (int i = 0; i < n; ++i, ++*k) {
    clones.AddStep(WalkStep(*k));
    ref.AddStep(WalkStep(*k));
  }
}

TEST(DeadReckoningClones, IsTheAugmentedKalmanFilterBeforeAndAfterConditioning) {
  const DeadReckoning dr(Vec3(2, -1, 0), 0.2, PdrOptions{}, 0.05);
  DeadReckoningClones clones(dr);
  AugmentedFilter ref(dr);
  int k = 0;
  for (int stop = 0; stop < 3; ++stop) {
    Walk(clones, ref, &k, 15);
    clones.Clone(1e-6);
    ref.Clone(1e-6);
    // Cloning does not move the current position or its covariance.
    EXPECT_LT((clones.position_n() - ref.position()).norm(), 1e-12);
  }
  // The clones' joint prior is the reference's (correlated by the shared errors).
  const Eigen::MatrixXd& S = clones.clone_covariance();
  ASSERT_EQ(S.rows(), 6);
  EXPECT_LT((S - ref.cov.bottomRightCorner(6, 6)).norm(), 1e-12 * S.norm());
  EXPECT_GT(std::abs(S(0, 4)), 1e-4);  // the first and the last stop share errors
  const auto [H, y] = ThreeClonesMeasured();
  Eigen::MatrixXd R = Eigen::MatrixXd::Identity(5, 5) * 0.09;
  R(0, 1) = R(1, 0) = 0.02;
  ref.Measure(H, y, R);
  const auto [post_n, post_cov] = ref.ClonePosterior();
  clones.Condition(post_n, post_cov);
  EXPECT_LT((clones.position_n() - ref.position()).norm(), 1e-9);
  EXPECT_LT((clones.covariance() - ref.position_cov()).norm(), 1e-9);
  // It stays so as steps and a new clone are added.
  Walk(clones, ref, &k, 25);
  clones.Clone(1e-6);
  ref.Clone(1e-6);
  Walk(clones, ref, &k, 5);
  EXPECT_LT((clones.position_n() - ref.position()).norm(), 1e-9);
  EXPECT_LT((clones.covariance() - ref.position_cov()).norm(), 1e-9);
  // The radio's information shrank the current position's ellipse below the dead reckoning's.
  EXPECT_LT(clones.covariance().trace(), clones.dead_reckoning().covariance().trace() - 0.01);
  // Conditioning on the whole posterior again (the four clones) is the reference's too.
  const auto [post4_n, post4_cov] = ref.ClonePosterior();
  clones.Condition(post4_n, post4_cov);
  EXPECT_LT((clones.position_n() - ref.position()).norm(), 1e-9);
  EXPECT_LT((clones.covariance() - ref.position_cov()).norm(), 1e-9);
}

// Forgetting the oldest clone: the current position is conditioned on the posterior of the
// clones that remain. Reference: Gaussian conditioning on the augmented filter's prior joint
// covariance, done here directly.
TEST(DeadReckoningClones, DroppingTheOldestConditionsOnTheRest) {
  const DeadReckoning dr(Vec3(0, 0, 0), 0.1);
  DeadReckoningClones clones(dr);
  AugmentedFilter ref(dr);
  int k = 0;
  for (int stop = 0; stop < 3; ++stop) {
    Walk(clones, ref, &k, 12);
    clones.Clone(0.0);
    ref.Clone(0.0);
  }
  const AugmentedFilter prior = ref;  // before any measurement
  Eigen::MatrixXd H = Eigen::MatrixXd::Identity(6, 6);
  Eigen::VectorXd y(6);
  y << 0.5, 0.2, 8.0, 1.0, 14.0, 4.0;
  ref.Measure(H, y, Eigen::MatrixXd::Identity(6, 6) * 0.04);
  const auto [post_n, post_cov] = ref.ClonePosterior();
  clones.Condition(post_n, post_cov);
  Walk(clones, ref, &k, 6);
  clones.DropOldest();
  ASSERT_EQ(clones.clones(), 2);
  // Reference: the prior joint of [current; clone 2; clone 3] propagated by the same steps,
  // conditioned on the last two clones' posterior marginal.
  AugmentedFilter p = prior;
  for (int i = 0; i < 6; ++i) p.AddStep(WalkStep(k - 6 + i));
  std::vector<int> keep = {0, 1, 2, 3, 4, 5, 8, 9, 10, 11};
  Eigen::MatrixXd joint(10, 10);
  for (int r = 0; r < 10; ++r) {
    for (int c = 0; c < 10; ++c) joint(r, c) = p.cov(keep[r], keep[c]);
  }
  const Eigen::MatrixXd Cec = joint.topRightCorner(6, 4);
  const Eigen::MatrixXd Scc = joint.bottomRightCorner(4, 4);
  Eigen::VectorXd dr_c(4);
  dr_c << p.clone_n[1], p.clone_n[2];
  const Eigen::VectorXd e_c = dr_c - post_n.tail(4);
  const Eigen::MatrixXd Si = Scc.inverse();
  const Eigen::VectorXd e_cur = Cec * Si * e_c;
  const Eigen::MatrixXd cov_cur =
      joint.topLeftCorner(6, 6) - Cec * Si * Cec.transpose() +
      Cec * Si * post_cov.bottomRightCorner(4, 4) * Si * Cec.transpose();
  const Vec2 expected = p.dr.position_n().head<2>() - e_cur.head<2>();
  EXPECT_LT((clones.position_n() - expected).norm(), 1e-9);
  EXPECT_LT((clones.covariance() - cov_cur.topLeftCorner<2, 2>()).norm(), 1e-9);
  // Not the same as keeping the dropped clone's information (the check above can fail).
  EXPECT_GT((clones.position_n() - ref.position()).norm(), 1e-4);
}

// A considered heading offset (PdrOptions::track_heading_offset_considered): the estimate is
// the one without it, to the bit; the covariance is the true error covariance of that estimate
// when the walk's heading carries the offset: the augmented filter's [error; clones; offset],
// propagated alike and updated in Joseph form with the gain computed without the offset.
TEST(DeadReckoningClones, AConsideredOffsetIsTheJosephFormOfTheGainWithoutIt) {
  PdrOptions considered;
  considered.track_heading_offset_considered = true;
  PdrOptions none;
  none.track_heading_offset_sigma_rad = 0.0;
  const DeadReckoning dr(Vec3(2, -1, 0), 0.2, considered, 0.02);
  DeadReckoningClones clones(dr), plain(DeadReckoning(Vec3(2, -1, 0), 0.2, none, 0.02));
  AugmentedFilter ref(dr);
  int k = 0;
  for (int stop = 0; stop < 3; ++stop) {
    for (int i = 0; i < 15; ++i, ++k) plain.AddStep(WalkStep(k));
    k -= 15;
    Walk(clones, ref, &k, 15);
    clones.Clone(1e-6);
    plain.Clone(1e-6);
    ref.Clone(1e-6);
  }
  // Before any measurement: the dead reckoning's state form (the offset in the heading).
  EXPECT_LT((clones.covariance() - ref.with_offset.topLeftCorner<2, 2>()).norm(), 1e-12);
  const auto [H, y] = ThreeClonesMeasured();
  ref.Measure(H, y, Eigen::MatrixXd::Identity(5, 5) * 0.09);
  const auto [post_n, post_cov] = ref.ClonePosterior();
  clones.Condition(post_n, post_cov);
  plain.Condition(post_n, post_cov);
  EXPECT_EQ(clones.position_n(), plain.position_n());
  EXPECT_LT((clones.position_n() - ref.position()).norm(), 1e-9);
  EXPECT_LT((clones.covariance() - ref.with_offset.topLeftCorner<2, 2>()).norm(), 1e-9);
  // The offset's share is what the radio left of it, neither none nor all of it.
  const Mat2 share = clones.covariance() - plain.covariance();
  EXPECT_GT(share.trace(), 1e-3);
  EXPECT_LT(share.trace(),
            0.9 * (clones.dead_reckoning().covariance() - clones.dead_reckoning().own_covariance())
                      .trace());
  // Steps on and a new clone: still the reference.
  for (int i = 0; i < 30; ++i, ++k) plain.AddStep(WalkStep(k));
  k -= 30;
  Walk(clones, ref, &k, 25);
  clones.Clone(1e-6);
  ref.Clone(1e-6);
  Walk(clones, ref, &k, 5);
  EXPECT_LT((clones.position_n() - ref.position()).norm(), 1e-9);
  EXPECT_LT((clones.covariance() - ref.with_offset.topLeftCorner<2, 2>()).norm(), 1e-9);
}

TEST(DeadReckoningClones, RefusesAPosteriorOfTheWrongSizeOrNotFinite) {
  DeadReckoningClones clones(DeadReckoning(Vec3::Zero(), 0.1));
  clones.AddStep(WalkStep(1));
  clones.Clone(0.0);
  EXPECT_THROW(clones.Condition(Eigen::VectorXd::Zero(4), Eigen::MatrixXd::Identity(4, 4)),
               std::invalid_argument);
  Eigen::VectorXd nan(2);
  nan << 0.0, std::nan("");
  EXPECT_THROW(clones.Condition(nan, Eigen::MatrixXd::Identity(2, 2)), std::invalid_argument);
  // Nothing changed: still the dead reckoning.
  EXPECT_EQ(clones.position_n(), clones.dead_reckoning().position_n().head<2>());
}

}  // namespace
}  // namespace trailmark

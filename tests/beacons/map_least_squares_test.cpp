// SPDX-License-Identifier: MIT
#include "trailmark/beacons/map_least_squares.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>

#include <cmath>
#include <stdexcept>

#include "trailmark/core/random.h"

namespace trailmark::beacons {
namespace {

// A U-shaped trail: beacons 2 m apart along it, links to the next two only (no link across).
std::vector<Vec2> UTrail() {
  std::vector<Vec2> p;
  for (double x = 0; x <= 16; x += 2) p.emplace_back(x, 0);
  for (double y = 2; y <= 8; y += 2) p.emplace_back(16, y);
  for (double x = 14; x >= 0; x -= 2) p.emplace_back(x, 8);
  return p;
}

MapProblem Problem(const std::vector<Vec2>& truth, double link_noise_m, double prior_noise_m,
                   Random& rng) {
  MapProblem p;
  p.beacons = static_cast<int>(truth.size());
  for (int i = 0; i < p.beacons; ++i)
    for (int j = i + 1; j <= i + 2 && j < p.beacons; ++j)
      p.links.push_back({i, j, (truth[i] - truth[j]).norm() + link_noise_m * rng.Normal(), 0.1});
  for (int i = 0; i < p.beacons; ++i) {
    const double s = i == 4 || i == 12 ? 0.05 : 1.0;  // two surveyed, the rest drop priors
    const Vec2 mu = truth[i] + (i == 4 || i == 12 ? 0.0 : prior_noise_m) *
                                   Vec2(rng.Normal(), rng.Normal());
    p.priors.push_back({i, mu, Mat2::Identity() * s * s});
  }
  return p;
}

TEST(MapLeastSquares, RecoversANoiseFreeTrailFromItsPriors) {
  Random rng(3);
  const auto truth = UTrail();
  const MapProblem p = Problem(truth, 0.0, 0.0, rng);
  std::vector<Vec2> start = truth;
  for (auto& s : start) s += Vec2(0.5 * rng.Normal(), 0.5 * rng.Normal());
  const MapSolution s = SolveMapLeastSquares(p, {start});
  ASSERT_TRUE(s.ok) << s.why;
  for (std::size_t i = 0; i < truth.size(); ++i) EXPECT_NEAR((s.position_n[i] - truth[i]).norm(), 0, 1e-6);
  EXPECT_TRUE(s.consistent);
  for (const Mat2& c : s.cov) EXPECT_GT(c.determinant(), 0);
}

TEST(MapLeastSquares, KeepsTheStartOfLowerCostWhenTheOtherIsFolded) {
  Random rng(5);
  const auto truth = UTrail();
  const MapProblem p = Problem(truth, 0.0, 0.3, rng);
  std::vector<Vec2> folded = truth;  // the north leg folded onto the south one
  for (auto& q : folded)
    if (q.y() > 4) q.y() = 8 - q.y();
  const MapSolution s = SolveMapLeastSquares(p, {folded, truth});
  ASSERT_TRUE(s.ok);
  EXPECT_EQ(s.start, 1);
  EXPECT_LT(s.start_chi2[1], s.start_chi2[0]);
}

TEST(MapLeastSquares, MarginalCovariancesAreHonestOverMonteCarlo) {
  // In its exact model (Gaussian links and priors, no robust loss active) the NEES of each
  // beacon averages 2 (2 dof); 100 runs x 21 beacons.
  const auto truth = UTrail();
  double nees = 0;
  int n = 0;
  for (int run = 0; run < 100; ++run) {
    Random rng(100 + run);
    MapProblem p = Problem(truth, 0.1, 1.0, rng);
    const MapSolution s = SolveMapLeastSquares(p, {truth});
    ASSERT_TRUE(s.ok);
    for (std::size_t i = 0; i < truth.size(); ++i) {
      const Vec2 e = s.position_n[i] - truth[i];
      nees += e.dot(s.cov[i].ldlt().solve(e));
      ++n;
    }
  }
  EXPECT_NEAR(nees / n, 2.0, 0.3);
}

TEST(MapLeastSquares, MarginalsEqualCeresCovarianceWithTracksAndTheRobustLossActive) {
  // Our sparse-Cholesky marginals against ceres::Covariance (SPARSE_QR) on a problem with a
  // track's shared errors, drop priors on it and one NLOS link far into the Huber loss.
  Random rng(21);
  const auto truth = UTrail();
  MapProblem p = Problem(truth, 0.1, 0.0, rng);
  p.links[5].range_m += 1.5;  // NLOS
  p.tracks.push_back({Vec3(0.05 * 0.05, 1e-6, 0.03 * 0.03).asDiagonal()});
  for (auto& q : p.priors) {
    if (q.i == 4 || q.i == 12) continue;
    q.track = 0;
    q.along << -truth[q.i].y(), 0.5 * q.i, truth[q.i].x(), truth[q.i].x(), 0.1 * q.i, truth[q.i].y();
  }
  MapLeastSquaresOptions ours, reference;
  reference.reference_covariance = true;
  const MapSolution a = SolveMapLeastSquares(p, {truth}, ours);
  const MapSolution b = SolveMapLeastSquares(p, {truth}, reference);
  ASSERT_TRUE(a.ok) << a.why;
  ASSERT_TRUE(b.ok) << b.why;
  ASSERT_EQ(a.cov.size(), truth.size());
  for (std::size_t i = 0; i < truth.size(); ++i)
    EXPECT_LT((a.cov[i] - b.cov[i]).norm(), 1e-9 * (1 + b.cov[i].norm())) << i;
}

TEST(MapLeastSquares, AMovedSurveyIsInconsistent) {
  Random rng(7);
  const auto truth = UTrail();
  MapProblem p = Problem(truth, 0.1, 0.3, rng);
  for (auto& q : p.priors)
    if (q.i == 12) q.position_n += Vec2(3, 0);  // surveyed 3 m off
  const MapSolution s = SolveMapLeastSquares(p, {truth});
  ASSERT_TRUE(s.ok);
  EXPECT_FALSE(s.consistent);
  EXPECT_GT(s.chi2, s.chi2_threshold);
}

TEST(MapLeastSquares, BadInputIsRefusedAndAnUnanchoredPartIsNotSolved) {
  Random rng(9);
  const auto truth = UTrail();
  MapProblem p = Problem(truth, 0.0, 0.0, rng);
  MapProblem bad = p;
  bad.links[0].j = 99;
  EXPECT_THROW(SolveMapLeastSquares(bad, {truth}), std::invalid_argument);
  bad = p;
  bad.links[0].range_m = std::nan("");
  EXPECT_THROW(SolveMapLeastSquares(bad, {truth}), std::invalid_argument);
  bad = p;
  bad.priors[0].cov = -Mat2::Identity();
  EXPECT_THROW(SolveMapLeastSquares(bad, {truth}), std::invalid_argument);
  EXPECT_THROW(SolveMapLeastSquares(p, {{Vec2::Zero()}}), std::invalid_argument);
  bad = p;
  bad.priors.resize(1);  // one prior: rotation free
  const MapSolution s = SolveMapLeastSquares(bad, {truth});
  EXPECT_FALSE(s.ok);
  EXPECT_NE(s.why.find("not anchored"), std::string::npos);
}

}  // namespace
}  // namespace trailmark::beacons

// SPDX-License-Identifier: MIT
// The SCAAT EKF of the ultrasound-beacons paper (sec. 6), its ultrasound-only baseline and the
// initialization from ultrasound: Jacobians against numerical derivatives, the EKF against a
// plain linear Kalman filter where the model is linear, NEES consistency on simulated data,
// gating of NLOS ranges, exact recovery of the start.
#include "trailmark/beacons/scaat_ekf.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <cmath>
#include <numbers>

#include "trailmark/core/random.h"

namespace trailmark::beacons {
namespace {

Mat2 Rot(double a) { return Eigen::Rotation2Dd(a).toRotationMatrix(); }

TEST(UltrasoundModels, JacobiansMatchNumericalDerivatives) {
  const Vec2 b(1.0, -2.0);
  for (const Vec2& p : {Vec2(3.0, 1.0), Vec2(-2.0, 0.5), Vec2(1.2, -2.3)}) {
    Eigen::RowVector2d Hr, Hb;
    UltrasoundRange(p, b, &Hr);
    UltrasoundBearing(p, b, &Hb);
    const double h = 1e-6;
    for (int k = 0; k < 2; ++k) {
      Vec2 dp = Vec2::Zero();
      dp(k) = h;
      EXPECT_NEAR(Hr(k), (UltrasoundRange(p + dp, b) - UltrasoundRange(p - dp, b)) / (2 * h), 1e-7);
      EXPECT_NEAR(Hb(k),
                  WrapAngle(UltrasoundBearing(p + dp, b) - UltrasoundBearing(p - dp, b)) / (2 * h),
                  1e-7);
    }
  }
}

TEST(ScaatEkf, StepPropagationMatchesLinearizationNumerically) {
  // The covariance after a step equals F P F^T + Q with F from finite differences of
  // f(x) = (p + s R(psi) d, psi, s, k).
  ScaatEkf::Options o;
  o.step_sigma_floor_m = 0;
  o.heading_walk_rad_per_sqrt_m = 0;
  o.scale_walk_per_sqrt_m = 0;
  ScaatEkf::Cov P0 = ScaatEkf::Cov::Identity() * 0.1;
  P0(0, 2) = P0(2, 0) = 0.02;
  P0(1, 4) = P0(4, 1) = 0.01;
  ScaatEkf::State x0;
  x0 << 1, 2, 0.3, 1.1, 1.05;
  ScaatEkf ekf(x0, P0, o);
  const Vec2 d(0.7, -0.2);
  ekf.PredictStep(d, Mat2::Zero());
  auto f = [&](const ScaatEkf::State& x) {
    ScaatEkf::State y = x;
    y.head<2>() += x(3) * Rot(x(2)) * d;
    return y;
  };
  ScaatEkf::Cov F;
  for (int k = 0; k < ScaatEkf::kDim; ++k) {
    ScaatEkf::State dx = ScaatEkf::State::Zero();
    dx(k) = 1e-6;
    F.col(k) = (f(x0 + dx) - f(x0 - dx)) / 2e-6;
  }
  EXPECT_TRUE(ekf.state().isApprox(f(x0), 1e-12));
  EXPECT_LT((ekf.covariance() - F * P0 * F.transpose()).norm(), 1e-8);
}

TEST(ScaatEkf, EqualsALinearKalmanFilterWhenHeadingAndScaleAreKnown) {
  // With psi = 0 and scale = 1 known exactly, steps are a linear random walk and the paper's
  // position update is linear: the EKF must equal a 2-state Kalman filter to round-off.
  ScaatEkf::Options o;
  o.heading_walk_rad_per_sqrt_m = 0;
  o.scale_walk_per_sqrt_m = 0;
  o.step_sigma_floor_m = 0;
  o.gate_chi2_2dof = 1e9;
  ScaatEkf::State x0;
  x0 << 0.5, -0.5, 0, 1, 1;
  ScaatEkf::Cov P0 = ScaatEkf::Cov::Zero();
  P0.topLeftCorner<2, 2>() << 0.3, 0.05, 0.05, 0.2;
  P0(2, 2) = 1e-30;
  P0(3, 3) = 1e-30;
  P0(4, 4) = 1e-30;
  ScaatEkf ekf(x0, P0, o);
  Vec2 x = x0.head<2>();
  Mat2 P = P0.topLeftCorner<2, 2>();
  Random rng(3);
  for (int k = 0; k < 50; ++k) {
    const Vec2 d(rng.Normal(0.5, 0.2), rng.Normal(0, 0.2));
    const Mat2 Q = Mat2::Identity() * 0.01;
    ekf.PredictStep(d, Q);
    x += d;
    P += Q;
    const BeaconPosition b{Vec2(rng.Uniform(-5, 5), rng.Uniform(-5, 5)), Mat2::Identity() * 0.04};
    const double r = rng.Uniform(0.5, 4), bearing = rng.Uniform(-3, 3);
    ASSERT_EQ(ekf.UpdatePosition(b, r, bearing, 0.3, 0.5), UpdateResult::kAccepted);
    Vec2 z;
    Mat2 R;
    PolarToPosition(b, r, bearing, 0.3, 0.5, &z, &R);
    const Mat2 K = P * (P + R).inverse();
    x += K * (z - x);
    P = (Mat2::Identity() - K) * P;
    ASSERT_LT((ekf.position() - x).norm(), 1e-9) << k;
    ASSERT_LT((ekf.position_cov() - P).norm(), 1e-9) << k;
  }
}

// Simulates the filter's own model: a walk with heading offset psi, scale s and range scale k
// drawn from the prior, PDR steps with noise, range (k times the distance) and bearing to
// beacons with Gaussian noise. Returns the NEES of the full state at the end. `outliers`: that
// share of the ranges is NLOS (0.2-2.5 m long) and of the bearings uniform on the circle (issue
// 22); `mixture`: the filter's mixture updates, else its hard 3-sigma gate.
struct NeesRun {
  ScaatEkf::State error;  ///< truth minus estimate
  ScaatEkf::Cov cov;
};

NeesRun RunNees(std::uint64_t seed, bool position_update, double outliers = 0,
                bool mixture = false) {
  Random rng(seed);
  ScaatEkf::Options o;
  o.mixture_updates = mixture;
  o.range_outlier_probability = o.bearing_outlier_probability = std::max(outliers, 0.01);
  const double psi = rng.Normal(0, o.initial_heading_sigma_rad);
  const double scale = 1.0 + rng.Normal(0, o.initial_scale_sigma);
  const double range_scale = 1.0 + rng.Normal(0, o.range_scale_sigma);
  const Vec2 start(0, 0);
  const Vec2 p0 = start + Vec2(rng.Normal(0, o.initial_position_sigma_m),
                               rng.Normal(0, o.initial_position_sigma_m));
  ScaatEkf ekf(start, o);
  std::vector<Vec2> beacons;
  for (int i = 0; i < 12; ++i) beacons.emplace_back(3.0 * i, i % 2 ? 2.0 : -2.0);
  Vec2 p = p0;
  double true_psi = psi, true_scale = scale;
  for (int k = 0; k < 120; ++k) {
    const Vec2 d_true(0.3 + 0.05 * std::sin(0.1 * k), 0.1 * std::cos(0.3 * k));
    const double step_sigma = 0.03;
    const Vec2 d_noise(rng.Normal(0, step_sigma), rng.Normal(0, step_sigma));
    // p <- p + s R(psi) (d_meas) is the model; generate truth consistently with it.
    const Vec2 d_meas = d_true;
    p += true_scale * Rot(true_psi) * d_meas + true_scale * Rot(true_psi) * d_noise;
    const double len = d_meas.norm();
    true_psi += rng.Normal(0, o.heading_walk_rad_per_sqrt_m * std::sqrt(len));
    true_scale += rng.Normal(0, o.scale_walk_per_sqrt_m * std::sqrt(len));
    ekf.PredictStep(d_meas, Mat2::Identity() * step_sigma * step_sigma -
                                Mat2::Identity() * o.step_sigma_floor_m * o.step_sigma_floor_m +
                                Mat2::Identity() * 1e-12);
    for (const Vec2& b : beacons) {
      const double dist = (p - b).norm();
      if (dist > 5.0) continue;
      double r = range_scale * dist + rng.Normal(0, o.range_sigma_m);
      double br = std::atan2(p.y() - b.y(), p.x() - b.x()) + rng.Normal(0, o.bearing_sigma_rad);
      if (outliers > 0 && rng.Uniform() < outliers) r = dist + rng.Uniform(0.2, 2.5);  // NLOS: long
      if (outliers > 0 && rng.Uniform() < outliers) br = rng.Uniform(-std::numbers::pi, std::numbers::pi);
      const BeaconPosition bp{b, Mat2::Zero()};
      if (position_update) {
        ekf.UpdatePosition(bp, r, br);
      } else {
        ekf.UpdateRange(bp, r);
        ekf.UpdateBearing(bp, br);
      }
    }
  }
  ScaatEkf::State e;
  e << p - ekf.position(), WrapAngle(true_psi - ekf.psi()), true_scale - ekf.scale(),
      range_scale - ekf.range_scale();
  return {e, ekf.covariance()};
}

double Nees(const NeesRun& r) { return r.error.dot(r.cov.ldlt().solve(r.error)); }

// The NEES of the paper's four states (position, heading and step scale corrections).
double PaperStatesNees(const NeesRun& r) {
  const Eigen::Vector4d e = r.error.head<4>();
  return e.dot(r.cov.topLeftCorner<4, 4>().ldlt().solve(e));
}

TEST(ScaatEkf, NormalizedEstimationErrorSquaredIsWithinChiSquareBounds) {
  // 200 Monte Carlo runs: the average NEES of a consistent 5-state filter lies within the 95 %
  // two-sided chi-square interval of 5 x 200 degrees of freedom divided by 200: [4.57, 5.45].
  const int runs = 200;
  double ours = 0, paper = 0;
  for (int s = 1; s <= runs; ++s) {
    ours += Nees(RunNees(static_cast<std::uint64_t>(s), false)) / runs;
    paper += Nees(RunNees(static_cast<std::uint64_t>(s), true)) / runs;
  }
  EXPECT_GT(ours, 4.57);
  EXPECT_LT(ours, 5.45);
  // The paper's update converts (range, bearing) to a position by first-order propagation; with
  // the moving node's bearing noise (~33 deg) that linearization is overconfident. This is why
  // the default updates range and bearing separately (measured NEES ~9.5 for the conversion).
  EXPECT_GT(paper, 5.45);
}

TEST(ScaatEkf, MixtureUpdatesStayConsistentWithNlosRangesAndBearingOutliers) {
  // 15 % of ranges NLOS (0.2-2.5 m long) and 15 % of bearings uniform on the circle, as on a
  // trail laid out by someone else. The mixture (one-measurement PDA) keeps the mean NEES of
  // the paper's four states over 200 runs within the 95 % interval of 4 dof, [3.61, 4.41]
  // (measured 4.16; 4.00 before the range scale state), below the 3-sigma gate's (the long
  // ranges inside the gate go in whole).
  // The range scale is outside that model here: the NLOS ranges that pass as inliers are long
  // by a few tenths of a metre, which a scale reads as ranges too long (its mean error -0.008
  // against its sigma of 0.008, measured). What must hold: estimating it is still better than
  // taking the ranges as they are (its RMS error below the prior's sigma, the error of k = 1).
  const int runs = 200;
  double mixture = 0, gate = 0, k_squared = 0;
  ScaatEkf::Options o;
  for (int s = 1; s <= runs; ++s) {
    const NeesRun m = RunNees(static_cast<std::uint64_t>(s), false, 0.15, true);
    mixture += PaperStatesNees(m) / runs;
    k_squared += m.error(ScaatEkf::kRangeScale) * m.error(ScaatEkf::kRangeScale) / runs;
    gate += PaperStatesNees(RunNees(static_cast<std::uint64_t>(s), false, 0.15, false)) / runs;
  }
  EXPECT_GT(mixture, 3.61);
  EXPECT_LT(mixture, 4.41);
  EXPECT_LT(mixture, gate);
  EXPECT_LT(std::sqrt(k_squared), o.range_scale_sigma);
}

TEST(ScaatEkf, MixtureUpdateEqualsTheMomentsOfItsTwoHypotheses) {
  // One range update, compared with the reference computed from the two hypotheses' posteriors
  // (the Kalman update in information form, the prior) and their weights: mean and second
  // moment of the mixture, not the closed form the filter uses.
  ScaatEkf::Options o;
  o.range_outlier_probability = 0.2;
  const Vec2 b(3.0, 1.0);
  for (const double r : {2.4, 3.1, 3.9, 4.6}) {
    ScaatEkf::State x0;
    x0 << 0.2, -0.1, 0.05, 1.02, 1.03;
    ScaatEkf::Cov P0 = ScaatEkf::Cov::Identity() * 0.04;
    P0(0, 1) = P0(1, 0) = 0.01;
    P0(2, 2) = 0.01;
    P0(3, 3) = 0.0025;
    P0(4, 4) = 0.0004;
    P0(0, 4) = P0(4, 0) = 0.001;
    ScaatEkf ekf(x0, P0, o);
    ASSERT_EQ(ekf.UpdateRange({b, Mat2::Zero()}, r, 0.3), UpdateResult::kAccepted);
    // h = k |p - b|: dh/dp = k (p - b)' / |p - b|, dh/dk = |p - b|.
    Eigen::RowVector2d Hp;
    const double distance = UltrasoundRange(x0.head<2>(), b, &Hp);
    const double h = x0(4) * distance;
    Eigen::Matrix<double, 1, ScaatEkf::kDim> H = Eigen::Matrix<double, 1, ScaatEkf::kDim>::Zero();
    H.head<2>() = x0(4) * Hp;
    H(4) = distance;
    const double R = 0.09, y = r - h;
    const double S = (H * P0 * H.transpose())(0) + R;
    const double inlier = (1 - 0.2) * std::exp(-0.5 * y * y / S) / std::sqrt(2 * std::numbers::pi * S);
    const double w = inlier / (inlier + 0.2 / o.range_outlier_span_m);
    const ScaatEkf::Cov P1 = (P0.inverse() + H.transpose() * H / R).inverse();
    const ScaatEkf::State x1 = x0 + P1 * H.transpose() * y / R;
    const ScaatEkf::State mean = w * x1 + (1 - w) * x0;
    const ScaatEkf::Cov second = w * (P1 + x1 * x1.transpose()) + (1 - w) * (P0 + x0 * x0.transpose());
    EXPECT_LT((ekf.state() - mean).norm(), 1e-9) << r;
    EXPECT_LT((ekf.covariance() - (second - mean * mean.transpose())).norm(), 1e-9) << r;
  }
}

TEST(ScaatEkf, GatesNlosRangesAndSkipsBadInput) {
  ScaatEkf ekf(Vec2(0, 0));
  const BeaconPosition b{Vec2(2, 0), Mat2::Zero()};
  EXPECT_EQ(ekf.UpdateRange(b, 2.0), UpdateResult::kAccepted);
  EXPECT_EQ(ekf.UpdateRange(b, 4.5), UpdateResult::kGated);  // +2.5 m: a reflection
  EXPECT_EQ(ekf.UpdateRange(b, std::nan("")), UpdateResult::kSkipped);
  EXPECT_EQ(ekf.UpdateRange(b, -1.0), UpdateResult::kSkipped);
  EXPECT_EQ(ekf.UpdateBearing(b, std::numeric_limits<double>::infinity()), UpdateResult::kSkipped);
  EXPECT_EQ(ekf.UpdatePosition(b, 1.0, std::nan("")), UpdateResult::kSkipped);
  // A beacon on top of the node: no bearing, no range direction.
  EXPECT_EQ(ekf.UpdateRange({ekf.position(), Mat2::Zero()}, 0.0), UpdateResult::kSkipped);
  EXPECT_EQ(ekf.summary().gated, 1u);
  EXPECT_TRUE(ekf.state().allFinite());
  const Eigen::SelfAdjointEigenSolver<ScaatEkf::Cov> eig(ekf.covariance());
  EXPECT_GT(eig.eigenvalues().minCoeff(), 0);
  EXPECT_EQ(ekf.covariance(), ekf.covariance().transpose());
}

TEST(ScaatEkf, LearnsHeadingAndScaleOfThePdr) {
  // A PDR rotated by 12 deg and 8 % short: along a beacon trail the filter recovers both.
  Random rng(5);
  ScaatEkf ekf(Vec2(0, 0));
  Vec2 p(0, 0);
  const double psi = 0.21, scale = 1.08;
  for (int k = 0; k < 200; ++k) {
    const Vec2 d_true(0.35 * std::cos(0.02 * k), 0.35 * std::sin(0.02 * k));
    p += d_true;
    ekf.PredictStep(Rot(-psi) * d_true / scale, Mat2::Identity() * 1e-4);
    // Beacons every 3 m along the arc, 1 m to its left.
    const double radius = 0.35 / 0.02;
    for (int i = 0; i < 25; ++i) {
      const double a = 3.0 * i / radius;
      const Vec2 b = Vec2(radius * std::sin(a), radius * (1 - std::cos(a))) * (radius - 1) / radius;
      if ((p - b).norm() > 5) continue;
      ekf.UpdateRange({b, Mat2::Zero()}, (p - b).norm() + rng.Normal(0, 0.1), 0.1);
    }
  }
  EXPECT_NEAR(ekf.psi(), psi, 0.03);
  EXPECT_NEAR(ekf.scale(), scale, 0.03);
  EXPECT_LT((ekf.position() - p).norm(), 0.3);
}

// The ultrasound-only KF on its own model: white-noise-acceleration kinematics from a start drawn
// from its prior, range and bearing to the beacons within 4 m at 5 Hz with the stated sigmas.
// Returns the position NEES after 40 s.
double RunUltrasoundOnlyNees(std::uint64_t seed, double bearing_sigma_rad) {
  Random rng(seed);
  UltrasoundOnlyKf::Options o;
  o.bearing_sigma_rad = bearing_sigma_rad;
  o.gate_chi2_2dof = 1e9;  // the model's own noise: nothing to gate
  const Vec2 start(6, 4);
  UltrasoundOnlyKf kf(start, 0.0, o);
  Eigen::Vector4d x;
  x << start + Vec2(rng.Normal(0, o.initial_position_sigma_m), rng.Normal(0, o.initial_position_sigma_m)),
      rng.Normal(0, o.initial_velocity_sigma_mps), rng.Normal(0, o.initial_velocity_sigma_mps);
  std::vector<Vec2> beacons;
  for (int i = 0; i < 5; ++i)
    for (int j = 0; j < 3; ++j) beacons.emplace_back(3.0 * i, 4.0 * j);
  const double dt = 0.2, q = o.accel_sigma_mps2 * o.accel_sigma_mps2;
  Eigen::Matrix4d F = Eigen::Matrix4d::Identity(), Q = Eigen::Matrix4d::Zero();
  F(0, 2) = F(1, 3) = dt;
  for (int i = 0; i < 2; ++i) {
    Q(i, i) = q * dt * dt * dt / 3;
    Q(i, i + 2) = Q(i + 2, i) = q * dt * dt / 2;
    Q(i + 2, i + 2) = q * dt;
  }
  const Eigen::Matrix4d L = Q.llt().matrixL();
  for (int k = 1; k <= 200; ++k) {
    const Eigen::Vector4d w(rng.Normal(), rng.Normal(), rng.Normal(), rng.Normal());
    x = F * x + L * w;
    for (const Vec2& b : beacons) {
      const Vec2 rel = x.head<2>() - b;
      if (rel.norm() > 4.0 || rel.norm() < 0.5) continue;
      kf.UpdatePosition(dt * k, {b, Mat2::Zero()}, rel.norm() + rng.Normal(0, o.range_sigma_m),
                        std::atan2(rel.y(), rel.x()) + rng.Normal(0, bearing_sigma_rad));
    }
    kf.PredictTo(dt * k);
  }
  const Vec2 e = x.head<2>() - kf.position();
  return e.dot(kf.position_cov().ldlt().solve(e));
}

TEST(UltrasoundOnlyKf, IsNotOverconfidentOnItsOwnModel) {
  // 300 Monte Carlo runs, 2-dof position NEES; an overconfident filter's mean would lie above
  // the 95 % point of chi-square(2 x 300) / 300 (2.23). Measured 2026-12-02: 1.75 with a bearing
  // sigma of 0.05 rad and 2.01 with the moving node's 0.57 rad (the paper's characterization) —
  // with several beacons in range the first-order polar-to-position conversion holds here, unlike
  // the EKF's single-fix position update above. Neither is more than 2x conservative (mean > 1).
  const int runs = 300;
  double linear = 0, paper = 0;
  for (int s = 1; s <= runs; ++s) {
    linear += RunUltrasoundOnlyNees(static_cast<std::uint64_t>(s), 0.05) / runs;
    paper += RunUltrasoundOnlyNees(static_cast<std::uint64_t>(s), 0.57) / runs;
  }
  EXPECT_LT(linear, 2.23);
  EXPECT_LT(paper, 2.23);
  EXPECT_GT(linear, 1.0);
  EXPECT_GT(paper, 1.0);
}

TEST(UltrasoundOnlyKf, ConvergesOnAStandingNode) {
  Random rng(9);
  const Vec2 truth(2.0, 1.0);
  UltrasoundOnlyKf::Options o;
  o.initial_position_sigma_m = 3.0;  // the start is unknown
  o.accel_sigma_mps2 = 0.05;         // a standing node
  UltrasoundOnlyKf kf(Vec2(0, 0), 0.0, o);
  for (int k = 1; k <= 200; ++k) {
    const Vec2 b(k % 2 ? 0.0 : 4.0, 0.0);
    const Vec2 rel = truth - b;
    kf.UpdatePosition(0.3 * k, {b, Mat2::Zero()}, rel.norm() + rng.Normal(0, 0.1),
                      std::atan2(rel.y(), rel.x()) + rng.Normal(0, 0.1), 0.1, 0.1);
  }
  // A constant-velocity filter tracks rather than averages: its steady-state gain (tracking
  // index 0.02 here) averages ~10 fixes of 0.1 m / 0.22 m noise, so 0.25 m is ~3 sigma.
  EXPECT_LT((kf.position() - truth).norm(), 0.25);
  EXPECT_GT(kf.accepted(), 190u);
  // The prediction is the textbook white-noise-acceleration model.
  const Mat2 before = kf.position_cov();
  kf.PredictTo(0.3 * 200 + 1.0);
  EXPECT_GT(kf.position_cov()(0, 0), before(0, 0));
}

std::vector<InitMeasurement> InitData(const Vec2& origin, double psi, double noise,
                                      std::uint64_t seed, int n_beacons, double track_m) {
  Random rng(seed);
  std::vector<InitMeasurement> ms;
  std::vector<Vec2> beacons;
  for (int i = 0; i < n_beacons; ++i) beacons.emplace_back(2.0 * i, 1.5);
  for (int k = 0; k < 30; ++k) {
    const Vec2 pdr(track_m * k / 29.0, 0.2 * std::sin(0.5 * k));
    const Vec2 p = origin + Rot(psi) * pdr;
    for (const Vec2& b : beacons) {
      InitMeasurement m;
      m.pdr_n = pdr;
      m.beacon_n = b;
      m.range_m = (p - b).norm() + noise * rng.Normal();
      m.bearing_rad = std::atan2(p.y() - b.y(), p.x() - b.x()) + noise * rng.Normal();
      m.range_sigma_m = m.bearing_sigma_rad = std::max(noise, 0.01);
      ms.push_back(m);
    }
  }
  return ms;
}

TEST(InitializeFromUltrasound, RecoversTheStartExactlyFromExactData) {
  const Vec2 origin(1.0, -0.5);
  const double psi = 2.0;  // the PDR frame is far off: no prior needed
  const InitResult r = InitializeFromUltrasound(InitData(origin, psi, 0.0, 1, 3, 4.0));
  ASSERT_TRUE(r.ok) << r.why;
  EXPECT_LT((r.origin_n - origin).norm(), 1e-6);
  EXPECT_NEAR(WrapAngle(r.psi_rad - psi), 0.0, 1e-6);
  const InitResult noisy = InitializeFromUltrasound(InitData(origin, psi, 0.2, 2, 3, 4.0));
  ASSERT_TRUE(noisy.ok) << noisy.why;
  EXPECT_LT((noisy.origin_n - origin).norm(), 0.3);
  EXPECT_NEAR(WrapAngle(noisy.psi_rad - psi), 0.0, 0.15);
}

TEST(InitializeFromUltrasound, WaitsWhileTheHeadingIsNotObservable) {
  // One beacon and 0.5 m of walk: the heading cannot be known yet.
  const InitResult r = InitializeFromUltrasound(InitData(Vec2(1, 1), 0.5, 0.1, 3, 1, 0.5));
  EXPECT_FALSE(r.ok);
  EXPECT_FALSE(r.why.empty());
  EXPECT_FALSE(InitializeFromUltrasound({}).ok);
}

}  // namespace
}  // namespace trailmark::beacons

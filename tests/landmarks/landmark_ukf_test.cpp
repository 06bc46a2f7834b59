// SPDX-License-Identifier: MIT
// The landmark UKF: equal to a linear Kalman filter on the linear parts (prediction and
// acceleration/velocity updates), an RSSI update that moves the estimate toward a landmark it
// hears loudly, covariances symmetric positive definite throughout, and NEES consistency on
// its own model (Monte Carlo).
#include "trailmark/landmarks/landmark_ukf.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>

#include "trailmark/core/random.h"
#include "trailmark/integrity/consistency.h"

namespace trailmark::landmarks {
namespace {

TEST(LandmarkUkf, EqualsALinearKalmanFilterOnTheLinearCase) {
  const radio::LogDistanceModel radio{-30, 3, 4};
  LandmarkUkfOptions o;
  LandmarkUkf ukf(Vec2(1, 2), radio, o);
  // Reference KF with the same matrices, written out.
  LandmarkUkf::State x = ukf.state();
  LandmarkUkf::Cov P = ukf.covariance();
  Random rng(4);
  for (int k = 0; k < 200; ++k) {
    const double dt = 0.02;
    ukf.Predict(dt);
    const auto F = LandmarkUkf::Transition(dt);
    x = F * x;
    P = F * P * F.transpose() + LandmarkUkf::ProcessNoise(dt, o.tau);
    const Vec2 a(rng.Normal(0.5, 1), rng.Normal(-0.2, 1));
    ukf.UpdateAcceleration(a);
    Eigen::Matrix<double, 2, 6> H = Eigen::Matrix<double, 2, 6>::Zero();
    H(0, 4) = H(1, 5) = 1;
    const Mat2 R = Mat2::Identity() * o.accel_sigma_mps2 * o.accel_sigma_mps2;
    const Mat2 S = H * P * H.transpose() + R;
    const Eigen::Matrix<double, 6, 2> K = P * H.transpose() * S.inverse();
    x += K * (a - H * x);
    P = (LandmarkUkf::Cov::Identity() - K * H) * P;
    P = 0.5 * (P + P.transpose());
  }
  EXPECT_LT((ukf.state() - x).norm(), 1e-9);
  EXPECT_LT((ukf.covariance() - P).norm(), 1e-9);
  // Wiener-process kinematics: from rest with a constant acceleration a, the position after t
  // is a t^2 / 2 (no measurement, no noise).
  LandmarkUkf::State s = LandmarkUkf::State::Zero();
  s(4) = 2.0;
  for (int k = 0; k < 100; ++k) s = LandmarkUkf::Transition(0.01) * s;
  EXPECT_NEAR(s(0), 0.5 * 2.0 * 1.0, 1e-9);
}

TEST(LandmarkUkf, RssiPullsTowardTheLandmarkAndStaysPsd) {
  const radio::LogDistanceModel radio{-30, 3, 4};
  LandmarkUkfOptions o;
  o.initial_sigma_m = 3.0;
  const Vec2 truth(4, 0);
  const std::vector<Vec2> landmarks = {{0, 0}, {8, 0}, {4, 6}, {4, -6}};
  LandmarkUkf ukf(Vec2(0.5, 2.0), radio, o);
  Random rng(1);
  for (int k = 0; k < 60; ++k) {
    ukf.Predict(0.5);
    ukf.ZeroMotion();  // standing still
    for (const auto& l : landmarks) {
      const double rssi = -30 - 30 * std::log10((truth - l).norm()) + rng.Normal(0, 2);
      ukf.UpdateRssi(l, Mat2::Zero(), rssi);
    }
    const auto P = ukf.covariance();
    ASSERT_NEAR((P - P.transpose()).norm(), 0.0, 1e-12);
    ASSERT_GT(Eigen::SelfAdjointEigenSolver<LandmarkUkf::Cov>(P).eigenvalues().minCoeff(), 0.0);
  }
  EXPECT_LT((ukf.position() - truth).norm(), 0.5);
  EXPECT_LT(ukf.position_cov().trace(), 1.0);
}

}  // namespace
}  // namespace trailmark::landmarks

namespace trailmark::landmarks {
namespace {

// Simulates the filter's own model: the Wiener-process acceleration kinematics of eqs. (19)-(20)
// from a start drawn from the prior, acceleration measurements (eq. 22) at 10 Hz and RSSI of four
// landmarks by eq. (21) with the stated sigma at 2 Hz. Returns the NEES of the full state at
// the end of 30 s.
double RunNees(std::uint64_t seed) {
  Random rng(seed);
  const radio::LogDistanceModel radio{-40, 2.3, 6};
  LandmarkUkfOptions o;
  o.tau = 0.05;
  o.rssi_sigma_db = 6;
  o.gate_sigma = 1e9;  // the model's own noise is Gaussian: nothing to gate
  LandmarkUkf ukf(Vec2(5, 5), radio, o);
  auto draw = [&](const LandmarkUkf::Cov& P) {
    const LandmarkUkf::Cov L = P.llt().matrixL();
    LandmarkUkf::State z;
    for (int i = 0; i < 6; ++i) z(i) = rng.Normal();
    return LandmarkUkf::State(L * z);
  };
  LandmarkUkf::State x = ukf.state() + draw(ukf.covariance());
  const std::vector<Vec2> landmarks = {{0, 0}, {12, 0}, {0, 12}, {12, 12}};
  const double dt = 0.1;
  for (int k = 1; k <= 300; ++k) {
    x = LandmarkUkf::Transition(dt) * x + draw(LandmarkUkf::ProcessNoise(dt, o.tau));
    ukf.Predict(dt);
    ukf.UpdateAcceleration(x.tail<2>() + Vec2(rng.Normal(0, o.accel_sigma_mps2),
                                              rng.Normal(0, o.accel_sigma_mps2)));
    if (k % 5 != 0) continue;
    for (const Vec2& l : landmarks) {
      const double d = std::max((x.head<2>() - l).norm(), 0.1);
      const double rssi = radio.alpha_dbm - 10 * radio.path_loss_exponent * std::log10(d) +
                          rng.Normal(0, o.rssi_sigma_db);
      ukf.UpdateRssi(l, Mat2::Zero(), rssi);
    }
  }
  const LandmarkUkf::State e = x - ukf.state();
  return e.dot(ukf.covariance().ldlt().solve(e));
}

TEST(LandmarkUkf, NormalizedEstimationErrorSquaredIsWithinChiSquareBounds) {
  // 200 Monte Carlo runs: the average NEES of a consistent 6-state filter lies within the 95 %
  // two-sided chi-square interval of 6 x 200 degrees of freedom divided by 200 ([5.53, 6.50];
  // measured 6.17).
  const int runs = 200;
  double mean = 0;
  for (int s = 1; s <= runs; ++s) mean += RunNees(static_cast<std::uint64_t>(s)) / runs;
  EXPECT_GT(mean, integrity::ChiSquareQuantile(6 * runs, 0.025) / runs);
  EXPECT_LT(mean, integrity::ChiSquareQuantile(6 * runs, 0.975) / runs);
}

}  // namespace
}  // namespace trailmark::landmarks

// SPDX-License-Identifier: MIT
#include "trailmark/fusion/covariance_intersection.h"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <random>

namespace trailmark::fusion {
namespace {

Mat2 Cov(double sxx, double sxy, double syy) {
  Mat2 p;
  p << sxx, sxy, sxy, syy;
  return p;
}

double Det(const std::vector<PositionGaussian>& in, const std::vector<double>& w) {
  Mat2 m = Mat2::Zero();
  for (std::size_t i = 0; i < in.size(); ++i) m += w[i] * in[i].cov_m2.inverse();
  return m.determinant();
}

TEST(CovarianceIntersection, TwoEstimatesMatchABruteForceSearchOfTheWeight) {
  const std::vector<PositionGaussian> in{{Vec2(1, 2), Cov(4, 0.5, 0.3)},
                                         {Vec2(-1, 0.5), Cov(0.2, -0.1, 3)}};
  double best_w = 0, best_det = -1;
  for (int k = 0; k <= 100000; ++k) {
    const double w = k / 100000.0;
    const double d = Det(in, {w, 1 - w});
    if (d > best_det) {
      best_det = d;
      best_w = w;
    }
  }
  const Intersection ci = Intersect(in);
  EXPECT_NEAR(ci.weights[0], best_w, 1e-3);
  EXPECT_NEAR(ci.weights[0] + ci.weights[1], 1.0, 1e-12);
  // The fused estimate is the formula at that weight.
  const Mat2 m = ci.weights[0] * in[0].cov_m2.inverse() + ci.weights[1] * in[1].cov_m2.inverse();
  EXPECT_LT((ci.fused.cov_m2 - m.inverse()).norm(), 1e-12);
  const Vec2 x = m.inverse() * (ci.weights[0] * in[0].cov_m2.inverse() * in[0].mean_m +
                                ci.weights[1] * in[1].cov_m2.inverse() * in[1].mean_m);
  EXPECT_LT((ci.fused.mean_m - x).norm(), 1e-12);
  EXPECT_NEAR(1.0 / ci.fused.cov_m2.determinant(), best_det, 1e-6 * best_det);
}

TEST(CovarianceIntersection, ThreeEstimatesReachTheBestDeterminantOfAGridOverTheSimplex) {
  const std::vector<PositionGaussian> in{
      {Vec2(0, 0), Cov(1, 0.9, 1)}, {Vec2(1, 0), Cov(1, -0.9, 1)}, {Vec2(0, 1), Cov(0.5, 0, 2)}};
  double grid_best = -1;
  for (int a = 0; a <= 400; ++a) {
    for (int b = 0; a + b <= 400; ++b) {
      grid_best = std::max(grid_best, Det(in, {a / 400.0, b / 400.0, (400 - a - b) / 400.0}));
    }
  }
  const Intersection ci = Intersect(in);
  const double ours = Det(in, ci.weights);
  EXPECT_GE(ours, grid_best * (1 - 1e-6));
  for (double w : ci.weights) EXPECT_GE(w, 0.0);
}

TEST(CovarianceIntersection, AnEstimateInsideAllOthersTakesAllTheWeight) {
  const std::vector<PositionGaussian> in{
      {Vec2(3, 4), Cov(0.1, 0, 0.1)}, {Vec2(0, 0), Cov(5, 1, 6)}, {Vec2(9, 9), Cov(2, 0, 2)}};
  const Intersection ci = Intersect(in);
  EXPECT_GT(ci.weights[0], 0.999);
  EXPECT_LT((ci.fused.mean_m - Vec2(3, 4)).norm(), 1e-2);
  EXPECT_NEAR(ci.fused.cov_m2(0, 0), 0.1, 1e-3);
}

TEST(CovarianceIntersection, TheSameEstimateTwiceIsThatEstimate) {
  const PositionGaussian g{Vec2(2, -1), Cov(0.7, 0.2, 0.4)};
  const std::vector<PositionGaussian> in{g, g};
  const Intersection ci = Intersect(in);
  EXPECT_LT((ci.fused.mean_m - g.mean_m).norm(), 1e-12);
  EXPECT_LT((ci.fused.cov_m2 - g.cov_m2).norm(), 1e-12);
}

// The defining property: whatever the correlation of the inputs' errors, the intersection's
// covariance bounds the fused estimate's actual error covariance (exact, from the joint
// covariance of the two errors).
TEST(CovarianceIntersection, BoundsTheActualErrorCovarianceForEveryCorrelation) {
  std::mt19937 rng(7);
  std::normal_distribution<double> n01;
  for (int trial = 0; trial < 200; ++trial) {
    // A random joint covariance of the two errors (4x4, positive definite).
    Eigen::Matrix4d a;
    for (int i = 0; i < 16; ++i) a.data()[i] = n01(rng);
    const Eigen::Matrix4d joint = a * a.transpose() + 1e-3 * Eigen::Matrix4d::Identity();
    const std::vector<PositionGaussian> in{{Vec2::Zero(), joint.topLeftCorner<2, 2>()},
                                           {Vec2::Zero(), joint.bottomRightCorner<2, 2>()}};
    const Intersection ci = Intersect(in);
    const Mat2 k0 = ci.fused.cov_m2 * ci.weights[0] * in[0].cov_m2.inverse();
    const Mat2 k1 = ci.fused.cov_m2 * ci.weights[1] * in[1].cov_m2.inverse();
    Eigen::Matrix<double, 2, 4> k;
    k << k0, k1;
    const Mat2 actual = k * joint * k.transpose();
    const Eigen::SelfAdjointEigenSolver<Mat2> es(ci.fused.cov_m2 - actual);
    EXPECT_GE(es.eigenvalues().minCoeff(), -1e-9 * ci.fused.cov_m2.norm()) << trial;
  }
}

TEST(CovarianceIntersection, AZeroCovarianceIsFlooredNotInverted) {
  const std::vector<PositionGaussian> in{{Vec2(1, 1), Mat2::Zero()}, {Vec2(0, 0), Cov(1, 0, 1)}};
  const Intersection ci = Intersect(in);
  EXPECT_TRUE(ci.fused.mean_m.allFinite());
  EXPECT_TRUE(ci.fused.cov_m2.allFinite());
  EXPECT_LT((ci.fused.mean_m - Vec2(1, 1)).norm(), 1e-3);
  EXPECT_THROW(Intersect(std::vector<PositionGaussian>{}), std::invalid_argument);
}

}  // namespace
}  // namespace trailmark::fusion

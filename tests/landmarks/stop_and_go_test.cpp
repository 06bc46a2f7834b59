// SPDX-License-Identifier: MIT
// Stop-and-go localization (radio-landmarks paper, sec. 5.3): exact ranges converge to the truth,
// handheld localization with known landmarks, the solvability condition of eq. (8), degenerate
// geometry reported, a robust loss against NLOS outliers, and the energy model of sec. 4.2.
#include "trailmark/landmarks/stop_and_go.h"

#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <cmath>
#include <stdexcept>

#include "trailmark/core/random.h"
#include "trailmark/landmarks/energy.h"

namespace trailmark::landmarks {
namespace {

// Off the initialization grid (0.25 m), so that Gauss-Newton has work to do.
const std::vector<Vec2> kLandmarks = {{1.13, 2.47}, {6.08, -1.41}, {11.2, 2.53}, {15.9, -1.56}, {21.07, 2.44}};
const std::vector<Vec2> kStanding = {{0, 0.6}, {3.5, -0.6}, {7, 0.6}, {10.5, -0.6},
                                     {14, 0.6}, {17.5, -0.6}, {21, 0.6}};

StopAndGoProblem Exact(bool landmarks_known, bool standing_known) {
  StopAndGoProblem p;
  p.landmarks = landmarks_known ? kLandmarks : std::vector<Vec2>(kLandmarks.size(), Vec2::Zero());
  p.landmark_known.assign(kLandmarks.size(), landmarks_known);
  p.standing = standing_known ? kStanding : std::vector<Vec2>(kStanding.size(), Vec2::Zero());
  p.standing_known.assign(kStanding.size(), standing_known);
  for (const auto& h : kStanding) {
    std::vector<std::optional<double>> row;
    for (const auto& s : kLandmarks) row.push_back((h - s).norm());
    p.range_m.push_back(row);
    p.sigma_m.emplace_back(kLandmarks.size(), 0.3);
  }
  return p;
}

TEST(StopAndGo, ExactRangesConvergeToTheTruth) {
  const StopAndGoResult r = SolveStopAndGo(Exact(false, true));
  ASSERT_TRUE(r.solvable);
  EXPECT_FALSE(r.degenerate);
  EXPECT_GT(r.gn_iterations, 0);
  for (std::size_t j = 0; j < kLandmarks.size(); ++j) {
    EXPECT_LT((r.landmarks[j] - kLandmarks[j]).norm(), 1e-5) << j;
  }
  EXPECT_LT(r.rms_residual_m, 1e-6);
}

TEST(StopAndGo, HandheldWithKnownLandmarks) {
  const StopAndGoResult r = SolveStopAndGo(Exact(true, false));
  for (std::size_t p = 0; p < kStanding.size(); ++p) {
    EXPECT_LT((r.standing[p] - kStanding[p]).norm(), 1e-5) << p;
  }
}

TEST(StopAndGo, JointProblemRecoversTheShape) {
  // Nothing known: the geometry is recovered up to a rigid motion (compare distances).
  StopAndGoProblem p = Exact(false, false);
  // A rough start (e.g. from PDR) for the standing positions; landmarks by grid search.
  for (std::size_t k = 0; k < kStanding.size(); ++k) p.standing[k] = kStanding[k] + Vec2(0.3, -0.2);
  const StopAndGoResult r = SolveStopAndGo(p);
  EXPECT_TRUE(r.solvable);
  for (std::size_t a = 0; a < kLandmarks.size(); ++a) {
    for (std::size_t b = a + 1; b < kLandmarks.size(); ++b) {
      EXPECT_NEAR((r.landmarks[a] - r.landmarks[b]).norm(), (kLandmarks[a] - kLandmarks[b]).norm(), 1e-3);
    }
  }
}

TEST(StopAndGo, SolvabilityConditionOfEquationEight) {
  EXPECT_FALSE(SolvableStopAndGo(5, 3));  // q >= 10/3
  EXPECT_TRUE(SolvableStopAndGo(5, 4));
  EXPECT_FALSE(SolvableStopAndGo(3, 5));  // q >= 6
  EXPECT_TRUE(SolvableStopAndGo(3, 6));
  EXPECT_FALSE(SolvableStopAndGo(2, 100));
  StopAndGoProblem p = Exact(false, false);
  p.standing.resize(3);
  p.standing_known.resize(3);
  p.range_m.resize(3);
  p.sigma_m.resize(3);
  const StopAndGoResult r = SolveStopAndGo(p);
  EXPECT_FALSE(r.solvable);
  ASSERT_FALSE(r.notes.empty());
  EXPECT_NE(r.notes[0].find("eq. (8)"), std::string::npos);
}

TEST(StopAndGo, CollinearStandingPositionsAreReported) {
  StopAndGoProblem p = Exact(false, true);
  for (auto& h : p.standing) h.y() = 0;  // a straight corridor walk
  for (std::size_t k = 0; k < p.standing.size(); ++k) {
    for (std::size_t j = 0; j < kLandmarks.size(); ++j) p.range_m[k][j] = (p.standing[k] - kLandmarks[j]).norm();
  }
  const StopAndGoResult r = SolveStopAndGo(p);
  EXPECT_TRUE(r.degenerate);
  bool mirror = false;
  for (const auto& n : r.notes) mirror = mirror || n.find("mirror") != std::string::npos;
  EXPECT_TRUE(mirror);
}

TEST(StopAndGo, RobustLossResistsNlosOutliers) {
  Random rng(2);
  double err_sq = 0, err_huber = 0;
  for (int trial = 0; trial < 20; ++trial) {
    StopAndGoProblem p = Exact(false, true);
    for (auto& row : p.range_m) {
      for (auto& z : row) *z += rng.Normal(0, 0.2);
    }
    // NLOS: two links read 6 m long (a wall between).
    *p.range_m[1][2] += 6.0;
    *p.range_m[4][0] += 6.0;
    StopAndGoOptions sq;
    sq.loss = Loss::kSquared;
    const StopAndGoResult a = SolveStopAndGo(p, sq);
    const StopAndGoResult b = SolveStopAndGo(p);  // Huber
    for (std::size_t j = 0; j < kLandmarks.size(); ++j) {
      err_sq += (a.landmarks[j] - kLandmarks[j]).norm();
      err_huber += (b.landmarks[j] - kLandmarks[j]).norm();
    }
  }
  EXPECT_LT(err_huber, 0.7 * err_sq);
}

// The standing prior and landmark priors (ours): the solution minimizes the ranges' cost plus
// both priors. Reference: that cost written out here — its numerical gradient vanishes at the
// solution, and the inverse of its numerical Gauss-Newton matrix is the joint covariance.
TEST(StopAndGo, StandingPriorIsTheMinimumOfRangesAndPriors) {
  Random rng(5);
  StopAndGoProblem p = Exact(false, false);
  const std::size_t B = kLandmarks.size(), q = kStanding.size();
  for (auto& row : p.range_m) {
    for (auto& z : row) *z += rng.Normal(0, 0.1);
  }
  // Landmark 0 surveyed (sigma 0.2 m, 0.15 m off); the others unknown, found by grid search.
  p.landmark_prior_sigma_m.assign(B, 0.0);
  p.landmark_prior_sigma_m[0] = 0.2;
  p.landmarks[0] = kLandmarks[0] + Vec2(0.1, -0.11);
  // The prior: the walk turned by 3 degrees about its start (a heading error shared by all
  // stops) and shifted; its covariance that of such a heading error plus white noise.
  const double a = 0.052;
  Eigen::MatrixXd lever(2 * q, 1);
  for (std::size_t k = 0; k < q; ++k) {
    const Vec2 d = kStanding[k] - kStanding[0];
    p.standing[k] =
        kStanding[0] + Vec2(0.2, 0.1) +
        Vec2(std::cos(a) * d.x() - std::sin(a) * d.y(), std::sin(a) * d.x() + std::cos(a) * d.y());
    lever(2 * k, 0) = -d.y();
    lever(2 * k + 1, 0) = d.x();
  }
  const Eigen::MatrixXd prior_cov =
      0.06 * 0.06 * lever * lever.transpose() + 0.09 * Eigen::MatrixXd::Identity(2 * q, 2 * q);
  p.standing_prior_information = prior_cov.inverse();
  StopAndGoOptions o;
  o.loss = Loss::kSquared;
  const StopAndGoResult r = SolveStopAndGo(p, o);
  EXPECT_TRUE(r.solvable);
  ASSERT_EQ(r.standing_joint_cov.rows(), static_cast<Eigen::Index>(2 * q));
  // Unknowns [landmarks (2B); standing (2q)]; residuals: ranges, then priors (whitened).
  const Eigen::Index n = static_cast<Eigen::Index>(2 * (B + q));
  Eigen::VectorXd mean(2 * q);
  for (std::size_t k = 0; k < q; ++k) mean.segment<2>(2 * k) = p.standing[k];
  const Eigen::MatrixXd whiten =
      Eigen::LLT<Eigen::MatrixXd>(p.standing_prior_information).matrixU();
  const auto residuals = [&](const Eigen::VectorXd& u) {
    std::vector<double> out;
    for (std::size_t k = 0; k < q; ++k) {
      for (std::size_t j = 0; j < B; ++j) {
        const double d = (u.segment<2>(2 * (B + k)) - u.segment<2>(2 * j)).norm();
        out.push_back((d - *p.range_m[k][j]) / p.sigma_m[k][j]);
      }
    }
    const Eigen::VectorXd w = whiten * (u.tail(2 * q) - mean);
    for (Eigen::Index i = 0; i < w.size(); ++i) out.push_back(w(i));
    out.push_back((u(0) - p.landmarks[0].x()) / 0.2);
    out.push_back((u(1) - p.landmarks[0].y()) / 0.2);
    return Eigen::Map<Eigen::VectorXd>(out.data(), static_cast<Eigen::Index>(out.size())).eval();
  };
  Eigen::VectorXd u(n);
  for (std::size_t j = 0; j < B; ++j) u.segment<2>(2 * j) = r.landmarks[j];
  for (std::size_t k = 0; k < q; ++k) u.segment<2>(2 * (B + k)) = r.standing[k];
  const Eigen::VectorXd f0 = residuals(u);
  EXPECT_NEAR(0.5 * f0.squaredNorm(), r.cost, 1e-9 * r.cost);
  Eigen::MatrixXd J(f0.size(), n);
  const double h = 1e-6;
  for (Eigen::Index i = 0; i < n; ++i) {
    Eigen::VectorXd up = u, dn = u;
    up(i) += h;
    dn(i) -= h;
    J.col(i) = (residuals(up) - residuals(dn)) / (2 * h);
  }
  const Eigen::VectorXd gradient = J.transpose() * f0;
  EXPECT_LT(gradient.norm(), 1e-4) << gradient.transpose();
  // The covariance: (J^T J)^-1, scaled by the residual variance when above 1 (documented).
  const double dof = static_cast<double>(f0.size() - n);
  const double scale = std::max(1.0, 2.0 * r.cost / dof);
  const Eigen::MatrixXd cov = scale * (J.transpose() * J).inverse();
  const Eigen::MatrixXd standing_cov = cov.bottomRightCorner(2 * q, 2 * q);
  EXPECT_LT((r.standing_joint_cov - standing_cov).norm(), 1e-5 * standing_cov.norm());
  for (std::size_t j = 0; j < B; ++j) {
    EXPECT_LT((r.landmark_cov[j] - cov.block<2, 2>(2 * j, 2 * j)).norm(), 1e-5 * cov.norm()) << j;
  }
  // The radio took out most of the prior's turn: every stop closer to the truth than its prior.
  for (std::size_t k = 1; k < q; ++k) {
    EXPECT_LT((r.standing[k] - kStanding[k]).norm(), (p.standing[k] - kStanding[k]).norm()) << k;
  }
}

// The ranges' calibration (ours): ranges read through a radio model with the wrong intercept
// and exponent are z = e^a d^b of the true distances; from exact such ranges the solve recovers
// a and b and the geometry (the data outweigh the calibration's priors).
TEST(StopAndGo, RangeCalibrationRecoversTheModelsError) {
  StopAndGoProblem p = Exact(false, false);
  const double a = 0.3, b = 1.4;
  for (std::size_t k = 0; k < kStanding.size(); ++k) {
    for (std::size_t j = 0; j < kLandmarks.size(); ++j) {
      const double d = (kStanding[k] - kLandmarks[j]).norm();
      p.range_m[k][j] = std::exp(a) * std::pow(d, b);
      p.sigma_m[k][j] = 0.001 * *p.range_m[k][j];  // 0.1 % of the reading
    }
    p.standing[k] = kStanding[k];
  }
  p.landmark_prior_sigma_m.assign(kLandmarks.size(), 0.0);
  p.landmark_prior_sigma_m[0] = 0.2;
  p.landmarks[0] = kLandmarks[0];
  p.standing_prior_information = Eigen::MatrixXd::Identity(14, 14) / (0.3 * 0.3);
  p.range_calibration = StopAndGoProblem::RangeCalibration{};
  const StopAndGoResult r = SolveStopAndGo(p);
  EXPECT_NEAR(r.range_log_scale, a, 1e-2);
  EXPECT_NEAR(r.range_exponent_ratio, b, 1e-2);
  EXPECT_GT(r.range_exponent_ratio_sigma, 0.0);
  for (std::size_t j = 0; j < kLandmarks.size(); ++j) {
    EXPECT_LT((r.landmarks[j] - kLandmarks[j]).norm(), 0.02) << j;
  }
  // 35 ranges + 14 + 2 + 2 prior rows, 24 + 2 unknowns.
  EXPECT_EQ(r.dof, 35 + 14 + 2 + 2 - 26);
  // Without the calibration the same ranges cannot be fitted.
  p.range_calibration.reset();
  const StopAndGoResult plain = SolveStopAndGo(p);
  EXPECT_GT(plain.cost, 1e3 * std::max(r.cost, 1e-6));
}

// Without ranges, the standing positions are their prior: mean and joint covariance.
TEST(StopAndGo, StandingPriorAloneIsItself) {
  StopAndGoProblem p = Exact(true, false);
  for (auto& row : p.range_m) {
    for (auto& z : row) z.reset();
  }
  for (std::size_t k = 0; k < kStanding.size(); ++k)
    p.standing[k] = kStanding[k] + Vec2(0.1 * k, -0.2);
  Eigen::MatrixXd cov = Eigen::MatrixXd::Identity(14, 14) * 0.5;
  cov(0, 2) = cov(2, 0) = 0.3;
  p.standing_prior_information = cov.inverse();
  const StopAndGoResult r = SolveStopAndGo(p);
  for (std::size_t k = 0; k < kStanding.size(); ++k) {
    EXPECT_LT((r.standing[k] - p.standing[k]).norm(), 1e-12) << k;
  }
  EXPECT_LT((r.standing_joint_cov - cov).norm(), 1e-9);
  p.standing_prior_information = Eigen::MatrixXd::Identity(4, 4);  // not 14 x 14
  EXPECT_THROW(SolveStopAndGo(p), std::invalid_argument);
}

TEST(Energy, PaperSleepLifetimeAndOperatingTime) {
  const EnergyModel e;  // 230 mAh, 3.044 uA, 15 mA for 13 ms
  EXPECT_NEAR(e.SleepLifetimeS() / kSecondsPerYear, 8.62, 0.005);
  EXPECT_NEAR(e.ChargeLeftMAh(e.SleepLifetimeS()), 0.0, 1e-9);
  // Woken every second right away: 828 As / (0.013 * 0.015 + 0.987 * 3.044e-6) As per second.
  EXPECT_NEAR(e.MaxOperatingTimeS(0, 1.0) / 86400, 828.0 / (1.95e-4 + 0.987 * 3.044e-6) / 86400, 1e-6);
  EXPECT_LT(e.MaxOperatingTimeS(5 * kSecondsPerYear, 3), e.MaxOperatingTimeS(0, 3));
  EXPECT_THROW(e.MaxOperatingTimeS(0, 0.001), std::invalid_argument);  // shorter than a send
}

}  // namespace
}  // namespace trailmark::landmarks

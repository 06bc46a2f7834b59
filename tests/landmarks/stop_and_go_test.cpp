// SPDX-License-Identifier: MIT
// Stop-and-go localization (radio-landmarks paper, sec. 5.3): exact ranges converge to the truth,
// handheld localization with known landmarks, the solvability condition of eq. (8), degenerate
// geometry reported, a robust loss against NLOS outliers, and the energy model of sec. 4.2.
#include "trailmark/landmarks/stop_and_go.h"

#include <gtest/gtest.h>

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

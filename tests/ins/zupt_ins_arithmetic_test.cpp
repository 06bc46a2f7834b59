// SPDX-License-Identifier: MIT
// The INS's structured arithmetic (Phi P Phi^T from Phi's blocks, column-wise Kalman updates,
// the detector's running window sums) against the textbook dense form it replaces
// (`reference_arithmetic`: Phi as a full 15x15 matrix, P - K H P with the full H, every window
// summed anew), sample by sample: the same stance decisions and steps, positions within 1e-9 m,
// position covariances within 1e-9 relative. On simulated walks of every IMU grade and both
// state sizes, every detector, and on the recorded sets (skipped without ../shared/data).
#include <gtest/gtest.h>

#include <cmath>

#include "test_util.h"
#include "trailmark/core/random.h"
#include "trailmark/io/convert_foot_imu.h"
#include "trailmark/io/convert_pyshoe.h"
#include "trailmark/ins/zupt_detectors.h"
#include "trailmark/ins/zupt_ins.h"
#include "trailmark/sim/imu_sim.h"
#include "trailmark/sim/scenarios.h"

namespace trailmark::ins {
namespace {

struct Trace {
  std::vector<InsState> states;
  std::vector<Step> steps;
};

Trace RunIns(const std::vector<ImuSample>& imu, InsOptions options) {
  ZuptIns ins(options);
  Trace trace;
  ins.on_state = [&](const InsState& s) { trace.states.push_back(s); };
  ins.on_step = [&](const Step& s) { trace.steps.push_back(s); };
  for (const auto& s : imu) ins.Add(s);
  ins.Finish();
  return trace;
}

/// Runs both arithmetics; returns the largest position difference (m).
double CompareArithmetic(const std::vector<ImuSample>& imu, InsOptions options,
                         const std::string& what) {
  options.reference_arithmetic = false;
  const Trace fast = RunIns(imu, options);
  options.reference_arithmetic = true;
  const Trace dense = RunIns(imu, options);
  EXPECT_EQ(fast.states.size(), dense.states.size()) << what;
  EXPECT_EQ(fast.steps.size(), dense.steps.size()) << what;
  double worst = 0;
  std::size_t stance_differs = 0;
  for (std::size_t k = 0; k < std::min(fast.states.size(), dense.states.size()); ++k) {
    const InsState& a = fast.states[k];
    const InsState& b = dense.states[k];
    worst = std::max(worst, (a.position_n - b.position_n).norm());
    stance_differs += a.stance != b.stance;
    const double scale = std::max(b.position_cov.norm(), 1e-12);
    EXPECT_LE((a.position_cov - b.position_cov).norm(), 1e-9 * scale) << what << " sample " << k;
    EXPECT_EQ(a.position_cov, a.position_cov.transpose()) << what << " sample " << k;
    if (::testing::Test::HasFailure()) return worst;
  }
  EXPECT_EQ(stance_differs, 0u) << what;
  for (std::size_t k = 0; k < std::min(fast.steps.size(), dense.steps.size()); ++k) {
    EXPECT_EQ(fast.steps[k].t1, dense.steps[k].t1) << what;
    EXPECT_LE((fast.steps[k].delta_n - dense.steps[k].delta_n).norm(), 1e-9) << what;
  }
  EXPECT_LE(worst, 1e-9) << what;
  return worst;
}

std::vector<ImuSample> SimulatedWalk(const ImuGrade& grade, FootMotion motion, std::uint64_t seed) {
  const SimulatedMission sim = SimulateScenario("office-loop-1lap", seed);
  ImuSimOptions o;
  o.grade = grade;
  o.motion = motion;
  const auto& [id, walk] = sim.walks.front();
  return SimulateFootImu(walk, id, o, Random(seed + 100)).samples;
}

TEST(ZuptInsArithmetic, StructuredEqualsDenseOnSimulatedWalks) {
  int case_index = 0;
  for (const ImuGrade& grade : {ImuGrade::Tactical(), ImuGrade::Industrial(), ImuGrade::Consumer()}) {
    for (const FootMotion motion : {FootMotion::kWalk, FootMotion::kStairs}) {
      const auto imu = SimulatedWalk(grade, motion, 11 + case_index++);
      for (const bool biases : {true, false}) {
        InsOptions o;
        o.estimate_biases = biases;
        CompareArithmetic(imu, o, grade.name + (biases ? " 15 states" : " 9 states"));
      }
    }
  }
}

TEST(ZuptInsArithmetic, StructuredEqualsDenseForEveryDetector) {
  const auto imu = SimulatedWalk(ImuGrade::Industrial(), FootMotion::kWalk, 5);
  for (const DetectorKind kind : {DetectorKind::kShoe, DetectorKind::kAre, DetectorKind::kMv,
                                  DetectorKind::kMag, DetectorKind::kAdaptive}) {
    InsOptions o;
    o.detector.kind = kind;
    CompareArithmetic(imu, o, ToString(kind));
  }
}

// The running window sums against the window summed anew, on a long noisy stream with rests
// (the statistic near zero, where the expanded form cancels most) and a window of 41 samples.
TEST(ZuptInsArithmetic, RunningDetectorSumsEqualTheWindowSummedAnew) {
  Random rng(3);
  for (const DetectorKind kind : {DetectorKind::kShoe, DetectorKind::kAre, DetectorKind::kMv,
                                  DetectorKind::kMag, DetectorKind::kAdaptive}) {
    DetectorOptions o;
    o.kind = kind;
    o.window = 41;
    DetectorOptions ref = o;
    ref.reference_arithmetic = true;
    ZuptDetector fast(o), dense(ref);
    std::size_t decisions = 0, stance = 0;
    for (int k = 0; k < 100000; ++k) {
      const bool rest = (k / 400) % 2 == 0;
      const double e = rest ? 0.0 : std::sin(0.02 * k);
      const Vec3 a(rng.Normal(0, 0.001) + 12 * e, rng.Normal(0, 0.001), 9.8029 + 8 * e);
      const Vec3 w(rng.Normal(0, 1e-4), rng.Normal(0, 1e-4) + 5 * e, rng.Normal(0, 1e-4));
      const auto x = fast.Add(a, w, 1.0 / 820);
      const auto y = dense.Add(a, w, 1.0 / 820);
      ASSERT_EQ(x.has_value(), y.has_value());
      if (!x) continue;
      ++decisions;
      stance += y->stance;
      ASSERT_EQ(x->stance, y->stance) << ToString(kind) << " sample " << k;
      // The expanded form cancels terms of g^2 / sigma_a^2 per sample (~1e8): 1e-12 of that in
      // absolute terms (4 orders below the thresholds' scale of 1e7-1e8), else 1e-9 relative.
      const double cancelled = 9.8029 * 9.8029 / (o.sigma_a_mps2 * o.sigma_a_mps2);
      const double slack = std::max(1e-9 * y->statistic, 1e-12 * cancelled);
      ASSERT_NEAR(x->statistic, y->statistic, slack) << ToString(kind) << " sample " << k;
    }
    EXPECT_GT(decisions, 99000u);
    EXPECT_GT(stance, 10000u) << ToString(kind);  // both phases exercised
    EXPECT_LT(stance, decisions - 10000) << ToString(kind);
  }
}

TEST(ZuptInsArithmetic, StructuredEqualsDenseOnRecordedSets) {
  bool any = false;
  if (const auto dir = testing::SharedData("openshoe-figure8"); !dir.empty()) {
    any = true;
    CompareArithmetic(ReadOpenShoeFigure8(dir / "imu_820hz.txt").imu, InsOptions{}, "figure-8");
  }
  if (const auto dir = testing::SharedData("pyshoe-vicon"); !dir.empty()) {
    any = true;
    for (const char* name : {"2017-11-22-11-22-03", "2017-11-27-11-11-53"}) {
      CompareArithmetic(ReadPyShoeTrial(dir / (std::string(name) + ".csv")).imu, InsOptions{}, name);
    }
  }
  if (const auto dir = testing::SharedData("zupt-dualfoot-60hz"); !dir.empty()) {
    any = true;
    const MissionData walk = ReadDualFoot(dir);
    std::vector<ImuSample> left;
    for (const auto& s : walk.imu) {
      if (s.agent == walk.imu.front().agent) left.push_back(s);
    }
    CompareArithmetic(left, InsOptions{}, "dual-foot");
  }
  if (!any) GTEST_SKIP() << "../shared/data not present";
}

}  // namespace
}  // namespace trailmark::ins

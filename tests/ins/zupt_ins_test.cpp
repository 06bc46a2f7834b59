// SPDX-License-Identifier: MIT
// The ZUPT INS: an exact reference (pure translation with known acceleration pulses), drift of
// a stationary IMU for 10 minutes within what ZUPTs allow, detectors against labelled stance,
// bad units reported, and the recorded PyShoe trials (skipped without ../shared/data).
#include "trailmark/ins/zupt_ins.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>

#include "test_util.h"
#include "trailmark/core/random.h"
#include "trailmark/eval/trajectory_metrics.h"
#include "trailmark/io/convert_pyshoe.h"

namespace trailmark::ins {
namespace {

constexpr double kG = 9.8029;

/// A level foot at rest for `rest` s, then pushed along +x by +a for T s and braked by -a for
/// T s (displacement a T^2, no rotation), repeated `strides` times; 200 Hz, noise-free.
std::vector<ImuSample> TranslationStrides(int strides, double a, double T, double rest) {
  std::vector<ImuSample> out;
  const double dt = 0.005;
  double t = 0;
  auto emit = [&](double ax, double duration) {
    const int n = static_cast<int>(std::lround(duration / dt));
    for (int k = 0; k < n; ++k) {
      out.push_back({t, "foot", Vec3(ax, 0, kG), Vec3::Zero()});
      t += dt;
    }
  };
  emit(0, rest);
  for (int s = 0; s < strides; ++s) {
    emit(a, T);
    emit(-a, T);
    emit(0, rest);
  }
  return out;
}

/// The strides' detector (accelerometer-only: stance = |a| == g) and one step per stride.
InsOptions StrideOptions() {
  InsOptions o;
  o.detector.kind = DetectorKind::kMag;
  o.detector.gamma = 1.0;
  o.mid_swing_steps = false;
  return o;
}

TEST(ZuptIns, PureTranslationIsIntegratedExactlyAndGivesOneStepPerStride) {
  InsOptions o;
  o.detector.kind = DetectorKind::kMag;  // accelerometer-only: stance = |a| == g
  o.detector.gamma = 1.0;
  o.mid_swing_steps = false;  // one step per stride (the mid-swing steps: the test below)
  const auto imu = TranslationStrides(5, 4.0, 0.25, 0.4);  // 0.25 m per stride
  ZuptIns ins(o);
  std::vector<Step> steps;
  ins.on_step = [&](const Step& s) { steps.push_back(s); };
  InsState last;
  ins.on_state = [&](const InsState& s) { last = s; };
  for (const auto& s : imu) ins.Add(s);
  ins.Finish();
  ASSERT_EQ(steps.size(), 5u);
  for (const auto& s : steps) {
    EXPECT_NEAR(s.delta_n.x(), 0.25, 0.01);  // a T^2 (discretization: < 1 cm)
    EXPECT_NEAR(s.delta_n.y(), 0.0, 1e-9);
    EXPECT_NEAR(s.delta_n.z(), 0.0, 1e-3);
    ASSERT_TRUE(s.variance_m2);
    EXPECT_GT(s.variance_m2->x(), 0.0);
  }
  EXPECT_NEAR(last.position_n.x(), 1.25, 0.05);
  EXPECT_NEAR(ins.summary().distance_m, 1.25, 0.05);
}

TEST(ZuptIns, EachStepCarriesTheGrowthOfTheFiltersYawVariance) {
  // The yaw is not observed by zero-velocity updates: its variance grows with the gyro's noise
  // and bias, and each step carries its growth since the last step (what the consumers take as
  // the INS's own heading walk, PdrOptions::HeadingWalkVariance). A noisier gyro stated makes
  // it grow faster.
  auto run = [](double gyro_noise_scale) {
    InsOptions o;
    o.detector.kind = DetectorKind::kMag;
    o.detector.gamma = 1.0;
    o.mid_swing_steps = false;
    o.gyro_noise_radps *= gyro_noise_scale;
    ZuptIns ins(o);
    std::vector<Step> steps;
    ins.on_step = [&](const Step& s) { steps.push_back(s); };
    for (const auto& s : TranslationStrides(8, 4.0, 0.25, 0.4)) ins.Add(s);
    ins.Finish();
    return steps;
  };
  const auto steps = run(1.0), noisier = run(2.0);
  ASSERT_EQ(steps.size(), 8u);
  ASSERT_EQ(noisier.size(), 8u);
  double sum = 0, sum_noisier = 0;
  for (std::size_t k = 0; k < steps.size(); ++k) {
    ASSERT_TRUE(steps[k].heading_var_rad2);
    EXPECT_TRUE(std::isfinite(*steps[k].heading_var_rad2));
    EXPECT_GT(*steps[k].heading_var_rad2, 0.0);
    sum += *steps[k].heading_var_rad2;
    sum_noisier += *noisier[k].heading_var_rad2;
  }
  EXPECT_GT(sum_noisier, 1.3 * sum);  // (the gyro bias's share grows less)
  EXPECT_LT(sum_noisier, 4.5 * sum);  // at most the gyro noise's variance ratio (and bias)
}

TEST(ZuptIns, AGyroOutsideTheStatedModelGivesStepsWithoutAHeadingVarianceOfTheirOwn) {
  // The same strides read by a gyro with 1.7 deg/s of bias on z (an uncalibrated consumer
  // part's), ten times the stated sigma: the INS says its own errors are not this device's —
  // no heading variance on its steps (consumers go on with a PDR's errors) and a warning.
  const InsOptions o = StrideOptions();
  auto run = [&o](double bias_radps) {
    ZuptIns ins(o);
    std::vector<Step> steps;
    ins.on_step = [&](const Step& s) { steps.push_back(s); };
    for (auto s : TranslationStrides(4, 4.0, 0.25, 0.4)) {
      s.gyro_b.z() += bias_radps;
      ins.Add(s);
    }
    ins.Finish();
    return std::make_pair(steps, ins);
  };
  const auto [biased, biased_ins] = run(0.03);
  ASSERT_EQ(biased.size(), 4u);
  EXPECT_FALSE(biased_ins.OwnErrorsHold());
  for (const auto& s : biased) EXPECT_FALSE(s.heading_var_rad2.has_value());
  ASSERT_FALSE(biased_ins.summary().warnings.empty());
  EXPECT_NE(biased_ins.summary().warnings.back().find("gyro bias at rest"), std::string::npos);
  // Within the stated sigma (a third of it): the steps carry it.
  const auto [fine, fine_ins] = run(o.gyro_bias_sigma0 / 3);
  EXPECT_TRUE(fine_ins.OwnErrorsHold());
  ASSERT_EQ(fine.size(), 4u);
  for (const auto& s : fine) EXPECT_TRUE(s.heading_var_rad2.has_value());
}

// The steps sum to the INS's walk even when the detector does not see the rest at the start
// as stance (an uncalibrated consumer gyro reads degrees per second at rest, above the
// detector's threshold until the bias is estimated; here the foot's rest shakes vertically,
// zero mean, which the accelerometer-only detector reads as motion): the first stance then
// comes after the first stride, and the walk to it was in no step (imu family, corridor K 1:
// every consumer 1.4 m behind the INS for the whole walk). The first step starts at the
// alignment's state instead.
TEST(ZuptIns, TheStepsSumToTheWalkWhenTheRestAtTheStartIsNotSeenAsStance) {
  const InsOptions o = StrideOptions();
  auto run = [&o](double shake_mps2) {
    ZuptIns ins(o);
    std::vector<Step> steps;
    ins.on_step = [&](const Step& s) { steps.push_back(s); };
    for (auto s : TranslationStrides(4, 4.0, 0.25, 0.4)) {
      if (s.t < 0.4) s.accel_b.z() += shake_mps2 * std::sin(2 * M_PI * 10 * s.t);
      ins.Add(s);
    }
    ins.Finish();
    Vec2 sum = Vec2::Zero();
    for (const Step& st : steps) sum += st.delta_n.head<2>();
    return std::make_pair(steps, Vec2(sum - ins.LastState()->position_n.head<2>()));
  };
  const auto [quiet, quiet_gap] = run(0.0);
  ASSERT_EQ(quiet.size(), 4u);
  EXPECT_LT(quiet_gap.norm(), 1e-3);
  const auto [shaken, shaken_gap] = run(3.0);
  ASSERT_FALSE(shaken.empty());
  EXPECT_LT(shaken.front().t0, 0.05);  // from the alignment's state, not the first stance's
  EXPECT_LT(shaken_gap.norm(), 0.02) << shaken.size() << " steps";
  EXPECT_NEAR(shaken.front().delta_n.x(), 0.25, 0.05);
}

// A resting gyro's mean above kRestGyroBiasRadps is ambiguous over the short alignment: a large
// turn-on bias (an uncalibrated consumer part: 4 deg/s here) or a foot still turning as it
// settles (6 deg/s for the first 0.1 s, nothing after: the LLIO walks' start). Either way the
// first stances' ZARU must find the bias: with the stated prior alone the gate refused the
// 4 deg/s at every stance and the walk turned 30 deg in 8 strides (before 2026-12-07); taken as
// the bias from the alignment, the settling foot's 6 deg/s would have been refused the same way.
TEST(ZuptIns, AnAmbiguousGyroMeanAtTheStartIsSettledByTheFirstStances) {
  const InsOptions o = StrideOptions();
  ASSERT_GT(0.07, ZuptIns::kRestGyroBiasRadps);
  auto run = [&o](double bias_radps, double settling_radps) {
    ZuptIns ins(o);
    std::vector<Step> steps;
    ins.on_step = [&](const Step& s) { steps.push_back(s); };
    for (auto s : TranslationStrides(8, 4.0, 0.25, 0.4)) {
      s.gyro_b.z() += bias_radps + (s.t < 0.1 ? settling_radps : 0.0);
      ins.Add(s);
    }
    ins.Finish();
    return std::make_pair(steps, ins.summary().gyro_bias);
  };
  for (const auto& [bias, settling] : {std::pair{0.07, 0.0}, std::pair{0.0, 0.1}}) {
    const auto [steps, estimated] = run(bias, settling);
    ASSERT_EQ(steps.size(), 8u) << bias;
    EXPECT_NEAR(estimated.z(), bias, 0.005) << bias;
    for (const auto& s : steps) {  // every stride along +x (0.25 m), none turned
      const double turned_deg = std::atan2(s.delta_n.y(), s.delta_n.x()) * 180 / M_PI;
      EXPECT_LT(std::abs(turned_deg), 2.0) << bias << " " << s.t1;
    }
  }
}

// A gyro bias that jumps during the walk (3.4 deg/s on z from the fourth stride on: a
// temperature step, a knock) is refused by the ZARU gate at every stance, steadily: after
// zaru_recover_s of such stance the bias's covariance grows to take it and the walk stops
// turning; the heading already turned stays (nothing observes the yaw), its variance grown by
// what the bias turned meanwhile. With the gate alone (zaru_recover_s = 0) it turns for ever.
TEST(ZuptIns, ABiasTheGateRefusesSteadilyIsTakenAfterASecondOfStance) {
  auto run = [](double recover_s) {
    InsOptions o = StrideOptions();
    o.zaru_recover_s = recover_s;
    ZuptIns ins(o);
    std::vector<Step> steps;
    ins.on_step = [&](const Step& s) { steps.push_back(s); };
    for (auto s : TranslationStrides(12, 4.0, 0.25, 0.4)) {
      if (s.t > 3 * 0.9 + 0.4) s.gyro_b.z() += 0.06;
      ins.Add(s);
    }
    ins.Finish();
    return std::make_tuple(steps, ins.summary(), ins.LastState()->position_cov);
  };
  const auto [steps, summary, cov] = run(1.0);
  const auto [gated, gated_summary, gated_cov] = run(0.0);
  ASSERT_EQ(steps.size(), 12u);
  ASSERT_EQ(gated.size(), 12u);
  EXPECT_EQ(summary.zaru_recoveries, 1u);
  EXPECT_EQ(gated_summary.zaru_recoveries, 0u);
  EXPECT_NEAR(summary.gyro_bias.z(), 0.06, 0.005);
  EXPECT_LT(gated_summary.gyro_bias.z(), 0.01);
  auto direction_deg = [](const Step& s) {
    return std::atan2(s.delta_n.y(), s.delta_n.x()) * 180 / M_PI;
  };
  // The last strides no longer turn once the bias is taken; with the gate alone each turns by
  // the bias times a stride's 0.9 s (3 deg).
  EXPECT_LT(std::abs(direction_deg(steps[11]) - direction_deg(steps[10])), 0.3);
  EXPECT_GT(std::abs(direction_deg(gated[11]) - direction_deg(gated[10])), 2.5);
  // The turn before the recovery is in the covariance: wider than the gated run's across the walk.
  EXPECT_GT(cov(1, 1), gated_cov(1, 1));
}

// When a step ends: the strides above land at rest + k (2T + rest) + 2T and lift off at
// (k + 1)(2T + rest) + rest. At the landing (default) each step's t1 is the landing, within the
// detector's `min_stance_samples` (and its window); at the lift-off (the old behaviour) one rest
// later. The displacements are the same either way.
TEST(ZuptIns, AStepEndsWhenTheFootLandsUnlessAskedForTheLiftOff) {
  const double T = 0.25, rest = 0.4, dt = 0.005;
  const auto imu = TranslationStrides(5, 4.0, T, rest);
  auto steps_of = [&](bool at_landing) {
    InsOptions o = StrideOptions();
    o.step_at_landing = at_landing;
    ZuptIns ins(o);
    std::vector<Step> steps;
    ins.on_step = [&](const Step& s) { steps.push_back(s); };
    for (const auto& s : imu) ins.Add(s);
    ins.Finish();
    return steps;
  };
  const std::vector<Step> landing = steps_of(true), lift_off = steps_of(false);
  ASSERT_EQ(landing.size(), 5u);
  ASSERT_EQ(lift_off.size(), 5u);  // the last stance ends with the data
  for (std::size_t k = 0; k < landing.size(); ++k) {
    const double landed = rest + k * (2 * T + rest) + 2 * T;
    EXPECT_GE(landing[k].t1, landed - 1e-9) << k;
    EXPECT_LT(landing[k].t1, landed + 12 * dt) << k;  // 3 samples and the detector's window
    EXPECT_NEAR(landing[k].delta_n.x(), 0.25, 0.01);
    EXPECT_NEAR(lift_off[k].t1, landed + rest, 12 * dt) << k;
    EXPECT_NEAR(lift_off[k].delta_n.x(), 0.25, 0.01);
  }
}

// Half way through each swing a step ends too (from the second swing on: the first has no
// swing before it to time the half by): a swing pushed for T and braked for T is half way,
// a T^2 / 2 = 0.125 m, after T; the landing's step is the other half. The same total.
TEST(ZuptIns, AStepEndsHalfWayThroughEachSwingToo) {
  const double T = 0.25, rest = 0.4, dt = 0.005;
  const auto imu = TranslationStrides(5, 4.0, T, rest);
  InsOptions o;
  o.detector.kind = DetectorKind::kMag;
  o.detector.gamma = 1.0;
  ASSERT_TRUE(o.mid_swing_steps);  // the default
  ZuptIns ins(o);
  std::vector<Step> steps;
  ins.on_step = [&](const Step& s) { steps.push_back(s); };
  for (const auto& s : imu) ins.Add(s);
  ins.Finish();
  ASSERT_EQ(steps.size(), 9u);
  EXPECT_NEAR(steps[0].delta_n.x(), 0.25, 0.01);  // the first stride: landing only
  double total = 0;
  for (const Step& s : steps) total += s.delta_n.x();
  EXPECT_NEAR(total, 1.25, 0.05);
  for (int k = 1; k < 5; ++k) {
    const Step& mid = steps[2 * k - 1];
    const Step& landing = steps[2 * k];
    const double lift_off = rest + k * (2 * T + rest);  // this stride's swing starts
    EXPECT_NEAR(mid.t1, lift_off + T, 12 * dt) << k;
    EXPECT_NEAR(mid.delta_n.x(), 0.125, 0.01) << k;
    EXPECT_NEAR(landing.delta_n.x(), 0.125, 0.01) << k;
    EXPECT_GT(landing.t1, mid.t1);
  }
}

// A stationary MEMS IMU (white noise and a constant bias) for 10 minutes: every sample is a
// stance, the ZUPTs hold the velocity at zero within sigma_zupt, and the position may only
// random-walk with that residual: sigma_v * sqrt(T * dt) ~ 0.01 m/s * sqrt(600 s * 0.01 s) =
// 2.4 cm. Tested at 10 cm (4 sigma); the covariance stays symmetric positive definite.
TEST(ZuptIns, StationaryTenMinutesStaysPut) {
  Random rng(3);
  InsOptions o;
  ZuptIns ins(o);
  InsState last;
  std::size_t stance = 0, samples = 0;
  ins.on_state = [&](const InsState& s) {
    last = s;
    stance += s.stance;
    ++samples;
  };
  const Vec3 bias_a(0.02, -0.01, 0.03), bias_g(0.002, -0.001, 0.0015);
  for (int k = 0; k < 60000; ++k) {  // 100 Hz
    ImuSample s;
    s.t = 0.01 * k;
    s.agent = "foot";
    s.accel_b = Vec3(0, 0, kG) + bias_a + Vec3(rng.Normal(0, 0.01), rng.Normal(0, 0.01), rng.Normal(0, 0.01));
    s.gyro_b = bias_g + Vec3(rng.Normal(0, 1e-4), rng.Normal(0, 1e-4), rng.Normal(0, 1e-4));
    ins.Add(s);
  }
  ins.Finish();
  EXPECT_EQ(samples, 60000u);
  EXPECT_GT(static_cast<double>(stance) / samples, 0.99);
  EXPECT_LT(last.position_n.head<2>().norm(), 0.10);
  EXPECT_LT(last.velocity_n.norm(), 0.01);
  EXPECT_NEAR(last.position_cov(0, 1), last.position_cov(1, 0), 1e-12);
  EXPECT_GT(last.position_cov.determinant(), 0);
  EXPECT_EQ(ins.summary().steps, 0u);
}

/// Labelled synthetic gait: stance (gravity + sensor noise) alternating with swing (large
/// rotation and specific force), at the given stance and swing lengths.
struct Labelled {
  std::vector<ImuSample> imu;
  std::vector<bool> stance;
};
Labelled SyntheticGait(double swing_scale, int stance_n, int swing_n, std::uint64_t seed) {
  Random rng(seed);
  Labelled out;
  double t = 0;
  for (int cycle = 0; cycle < 40; ++cycle) {
    for (int k = 0; k < stance_n; ++k, t += 0.005) {
      out.imu.push_back({t, "foot",
                         Vec3(rng.Normal(0, 0.02), rng.Normal(0, 0.02), kG + rng.Normal(0, 0.02)),
                         Vec3(rng.Normal(0, 0.005), rng.Normal(0, 0.005), rng.Normal(0, 0.005))});
      out.stance.push_back(true);
    }
    for (int k = 0; k < swing_n; ++k, t += 0.005) {
      // Swing: a rotation and specific force that never fall below 30 % of their peak (a foot
      // in the air does not rest), plus the 30 Hz shake of heel-off and toe-off.
      const double ph = 3.14159265 * k / swing_n, env = 0.3 + 0.7 * std::sin(ph);
      const double shake = 3.0 * std::sin(2 * 3.14159265 * 30 * t);
      out.imu.push_back({t, "foot",
                         Vec3(swing_scale * (15 * env + shake), shake, kG + swing_scale * 10 * env),
                         Vec3(0, swing_scale * 6 * env, 0)});
      out.stance.push_back(false);
    }
  }
  return out;
}

class DetectorTest : public ::testing::TestWithParam<const char*> {};

TEST_P(DetectorTest, FindsLabelledStanceInWalkingAndRunning) {
  for (double swing : {1.0, 2.5}) {  // walking, running-like swing energy
    const Labelled gait = SyntheticGait(swing, 60, 80, 7);
    DetectorOptions o;
    o.kind = ParseDetectorKind(GetParam());
    ZuptDetector det(o);
    std::vector<bool> found;
    for (const auto& s : gait.imu) {
      if (auto d = det.Add(s.accel_b, s.gyro_b, 0.005)) found.push_back(d->stance);
    }
    for (const auto& d : det.Flush()) found.push_back(d.stance);
    ASSERT_EQ(found.size(), gait.stance.size());
    const PrecisionRecall pr = ComparePrecisionRecall(found, gait.stance);
    EXPECT_GT(pr.precision, 0.95) << GetParam() << " swing " << swing;
    EXPECT_GT(pr.recall, 0.80) << GetParam() << " swing " << swing;
  }
}

INSTANTIATE_TEST_SUITE_P(AllDetectors, DetectorTest,
                         ::testing::Values("shoe", "are", "mv", "mag", "adaptive"));

TEST(ZuptIns, ReportsWrongUnits) {
  auto run = [](double accel_scale, double gyro_scale, double gyro_value) {
    ZuptIns ins;
    for (int k = 0; k < 100; ++k) {
      ins.Add({0.005 * k, "foot", Vec3(0, 0, kG) * accel_scale, Vec3(0, gyro_value, 0) * gyro_scale});
    }
    ins.Finish();
  };
  try {
    run(1.0 / 9.80665, 1.0, 0.0);
    FAIL() << "g units not detected";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("in g, not m/s^2"), std::string::npos) << e.what();
  }
  try {
    run(1.0, 180.0 / 3.14159265, 3.0);  // 3 rad/s swing written in deg/s: 172
    FAIL() << "deg/s not detected";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("deg/s"), std::string::npos) << e.what();
  }
  try {
    run(0.5, 1.0, 0.0);  // 4.9 m/s^2 at rest: neither g nor m/s^2
    FAIL() << "implausible gravity not detected";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("not at rest"), std::string::npos) << e.what();
  }
  EXPECT_THROW(ZuptIns().Add({0, "foot", Vec3(0, 0, NAN), Vec3::Zero()}), std::invalid_argument);
}

TEST(ZuptIns, ReportsSaturationAndGaps) {
  ZuptIns ins;
  for (int k = 0; k < 400; ++k) {
    double t = 0.005 * k + (k >= 300 ? 0.5 : 0.0);  // a 0.5 s gap at sample 300
    Vec3 a(0, 0, kG);
    if (k >= 100 && k < 110) a.x() = 78.45;  // clipped at 8 g for 10 samples
    ins.Add({t, "foot", a, Vec3::Zero()});
  }
  ins.Finish();
  EXPECT_GE(ins.summary().saturated, 8u);
  EXPECT_EQ(ins.summary().gaps, 1u);
  bool saturation_warned = false, gap_warned = false;
  for (const auto& w : ins.summary().warnings) {
    saturation_warned = saturation_warned || w.find("saturates") != std::string::npos;
    gap_warned = gap_warned || w.find("gap of 0.505 s") != std::string::npos;
  }
  EXPECT_TRUE(saturation_warned);
  EXPECT_TRUE(gap_warned);
}

// Recorded: three PyShoe VICON trials with the default (adaptive) detector and one
// configuration; PyShoe's fixed-threshold SHOE scores 0.303 m mean over all 42 trials.
TEST(ZuptIns, RecordedPyShoeTrials) {
  const auto dir = testing::SharedData("pyshoe-vicon");
  if (dir.empty()) GTEST_SKIP() << "../shared/data/pyshoe-vicon not present";
  double sum = 0;
  int n = 0;
  for (const char* name : {"2017-11-22-11-22-03", "2017-11-22-11-35-59", "2017-11-27-11-11-53"}) {
    const PyShoeTrial trial = ReadPyShoeTrial(dir / (std::string(name) + ".csv"));
    ZuptIns ins;
    std::vector<Vec3> est;
    ins.on_state = [&](const InsState& s) { est.push_back(s.position_n); };
    for (const auto& s : trial.imu) ins.Add(s);
    ins.Finish();
    ASSERT_EQ(est.size(), trial.imu.size());
    const double armse = HeadingAlignedArmse(est, trial.truth_n, 0.8);
    EXPECT_LT(armse, 0.3) << name;
    sum += armse;
    ++n;
  }
  EXPECT_LT(sum / n, 0.2);
}

}  // namespace
}  // namespace trailmark::ins

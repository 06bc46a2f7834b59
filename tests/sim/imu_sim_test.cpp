// SPDX-License-Identifier: MIT
// Foot-IMU simulation against the INS: a perfect IMU is integrated back to the true foot path
// (the simulator and the mechanization agree), the tactical-grade closed 400 m loop ends within
// 1 % of the distance (issue 3), stairs climb, and the output is deterministic per seed.
#include "trailmark/sim/imu_sim.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <optional>

#include "trailmark/eval/trajectory_metrics.h"
#include "trailmark/ins/zupt_ins.h"
#include "trailmark/sim/scenarios.h"

namespace trailmark {
namespace {

struct InsRun {
  double end_error_m = 0, distance_m = 0, z_error_m = 0, stance_agreement = 0;
};

/// `stated_start`: the foot rests facing the mission's start heading, as AddFootImu has it (else
/// facing its first step).
InsRun RunInsOn(const std::string& scenario, const ImuGrade& grade, FootMotion motion,
                std::uint64_t seed, bool stated_start = false) {
  const SimulatedMission sim = SimulateScenario(scenario, seed);
  ImuSimOptions o;
  o.grade = grade;
  o.motion = motion;
  const auto& [id, walk] = sim.walks.front();
  const std::optional<double> start_yaw =
      stated_start ? sim.data.info.Find(id)->start_heading_rad : std::nullopt;
  const SimulatedImu imu = SimulateFootImu(walk, id, o, Random(seed + 100), start_yaw);
  ins::InsOptions io;
  io.initial_yaw_rad = sim.data.info.Find(id)->start_heading_rad.value_or(0.0);
  io.initial_position_n = imu.foot_truth.front().position_n;
  ins::ZuptIns ins(io);
  std::vector<Vec3> est;
  std::vector<bool> stance;
  ins.on_state = [&](const ins::InsState& s) {
    est.push_back(s.position_n);
    stance.push_back(s.stance);
  };
  for (const auto& s : imu.samples) ins.Add(s);
  ins.Finish();
  EXPECT_EQ(est.size(), imu.samples.size());
  InsRun r;
  for (std::size_t k = 1; k < imu.foot_truth.size(); ++k) {
    r.distance_m += (imu.foot_truth[k].position_n - imu.foot_truth[k - 1].position_n).head<2>().norm();
  }
  const Vec3 e = est.back() - imu.foot_truth.back().position_n;
  r.end_error_m = e.head<2>().norm();
  r.z_error_m = std::abs(e.z());
  const PrecisionRecall pr = ComparePrecisionRecall(stance, imu.stance);
  std::size_t same = 0;
  for (std::size_t k = 0; k < stance.size(); ++k) same += stance[k] == imu.stance[k];
  r.stance_agreement = static_cast<double>(same) / stance.size();
  EXPECT_GT(pr.precision, 0.95);
  return r;
}

TEST(ImuSim, PerfectImuIsIntegratedBackToTheFootPath) {
  const InsRun r = RunInsOn("office-loop-1lap", ImuGrade::Perfect(), FootMotion::kWalk, 1);
  EXPECT_GT(r.distance_m, 95.0);
  EXPECT_LT(r.end_error_m, 0.02);  // 2 cm over 100 m: simulator and mechanization agree
  EXPECT_GT(r.stance_agreement, 0.98);
}

TEST(ImuSim, TacticalGradeClosedLoopWithinOnePercent) {
  const InsRun r = RunInsOn("office-loop", ImuGrade::Tactical(), FootMotion::kWalk, 2);
  EXPECT_GT(r.distance_m, 390.0);
  EXPECT_LT(r.end_error_m, 0.01 * r.distance_m);  // issue 3: <= 1 % of distance
}

TEST(ImuSim, StairsAndCrawling) {
  const InsRun stairs = RunInsOn("office-loop-1lap", ImuGrade::Industrial(), FootMotion::kStairs, 3);
  EXPECT_LT(stairs.z_error_m, 0.2);  // ~24 m climbed
  EXPECT_LT(stairs.end_error_m, 0.01 * stairs.distance_m);
  const InsRun crawl = RunInsOn("office-loop-1lap", ImuGrade::Industrial(), FootMotion::kCrawl, 3);
  EXPECT_LT(crawl.end_error_m, 0.01 * crawl.distance_m);
}

TEST(ImuSim, DeterministicPerSeedAndGradesByName) {
  const SimulatedMission sim = SimulateScenario("office-loop-1lap", 4);
  ImuSimOptions o;
  o.grade = ImuGrade::ByName("consumer");
  const auto a = SimulateFootImu(sim.walks.front().second, "ff1", o, Random(9));
  const auto b = SimulateFootImu(sim.walks.front().second, "ff1", o, Random(9));
  ASSERT_EQ(a.samples.size(), b.samples.size());
  for (std::size_t k = 0; k < a.samples.size(); k += 997) {
    EXPECT_EQ(a.samples[k].accel_b, b.samples[k].accel_b);
    EXPECT_EQ(a.samples[k].gyro_b, b.samples[k].gyro_b);
  }
  EXPECT_NEAR(a.samples[1].t - a.samples[0].t, 0.005, 1e-12);
  EXPECT_THROW(ImuGrade::ByName("navigation"), std::invalid_argument);
}

// Every scenario's foot motion stays within a MEMS gyro's range (the INS rejects > 34.9 rad/s
// as deg/s data): the landmark corridor's stop-and-go ends each leg with a 0.05 s shuffle step,
// which once produced a 49 rad/s pitch rate; the walking loop keeps walking at full swing and
// still closes (the ImuSim tests above).
TEST(ImuSim, ShortStridesIntoStopsStayWithinGyroRange) {
  for (const std::string scenario : {"landmark-corridor", "office-loop-1lap", "training-building"}) {
    const SimulatedMission sim = SimulateScenario(scenario, 3);
    ImuSimOptions o;
    o.grade = ImuGrade::Perfect();
    o.rate_hz = 100;
    for (const auto& [id, walk] : sim.walks) {
      double peak_gyro = 0;
      for (const auto& s : SimulateFootImu(walk, id, o, Random(5)).samples) {
        peak_gyro = std::max(peak_gyro, s.gyro_b.norm());
      }
      EXPECT_LT(peak_gyro, 20.0) << scenario << " " << id;  // walking peaks ~10-15 rad/s
      EXPECT_GT(peak_gyro, 3.0) << scenario << " " << id;   // the feet do swing
    }
  }
}

// A foot swings for about 0.4 s whatever the pace (a slower walker rests longer). Before
// 2026-12-05 a slow search's steps of up to 2 s swung for their whole length (the pitch rate
// then stood still while the foot moved at ~1 m/s, which a ZUPT detector takes for a stance)
// and a step cut short before a stop swung in 0.13 s (house searches: longest swing 1.2 / 2.2 s,
// 3 of ~110 / ~240 swings under 0.3 s, peak specific force 22 / 19 g). Now every swing of the
// slow searches lasts 0.3-0.6 s, and no foot of the searches or of the stop-and-go training
// walk (whose landings can be closer than a swing: two swings may then touch) exceeds 10 g.
// What the swings' duration meant for the INS: on the slow searches its detector took a long
// swing's still pitch for a stance and lost the stride (2-7 strides of ~0.9 m each per search,
// the `ins` pipeline 0.28-1.42 m mean, in95 18-96 % on seeds 7-10). With an industrial IMU the
// foot's end point is now within 1 % of the distance walked.
TEST(ImuSim, TheInsLosesNoStrideOfASlowSearch) {
  for (const std::string scenario : {"house1-search", "house2-search"}) {
    for (std::uint64_t seed : {7, 9}) {
      const InsRun r = RunInsOn(scenario, ImuGrade::Industrial(), FootMotion::kWalk, seed, true);
      EXPECT_GT(r.distance_m, 50.0) << scenario << " " << seed;
      EXPECT_LT(r.end_error_m, 0.01 * r.distance_m) << scenario << " " << seed;
    }
  }
}

TEST(ImuSim, EverySwingLastsAsAFootsDoesWhateverThePace) {
  for (const std::string scenario : {"house1-search", "house2-search", "training-building"}) {
    const SimulatedMission sim = SimulateScenario(scenario, 7);
    const bool search = scenario != "training-building";
    ImuSimOptions o;
    o.grade = ImuGrade::Perfect();
    o.rate_hz = 100;
    for (const auto& [id, walk] : sim.walks) {
      const SimulatedImu imu = SimulateFootImu(walk, id, o, Random(5));
      std::vector<double> swings_s;  // the runs of samples out of stance
      double peak_g = 0;
      std::size_t run = 0;
      for (std::size_t k = 0; k < imu.samples.size(); ++k) {
        peak_g = std::max(peak_g, imu.samples[k].accel_b.norm() / 9.80665);
        if (!imu.stance[k]) {
          ++run;
        } else if (run > 0) {
          swings_s.push_back(static_cast<double>(run) / o.rate_hz);
          run = 0;
        }
      }
      ASSERT_GT(swings_s.size(), 50u) << scenario << " " << id;
      EXPECT_LT(peak_g, 10.0) << scenario << " " << id;
      if (!search) continue;
      const double sample_s = 1.0 / o.rate_hz;
      EXPECT_LE(*std::max_element(swings_s.begin(), swings_s.end()), 0.6 + 1.5 * sample_s) << id;
      EXPECT_GE(*std::min_element(swings_s.begin(), swings_s.end()), 0.3 - 1.5 * sample_s) << id;
    }
  }
}

TEST(ImuSim, TheGaitTurnsTheLandingFootTowardItsNextStride) {
  // landing_anticipation a: the foot lands along its stride turned by a of the turn to the next
  // stride (a = 0, the pivot gait the simulator had alone; the `imu` family draws a in [0, 0.5]).
  // Each landing's heading against its chord and the next one (unless a short swing's largest
  // turn clamps it), and the strides themselves the same for every gait.
  const SimulatedMission sim = SimulateScenario("house1-search", 7);
  const auto& [id, walk] = sim.walks.front();
  ImuSimOptions o;
  o.grade = ImuGrade::Perfect();
  o.rate_hz = 100;
  const SimulatedImu pivot = SimulateFootImu(walk, id, o, Random(5));
  for (const double a : {0.0, 0.25, 0.5}) {
    o.landing_anticipation = a;
    const SimulatedImu imu = SimulateFootImu(walk, id, o, Random(5));
    ASSERT_EQ(imu.landings.size(), pivot.landings.size());
    int checked = 0, turned = 0;
    for (std::size_t k = 1; k + 1 < imu.landings.size(); ++k) {
      const auto& l = imu.landings;
      EXPECT_EQ(l[k].position_n, pivot.landings[k].position_n);
      const Vec2 chord = l[k].position_n - l[k - 1].position_n;
      const Vec2 next = l[k + 1].position_n - l[k].position_n;
      if (chord.norm() < 0.3 || next.norm() < 0.3) continue;
      const double c = std::atan2(chord.y(), chord.x());
      const double expected = c + a * WrapAngle(std::atan2(next.y(), next.x()) - c);
      const double turn = std::abs(WrapAngle(l[k].yaw_rad - l[k - 1].yaw_rad));
      if (turn > 2.3) continue;  // clamped: 8 rad/s over a 0.3 s swing at the most
      EXPECT_NEAR(WrapAngle(l[k].yaw_rad - expected), 0.0, 1e-9) << a << " " << k;
      ++checked;
      turned += std::abs(WrapAngle(expected - c)) > 0.1;
    }
    EXPECT_GT(checked, 100) << a;
    if (a > 0) EXPECT_GT(turned, 20) << a;  // a search turns often: the gait shows
  }
}

}  // namespace
}  // namespace trailmark

namespace trailmark {
namespace {

// An INS aligns its yaw to the mission's stated start heading, so a simulated foot IMU must
// rest facing it: with a perfect IMU, the INS started as a mission would start it follows the
// foot. The house searches' walks set off ~30 deg from the heading they state (the direction
// the team entered by), and the foot faced the first step: the INS ran 30 deg off.
TEST(ImuSim, EveryScenariosFootImuStartsAsItsMissionSays) {
  ImuSimOptions o;
  o.grade = ImuGrade::Perfect();
  o.rate_hz = 100;
  for (const ScenarioInfo& s : Scenarios()) {
    if (s.name == "incident-4h" || s.name == "all-sources-4h" || s.name == "search") continue;
    const SimulatedMission sim = SimulateScenario(s.name, 1);
    for (const auto& [agent, walk] : sim.walks) {
      const NodeInfo* node = sim.data.info.Find(agent);
      ASSERT_NE(node, nullptr) << s.name << " " << agent;
      if (!node->start_heading_rad || walk.steps.size() < 20) continue;
      const SimulatedImu imu = SimulateFootImu(walk, agent, o, Random(3), node->start_heading_rad);
      ins::InsOptions io;
      io.initial_yaw_rad = *node->start_heading_rad;
      io.initial_position_n = imu.foot_truth.front().position_n;
      ins::ZuptIns filter(io);
      std::vector<double> times;
      for (const auto& f : imu.foot_truth) times.push_back(f.t);
      double worst = 0;
      filter.on_state = [&](const ins::InsState& st) {
        const auto k = static_cast<std::size_t>(std::lower_bound(times.begin(), times.end(), st.t) -
                                                times.begin());
        if (k >= times.size() || times[k] != st.t) return;
        const Vec3 d = st.position_n - imu.foot_truth[k].position_n;
        worst = std::max(worst, d.head<2>().norm());
      };
      for (const ImuSample& sample : imu.samples) {
        if (sample.t > imu.samples.front().t + 60) break;
        filter.Add(sample);
      }
      EXPECT_LT(worst, 0.3) << s.name << " " << agent;
    }
  }
}

}  // namespace
}  // namespace trailmark

// SPDX-License-Identifier: MIT
// The landmark pipelines end to end on the simulated stop-and-go corridor mission.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>

#include "pipelines/run_named.h"
#include "test_util.h"
#include "trailmark/eval/metrics.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/sim/imu_sim.h"
#include "trailmark/sim/scenarios.h"

namespace trailmark {
namespace {


/// Runs `pipeline` on the mission; returns its summary and fills `rows`.
EstimatorSummary RunOn(const PipelineSpec& pipeline, const MissionDirectory& mission,
                      std::vector<Estimate>* rows) {
  VectorSink sink;
  const EstimatorSummary s = RunBatch(pipeline, {mission, {}}, sink);
  *rows = std::move(sink.rows);
  return s;
}

TEST(LandmarksPipeline, CorridorMissionLocalizesTheLandmarks) {
  const SimulatedMission sim = SimulateScenario("landmark-corridor", 2);
  testing::TempDir dir;
  WriteMissionDirectory(dir.path(), sim.data, &sim.plan);
  const MissionDirectory mission(dir.path());
  std::vector<Estimate> pdr_rows;
  RunOn(RequirePipeline("pdr"), mission, &pdr_rows);
  const double pdr_mean = Evaluate(sim.data.info, sim.data.truth, pdr_rows).agents.stats.mean_m;
  for (bool ukf : {false, true}) {
    const PipelineSpec& pipeline = RequirePipeline(ukf ? "landmarks-ukf" : "landmarks-stopgo");
    ASSERT_TRUE(CanRun(pipeline, mission));
    struct {
      std::vector<Estimate> rows;
    } sink;
    const EstimatorSummary s = RunOn(pipeline, mission, &sink.rows);
    EXPECT_EQ(s.numbers.at("stops"), 7.0);
    EXPECT_EQ(s.numbers.at("landmarks_localized"), 4.0);
    for (const auto& e : sink.rows) {
      ASSERT_TRUE(e.position_n.allFinite());
      ASSERT_GE(e.sxx, 0);
      ASSERT_GE(e.sxx * e.syy - e.sxy * e.sxy, 0);
    }
    const Metrics m = Evaluate(sim.data.info, sim.data.truth, sink.rows);
    // The 4 unknown landmarks end within 1.5 m on average (seeds 1-5: 0.32-1.09 m), each
    // within 3 m; the responder is no worse than dead reckoning by more than 20 %.
    double sum = 0;
    int n_unknown = 0;
    for (const auto& n : m.nodes) {
      if (n.kind != NodeKind::kLandmark || n.id == "lm1") continue;  // lm1 is surveyed
      EXPECT_LT(n.stats.final_m, 3.0) << n.id << (ukf ? " ukf" : "");
      sum += n.stats.final_m;
      ++n_unknown;
    }
    ASSERT_EQ(n_unknown, 4);
    EXPECT_LT(sum / n_unknown, 1.5);
    EXPECT_LT(m.agents.stats.mean_m, 1.2 * pdr_mean);
  }
}

// fix_fusion=intersection (issue 21): the dead reckoning's shared errors and covariance
// intersection with each stop's fix make the ellipse honest where the paper's independent
// update claims about three times less than its error (corridor seeds 1-5, 2026-12-02: mean in95
// 86 % against 32 %; docs/landmarks.md).
//
// drift=dead-reckoning (the default since 2026-12-03): the paper's update, the same estimate to
// the bit, reporting the dead reckoning's covariance between fixes, set at each fix to the
// intersection's plus the paper's offset from it (corridor seeds 1-5: in95 88 % against 32 %).
TEST(LandmarksPipeline, IntersectionFusionKeepsTheEllipseHonest) {
  const std::vector<std::map<std::string, std::string>> arms{
      {{"fix_fusion", "intersection"}},
      {{"fix_fusion", "independent"}, {"drift", "white"}},
      {{"fix_fusion", "independent"}, {"drift", "dead-reckoning"}}};
  std::vector<double> in95(arms.size(), 0.0);
  for (std::uint64_t seed = 1; seed <= 5; ++seed) {
    const SimulatedMission sim = SimulateScenario("landmark-corridor", seed);
    testing::TempDir dir;
    WriteMissionDirectory(dir.path(), sim.data, &sim.plan);
    const MissionDirectory mission(dir.path());
    std::vector<std::vector<Estimate>> rows;
    for (std::size_t k = 0; k < arms.size(); ++k) {
      VectorSink sink;
      RunBatch(RequirePipeline("landmarks-stopgo"), {mission, arms[k]}, sink);
      for (const auto& e : sink.rows) {
        ASSERT_TRUE(e.position_n.allFinite());
        ASSERT_GT(e.sxx * e.syy - e.sxy * e.sxy, 0);
      }
      const Metrics m = Evaluate(sim.data.info, sim.data.truth, sink.rows);
      in95[k] += m.agents.stats.in95 / 5;
      rows.push_back(sink.rows);
    }
    // The two drift models: the same estimates, other covariances.
    ASSERT_EQ(rows[1].size(), rows[2].size());
    for (std::size_t i = 0; i < rows[1].size(); ++i) {
      ASSERT_EQ(rows[1][i].id, rows[2][i].id);
      ASSERT_EQ(rows[1][i].position_n, rows[2][i].position_n) << rows[1][i].id << " " << rows[1][i].t;
    }
  }
  EXPECT_GT(in95[0], 0.80);
  EXPECT_LT(in95[1], 0.60);  // the paper's update and drift are still what they were
  EXPECT_GT(in95[2], 0.80);
  // The UKF tracks otherwise: the option is refused there, not silently ignored.
  const SimulatedMission sim = SimulateScenario("landmark-corridor", 1);
  EXPECT_THAT([&] {
    RequirePipeline("landmarks-ukf")
        .make({sim.data.info, &sim.plan}, {{"fix_fusion", "intersection"}}, Feed::kTimeOrdered);
  }, ::testing::ThrowsMessage<std::invalid_argument>(::testing::HasSubstr("fix_fusion")));
}

// The default stop fixes (fix_fusion=joint): the stops solved with the landmarks under the dead
// reckoning's joint prior. With the corridor's radio model given stale (intercept 12 dB off,
// exponent 3.0 for 7.1), every solve is tested against its stated noise, fails, and is solved
// again with the ranges' calibration as unknowns: the track stays near dead reckoning's while
// the paper's independent fixes follow the stale model off; the ellipses stay honest.
TEST(LandmarksPipeline, JointFixesHoldWithAStaleRadioModel) {
  double joint_p75 = 0, paper_p75 = 0, pdr_p75 = 0, joint_in95 = 0;
  for (std::uint64_t seed = 1; seed <= 3; ++seed) {
    SimulatedMission sim = SimulateScenario("landmark-corridor", seed);
    ASSERT_TRUE(sim.data.info.radio.has_value());
    sim.data.info.radio->alpha_dbm -= 12;
    sim.data.info.radio->path_loss_exponent = 3.0;
    testing::TempDir dir;
    WriteMissionDirectory(dir.path(), sim.data, &sim.plan);
    const MissionDirectory mission(dir.path());
    VectorSink joint, paper, pdr;
    const EstimatorSummary s = RunBatch(RequirePipeline("landmarks-stopgo"), {mission, {}}, joint);
    RunBatch(RequirePipeline("landmarks-stopgo"), {mission, {{"fix_fusion", "independent"}}},
             paper);
    RunBatch(RequirePipeline("pdr"), {mission, {}}, pdr);
    EXPECT_GT(s.numbers.at("joint_solves_inconsistent"), 0.0);
    // Ranges read e^a d^b of the distance d: b = 7.1 / 3.0 = 2.37 (the prior pulls toward 1).
    EXPECT_GT(s.numbers.at("range_exponent_ratio"), 1.5);
    for (const auto& e : joint.rows) {
      ASSERT_TRUE(e.position_n.allFinite());
      ASSERT_GT(e.sxx * e.syy - e.sxy * e.sxy, 0);
    }
    const Metrics mj = Evaluate(sim.data.info, sim.data.truth, joint.rows);
    joint_p75 += mj.agents.stats.p75_m / 3;
    joint_in95 += mj.agents.stats.in95 / 3;
    paper_p75 += Evaluate(sim.data.info, sim.data.truth, paper.rows).agents.stats.p75_m / 3;
    pdr_p75 += Evaluate(sim.data.info, sim.data.truth, pdr.rows).agents.stats.p75_m / 3;
  }
  EXPECT_LT(joint_p75, 1.1 * pdr_p75);
  EXPECT_LT(joint_p75, paper_p75);
  EXPECT_GT(joint_in95, 0.85);
}

// The steps' own heading offset (track_heading_offset_sigma_rad, 5 deg) is a consider parameter
// of the stops' dead reckoning: every fix fusion's estimate is the one without it, to the bit;
// only the reported covariance grows. On a corridor walk whose steps are all turned by 6 deg
// (a boot's toe-out; the `pdr` robustness family turns them by 2-10 deg) the ellipse holds the
// truth with it and does not without it (2026-12-06, docs/robustness.md).
TEST(LandmarksPipeline, TheStepsHeadingOffsetWidensTheStopFixesEllipseOnly) {
  const std::vector<std::map<std::string, std::string>> arms{
      {}, {{"fix_fusion", "intersection"}}, {{"fix_fusion", "independent"}}};
  double in95_with = 0, in95_without = 0;
  const int seeds = 3;
  for (std::uint64_t seed = 1; seed <= seeds; ++seed) {
    SimulatedMission sim = SimulateScenario("landmark-corridor", seed);
    testing::TurnSteps(sim.data.steps, 6.0);
    testing::TempDir dir;
    WriteMissionDirectory(dir.path(), sim.data, &sim.plan);
    const MissionDirectory mission(dir.path());
    for (std::size_t k = 0; k < arms.size(); ++k) {
      auto without_options = arms[k];
      without_options["track_heading_offset_sigma_rad"] = "0";
      VectorSink with, without;
      RunBatch(RequirePipeline("landmarks-stopgo"), {mission, arms[k]}, with);
      RunBatch(RequirePipeline("landmarks-stopgo"), {mission, without_options}, without);
      const double grew =
          testing::ExpectSameEstimatesWiderCovariances(with.rows, without.rows, true);
      EXPECT_GT(grew, 0.05) << k;
      if (k == 0) {
        in95_with += Evaluate(sim.data.info, sim.data.truth, with.rows).agents.stats.in95 / seeds;
        in95_without +=
            Evaluate(sim.data.info, sim.data.truth, without.rows).agents.stats.in95 / seeds;
      }
    }
  }
  EXPECT_GT(in95_with, 0.8);
  EXPECT_LT(in95_without, 0.6);
}

// The fusion takes the joint stop fixes as a member only when asked (use.stopgo, off by
// default: docs/fusion.md); with them its estimates change, and the member's summary shows.
TEST(LandmarksPipeline, TheFusionTakesTheStopFixesWhenAsked) {
  const SimulatedMission sim = SimulateScenario("landmark-corridor", 1);
  testing::TempDir dir;
  WriteMissionDirectory(dir.path(), sim.data, &sim.plan);
  const MissionDirectory mission(dir.path());
  VectorSink plain, with_stops;
  const EstimatorSummary a = RunBatch(RequirePipeline("fusion"), {mission, {}}, plain);
  const EstimatorSummary b =
      RunBatch(RequirePipeline("fusion"), {mission, {{"use.stopgo", "true"}}}, with_stops);
  const auto has_member = [](const EstimatorSummary& s) {
    return std::any_of(s.numbers.begin(), s.numbers.end(),
                       [](const auto& kv) { return kv.first.rfind("landmarks-stopgo.", 0) == 0; });
  };
  EXPECT_FALSE(has_member(a));
  EXPECT_TRUE(has_member(b));
  bool differ = plain.rows.size() != with_stops.rows.size();
  for (std::size_t i = 0; !differ && i < plain.rows.size(); ++i) {
    differ = plain.rows[i].position_n != with_stops.rows[i].position_n;
  }
  EXPECT_TRUE(differ);
}

// Without a calibration in mission.json the radio model is fitted online from the stops' RSSI
// of the surveyed landmark, and the unknown landmarks are still localized.
TEST(LandmarksPipeline, FitsTheRadioOnlineWithoutCalibration) {
  SimulatedMission sim = SimulateScenario("landmark-corridor", 3);
  sim.data.info.radio.reset();
  testing::TempDir dir;
  WriteMissionDirectory(dir.path(), sim.data, &sim.plan);
  const MissionDirectory mission(dir.path());
  std::vector<Estimate> rows;
  const EstimatorSummary s = RunOn(RequirePipeline("landmarks-stopgo"), mission, &rows);
  EXPECT_GE(s.numbers.at("radio_refits"), 1.0);
  EXPECT_NEAR(s.numbers.at("radio_path_loss_exponent"), 7.1, 1.0);  // the simulated channel
  const Metrics m = Evaluate(sim.data.info, sim.data.truth, rows);
  double sum = 0;
  for (const auto& n : m.nodes) {
    if (n.kind == NodeKind::kLandmark && n.id != "lm1") sum += n.stats.final_m;
  }
  EXPECT_LT(sum / 4, 1.5);
}

// The office of issue 24 (landmark-office: no radio model, no stop/go events, walls, correlated
// shadowing, landmark and phone offsets, censoring, drifting PDR): the default tracker
// (error-state) at least halves dead reckoning's p75 where the paper's UKF does not, calibrates
// each phone's radio, and places unknown landmarks from the walk. Seeds 11-13 (the figures in
// docs/landmarks.md are on seeds 201-220).
TEST(LandmarksPipeline, TheErrorStateTrackerHoldsOnAnOfficeWithoutEventsOrRadioModel) {
  for (std::uint64_t seed : {11, 12, 13}) {
    const SimulatedMission sim = SimulateScenario("landmark-office", seed);
    ASSERT_FALSE(sim.data.info.radio.has_value());
    testing::TempDir dir;
    WriteMissionDirectory(dir.path(), sim.data, &sim.plan);
    const MissionDirectory mission(dir.path());
    std::vector<Estimate> pdr_rows, rows, paper_rows;
    RunOn(RequirePipeline("pdr"), mission, &pdr_rows);
    const EstimatorSummary s = RunOn(RequirePipeline("landmarks-ukf"), mission, &rows);
    VectorSink paper_sink;
    RunBatch(RequirePipeline("landmarks-ukf"), {mission, {{"filter", "paper"}}}, paper_sink);
    for (const auto& e : rows) {
      ASSERT_TRUE(e.position_n.allFinite());
      ASSERT_GT(e.sxx, 0);
      ASSERT_GT(e.sxx * e.syy - e.sxy * e.sxy, 0);
    }
    const Metrics dr = Evaluate(sim.data.info, sim.data.truth, pdr_rows);
    const Metrics ours = Evaluate(sim.data.info, sim.data.truth, rows);
    const Metrics paper = Evaluate(sim.data.info, sim.data.truth, paper_sink.rows);
    EXPECT_LT(ours.agents.stats.p75_m, 0.5 * dr.agents.stats.p75_m) << seed;
    EXPECT_LT(ours.agents.stats.p75_m, paper.agents.stats.p75_m) << seed;
    // Each phone's radio is calibrated from the surveyed landmarks: BLE at 1 m (-62 dBm, the
    // phone's offset 5 dB), n 2 plus the walls.
    for (const std::string ff : {"ff1", "ff2"}) {
      EXPECT_NEAR(s.numbers.at(ff + ".radio_alpha_dbm"), -62, 15) << seed;
      EXPECT_NEAR(s.numbers.at(ff + ".radio_path_loss_exponent"), 2.4, 1.0) << seed;
    }
    std::vector<double> unknown_final;
    for (const auto& n : ours.nodes) {
      const NodeInfo* info = sim.data.info.Find(n.id);
      if (n.kind == NodeKind::kLandmark && info && !info->position && n.stats.samples > 0) {
        unknown_final.push_back(n.stats.final_m);
      }
    }
    ASSERT_GE(unknown_final.size(), 3u) << seed;
    std::nth_element(unknown_final.begin(), unknown_final.begin() + unknown_final.size() / 2,
                     unknown_final.end());
    EXPECT_LT(unknown_final[unknown_final.size() / 2], 3.0) << seed;
  }
}

// dr_first (issues 21 and 24): a foot INS within its noise model dead-reckons the office to
// decimetres while RSSI places a handheld to metres (walls, offsets, shadowing over a room); the
// tracker's estimate is written only where the dead reckoning leaves the tracker's region, and a
// stated heading that lies is caught that way and said. Seeds 31-32 (docs/landmarks.md's figures:
// fresh seeds 415-422).
TEST(LandmarksPipeline, AGoodFootInsIsWrittenAsItsDeadReckoningUntilTheTrackerRejectsIt) {
  for (std::uint64_t seed : {31, 32}) {
    SimulatedMission sim = SimulateScenario("landmark-office", seed);
    ImuSimOptions imu;
    imu.rate_hz = 100;
    AddFootImu(sim, imu, seed);
    sim.data.steps.clear();
    struct Run {
      Metrics dr, ours, radio;
      EstimatorSummary summary;
    };
    const auto run = [&](const SimulatedMission& m) -> Run {
      testing::TempDir dir;
      WriteMissionDirectory(dir.path(), m.data, &m.plan);
      const MissionDirectory mission(dir.path());
      std::vector<Estimate> pdr_rows, rows;
      RunOn(RequirePipeline("pdr"), mission, &pdr_rows);
      Run r{.summary = RunOn(RequirePipeline("landmarks-ukf"), mission, &rows)};
      const bool finite_spd = std::all_of(rows.begin(), rows.end(), [](const Estimate& e) {
        return e.position_n.allFinite() && e.sxx * e.syy - e.sxy * e.sxy > 0;
      });
      EXPECT_TRUE(finite_spd);
      VectorSink radio;
      RunBatch(RequirePipeline("landmarks-ukf"), {mission, {{"dr_first", "false"}}}, radio);
      r.dr = Evaluate(m.data.info, m.data.truth, pdr_rows);
      r.ours = Evaluate(m.data.info, m.data.truth, rows);
      r.radio = Evaluate(m.data.info, m.data.truth, radio.rows);
      return r;
    };
    const Run good = run(sim);
    // Never worse than its dead reckoning by more than 10 % (issue 24), where the tracker alone
    // is (the radio pulls a right track off: 2-3x on seeds 411-414), and honest.
    EXPECT_LE(good.ours.agents.stats.p75_m, 1.1 * good.dr.agents.stats.p75_m) << seed;
    EXPECT_GT(good.radio.agents.stats.p75_m, 1.2 * good.ours.agents.stats.p75_m) << seed;
    EXPECT_GE(good.ours.agents.stats.in95, 0.9) << seed;
    ASSERT_TRUE(good.summary.numbers.count("ff1.dr_first_tracker_share")) << seed;
    // The same walks with the stated start heading 15 degrees off (the INS aligns to it): the
    // tracker rejects the turned dead reckoning, says so, and writes its own estimate.
    for (NodeInfo& n : sim.data.info.nodes) {
      if (n.kind == NodeKind::kAgent) n.start_heading_rad = *n.start_heading_rad + 15 * M_PI / 180;
    }
    const Run lie = run(sim);
    const auto resumed =
        std::count_if(lie.summary.integrity.begin(), lie.summary.integrity.end(),
                      [](const IntegrityNote& n) { return n.action == "resumed"; });
    EXPECT_GE(resumed, 1) << seed;
    EXPECT_GT(lie.summary.numbers.at("ff1.dr_first_tracker_share") +
                  lie.summary.numbers.at("ff2.dr_first_tracker_share"),
              0.2)
        << seed;
    EXPECT_LT(lie.ours.agents.stats.p75_m, 0.8 * lie.dr.agents.stats.p75_m) << seed;
  }
}

}  // namespace
}  // namespace trailmark

// SPDX-License-Identifier: MIT
// Integrity (issue 21, item 3) end to end: the kinds of lie the mechanism must catch, each on
// several seeds and magnitudes, through the registry's pipelines and their files. A lie is
// caught when the lying source is named in an integrity note and the estimate with the lie
// stays close to the estimate without it (the dead-reckoning guard only reports here, so that what is
// measured is the source check alone).
#include <gtest/gtest.h>

#include <cmath>

#include "pipelines/run_named.h"
#include "test_util.h"
#include "trailmark/eval/metrics.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/sim/beacon_lab.h"
#include "trailmark/sim/lies.h"
#include "trailmark/sim/scenarios.h"

namespace trailmark {
namespace {

struct Outcome {
  double p75_m = 0;
  EstimatorSummary summary;
};

Outcome RunLie(const std::string& pipeline, const SimulatedMission& sim, OptionValues options) {
  testing::TempDir dir;
  WriteMissionDirectory(dir.path(), sim.data, &sim.plan);
  const MissionDirectory mission(dir.path());
  for (const OptionInfo& o : RequirePipeline(pipeline).options) {
    if (o.key == "integrity.on_disagreement") options.emplace(o.key, "report");
  }
  VectorSink sink;
  Outcome out;
  out.summary = testing::RunNamed(pipeline, mission, options, sink);
  out.p75_m = Evaluate(sim.data.info, sim.data.truth, sink.TakeSortedByTime()).agents.stats.p75_m;
  return out;
}

bool Named(const EstimatorSummary& s, const std::string& source, const std::string& action) {
  for (const IntegrityNote& n : s.integrity) {
    if (n.source == source && n.action == action) return true;
  }
  return false;
}

std::size_t ExcludedOther(const EstimatorSummary& s, const std::string& source) {
  std::size_t n = 0;
  for (const IntegrityNote& note : s.integrity) n += note.source != source && note.action == "excluded";
  return n;
}

/// The corridor with every landmark surveyed where it truly is (sigma 0.2 m).
SimulatedMission SurveyedCorridor(std::uint64_t seed) {
  SimulatedMission sim = SimulateScenario("landmark-corridor", seed);
  SurveyAtTruth(sim.data, NodeKind::kLandmark, 0.2);
  return sim;
}

/// The estimate with a caught lie is within 15 % (+ 0.1 m) of the estimate without the lie.
void ExpectClose(const Outcome& caught, const Outcome& honest, const std::string& what) {
  EXPECT_LE(caught.p75_m, 1.15 * honest.p75_m + 0.1) << what;
}

/// Each (seed, magnitude) of one kind of lie: the lying source is named, no other source is
/// excluded when `alone` (the landmark UKF; the beacon tracker also excludes honest NLOS-heavy
/// windows, docs/integrity.md), and the track stays close to the honest one.
void ExpectCaught(const std::string& pipeline, SimulatedMission (*mission)(std::uint64_t),
                  LieKind kind, const std::string& node, const std::vector<double>& magnitudes,
                  const std::string& source, bool alone, const OptionValues& options = {}) {
  for (std::uint64_t seed : {1, 2, 3}) {
    const SimulatedMission honest = mission(seed);
    const Outcome base = RunLie(pipeline, honest, options);
    if (alone) EXPECT_EQ(ExcludedOther(base.summary, ""), 0u) << seed;
    for (const double magnitude : magnitudes) {
      SimulatedMission lie = honest;
      ApplyLie(lie.data, {kind, node, magnitude});
      const Outcome caught = RunLie(pipeline, lie, options);
      const std::string what = "seed " + std::to_string(seed) + ", " + Describe({kind, node, magnitude});
      EXPECT_TRUE(Named(caught.summary, source, "excluded")) << what;
      if (alone) EXPECT_EQ(ExcludedOther(caught.summary, source), 0u) << what;
      ExpectClose(caught, base, what);
    }
  }
}

SimulatedMission SurveyedLab(std::uint64_t seed) { return SimulateBeaconLab({}, seed); }

/// The paper's UKF (landmarks-ukf filter=paper): its landmark check alone.
const OptionValues kPaperUkf = {{"filter", "paper"}};

TEST(Lies, ASurveyedLandmarkThatIsElsewhereIsExcluded) {
  ExpectCaught("landmarks-ukf", SurveyedCorridor, LieKind::kMovedNode, "lm3", {3, 6, 12},
               "landmark lm3", true, kPaperUkf);
}

TEST(Lies, ALandmarkWhoseRssiCarriesAnOffsetIsExcluded) {
  // Detected from 10 dB (at 6 dB: 2 of these 3 seeds; docs/integrity.md).
  ExpectCaught("landmarks-ukf", SurveyedCorridor, LieKind::kRssiOffset, "lm2", {10, 20},
               "landmark lm2", true, kPaperUkf);
}

TEST(Lies, TheErrorStateTrackerNamesEachLieAndHoldsAsWellAsThePapersFilter) {
  // The default tracker (landmark_tracker.h) explains part of a lie by its link's bias state
  // before the check names it, and an honest landmark may then be excluded for a while
  // (docs/integrity.md); what must hold: the lie is named, and with it caught the track is no
  // worse than the paper's UKF with the same lie caught (+ 0.1 m).
  struct Case {
    LieKind kind;
    std::string node;
    double magnitude;
  };
  const std::vector<Case> cases = {{LieKind::kMovedNode, "lm3", 3},
                                   {LieKind::kMovedNode, "lm3", 6},
                                   {LieKind::kMovedNode, "lm3", 12},
                                   {LieKind::kRssiOffset, "lm2", 20}};
  for (std::uint64_t seed : {1, 2, 3}) {
    const SimulatedMission honest = SurveyedCorridor(seed);
    for (const Case& c : cases) {
      SimulatedMission lie = honest;
      ApplyLie(lie.data, {c.kind, c.node, c.magnitude});
      const Outcome ours = RunLie("landmarks-ukf", lie, {});
      const Outcome paper = RunLie("landmarks-ukf", lie, kPaperUkf);
      const std::string what = "seed " + std::to_string(seed) + ", " + Describe({c.kind, c.node, c.magnitude});
      EXPECT_TRUE(Named(ours.summary, "landmark " + c.node, "excluded")) << what;
      EXPECT_LE(ours.p75_m, paper.p75_m + 0.1) << what;
    }
  }
}

TEST(Lies, ASurveyedBeaconThatIsElsewhereIsExcluded) {
  ExpectCaught("beacons-ekf", SurveyedLab, LieKind::kMovedNode, "b03", {1, 2, 4},
               "beacon b03 range", false);
}

TEST(Lies, AWrongSpeedOfSoundIsNamedAndTheRangesReadWithTheEstimatedScale) {
  // Every range of the lab's surveyed beacons x 1.12 or x 0.88 (a device calibrated at 20 deg C
  // in air at ~100 deg C or ~-60 deg C: the magnitudes of sim/lies.h's scale lie): the surveys
  // contradict it, so the tracker names its ranges, reads them with the scale it estimates and
  // stays close to the honest track; without the range scale state (range_scale_sigma=0, the
  // paper's ranges as they are) the same lie costs more. An honest mission names nothing.
  for (std::uint64_t seed : {1, 2, 3}) {
    const SimulatedMission honest = SurveyedLab(seed);
    const Outcome base = RunLie("beacons-ekf", honest, {});
    EXPECT_FALSE(Named(base.summary, "ultrasound ranges of ff1", "scale")) << seed;
    EXPECT_NEAR(base.summary.numbers.at("ff1.range_scale"), 1.0, 0.02) << seed;
    for (const double scale : {1.12, 0.88}) {
      SimulatedMission lie = honest;
      ApplyLie(lie.data, {LieKind::kRangeScale, "", scale});
      const std::string what = "seed " + std::to_string(seed) + ", x" + std::to_string(scale);
      const Outcome caught = RunLie("beacons-ekf", lie, {});
      EXPECT_TRUE(Named(caught.summary, "ultrasound ranges of ff1", "scale")) << what;
      // At least three quarters of the lie estimated (measured: x1.12 read as 1.120-1.126, x0.88
      // as 0.896-0.900 — the lab's long NLOS ranges and the prior pull toward 1 from below).
      EXPECT_NEAR(caught.summary.numbers.at("ff1.range_scale"), scale, 0.25 * std::abs(scale - 1))
          << what;
      ExpectClose(caught, base, what);
      const Outcome taken = RunLie("beacons-ekf", lie, {{"range_scale_sigma", "0"}});
      EXPECT_FALSE(Named(taken.summary, "ultrasound ranges of ff1", "scale")) << what;
      EXPECT_GT(taken.p75_m, caught.p75_m) << what;
    }
  }
}

TEST(Lies, AFrozenRadioLinkIsExcludedAndAFrozenImuIsNamed) {
  for (std::uint64_t seed : {1, 2}) {
    const SimulatedMission honest = SurveyedCorridor(seed);
    EXPECT_EQ(RunLie("landmarks-ukf", honest, kPaperUkf).summary.numbers.at("integrity.repeated_rows"), 0.0);
    // The best a caught freeze can give: the mission without that link from then on.
    SimulatedMission without = honest;
    std::erase_if(without.data.rssi, [](const RssiPacket& p) {
      return (p.tx == "lm4" || p.rx == "lm4") && p.t >= 30;
    });
    const Outcome base = RunLie("landmarks-ukf", without, kPaperUkf);
    SimulatedMission lie = honest;
    ApplyLie(lie.data, {LieKind::kFrozenLink, "lm4", 0, 30});  // the driver returns its last value
    const Outcome caught = RunLie("landmarks-ukf", lie, kPaperUkf);
    // The default tracker: the frozen link is named too (its track before that: docs/integrity.md).
    const Outcome ours = RunLie("landmarks-ukf", lie, {});
    EXPECT_GT(ours.summary.numbers.at("integrity.repeated_rows"), 0.0) << seed;
    bool named = false;
    for (const IntegrityNote& n : caught.summary.integrity) {
      named = named || (n.action == "repeats" && n.source.find("lm4") != std::string::npos);
    }
    EXPECT_TRUE(named) << seed;
    EXPECT_GT(caught.summary.numbers.at("integrity.repeated_rows"), 0.0);
    ExpectClose(caught, base, "frozen link, seed " + std::to_string(seed));
  }
  // A foot IMU stuck for a second (100 samples) while walking.
  SimulatedMission sim = testing::WithFootImuOnly(SimulateScenario("office-loop-1lap", 1), 1);
  const TimeS from = sim.data.imu[sim.data.imu.size() / 2].t;
  std::optional<ImuSample> held;
  for (ImuSample& s : sim.data.imu) {
    if (s.t < from || s.t > from + 1.0) continue;
    if (!held) held = s;
    s.accel_b = held->accel_b;
    s.gyro_b = held->gyro_b;
  }
  const Outcome frozen = RunLie("ins", sim, {});
  ASSERT_FALSE(frozen.summary.integrity.empty());
  EXPECT_EQ(frozen.summary.integrity.front().action, "repeats");
  EXPECT_EQ(frozen.summary.integrity.front().source, "imu ff1");
  EXPECT_NEAR(frozen.summary.integrity.front().t, from, 0.5);
}

}  // namespace
}  // namespace trailmark

// SPDX-License-Identifier: MIT
// Floors end to end (issue 26): the multi-floor building written as a mission directory, run
// through the registry's pipelines, scored by the evaluation's floor metrics; and a
// single-floor mission stays on one floor with its horizontal estimates unchanged.
#include <gtest/gtest.h>

#include <cstdio>
#include <set>

#include "pipelines/run_named.h"
#include "test_util.h"
#include "trailmark/eval/metrics.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/io/streams.h"
#include "trailmark/sim/scenarios.h"
#include "trailmark/sim/variation.h"

namespace trailmark {
namespace {

using testing::RunNamed;
using testing::TempDir;

FloorMetrics RunAndScore(const std::string& pipeline, const MissionDirectory& mission,
                         const OptionValues& options = {}) {
  VectorSink sink;
  RunNamed(pipeline, mission, options, sink);
  const auto truth = ReadAll<TruthSample>(mission.Path("truth.csv").string());
  std::vector<Estimate> estimates = sink.rows;
  std::stable_sort(estimates.begin(), estimates.end(),
                   [](const Estimate& a, const Estimate& b) { return a.t < b.t; });
  const Metrics m = Evaluate(mission.info(), truth, estimates);
  EXPECT_TRUE(m.floors.has_value());
  return m.floors.value_or(FloorMetrics{});
}

/// The pipeline's metrics on the mission; `summary` gets its summary.
Metrics RunAndEvaluate(const std::string& pipeline, const MissionDirectory& mission,
                       const OptionValues& options, EstimatorSummary* summary) {
  VectorSink sink;
  *summary = RunNamed(pipeline, mission, options, sink);
  const auto truth = ReadAll<TruthSample>(mission.Path("truth.csv").string());
  return Evaluate(mission.info(), truth, sink.TakeSortedByTime());
}

// Seed 7: neither a development seed (1-5) nor a held-out one of docs/floors.md (101-120).
TEST(Floors, TheRightFloorInTheMultiFloorBuilding) {
  TempDir dir;
  const SimulatedMission sim = SimulateScenario("multi-floor", 7);
  ASSERT_EQ(sim.levels.size(), 4u);
  WriteMissionDirectory(dir.path(), sim.data, sim.levels);
  const MissionDirectory mission(dir.path());
  ASSERT_EQ(mission.info().floors.size(), 4u);
  // The plan on disk has every level.
  std::vector<int> levels;
  mission.LoadFloorPlan(std::nullopt, &levels);
  EXPECT_EQ(levels.size(), 4u);

  const FloorMetrics ins = RunAndScore("ins", mission);
  EXPECT_GE(ins.floor_hit_rate, 0.95);
  EXPECT_LT(ins.ve95_m, 1.0);
  const FloorMetrics pdr = RunAndScore("pdr", mission);
  EXPECT_GE(pdr.floor_hit_rate, 0.95);
  // Phone steps do not measure height: without the barometer the agents stay on the ground
  // floor (the test could fail: the barometer is what carries them).
  const FloorMetrics blind = RunAndScore("pdr", mission, {{"height.use_baro", "false"}});
  EXPECT_LT(blind.floor_hit_rate, 0.6);
  // The IPIN score adds 15 m per wrong floor: far worse without the barometer.
  EXPECT_GT(blind.ipin_score_m, pdr.ipin_score_m + 5.0);
}

// Map matching on every level's plan (issue 26, item 4), seed 13 (not one the defaults were
// chosen on, 1-10, nor a held-out one): each agent changes level in the stairwell only, as many
// times as it took stairs, and the horizontal error is far below that of the ground floor's plan
// used on every level (whose partitions differ from the basement's and level 2's).
TEST(Floors, MapMatchingFollowsTheLevelsThroughTheStairwell) {
  TempDir dir;
  const SimulatedMission sim = SimulateScenario("multi-floor", 13);
  WriteMissionDirectory(dir.path(), sim.data, sim.levels);
  const MissionDirectory mission(dir.path());
  auto horizontal = [&](const OptionValues& options, EstimatorSummary* summary) {
    VectorSink sink;
    const EstimatorSummary s = RunNamed("mapmatch", mission, options, sink);
    if (summary) *summary = s;
    const auto truth = ReadAll<TruthSample>(mission.Path("truth.csv").string());
    std::vector<Estimate> estimates = sink.TakeSortedByTime();
    return Evaluate(mission.info(), truth, estimates).agents.stats;
  };
  EstimatorSummary levels;
  const ErrorStatistics every = horizontal({}, &levels);
  const ErrorStatistics ground = horizontal({{"level", "0"}}, nullptr);
  EXPECT_EQ(levels.numbers.at("levels"), 4.0);
  EXPECT_EQ(levels.numbers.at("ff1.level_changes"), 4.0);  // 0-1-2-1-0
  EXPECT_EQ(levels.numbers.at("ff2.level_changes"), 2.0);  // 0-(-1)-0
  EXPECT_EQ(levels.numbers.at("ff1.level_changes_outside_stairwell"), 0.0);
  EXPECT_EQ(levels.numbers.at("ff2.level_changes_outside_stairwell"), 0.0);
  EXPECT_LT(every.mean_m, 1.5);
  // Measured 2026-12-03: mean 0.53 against 0.68 m, p95 1.05 against 1.84 m (with the search grid
  // along the map's axes, before issue 23: 0.50 against 0.70 m; the ratio on one seed moves with
  // the particles' draws, 0.72-0.78 here; over 20 held-out seeds in docs/floors.md).
  EXPECT_LT(every.mean_m, 0.85 * ground.mean_m);
  EXPECT_LT(every.p95_m, ground.p95_m);
}

// Breadcrumbs across floors (issue 26, item 4), seeds 11-14 (neither development nor held-out
// seeds): the multi-floor building's crumbs lie on every level and its RSSI loses 10-20 dB per
// floor; packets between nodes the height channel puts on different levels are not used (the
// path-loss model has no floors). Over the four buildings the agents and the crumbs are far
// better for it (on held-out seeds gating was better in 39 of 40 buildings, docs/floors.md; one
// building may not be). The crumbs' truth has their level.
TEST(Floors, BreadcrumbRadioIsGatedByFloor) {
  double gated_agents = 0, open_agents = 0, gated_crumbs = 0, open_crumbs = 0, in95 = 0;
  for (const int seed : {11, 12, 13, 14}) {
    TempDir dir;
    const SimulatedMission sim = SimulateScenario("multi-floor", seed);
    std::set<int> crumb_levels;
    for (const auto& t : sim.data.truth) {
      if (t.id.rfind("c", 0) != 0) continue;
      ASSERT_TRUE(t.floor.has_value()) << t.id;
      EXPECT_EQ(*t.floor, LevelAt(sim.data.info.floors, t.position_n.z())) << t.id;
      crumb_levels.insert(*t.floor);
    }
    EXPECT_GE(crumb_levels.size(), 3u) << seed;  // crumbs on three levels or more
    WriteMissionDirectory(dir.path(), sim.data, sim.levels);
    const MissionDirectory mission(dir.path());
    EstimatorSummary gated_summary, open_summary;
    const Metrics gated = RunAndEvaluate("breadcrumb", mission, {}, &gated_summary);
    const Metrics open =
        RunAndEvaluate("breadcrumb", mission, {{"gate_other_floors", "false"}}, &open_summary);
    EXPECT_GT(gated_summary.numbers.at("radio_other_floor"), 1000.0) << seed;
    EXPECT_EQ(open_summary.numbers.at("radio_other_floor"), 0.0) << seed;
    gated_agents += gated.agents.stats.mean_m;
    open_agents += open.agents.stats.mean_m;
    gated_crumbs += gated.static_nodes.stats.mean_m;
    open_crumbs += open.static_nodes.stats.mean_m;
    in95 += gated.agents.stats.in95 / 4;
  }
  // Measured 2026-12-02: agents 9.53 against 11.77 m (summed means), the magnitude on held-out
  // seeds is in docs/floors.md; here only that gating is better, and honest.
  EXPECT_LT(gated_agents, open_agents);
  EXPECT_LT(gated_crumbs, open_crumbs);
  EXPECT_GE(in95, 0.85);
  std::printf("breadcrumb, seeds 11-14, summed means: agents %.2f gated / %.2f not; crumbs %.2f / "
              "%.2f; in95 %.2f\n",
              gated_agents, open_agents, gated_crumbs, open_crumbs, in95);
}

// The building drawn another way (`simulate multi-floor --vary K --family frame`): rotated and
// shifted, doors across gaps on every level, walls as multi-vertex lines, CSV columns shuffled.
// The height channel sees the same readings: the same floors, row for row; map matching still
// changes level only in the stairwell, as often as the walk took stairs.
TEST(Floors, AMountedDeviceIsOnTheStoreyBelowItsCeiling) {
  // The spec's rule is for a person's z (feet or belt, 1 m tolerance): a landmark 2.7 m up a
  // 3 m storey would be on the level above. A mounted device's storey is the one whose floor is
  // at or below it (0.1 m for a survey's error).
  const std::vector<FloorLevel> floors = {{-1, -3.0}, {0, 0.0}, {1, 3.0}};
  EXPECT_EQ(LevelAt(floors, 2.7), 1);
  EXPECT_EQ(MountedLevelAt(floors, 2.7), 0);
  EXPECT_EQ(MountedLevelAt(floors, -0.05), 0);
  EXPECT_EQ(MountedLevelAt(floors, -0.3), -1);
  EXPECT_EQ(MountedLevelAt(floors, 3.0), 1);
  EXPECT_EQ(MountedLevelAt({}, 2.7), 0);  // default 3 m storeys
  EXPECT_EQ(MountedLevelAt({}, 5.5), 1);
  // NodeLevelOf uses it for the static nodes of mission.json.
  MissionInfo info;
  info.floors = floors;
  NodeInfo lm;
  lm.id = "lm";
  lm.kind = NodeKind::kLandmark;
  lm.position = Vec3(0, 0, 2.7);
  info.nodes.push_back(lm);
  lm.id = "lm-up";
  lm.position = Vec3(0, 0, 3.2);
  info.nodes.push_back(lm);
  EXPECT_EQ(NodeLevelOf(nullptr, info, "lm"), 0);
  EXPECT_EQ(NodeLevelOf(nullptr, info, "lm-up"), 1);
}

TEST(Floors, MissionLevelsAreNodeLevelOfReadOnce) {
  // The radio estimators ask every packet's two ends; MissionLevels reads mission.json once.
  // On the multi-floor building with landmarks (every node kind, positions and none), with and
  // without a level source that knows some nodes: the same answer as the free functions for
  // every node and every pair, and none for an id the mission does not name.
  const SimulatedMission sim = SimulateScenario("multi-floor-landmarks", 3);
  const MissionInfo& info = sim.data.info;
  struct Source : LevelSource {
    std::optional<LevelBelief> NodeLevel(const std::string& node) const override {
      if (node.size() % 3 != 0) return std::nullopt;  // knows about a third of the nodes
      LevelBelief b;
      b.level = static_cast<int>(node.size() % 4) - 1;
      return b;
    }
  } source;
  const MissionLevels levels(info);
  ASSERT_GT(info.nodes.size(), 12u);
  int known = 0, differ = 0;
  for (const LevelSource* src :
       {static_cast<const LevelSource*>(nullptr), static_cast<const LevelSource*>(&source)}) {
    for (const NodeInfo& a : info.nodes) {
      EXPECT_EQ(levels.Of(src, a.id), NodeLevelOf(src, info, a.id)) << a.id;
      known += levels.Of(src, a.id).has_value();
      for (const NodeInfo& b : info.nodes) {
        const bool d = levels.Differ(src, a.id, b.id);
        EXPECT_EQ(d, OnDifferentLevels(src, info, a.id, b.id)) << a.id << " " << b.id;
        differ += d;
      }
    }
    EXPECT_EQ(levels.Of(src, "nobody-xyz"), std::nullopt);  // 10 characters: no source either
  }
  EXPECT_GT(known, 0);
  EXPECT_GT(differ, 0);  // pairs on different levels exist: the comparison is not vacuous
}

TEST(Floors, LandmarkRadioIsGatedByFloor) {
  // The building with surveyed landmarks on every level (issue 26, item 4): each landmark's z
  // puts it on its own level by the format's rule, and landmarks-ukf gated by floor is better
  // than the same filter using the packets from the other floors.
  double gated_agents = 0, open_agents = 0;
  for (const int seed : {11, 12, 13, 14}) {
    TempDir dir;
    const SimulatedMission sim = SimulateScenario("multi-floor-landmarks", seed);
    std::set<int> levels;
    for (const NodeInfo& n : sim.data.info.nodes) {
      if (n.kind != NodeKind::kLandmark) continue;
      ASSERT_TRUE(n.position.has_value()) << n.id;
      levels.insert(LevelAt(sim.data.info.floors, n.position->z()));
      bool truth_found = false;
      for (const auto& t : sim.data.truth) {
        if (t.id != n.id) continue;
        truth_found = true;
        EXPECT_EQ(t.floor, LevelAt(sim.data.info.floors, n.position->z())) << n.id;
      }
      EXPECT_TRUE(truth_found) << n.id;
    }
    EXPECT_EQ(levels, (std::set<int>{-1, 0, 1, 2})) << seed;
    WriteMissionDirectory(dir.path(), sim.data, sim.levels);
    const MissionDirectory mission(dir.path());
    EstimatorSummary gated_summary, open_summary;
    const Metrics gated = RunAndEvaluate("landmarks-ukf", mission, {}, &gated_summary);
    const Metrics open =
        RunAndEvaluate("landmarks-ukf", mission, {{"gate_other_floors", "false"}}, &open_summary);
    EXPECT_GT(gated_summary.numbers.at("radio_other_floor"), 100.0) << seed;
    EXPECT_EQ(open_summary.numbers.at("radio_other_floor"), 0.0) << seed;
    gated_agents += gated.agents.stats.mean_m;
    open_agents += open.agents.stats.mean_m;
  }
  // The magnitude on held-out seeds, and this filter's ellipses (which are not honest here:
  // issue 24), are in docs/floors.md; here only that gating is better.
  EXPECT_LT(gated_agents, open_agents);
  std::printf("landmarks-ukf, seeds 11-14, summed agent means: %.2f gated / %.2f not\n",
              gated_agents, open_agents);
}

TEST(Floors, AVariantDrawnAnotherWayKeepsItsFloors) {
  const SimulatedMission sim = SimulateScenario("multi-floor", 13);
  Variation v;
  for (std::uint64_t k = 1; k < 100; ++k) {
    v = DrawVariation(VariationFamily::kFrame, k);
    if (v.doors_across_gaps && v.write.polyline_walls) break;
  }
  ASSERT_TRUE(v.doors_across_gaps && v.write.polyline_walls);
  v.write.csv_shuffled_columns = v.write.csv_comments = true;  // (the csv family's)
  SimulatedMission drawn = sim;
  ApplyVariation(v, drawn);
  TempDir a, b;
  WriteMissionDirectory(a.path(), sim.data, sim.levels);
  WriteMissionDirectory(b.path(), drawn.data, drawn.levels, v.write);
  const MissionDirectory original(a.path()), variant(b.path());
  std::vector<int> levels;
  variant.LoadFloorPlan(std::nullopt, &levels);
  EXPECT_EQ(levels, (std::vector<int>{-1, 0, 1, 2}));
  VectorSink pa, pb;
  RunNamed("pdr", original, {}, pa);
  RunNamed("pdr", variant, {}, pb);
  ASSERT_EQ(pa.rows.size(), pb.rows.size());
  for (std::size_t i = 0; i < pa.rows.size(); ++i) {
    ASSERT_EQ(pa.rows[i].floor, pb.rows[i].floor) << i;
    ASSERT_EQ(pa.rows[i].position_n.z(), pb.rows[i].position_n.z()) << i;
  }
  VectorSink mm;
  const EstimatorSummary s = RunNamed("mapmatch", variant, {}, mm);
  EXPECT_EQ(s.numbers.at("ff1.level_changes"), 4.0);
  EXPECT_EQ(s.numbers.at("ff2.level_changes"), 2.0);
  EXPECT_EQ(s.numbers.at("ff1.level_changes_outside_stairwell"), 0.0);
  EXPECT_EQ(s.numbers.at("ff2.level_changes_outside_stairwell"), 0.0);
}

TEST(Floors, ASingleFloorMissionStaysOnItsFloorWithTheSameHorizontalEstimates) {
  TempDir dir;
  // The office loop with a foot IMU: the INS's steps carry small dz noise.
  const SimulatedMission sim = testing::WithFootImuOnly(SimulateScenario("office-loop", 2), 2);
  WriteMissionDirectory(dir.path(), sim.data, &sim.plan);
  const MissionDirectory mission(dir.path());
  for (const std::string pipeline : {"pdr", "breadcrumb", "ins"}) {
    VectorSink with, without;
    const EstimatorSummary summary = RunNamed(pipeline, mission, {}, with);
    if (pipeline == "breadcrumb") EXPECT_EQ(summary.numbers.at("radio_other_floor"), 0.0);
    // Height steps counted only from 100 m up: the channel never moves.
    RunNamed(pipeline, mission, {{"height.stairs_min_rise_m", "100"}}, without);
    ASSERT_EQ(with.rows.size(), without.rows.size()) << pipeline;
    std::size_t agents = 0;
    for (std::size_t i = 0; i < with.rows.size(); ++i) {
      const Estimate& a = with.rows[i];
      const Estimate& b = without.rows[i];
      ASSERT_EQ(a.position_n.head<2>(), b.position_n.head<2>()) << pipeline << " " << i;
      ASSERT_EQ(a.sxx, b.sxx);
      if (mission.info().Find(a.id) && mission.info().Find(a.id)->kind == NodeKind::kAgent) {
        ++agents;
        ASSERT_TRUE(a.floor.has_value()) << pipeline;
        EXPECT_EQ(*a.floor, 0) << pipeline << " t=" << a.t;
        EXPECT_LT(std::abs(a.position_n.z()), 0.45) << pipeline << " t=" << a.t;
      }
    }
    EXPECT_GT(agents, 100u) << pipeline;
  }
  // estimates.csv keeps the 1.0 columns for a mission without floors or a barometer.
  const auto run = RunPipeline(RequirePipeline("pdr"), {mission, {}}, dir.path() / "run");
  std::ifstream in(dir.path() / "run" / "estimates.csv");
  std::string header;
  std::getline(in, header);
  EXPECT_EQ(header, "t,id,x,y,z,sxx,sxy,syy");
  EXPECT_GT(run.estimates, 0u);
}

}  // namespace
}  // namespace trailmark

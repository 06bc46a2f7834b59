// SPDX-License-Identifier: MIT
// Batch and live are the same code: every pipeline of the registry, fed a mission row by row
// through the live path (the estimator the server builds, Feed::kLive), gives the batch run's
// estimates — node by node, the same rows, bit for bit — whether the rows arrive in time order
// or as devices deliver them (each its own rows in order, in batches interleaved with the
// others'): the reorder buffer puts simultaneous rows in the batch run's order (by node).
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <numbers>
#include <random>
#include <set>

#include "device_batches.h"
#include "pipelines/run_named.h"
#include "test_util.h"
#include "trailmark/ins/ins_estimator.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/sim/house_search.h"
#include "trailmark/sim/imu_sim.h"
#include "trailmark/sim/scenarios.h"

namespace trailmark {
namespace {

using testing::DeviceBatches;
using testing::RunNamed;
using testing::TempDir;

std::map<std::string, std::vector<Estimate>> ByNode(const std::vector<Estimate>& rows) {
  std::map<std::string, std::vector<Estimate>> by;
  for (const auto& e : rows) by[e.id].push_back(e);
  return by;
}

/// Node by node, the same estimates, bit for bit: same count, times, positions, covariances.
void ExpectSameEstimates(const std::vector<Estimate>& batch, const std::vector<Estimate>& live) {
  const auto a = ByNode(batch), b = ByNode(live);
  ASSERT_EQ(a.size(), b.size());
  for (const auto& [id, rows] : a) {
    ASSERT_TRUE(b.count(id)) << id;
    const auto& other = b.at(id);
    ASSERT_EQ(rows.size(), other.size()) << id;
    for (std::size_t i = 0; i < rows.size(); ++i) {
      ASSERT_EQ(rows[i].t, other[i].t) << id << " " << i;
      ASSERT_EQ(rows[i].position_n, other[i].position_n) << id << " " << i;
      ASSERT_EQ(rows[i].sxx, other[i].sxx) << id << " " << i;
      ASSERT_EQ(rows[i].sxy, other[i].sxy) << id << " " << i;
      ASSERT_EQ(rows[i].syy, other[i].syy) << id << " " << i;
    }
  }
}

/// The rows of the mission's streams the pipeline reads, in the batch run's merge order (by
/// time, then stream as MissionRow orders them, then file order); steps.csv shadows imu.csv
/// for steps-based pipelines, as in the batch run.
std::vector<MissionRow> MergedRows(const PipelineSpec& spec, const MissionData& d) {
  std::vector<MissionRow> rows;
  auto add = [&](const auto& stream, Stream s) {
    if (!spec.uses.Has(s)) return;
    for (const auto& r : stream) rows.emplace_back(r);
  };
  const bool steps_shadow_imu = spec.steps_based && !d.steps.empty();
  add(d.events, Stream::kEvents);
  add(d.steps, Stream::kSteps);
  add(d.ranges, Stream::kRanges);
  add(d.bearings, Stream::kBearings);
  add(d.rssi, Stream::kRssi);
  if (!steps_shadow_imu) add(d.imu, Stream::kImu);
  add(d.baro, Stream::kBaro);
  std::stable_sort(rows.begin(), rows.end(), [](const MissionRow& a, const MissionRow& b) {
    return RowTime(a) != RowTime(b) ? RowTime(a) < RowTime(b) : a.index() < b.index();
  });
  return rows;
}

struct Fed {
  std::vector<Estimate> estimates;
  EstimatorSummary summary;
};

/// The live path: the registry's estimator for a live feed, the rows one by one, then the end
/// of the incident (Finish: the rows still held by the reorder buffer or an INS).
Fed Live(const PipelineSpec& spec, const MissionInfo& info, const FloorPlan* plan,
         const OptionValues& options, const std::vector<MissionRow>& rows) {
  auto live = spec.make({info, plan}, options, Feed::kLive);
  VectorSink sink;
  for (const MissionRow& r : rows) live->Add(r, sink);
  live->Finish(sink);
  return {sink.rows, live->Summary()};
}

struct Case {
  std::string pipeline;
  std::string mission;  ///< for the test's messages
  SimulatedMission sim;
  OptionValues options;
};

/// The mission with foot IMUs instead of steps, cut where the first agent's IMU ends. (A foot
/// IMU that stops sending in a stance holds its last step until the end of data; live, the
/// reorder buffer does not wait for a device that fell silent, so that step would come late.)
SimulatedMission WithImuOnly(SimulatedMission sim, std::uint64_t seed) {
  ImuSimOptions imu;
  imu.rate_hz = 100;
  AddFootImu(sim, imu, seed);
  sim.data.steps.clear();
  std::map<std::string, TimeS> last;
  for (const auto& s : sim.data.imu) last[s.agent] = s.t;
  TimeS end = 1e300;
  for (const auto& [agent, t] : last) end = std::min(end, t);
  auto cut = [end](auto& rows) {
    std::erase_if(rows, [end](const auto& r) { return RowTime(MissionRow(r)) > end; });
  };
  cut(sim.data.imu);
  cut(sim.data.rssi);
  cut(sim.data.ranges);
  cut(sim.data.bearings);
  cut(sim.data.events);
  std::erase_if(sim.data.truth, [end](const TruthSample& t) { return t.t > end; });
  return sim;
}

/// The same with the foot IMUs mounted turned 90 deg about their vertical: the INS holds its
/// output for a few strides until it has found the mounting (ins/mount_yaw.h).
SimulatedMission MountedTurned(SimulatedMission sim) {
  MountImu(sim.data.imu, ImuMounting(std::numbers::pi / 2));
  return sim;
}

SimulatedMission TwoFirefighters() {
  TrainingBuildingOptions o;  // two firefighters, walls, crumbs, RSSI between all
  o.rooms_per_side = 2;
  return SimulateTrainingBuilding(o, 5);
}

SimulatedMission ShortHouseSearch() {
  HouseSearchOptions o;
  o.duration_s = 150;
  return SimulateHouseSearch(o, 4);
}

void CheckCase(const Case& c) {
  SCOPED_TRACE(c.pipeline + " on " + c.mission);
  const PipelineSpec& spec = RequirePipeline(c.pipeline);
  TempDir dir;
  WriteMissionDirectory(dir.path(), c.sim.data, &c.sim.plan);
  const MissionDirectory mission(dir.path());
  ASSERT_TRUE(CanRun(spec, mission));
  VectorSink batch;
  RunNamed(c.pipeline, mission, c.options, batch);
  ASSERT_GT(batch.rows.size(), 20u);
  const bool with_plan =
      spec.needs_floor_plan || (spec.uses_floor_plan && mission.info().floorplan.has_value());
  const auto floor =
      with_plan ? LoadPipelineFloor(spec, mission, c.options) : std::optional<FloorPlan>();
  const FloorPlan* plan = floor ? &*floor : nullptr;
  const std::vector<MissionRow> merged = MergedRows(spec, c.sim.data);
  // In time order: the very same estimates.
  {
    SCOPED_TRACE("rows in time order");
    const Fed in_order = Live(spec, c.sim.data.info, plan, c.options, merged);
    ExpectSameEstimates(batch.rows, in_order.estimates);
  }
  // Devices delivering 0.5 s batches (the reorder buffer waits 1 s): the same estimates, as
  // the buffer orders simultaneous rows by node, not by arrival.
  SCOPED_TRACE("devices interleaved");
  const std::vector<MissionRow> shuffled = DeviceBatches(merged, 0.5, 7);
  std::size_t out_of_order = 0;
  for (std::size_t i = 1; i < shuffled.size(); ++i)
    out_of_order += RowTime(shuffled[i]) < RowTime(shuffled[i - 1]);
  const Fed interleaved = Live(spec, c.sim.data.info, plan, c.options, shuffled);
  ExpectSameEstimates(batch.rows, interleaved.estimates);
  const auto late = interleaved.summary.numbers.find("rows_late");
  if (late != interleaved.summary.numbers.end()) EXPECT_EQ(late->second, 0.0);
  std::set<std::string> devices;
  for (const MissionRow& r : merged) devices.insert(RowNode(r));
  if (devices.size() > 1) EXPECT_GT(out_of_order, 0u);  // the test does reorder
}

TEST(LiveEqualsBatch, Pdr) {
  CheckCase({"pdr", "training building, steps", TwoFirefighters(), {}});
  CheckCase({"pdr", "training building, foot IMU", WithImuOnly(TwoFirefighters(), 9), {}});
  CheckCase({"pdr",
             "training building, foot IMU mounted turned",
             MountedTurned(WithImuOnly(TwoFirefighters(), 9)),
             {}});
}

TEST(LiveEqualsBatch, Ins) {
  CheckCase({"ins", "training building, foot IMU", WithImuOnly(TwoFirefighters(), 9),
             {{"output_hz", "5"}}});
  const SimulatedMission turned = MountedTurned(WithImuOnly(TwoFirefighters(), 9));
  CheckCase({"ins", "training building, foot IMU mounted turned", turned, {{"output_hz", "5"}}});
  // (The case does exercise the wait: each agent's INS turned its walk by the mounting.)
  ins::MultiAgentIns ins(turned.data.info, {});
  for (const auto& s : turned.data.imu) ins.Add(s);
  ins.Finish();
  const auto numbers = ins.Summary().numbers;
  for (const std::string agent : {"ff1", "ff2"}) {
    ASSERT_TRUE(numbers.count(agent + ".mount_yaw_turned_deg")) << agent;
    EXPECT_NEAR(numbers.at(agent + ".mount_yaw_turned_deg"), 90.0, 3.0) << agent;
  }
}

TEST(LiveEqualsBatch, Breadcrumb) {
  CheckCase({"breadcrumb", "training building, steps", TwoFirefighters(), {}});
  CheckCase({"breadcrumb", "training building, foot IMU", WithImuOnly(TwoFirefighters(), 9), {}});
  CheckCase({"breadcrumb",
             "training building, foot IMU mounted turned",
             MountedTurned(WithImuOnly(TwoFirefighters(), 9)),
             {}});
}

TEST(LiveEqualsBatch, Landmarks) {
  for (const char* p : {"landmarks-stopgo", "landmarks-ukf"}) {
    CheckCase({p, "landmark corridor, steps", SimulateScenario("landmark-corridor", 2), {}});
    CheckCase({p, "landmark corridor, foot IMU",
               WithImuOnly(SimulateScenario("landmark-corridor", 2), 3), {}});
  }
}

TEST(LiveEqualsBatch, Beacons) {
  for (const char* p : {"beacons-mds", "beacons-ekf"}) {
    CheckCase({p, "beacon trail, steps", SimulateScenario("beacon-trail", 2), {}});
    CheckCase({p, "beacon trail, foot IMU", WithImuOnly(SimulateScenario("beacon-trail", 2), 3),
               {}});
    // The map solved on a worker and put in place 1 s later: the same map however long the
    // worker takes (a live feed and a batch run at different speeds).
    CheckCase({p, "beacon trail, steps, map on a worker", SimulateScenario("beacon-trail", 2),
               {{"map_lag_s", "1"}}});
  }
}

TEST(LiveEqualsBatch, MapMatch) {
  CheckCase({"mapmatch", "house 1, steps", ShortHouseSearch(), {{"init", "uniform"}}});
  CheckCase({"mapmatch", "house 1, foot IMU", WithImuOnly(ShortHouseSearch(), 5),
             {{"init", "uniform"}}});
}

// The fusion: live builds a member for every stream, the batch run only those the mission's
// streams can feed; a member is used once its own evidence arrives, so the two agree.
TEST(LiveEqualsBatch, Fusion) {
  CheckCase({"fusion", "beacon trail, steps", SimulateScenario("beacon-trail", 2), {}});
  CheckCase({"fusion", "training building, foot IMU", WithImuOnly(TwoFirefighters(), 9), {}});
}

TEST(LiveEqualsBatch, EveryPipelineOfTheRegistryIsCovered) {
  const std::set<std::string> covered{
      "pdr",         "ins",      "breadcrumb", "landmarks-stopgo", "landmarks-ukf", "beacons-mds",
      "beacons-ekf", "mapmatch", "fusion"};
  for (const auto& p : Pipelines()) EXPECT_TRUE(covered.count(p.name)) << p.name;
}

TEST(LiveEqualsBatch, MapMatchOnTheFloorItIsGiven) {
  // The house on level 1 of a two-floor plan whose level 0 is cut into 1 m strips: the batch
  // run with level=1 and the live estimator given that floor give the same estimates.
  HouseSearchOptions o;
  o.duration_s = 60;
  const SimulatedMission sim = SimulateHouseSearch(o, 4);
  std::vector<Segment2> strips;
  for (int x = 1; x < 12; ++x) strips.push_back({{x + 0.5, 0.0}, {x + 0.5, 10.0}});
  TempDir dir;
  WriteMissionDirectory(dir.path(), sim.data, &sim.plan);
  std::ofstream(dir.path() / "floorplan.geojson")
      << FloorPlanToGeoJson({{0, FloorPlan(strips, {}, {})}, {1, sim.plan}});
  const MissionDirectory mission(dir.path());
  const OptionValues options{{"init", "uniform"}, {"level", "1"}};
  const PipelineSpec& spec = RequirePipeline("mapmatch");
  VectorSink batch;
  RunNamed("mapmatch", mission, options, batch);
  EXPECT_EQ(spec.floor_level(options), 1);
  const auto floor = LoadPipelineFloor(spec, mission, options);
  ASSERT_TRUE(floor.has_value());
  const Fed live = Live(spec, sim.data.info, &*floor, options, MergedRows(spec, sim.data));
  ExpectSameEstimates(batch.rows, live.estimates);
  EXPECT_GT(live.summary.numbers.at("ff1.pattern_comparisons"), 0.0);
  // Without its floor plan, or with a level that is no whole number: refused.
  EXPECT_THROW(spec.make({sim.data.info}, {{"init", "uniform"}}, Feed::kLive),
               std::invalid_argument);
  EXPECT_THROW(spec.floor_level({{"level", "1.5"}}), std::invalid_argument);
}

// The view between rows turns and stretches the last step as the estimator does: each one's
// StepTransform, through every wrapper of the pipeline, is the heading and scale correction its
// summary reports (a rotation for map matching, none for dead reckoning).
TEST(LiveEqualsBatch, EachPipelinesStepTransformIsTheCorrectionItReports) {
  struct Want {
    std::string pipeline, scenario, heading_key, scale_key;
    bool degrees, scale_is_factor;
  };
  for (const Want& w :
       std::vector<Want>{{"landmarks-ukf", "landmark-office", "ff1.heading_correction_deg",
                          "ff1.step_scale_correction", true, false},
                         {"breadcrumb", "office-loop", "ff1.heading_correction_deg",
                          "ff1.step_scale_error", true, false},
                         {"beacons-ekf", "beacon-trail", "ff1.heading_correction_rad",
                          "ff1.scale_correction", false, true},
                         {"mapmatch", "house1-search", "", "", false, false},
                         {"pdr", "office-loop", "", "", false, false}}) {
    SCOPED_TRACE(w.pipeline);
    const SimulatedMission sim = SimulateScenario(w.scenario, 1);
    const PipelineSpec& spec = RequirePipeline(w.pipeline);
    auto estimator = spec.make({sim.data.info, &sim.plan}, {}, Feed::kTimeOrdered);
    VectorSink sink;
    for (const MissionRow& r : MergedRows(spec, sim.data)) estimator->Add(r, sink);
    const std::optional<Mat2> m = estimator->StepTransform("ff1");
    if (w.pipeline == "pdr") {
      EXPECT_FALSE(m.has_value());
      continue;
    }
    ASSERT_TRUE(m.has_value());
    const double scale = std::sqrt(m->determinant());
    const double heading = std::atan2((*m)(1, 0), (*m)(0, 0));
    const Mat2 r = *m / scale;
    EXPECT_NEAR((r.transpose() * r - Mat2::Identity()).norm(), 0.0, 1e-12);  // a rotation x scale
    if (w.heading_key.empty()) {
      EXPECT_NEAR(scale, 1.0, 1e-12);
      continue;
    }
    const EstimatorSummary summary = estimator->Summary();
    const double reported = summary.numbers.at(w.heading_key) * (w.degrees ? M_PI / 180 : 1.0);
    const double reported_scale =
        w.scale_is_factor ? summary.numbers.at(w.scale_key) : 1.0 + summary.numbers.at(w.scale_key);
    EXPECT_NEAR(heading, reported, 1e-9);
    EXPECT_NEAR(scale, reported_scale, 1e-9);
    EXPECT_GT(std::abs(reported) + std::abs(reported_scale - 1), 1e-4);  // a correction to see
  }
}

TEST(LiveEqualsBatch, RefusesNonAgentsAndBadOptionsNamingTheKeys) {
  MissionInfo info;
  info.nodes.push_back({.id = "ff1", .kind = NodeKind::kAgent, .start = Vec3::Zero()});
  info.nodes.push_back({.id = "lm", .kind = NodeKind::kLandmark, .position = Vec3(1, 0, 0)});
  auto live = RequirePipeline("pdr").make({info}, {}, Feed::kLive);
  VectorSink sink;
  live->Add(Step{0, 1, "ff1", Vec3(0.7, 0, 0), std::nullopt}, sink);
  EXPECT_EQ(sink.rows.size(), 2u);  // the start, then the step
  ASSERT_TRUE(live->Current("ff1").has_value());
  EXPECT_EQ(live->Current("ff1")->position_n, Vec3(0.7, 0, 0));
  EXPECT_FALSE(live->Current("lm").has_value());
  EXPECT_THROW(live->Add(Step{1, 2, "lm", Vec3(0.7, 0, 0), std::nullopt}, sink),
               std::invalid_argument);
  EXPECT_EQ(FindPipeline("no-such-pipeline"), nullptr);
  try {
    RequirePipeline("pdr").make({info}, {{"bogus", "1"}}, Feed::kLive);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_THAT(e.what(), ::testing::HasSubstr("unknown option 'bogus'"));
    EXPECT_THAT(e.what(), ::testing::HasSubstr("ins.detector"));  // the valid keys are named
  }
  EXPECT_THROW(RequirePipeline("breadcrumb").make({info}, {{"reorder_s", "-1"}}, Feed::kLive),
               std::invalid_argument);
}

}  // namespace
}  // namespace trailmark

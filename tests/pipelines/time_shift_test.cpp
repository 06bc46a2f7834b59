// SPDX-License-Identifier: MIT
// The same mission an hour earlier (mission times may be negative, spec) gives the same
// estimates an hour earlier: every pipeline of the registry, node by node. Catches a clock that
// starts at 0 (the final rows of crumbs and landmarks were stamped at t = 0, after a mission
// that ended at t = -3,000 s).
#include <gtest/gtest.h>

#include <cmath>
#include <map>

#include "pipelines/run_named.h"
#include "test_util.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/sim/house_search.h"
#include "trailmark/sim/imu_sim.h"
#include "trailmark/sim/scenarios.h"

namespace trailmark {
namespace {

constexpr double kShiftS = -3600.0;

SimulatedMission Shifted(SimulatedMission sim) {
  auto& d = sim.data;
  for (auto& r : d.imu) r.t += kShiftS;
  for (auto& r : d.steps) r.t0 += kShiftS, r.t1 += kShiftS;
  for (auto& r : d.rssi) r.t += kShiftS;
  for (auto& r : d.ranges) r.t += kShiftS;
  for (auto& r : d.bearings) r.t += kShiftS;
  for (auto& r : d.events) r.t += kShiftS;
  for (auto& r : d.truth) r.t += kShiftS;
  return sim;
}

std::vector<Estimate> Run(const std::string& pipeline, const SimulatedMission& sim) {
  testing::TempDir dir;
  WriteMissionDirectory(dir.path(), sim.data, &sim.plan);
  VectorSink sink;
  testing::RunNamed(pipeline, MissionDirectory(dir.path()), {}, sink);
  return sink.rows;
}

std::map<std::string, std::vector<Estimate>> ByNode(const std::vector<Estimate>& rows) {
  std::map<std::string, std::vector<Estimate>> by;
  for (const auto& e : rows) by[e.id].push_back(e);
  return by;
}

void ExpectShifted(const std::string& pipeline, const SimulatedMission& sim) {
  SCOPED_TRACE(pipeline);
  const auto rows_a = Run(pipeline, sim), rows_b = Run(pipeline, Shifted(sim));
  ASSERT_GT(rows_a.size(), 10u);
  const auto by_a = ByNode(rows_a), by_b = ByNode(rows_b);
  ASSERT_EQ(by_a.size(), by_b.size());
  for (const auto& [id, a] : by_a) {
    const auto& b = by_b.at(id);
    ASSERT_EQ(a.size(), b.size()) << id;
    for (std::size_t i = 0; i < a.size(); ++i) {
      // Times differ by the shift (to the rounding of the shifted times); positions by what
      // that rounding (4.5e-13 s near 3,600 s) does to the time differences integrated over a
      // walk: within 1 mm (measured 2026-12-01: ins 0.3 mm — it integrates every 100 Hz dt
      // twice —, breadcrumb 2e-9 m, the others bit for bit).
      ASSERT_NEAR(b[i].t - a[i].t, kShiftS, 1e-9) << id << " " << i;
      ASSERT_LT((a[i].position_n - b[i].position_n).norm(), 1e-3) << id << " " << i;
    }
    EXPECT_LT(b.back().t, 0.0) << id;  // the final rows within the shifted mission
  }
}

TEST(TimeShift, EveryPipelineGivesTheSameEstimatesEarlier) {
  TrainingBuildingOptions tb;
  tb.rooms_per_side = 1;
  const SimulatedMission building = SimulateTrainingBuilding(tb, 3);
  ExpectShifted("pdr", building);
  ExpectShifted("breadcrumb", building);
  ExpectShifted("ins", testing::WithFootImuOnly(building, 2));
  ExpectShifted("landmarks-stopgo", SimulateScenario("landmark-corridor", 1));
  ExpectShifted("landmarks-ukf", SimulateScenario("landmark-corridor", 1));
  ExpectShifted("beacons-mds", SimulateScenario("beacon-trail", 1));
  ExpectShifted("beacons-ekf", SimulateScenario("beacon-trail", 1));
  HouseSearchOptions house;
  house.duration_s = 60;
  ExpectShifted("mapmatch", SimulateHouseSearch(house, 2));
}

}  // namespace
}  // namespace trailmark

// SPDX-License-Identifier: MIT
// Metamorphic tests (issue 21, item 2): the same walk drawn in another frame — rotated by 33°
// about a point and shifted by a kilometre — gives the same estimates, mapped back into the
// first frame, within a stated tolerance. Catches an estimator that relies on the axes or the
// origin of the frame (a grid tied to x/y, a prior at the origin).
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <numbers>

#include "pipelines/run_named.h"
#include "test_util.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/sim/beacon_lab.h"
#include "trailmark/sim/imu_sim.h"
#include "trailmark/sim/scenarios.h"
#include "trailmark/sim/variation.h"

namespace trailmark {
namespace {

using Frame = FrameMotion;
SimulatedMission Drawn(SimulatedMission sim, const Frame& f) { return DrawnInFrame(std::move(sim), f); }

/// Isotropic step variances (what Drawn does to them), so that both frames have the same input.
SimulatedMission Isotropic(SimulatedMission sim) { return Drawn(std::move(sim), Frame{}); }

std::vector<Estimate> Run(const std::string& pipeline, const SimulatedMission& sim,
                          const OptionValues& options) {
  testing::TempDir dir;
  if (sim.levels.empty()) {
    WriteMissionDirectory(dir.path(), sim.data, &sim.plan);
  } else {
    WriteMissionDirectory(dir.path(), sim.data, sim.levels);
  }
  VectorSink sink;
  testing::RunNamed(pipeline, MissionDirectory(dir.path()), options, sink);
  return sink.rows;
}

/// The largest distance between the estimates in the first frame and those of the other
/// frame mapped back, node by node (and the estimate counts and their floors must agree).
double LargestDifference(const std::string& pipeline, const SimulatedMission& sim,
                         const Frame& f, const OptionValues& options = {}) {
  const SimulatedMission a_sim = Isotropic(sim);
  const auto a = Run(pipeline, a_sim, options), b = Run(pipeline, Drawn(sim, f), options);
  std::map<std::string, std::vector<Estimate>> by_a, by_b;
  for (const auto& e : a) by_a[e.id].push_back(e);
  for (const auto& e : b) by_b[e.id].push_back(e);
  EXPECT_EQ(by_a.size(), by_b.size()) << pipeline;
  double worst = 0;
  for (const auto& [id, rows] : by_a) {
    const auto& other = by_b[id];
    EXPECT_EQ(rows.size(), other.size()) << pipeline << " " << id;
    for (std::size_t i = 0; i < std::min(rows.size(), other.size()); ++i) {
      const Vec2 back = f.Back(Vec2(other[i].position_n.head<2>()));
      worst = std::max(worst, (back - Vec2(rows[i].position_n.head<2>())).norm());
      EXPECT_EQ(rows[i].floor, other[i].floor) << pipeline << " " << id << " t=" << rows[i].t;
      EXPECT_EQ(rows[i].position_n.z(), other[i].position_n.z()) << pipeline << " " << id;
    }
  }
  return worst;
}

const Frame kRotatedShifted{33.0 * std::numbers::pi / 180.0, Vec2(1000.0, -500.0)};

TEST(Metamorphic, DeadReckoningAndTheInsDoNotDependOnTheFrame) {
  TrainingBuildingOptions o;
  o.rooms_per_side = 1;
  const SimulatedMission sim = SimulateTrainingBuilding(o, 3);
  // Rounding of a kilometre-sized frame (ulp 1e-13 m) summed over a walk.
  EXPECT_LT(LargestDifference("pdr", sim, kRotatedShifted), 1e-6);
  // The INS integrates in the rotated frame from the rotated start heading: rounding only.
  EXPECT_LT(LargestDifference("ins", testing::WithFootImuOnly(sim, 2), kRotatedShifted), 1e-3);
  EXPECT_LT(LargestDifference("pdr", testing::WithFootImuOnly(sim, 2), kRotatedShifted), 1e-3);
}

// Measured 2026-12-01 (largest difference over every estimate of the mission): breadcrumb
// 3e-9 m, beacons-ekf 8e-13 m, pdr and ins to rounding. Map matching and the radio landmarks
// are tested below.
TEST(Metamorphic, TheBreadcrumbNetworkDoesNotDependOnTheFrame) {
  const SimulatedMission sim = SimulateScenario("office-loop-1lap", 2);
  EXPECT_LT(LargestDifference("breadcrumb", sim, kRotatedShifted), 1e-6);
}

TEST(Metamorphic, BeaconTrailsDoNotDependOnTheFrame) {
  const SimulatedMission sim = SimulateScenario("beacon-trail", 2);
  EXPECT_LT(LargestDifference("beacons-mds", sim, kRotatedShifted), 1e-6);
  EXPECT_LT(LargestDifference("beacons-ekf", sim, kRotatedShifted), 1e-6);
}

TEST(Metamorphic, TheRangesScaleAgainstSurveysDoesNotDependOnTheFrame) {
  // Where surveys make the ultrasound ranges' scale observable, the beacon map and the filter
  // estimate it — on the honest mission and with every range x 1.06. The lab (every beacon
  // surveyed): to rounding.
  SimulatedMission lab = SimulateBeaconLab({}, 2);
  EXPECT_LT(LargestDifference("beacons-ekf", lab, kRotatedShifted), 1e-6);
  for (auto& r : lab.data.ranges) r.range_m *= 1.06;
  EXPECT_LT(LargestDifference("beacons-ekf", lab, kRotatedShifted), 1e-6);
  // The neighbour trail (three surveyed beacons, the map solved from links, surveys and drops):
  // its map's solve stopped at Ceres' 100-iteration cap, not converged, and depended on the
  // frame by millimetres (1.9 mm, 2.2 mm with the scale, measured 2026-12-07); Newton's steps
  // on the exact Hessian now finish it: to rounding, with and without the lie.
  SimulatedMission trail = SimulateScenario("beacon-neighbour-trail", 2);
  EXPECT_LT(LargestDifference("beacons-ekf", trail, kRotatedShifted), 1e-6);
  for (auto& r : trail.data.ranges) r.range_m *= 1.06;
  EXPECT_LT(LargestDifference("beacons-ekf", trail, kRotatedShifted), 1e-6);
  EXPECT_LT(LargestDifference("beacons-mds", trail, kRotatedShifted), 1e-6);
}

TEST(Metamorphic, RadioLandmarksDoNotDependOnTheFramesRotation) {
  // Measured 2026-12-02 over corridor seeds 1-8: stopgo 0 (to rounding: its grid searches lie in
  // the stops' own frame now; they were axis-aligned, up to 3.05 m); ukf 3-28 mm — its sigma
  // points come from a Cholesky factor, which does not rotate with the frame, so the unscented
  // transform's higher-order error differs by a little: 5 cm is the stated tolerance.
  for (int seed = 1; seed <= 8; ++seed) {
    const SimulatedMission sim = SimulateScenario("landmark-corridor", seed);
    EXPECT_LT(LargestDifference("landmarks-stopgo", sim, kRotatedShifted), 1e-6) << seed;
    EXPECT_LT(LargestDifference("landmarks-ukf", sim, kRotatedShifted), 0.05) << seed;
  }
}

TEST(Metamorphic, TheLandmarkTrackerOnTheOfficeDoesNotDependOnTheFrame) {
  // The error-state tracker's unknown landmarks are fitted on a grid in their positions' own
  // frame; the rest is an EKF (equivariant). Seeds 11-12 of the office, rotated and shifted.
  for (int seed : {11, 12}) {
    const SimulatedMission sim = SimulateScenario("landmark-office", seed);
    EXPECT_LT(LargestDifference("landmarks-ukf", sim, kRotatedShifted), 0.01) << seed;
  }
}

TEST(Metamorphic, RadioLandmarksDoNotDependOnTheFramesOrigin) {
  const SimulatedMission sim = SimulateScenario("landmark-corridor", 2);
  const Frame shifted{0.0, kRotatedShifted.shift_m};
  EXPECT_LT(LargestDifference("landmarks-stopgo", sim, shifted), 1e-6);
  EXPECT_LT(LargestDifference("landmarks-ukf", sim, shifted), 1e-6);
}

// Issue 23: the search grid lies along the walls' dominant direction, turned by a quarter turn
// the plan itself defines (mapmatch/search_map.h, GridAxis), its offsets and the wall-distance
// raster count from the plan's corner, and every random draw of the particle filter is made in
// the grid's axes: a house drawn rotated by any angle and shifted gives the same estimates, from
// a known start and from none (measured 2026-12-03: 6.4e-11 to 6.6e-11 m at 33, 60, 137 and
// 251 degrees, seeds 2 and 3; 0.17-0.6 m from a known start and 3.8-9.2 m from none with the
// grid along the map's axes, `grid_align=false`).
TEST(Metamorphic, MapMatchingDoesNotDependOnTheFramesRotation) {
  const std::pair<double, int> cases[] = {{33.0, 2}, {137.0, 2}, {251.0, 2}, {60.0, 3}};
  for (const auto& [deg, seed] : cases) {
    const Frame f{deg * std::numbers::pi / 180.0, Vec2(1000.0, -500.0)};
    const SimulatedMission sim = SimulateScenario("house1-search", seed);
    EXPECT_LT(LargestDifference("mapmatch", sim, f, {{"init", "known"}}), 1e-6) << deg;
    EXPECT_LT(LargestDifference("mapmatch", sim, f, {{"init", "uniform"}}), 1e-6) << deg;
  }
}

TEST(Metamorphic, MapMatchingDoesNotDependOnTheFramesOrigin) {
  const Frame shifted{0.0, kRotatedShifted.shift_m};
  EXPECT_LT(LargestDifference("mapmatch", SimulateScenario("house1-search", 2), shifted,
                              {{"init", "known"}}),
            1e-6);
}

// Floors (issue 26): the multi-floor building in another frame gives the same heights and floors
// (exactly: the height channel sees no x or y) and the same horizontal estimates, map matching on
// every level's plan included.
TEST(Metamorphic, FloorsDoNotDependOnTheFrame) {
  const SimulatedMission sim = SimulateScenario("multi-floor", 13);
  EXPECT_LT(LargestDifference("pdr", sim, kRotatedShifted), 1e-6);
  EXPECT_LT(LargestDifference("mapmatch", sim, kRotatedShifted), 1e-6);
}

/// The largest difference between the estimates on `sim` as written by default and on the same
/// mission in the other door convention (walls drawn with gaps, doors across them) written in
/// another style the spec allows (columns shuffled, an extra quoted column, comment lines,
/// connected walls as multi-vertex LineStrings).
double StyleDifference(const std::string& pipeline, const SimulatedMission& sim,
                       const OptionValues& options = {}) {
  const auto a = Run(pipeline, sim, options);
  SimulatedMission other = sim;
  other.plan = FloorPlan(sim.plan.solid_walls(), sim.plan.doors(), sim.plan.rooms());
  MissionWriteStyle style;
  style.csv_comments = style.csv_shuffled_columns = style.csv_extra_column = true;
  style.polyline_walls = true;
  style.seed = 5;
  testing::TempDir dir;
  WriteMissionDirectory(dir.path(), other.data, &other.plan, style);
  VectorSink sink;
  testing::RunNamed(pipeline, MissionDirectory(dir.path()), options, sink);
  EXPECT_EQ(a.size(), sink.rows.size()) << pipeline;
  double worst = 0;
  for (std::size_t i = 0; i < std::min(a.size(), sink.rows.size()); ++i) {
    EXPECT_EQ(a[i].id, sink.rows[i].id) << pipeline;
    worst = std::max(worst, (a[i].position_n - sink.rows[i].position_n).norm());
  }
  return worst;
}

TEST(Metamorphic, NoPipelineDependsOnTheDoorConventionOrTheCsvStyle) {
  const SimulatedMission office = SimulateScenario("office-loop-1lap", 2);
  EXPECT_LT(StyleDifference("pdr", office), 1e-9);
  EXPECT_LT(StyleDifference("breadcrumb", office), 1e-9);
  const SimulatedMission corridor = SimulateScenario("landmark-corridor", 2);
  EXPECT_LT(StyleDifference("landmarks-stopgo", corridor), 1e-9);
  EXPECT_LT(StyleDifference("landmarks-ukf", corridor), 1e-9);
  const SimulatedMission trail = SimulateScenario("beacon-trail", 2);
  EXPECT_LT(StyleDifference("beacons-mds", trail), 1e-9);
  EXPECT_LT(StyleDifference("beacons-ekf", trail), 1e-9);
  // Map matching reads the plan: its enclosed area, grid and walls must not change (the
  // search grid's flood fill once leaked through doors drawn across gaps: "no enclosed area").
  const SimulatedMission house = SimulateScenario("house1-search", 2);
  EXPECT_LT(StyleDifference("mapmatch", house), 1e-9);
  EXPECT_LT(StyleDifference("mapmatch", house, {{"init", "known"}}), 1e-9);
}

}  // namespace
}  // namespace trailmark

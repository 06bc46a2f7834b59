// SPDX-License-Identifier: MIT
// Metamorphic tests (issue 21, item 2): the same walk drawn in another frame — rotated by 33°
// about a point and shifted by a kilometre — gives the same estimates, mapped back into the
// first frame, within a stated tolerance. Catches an estimator that relies on the axes or the
// origin of the frame (a grid tied to x/y, a prior at the origin).
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <map>
#include <numbers>

#include "pipelines/run_named.h"
#include "test_util.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/sim/imu_sim.h"
#include "trailmark/sim/scenarios.h"

namespace trailmark {
namespace {

/// A rigid motion of the navigation frame (about the z axis).
struct Frame {
  double angle_rad = 0;
  Vec2 shift = Vec2::Zero();
  Vec2 Point(const Vec2& p) const { return Eigen::Rotation2Dd(angle_rad) * p + shift; }
  Vec3 Point(const Vec3& p) const {
    const Vec2 q = Point(Vec2(p.head<2>()));
    return Vec3(q.x(), q.y(), p.z());
  }
  Vec3 Direction(const Vec3& d) const {
    const Vec2 q = Eigen::Rotation2Dd(angle_rad) * Vec2(d.head<2>());
    return Vec3(q.x(), q.y(), d.z());
  }
  Vec2 Back(const Vec2& p) const { return Eigen::Rotation2Dd(-angle_rad) * (p - shift); }
};

/// The mission drawn in `f`: positions, starts, headings, steps, bearings, truth and the plan.
/// (Foot-IMU samples are in the body frame: the start heading carries the rotation.)
SimulatedMission Drawn(SimulatedMission sim, const Frame& f) {
  MissionData& d = sim.data;
  for (NodeInfo& n : d.info.nodes) {
    if (n.position) n.position = f.Point(*n.position);
    if (n.start) n.start = f.Point(*n.start);
    if (n.start_heading_rad) n.start_heading_rad = WrapAngle(*n.start_heading_rad + f.angle_rad);
  }
  for (Step& s : d.steps) {
    s.delta_n = f.Direction(s.delta_n);
    // A per-axis variance is not rotation-invariant; the same total as isotropic.
    if (s.variance_m2) {
      const double h = 0.5 * (s.variance_m2->x() + s.variance_m2->y());
      s.variance_m2 = Vec3(h, h, s.variance_m2->z());
    }
  }
  for (BearingMeasurement& b : d.bearings) b.bearing_rad = WrapAngle(b.bearing_rad + f.angle_rad);
  for (TruthSample& t : d.truth) t.position_n = f.Point(t.position_n);
  std::vector<Segment2> walls, doors;
  for (const auto& w : sim.plan.walls()) walls.push_back({f.Point(w.a), f.Point(w.b)});
  for (const auto& w : sim.plan.doors()) doors.push_back({f.Point(w.a), f.Point(w.b)});
  std::vector<Room> rooms = sim.plan.rooms();
  for (Room& r : rooms) {
    for (Vec2& p : r.ring) p = f.Point(p);
  }
  sim.plan = FloorPlan(walls, doors, rooms);
  return sim;
}

/// Isotropic step variances (what Drawn does to them), so that both frames have the same input.
SimulatedMission Isotropic(SimulatedMission sim) { return Drawn(std::move(sim), Frame{}); }

std::vector<Estimate> Run(const std::string& pipeline, const SimulatedMission& sim,
                          const OptionValues& options) {
  testing::TempDir dir;
  WriteMissionDirectory(dir.path(), sim.data, &sim.plan);
  VectorSink sink;
  testing::RunNamed(pipeline, MissionDirectory(dir.path()), options, sink);
  return sink.rows;
}

/// The largest distance between the estimates in the first frame and those of the other
/// frame mapped back, node by node (and the estimate counts must agree).
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
// 3e-9 m, beacons-ekf 8e-13 m, pdr and ins to rounding. Not yet invariant to rotation: the
// radio-landmark estimators, up to 3.05 m over corridor seeds 1-8 (stopgo 0.001-3.05 m, ukf
// 0.005-3.05 m: unknown landmarks start from an axis-aligned grid search and land in another
// local minimum of the robust cost; issue 24), and mapmatch, 0.49 m from a known start (search
// patterns from an axis-aligned grid; issue 23): for those only the shift is tested here.
TEST(Metamorphic, TheBreadcrumbNetworkDoesNotDependOnTheFrame) {
  const SimulatedMission sim = SimulateScenario("office-loop-1lap", 2);
  EXPECT_LT(LargestDifference("breadcrumb", sim, kRotatedShifted), 1e-6);
}

TEST(Metamorphic, BeaconTrailsDoNotDependOnTheFrame) {
  const SimulatedMission sim = SimulateScenario("beacon-trail", 2);
  EXPECT_LT(LargestDifference("beacons-mds", sim, kRotatedShifted), 1e-6);
  EXPECT_LT(LargestDifference("beacons-ekf", sim, kRotatedShifted), 1e-6);
}

TEST(Metamorphic, RadioLandmarksDoNotDependOnTheFramesOrigin) {
  const SimulatedMission sim = SimulateScenario("landmark-corridor", 2);
  const Frame shifted{0.0, kRotatedShifted.shift};
  EXPECT_LT(LargestDifference("landmarks-stopgo", sim, shifted), 1e-6);
  EXPECT_LT(LargestDifference("landmarks-ukf", sim, shifted), 1e-6);
}

TEST(Metamorphic, MapMatchingDoesNotDependOnTheFramesOrigin) {
  const Frame shifted{0.0, kRotatedShifted.shift};
  EXPECT_LT(LargestDifference("mapmatch", SimulateScenario("house1-search", 2), shifted,
                              {{"init", "known"}}),
            1e-6);
}

}  // namespace
}  // namespace trailmark

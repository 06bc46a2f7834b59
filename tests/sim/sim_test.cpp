// SPDX-License-Identifier: MIT
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <utility>
#include <vector>

#include "trailmark/sim/house_search.h"
#include "trailmark/sim/pdr_error_model.h"
#include "trailmark/sim/rssi_channel.h"
#include "trailmark/sim/scenarios.h"
#include "trailmark/sim/synthetic_incident.h"
#include "trailmark/sim/walker.h"

namespace trailmark {
namespace {

TEST(Walker, RealisticStepsAndSpeedAndStops) {
  Route route{{{0, 0}, {10, 0}, {10, 10}}, {{5.0, 3.0}}};
  Random rng(1);
  const Walk walk = WalkRoute(route, {}, 0.0, rng);
  double length = 0;
  for (const auto& s : walk.steps) {
    const double l = (s.to - s.from).norm();
    length += l;
    EXPECT_LT(l, 1.0);
    EXPECT_GT(s.t1, s.t0);
  }
  EXPECT_NEAR(length, 20.0, 0.5);  // chords cut the corner slightly
  ASSERT_EQ(walk.stops.size(), 1u);
  EXPECT_NEAR(walk.stops[0].t_go - walk.stops[0].t_stop, 3.0, 1e-9);
  // Duration = distance / speed + stop.
  EXPECT_NEAR(walk.truth.back().t, 20.0 / 1.2 + 3.0, 0.2);
  EXPECT_NEAR((walk.truth.back().position - Vec2(10, 10)).norm(), 0.0, 0.15);
}

TEST(Walker, WallFollowingGoesRoundARoomAndBack) {
  // 10 x 6 room; right-hand search from the middle of the bottom wall heading east.
  const FloorPlan room({{{0, 0}, {10, 0}}, {{10, 0}, {10, 6}}, {{10, 6}, {0, 6}}, {{0, 6}, {0, 0}}},
                       {}, {});
  for (Hand hand : {Hand::kLeft, Hand::kRight}) {
    const Vec2 start = hand == Hand::kRight ? Vec2(5, 0.6) : Vec2(5, 5.4);
    const Route r = FollowWall(room, start, 0.0, hand, {.max_length_m = 60});
    bool back_near_start = false;
    double walked = 0;
    for (std::size_t i = 1; i < r.waypoints.size(); ++i) {
      walked += (r.waypoints[i] - r.waypoints[i - 1]).norm();
      // Never through a wall, always about an arm's length from the nearest wall.
      ASSERT_FALSE(room.Crosses(r.waypoints[i - 1], r.waypoints[i]));
      if (walked > 20 && (r.waypoints[i] - start).norm() < 0.5) back_near_start = true;
    }
    EXPECT_TRUE(back_near_start) << (hand == Hand::kLeft ? "left" : "right");
  }
}

// An odometry model with every random error off.
PdrErrorOptions ErrorFree() {
  return {.heading_random_walk_rad = 0,
          .heading_drift_sigma_rad_per_s = 0,
          .turn_scale_error_sigma = 0,
          .scale_error_sigma = 0,
          .step_noise_m = 0};
}

TEST(PdrErrorModel, ErrorFreeIsExactAndDriftRotates) {
  const PdrErrorOptions none = ErrorFree();
  PdrErrorModel exact(none, Random(1));
  EXPECT_TRUE(exact.Apply({0.7, 0.1}, 0.5).isApprox(Vec2(0.7, 0.1), 1e-15));
  PdrErrorOptions drift = none;
  drift.heading_drift_rad_per_s = 0.1;
  PdrErrorModel m(drift, Random(1));
  const Vec2 d = m.Apply({1, 0}, 1.0);  // 0.1 rad of heading error after 1 s
  EXPECT_NEAR(std::atan2(d.y(), d.x()), 0.1, 1e-12);
}

// The gyro scale error accrues on real turns only: a few short steps in scattered directions
// (edging round furniture) between two steps in the same direction add nothing with
// turn_min_step_m, and a wrapped "rotation" of hundreds of degrees without it.
TEST(PdrErrorModel, ShortShufflingStepsDoNotTurnTheGyro) {
  PdrErrorOptions o = ErrorFree();
  o.turn_scale_error_sigma = 0.05;
  const std::vector<double> shuffle_deg = {-1, -133, 80, -44, -168, 65, -150};
  auto heading_error_after_shuffle = [&](double turn_min_step_m) {
    PdrErrorOptions oo = o;
    oo.turn_min_step_m = turn_min_step_m;
    PdrErrorModel m(oo, Random(7));
    m.Apply({0.5, 0}, 1.0);
    for (double deg : shuffle_deg) {
      const double a = deg * std::numbers::pi / 180;
      m.Apply(0.15 * Vec2(std::cos(a), std::sin(a)), 1.0);
    }
    m.Apply({0.5, 0}, 1.0);
    return std::pair{m.heading_error_rad(), m.turn_scale()};
  };
  const auto [with_rule, scale] = heading_error_after_shuffle(0.3);
  ASSERT_GT(std::abs(scale), 1e-4);
  EXPECT_NEAR(with_rule, 0.0, 1e-12);
  // Without the rule: the wrapped direction changes of the shuffle sum to a whole number of
  // turns that the foot never made (here -360 deg), times the scale error.
  const auto [without_rule, same_scale] = heading_error_after_shuffle(0.0);
  double wrapped_sum = 0, last = 0;
  for (double deg : shuffle_deg) {
    wrapped_sum += std::remainder(deg - last, 360.0);
    last = deg;
  }
  wrapped_sum += std::remainder(0 - last, 360.0);
  EXPECT_NEAR(wrapped_sum, -360.0, 1e-9);
  EXPECT_NEAR(without_rule, same_scale * wrapped_sum * std::numbers::pi / 180, 1e-9);
}

TEST(RssiChannel, MeanFollowsLogDistanceWallsAndBody) {
  RssiChannelOptions o;
  const FloorPlan wall({{{5, -10}, {5, 10}}}, {}, {});
  RssiChannel free(o, nullptr, {}, Random(1));
  EXPECT_NEAR(free.MeanRssi({0, 0}, {10, 0}, std::nullopt, std::nullopt),
              o.alpha_dbm - 10 * o.path_loss_exponent, 1e-12);
  RssiChannel walled(o, &wall, {}, Random(1));
  EXPECT_NEAR(walled.MeanRssi({0, 0}, {10, 0}, std::nullopt, std::nullopt),
              o.alpha_dbm - 10 * o.path_loss_exponent - o.wall_loss_db, 1e-12);
  // The other node straight behind the wearer: full body loss; in front: none.
  EXPECT_NEAR(free.MeanRssi({0, 0}, {10, 0}, std::numbers::pi, std::nullopt),
              o.alpha_dbm - 10 * o.path_loss_exponent - o.body_loss_db, 1e-9);
  EXPECT_NEAR(free.MeanRssi({0, 0}, {10, 0}, 0.0, std::nullopt),
              o.alpha_dbm - 10 * o.path_loss_exponent, 1e-9);
  // A fire zone across the link adds its loss per metre inside.
  RssiChannel fire(o, nullptr, {{"fire", {{4, -1}, {6, -1}, {6, 1}, {4, 1}}, 3.0, 0.0}}, Random(1));
  EXPECT_NEAR(fire.MeanRssi({0, 0}, {10, 0}, std::nullopt, std::nullopt),
              o.alpha_dbm - 10 * o.path_loss_exponent - 2.0 * 3.0, 1e-9);
  // Two floors between the ends, 7.5 m higher (issue 26): the floors' loss, and the height in
  // the path (10 m across, 7.5 m up: 12.5 m); the walls of the level given, not the channel's.
  LinkLevels up;
  up.floors_crossed = 2;
  up.dz_m = 7.5;
  const FloorPlan open({{{50, -10}, {50, 10}}}, {}, {});
  up.plan = &open;
  EXPECT_NEAR(walled.MeanRssi({0, 0}, {10, 0}, std::nullopt, std::nullopt, up),
              o.alpha_dbm - 10 * o.path_loss_exponent * std::log10(12.5) - 2 * o.floor_loss_db,
              1e-9);
  // Same level: exactly the single-floor channel.
  EXPECT_EQ(walled.MeanRssi({0, 0}, {10, 0}, std::nullopt, std::nullopt, LinkLevels{}),
            walled.MeanRssi({0, 0}, {10, 0}, std::nullopt, std::nullopt));
}

TEST(RssiChannel, SamplesAreUnbiasedWithTheStatedSpread) {
  RssiChannelOptions o;
  o.sensitivity_dbm = -200;
  RssiChannel ch(o, nullptr, {}, Random(5));
  double sum = 0, sum2 = 0;
  const int n = 20000;
  for (int i = 0; i < n; ++i) {
    // Move the link so the slow shadowing decorrelates.
    const Vec2 rx(10 + 0.0, 50.0 * i);
    const double r = *ch.Sample("a", rx, "b", rx + Vec2(10, 0), std::nullopt, std::nullopt);
    sum += r;
    sum2 += r * r;
  }
  const double mean = sum / n;
  const double sd = std::sqrt(sum2 / n - mean * mean);
  EXPECT_NEAR(mean, o.alpha_dbm - 10 * o.path_loss_exponent, 0.15);
  EXPECT_NEAR(sd, o.shadowing_sigma_db, 0.15);  // rounding to 1 dB adds ~0.01 dB^2
}

TEST(Scenario, OfficeLoopIsDeterministicAndLikeThePaper) {
  const SimulatedMission a = SimulateScenario("office-loop", 3);
  const SimulatedMission b = SimulateScenario("office-loop", 3);
  const SimulatedMission c = SimulateScenario("office-loop", 4);
  ASSERT_EQ(a.data.steps.size(), b.data.steps.size());
  for (std::size_t i = 0; i < a.data.steps.size(); ++i) {
    ASSERT_EQ(a.data.steps[i].delta_n, b.data.steps[i].delta_n);
  }
  ASSERT_EQ(a.data.rssi.size(), b.data.rssi.size());
  EXPECT_NE(a.data.steps[10].delta_n, c.data.steps[10].delta_n);

  // 400 m walked; crumbs dropped on the first lap only (paper: six).
  double distance = 0;
  Vec2 prev = Vec2::Zero();
  bool first = true;
  int crumbs = 0, crumbs_lap1 = 0;
  for (const auto& t : a.data.truth) {
    if (t.id != "ff1") continue;
    if (!first) distance += (t.position_n.head<2>() - prev).norm();
    prev = t.position_n.head<2>();
    first = false;
  }
  for (const auto& e : a.data.events) {
    if (e.event == "drop") {
      ++crumbs;
      crumbs_lap1 += e.t < a.data.truth.back().t / 4 + 5;
    }
  }
  EXPECT_NEAR(distance, 400.0, 2.0);
  EXPECT_GE(crumbs, 4);
  EXPECT_LE(crumbs, 8);
  // The chain is laid on the first lap; a later lap drops one only where shadowing makes
  // every link weak at once.
  EXPECT_GE(crumbs_lap1, crumbs - 1);

  // The truth path never crosses a wall; rows are in time order.
  prev = Vec2::Zero();
  double t_prev = -1;
  for (const auto& t : a.data.truth) {
    EXPECT_GE(t.t, t_prev);
    t_prev = t.t;
    if (t.id != "ff1") continue;
    EXPECT_FALSE(a.plan.Crosses(prev, t.position_n.head<2>()));
    prev = t.position_n.head<2>();
  }
  // Encounters: passing a crumb gives RSSI above -40 dBm only nearby (paper Fig. 7).
  int strong = 0;
  for (const auto& p : a.data.rssi) strong += p.rssi_dbm > -40 && p.rx == "ff1";
  EXPECT_GT(strong, 0);
}

TEST(LandmarkIncident, RowsInTimeOrderEveryPacketFromALandmarkInRangeAndLoudEnough) {
  // The benchmark's incident (`trailmark bench landmarks`): what it claims to contain.
  LandmarkIncidentOptions o;
  o.agents = 5;
  o.duration_s = 300;
  const LandmarkIncident inc = MakeLandmarkIncident(o, 3);
  EXPECT_EQ(inc.steps, static_cast<std::size_t>(5 * 500));
  EXPECT_EQ(inc.rows.size(), inc.steps + inc.packets);
  EXPECT_EQ(inc.truth.size(), inc.steps);
  EXPECT_GT(inc.packets, static_cast<std::size_t>(5 * 300 * 3));  // several landmarks a second
  for (std::size_t k = 1; k < inc.rows.size(); ++k) {
    ASSERT_LE(RowTime(inc.rows[k - 1]), RowTime(inc.rows[k])) << k;
  }
  std::map<std::string, const NodeInfo*> landmarks;
  std::size_t unknown = 0;
  for (const NodeInfo& n : inc.info.nodes) {
    if (n.kind != NodeKind::kLandmark) continue;
    landmarks[n.id] = &n;
    unknown += !n.position.has_value();
  }
  EXPECT_EQ(landmarks.size(), inc.landmarks);
  EXPECT_EQ(unknown, inc.unknown);
  EXPECT_NEAR(static_cast<double>(unknown) / static_cast<double>(inc.landmarks), 0.25, 0.02);
  // Each packet from a landmark within hearing range of the walker's truth (a step's end at
  // most one step away), above the receiver's sensitivity.
  std::map<std::string, std::vector<const TruthSample*>> truth;
  for (const TruthSample& s : inc.truth) truth[s.id].push_back(&s);
  std::size_t checked = 0;
  for (const MissionRow& row : inc.rows) {
    const auto* p = std::get_if<RssiPacket>(&row);
    if (p == nullptr) continue;
    ASSERT_TRUE(landmarks.count(p->tx)) << p->tx;
    EXPECT_GE(p->rssi_dbm, o.sensitivity_dbm);
    const NodeInfo* l = landmarks[p->tx];
    if (!l->position) continue;
    const auto& v = truth.at(p->rx);
    const auto s = std::lower_bound(v.begin(), v.end(), p->t,
                                    [](const TruthSample* a, double t) { return a->t < t; });
    if (s == v.end()) continue;
    EXPECT_LE(((*s)->position_n - *l->position).head<2>().norm(),
              o.hearing_range_m + o.step_length_m + 1e-9);
    ++checked;
  }
  EXPECT_GT(checked, inc.packets / 2);
  // Deterministic for a seed, another for another.
  EXPECT_EQ(MakeLandmarkIncident(o, 3).packets, inc.packets);
  EXPECT_NE(MakeLandmarkIncident(o, 4).packets, inc.packets);
}

TEST(Scenario, UnknownNameListsKnownOnes) {
  try {
    SimulateScenario("mars", 1);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("office-loop"), std::string::npos);
  }
}

}  // namespace
TEST(Scenario, ADirectionalSearchOnAnyFloorPlan) {
  // House 2 as its map shows it (the entry door open): entering at the house's entry with no
  // heading given, the search walks in away from that door, which is shut behind the team —
  // the truth never crosses a wall of the map nor leaves the building's bounds.
  const FloorPlan map = BuildHouse(2, false);
  HouseSearchOptions o;
  o.duration_s = 300;
  const SimulatedMission sim = SimulateSearchOnPlan(map, HouseEntry(2), std::nullopt, o, 5);
  ASSERT_EQ(sim.data.info.nodes.size(), 1u);
  EXPECT_NEAR(sim.data.info.nodes[0].start_heading_rad.value_or(99), HouseEntryHeading(2), 1e-12);
  ASSERT_GT(sim.data.truth.size(), 2000u);  // 10 Hz for 300 s
  EXPECT_NEAR(sim.data.truth.back().t, 300, 0.2);
  double walked = 0;
  const Box2 box = map.Bounds();
  for (std::size_t k = 1; k < sim.data.truth.size(); ++k) {
    const Vec2 a = sim.data.truth[k - 1].position_n.head<2>();
    const Vec2 b = sim.data.truth[k].position_n.head<2>();
    ASSERT_FALSE(map.Crosses(a, b)) << sim.data.truth[k].t;
    ASSERT_TRUE((b.array() >= box.min.array()).all() && (b.array() <= box.max.array()).all());
    walked += (b - a).norm();
  }
  EXPECT_GT(walked, 100.0);  // about 0.45 m/s less the pauses
  EXPECT_FALSE(sim.data.steps.empty());
  EXPECT_EQ(sim.plan.walls().size(), map.walls().size());  // the map as given
  // Deterministic per seed.
  const SimulatedMission again = SimulateSearchOnPlan(map, HouseEntry(2), std::nullopt, o, 5);
  EXPECT_EQ(again.data.truth.back().position_n, sim.data.truth.back().position_n);
  // Named errors: outside the plan, no door to walk in from and no heading, no walls.
  EXPECT_THROW(SimulateSearchOnPlan(map, Vec2(40, 5), 0.0, o, 1), std::invalid_argument);
  EXPECT_THROW(SimulateSearchOnPlan(map, Vec2(11, 2), std::nullopt, o, 1), std::invalid_argument);
  EXPECT_NO_THROW(SimulateSearchOnPlan(map, Vec2(11, 2), 0.5, o, 1));
  EXPECT_THROW(SimulateSearchOnPlan(FloorPlan(), Vec2(0, 0), 0.0, o, 1), std::invalid_argument);
  EXPECT_THROW(SimulateSearchOnPlan(map, Vec2(5.0, 2.0), 0.0, o, 1),  // on a wall
               std::invalid_argument);
  // Boxed in: a 0.5 m cell round the entry.
  std::vector<Segment2> walls = map.walls();
  AddRectangle(walls, Vec2(2.75, 2.75), Vec2(3.25, 3.25));
  EXPECT_THROW(SimulateSearchOnPlan(FloorPlan(walls, {}, {}), Vec2(3, 3), 0.0, o, 1),
               std::invalid_argument);
  o.duration_s = 0;
  EXPECT_THROW(SimulateSearchOnPlan(map, HouseEntry(2), 0.0, o, 1), std::invalid_argument);
}

}  // namespace trailmark

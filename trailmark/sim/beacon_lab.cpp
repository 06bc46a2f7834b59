// SPDX-License-Identifier: MIT
#include "trailmark/sim/beacon_lab.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <numbers>

#include "trailmark/core/random.h"

namespace trailmark {
namespace {

constexpr double kPi = std::numbers::pi;

// Aisle centre lines of the lab.
constexpr double kWest = 1.5, kEast = 13.5, kSouth = 1.5, kNorth = 7.5, kCross = 7.5, kMid = 4.5;
const Vec2 kEntryOutside(-1.0, kMid);  // the base, outside the door
const Vec2 kTraceStart(kWest, kMid);

std::vector<Vec2> RingCcw() {
  return {{kWest, kMid},   {kWest, kSouth}, {kEast, kSouth},
          {kEast, kNorth}, {kWest, kNorth}, {kWest, kMid}};
}
std::vector<Vec2> Reversed(std::vector<Vec2> v) {
  std::reverse(v.begin(), v.end());
  return v;
}
std::vector<Vec2> WestLoop() {
  return {{kWest, kMid},    {kWest, kSouth}, {kCross, kSouth},
          {kCross, kNorth}, {kWest, kNorth}, {kWest, kMid}};
}
std::vector<Vec2> EastLoop() {
  return {{kWest, kMid},    {kWest, kSouth},  {kEast, kSouth}, {kEast, kNorth},
          {kCross, kNorth}, {kCross, kSouth}, {kWest, kSouth}, {kWest, kMid}};
}
std::vector<Vec2> FigureEight() {
  return {{kWest, kMid},   {kWest, kSouth},  {kCross, kSouth}, {kCross, kNorth}, {kEast, kNorth},
          {kEast, kSouth}, {kCross, kSouth}, {kCross, kNorth}, {kWest, kNorth},  {kWest, kMid}};
}

// Loops appended until the route is long enough for the trace's duration.
Route TraceRoute(LabTrace trace, double speed_mps) {
  std::vector<std::vector<Vec2>> cycle;
  switch (trace) {
    case LabTrace::kA:
      cycle = {RingCcw()};
      break;
    case LabTrace::kB:
      cycle = {Reversed(RingCcw())};
      break;
    case LabTrace::kC:
      cycle = {FigureEight()};
      break;
    case LabTrace::kD:
      cycle = {WestLoop(), Reversed(WestLoop())};
      break;
    case LabTrace::kE:
      cycle = {EastLoop(), WestLoop()};
      break;
    case LabTrace::kF:
      cycle = {RingCcw(), FigureEight(), Reversed(EastLoop())};
      break;
  }
  Route route;
  route.waypoints.push_back(kTraceStart);
  const double want_m = LabTraceMinutes(trace) * 60.0 * speed_mps;
  for (std::size_t k = 0; route.Length() < want_m; ++k) {
    const auto& loop = cycle[k % cycle.size()];
    for (std::size_t i = 1; i < loop.size(); ++i) {
      route.waypoints.push_back(loop[i]);
      // Trace f searches: a pause at every corner of its first loop kind.
      if (trace == LabTrace::kF && k % cycle.size() == 0 && i + 1 < loop.size()) {
        route.stops.push_back({route.Length(), 4.0});
      }
      if (route.Length() >= want_m) break;
    }
  }
  return route;
}

// The walk that lays the trail: in through the door, around the ring, through the cross aisle.
Route DeploymentRoute() {
  Route r;
  r.waypoints = {kEntryOutside,   {kWest, kMid},    {kWest, kSouth},  {kEast, kSouth},
                 {kEast, kNorth}, {kCross, kNorth}, {kCross, kSouth}, {kCross, kNorth},
                 {kWest, kNorth}, {kWest, kMid}};
  return r;
}

Walk Concatenate(std::vector<Walk> parts) {
  Walk all;
  for (auto& w : parts) {
    all.steps.insert(all.steps.end(), w.steps.begin(), w.steps.end());
    for (const auto& s : w.truth) {
      if (all.truth.empty() || s.t > all.truth.back().t + 1e-9) all.truth.push_back(s);
    }
    all.stops.insert(all.stops.end(), w.stops.begin(), w.stops.end());
  }
  return all;
}

double TurnAngle(const Vec2& a, const Vec2& b, const Vec2& c) {
  const Vec2 u = b - a, v = c - b;
  if (u.norm() < 1e-9 || v.norm() < 1e-9) return 0;
  return std::abs(std::atan2(u.x() * v.y() - u.y() * v.x(), u.dot(v)));
}

// PDR steps of ff1 (the IMU's heading starts off by a magnetometer error) and its truth.
void AddPdrSteps(const Walk& walk, PdrErrorOptions pdr_options, double heading_sigma_rad,
                 Random& pdr_rng, MissionData& m) {
  pdr_options.initial_heading_error_rad = heading_sigma_rad * pdr_rng.Normal();
  PdrErrorModel pdr(pdr_options, pdr_rng.Fork());
  AppendPdrWalk(pdr, walk, "ff1", m);
}

void SortByTime(MissionData& m) {
  auto by_time = [](const auto& a, const auto& b) { return a.t < b.t; };
  std::stable_sort(m.ranges.begin(), m.ranges.end(), by_time);
  std::stable_sort(m.bearings.begin(), m.bearings.end(), by_time);
  std::stable_sort(m.events.begin(), m.events.end(), by_time);
  std::stable_sort(m.truth.begin(), m.truth.end(), by_time);
}

}  // namespace

BeaconLayout DeployBeacons(const FloorPlan& plan, const Route& route, const Walk& walk,
                           const DeploymentOptions& o, double range_m, Random& rng) {
  BeaconLayout layout;
  std::vector<Vec2> turns;
  for (std::size_t i = 1; i + 1 < route.waypoints.size(); ++i) {
    if (TurnAngle(route.waypoints[i - 1], route.waypoints[i], route.waypoints[i + 1]) >
        o.major_turn_rad) {
      turns.push_back(route.waypoints[i]);
    }
  }
  std::vector<bool> turn_done(turns.size(), false);
  int last = -1;
  auto drop = [&](const Vec2& at, TimeS t) {
    for (std::size_t j = 0; j < layout.beacons.size(); ++j) {
      if ((layout.beacons[j] - at).norm() < o.skip_if_beacon_within_m) {
        last = static_cast<int>(j);  // already marked: that one is now the last heard
        return;
      }
    }
    layout.beacons.push_back(
        at + Vec2(rng.Normal(0, o.drop_scatter_m), rng.Normal(0, o.drop_scatter_m)));
    layout.drop_time_s.push_back(std::round(t * 1000) / 1000);
    last = static_cast<int>(layout.beacons.size()) - 1;
  };
  const Walk::Sample* previous = nullptr;
  for (const auto& s : walk.truth) {
    if (last < 0) {
      if (s.position.x() >= 0.3) drop(s.position, s.t);  // rule (i): at the entry
      previous = &s;
      continue;
    }
    const Vec2& b = layout.beacons[last];
    const bool heard = (s.position - b).norm() <= o.receive_threshold_m &&
                       UltrasoundLineOfSight(plan, b, s.position, range_m);
    if (!heard && previous != nullptr) drop(previous->position, previous->t);  // rule (ii)
    for (std::size_t k = 0; k < turns.size(); ++k) {                           // rule (iii)
      if (!turn_done[k] && (s.position - turns[k]).norm() < 0.2) {
        turn_done[k] = true;
        drop(s.position, s.t);
      }
    }
    previous = &s;
  }
  return layout;
}

std::string BeaconId(int j) { return fmt::format("b{:02d}", j + 1); }

namespace {
// A NLOS range is long: by U(min, max) (the paper's multipath), or with a long tail.
double LongBy(const UltrasoundOptions& us, Random& rng) {
  if (us.nlos_tail_mean_m > 0)
    return std::min(us.nlos_min_m - us.nlos_tail_mean_m * std::log(1.0 - rng.Uniform()),
                    us.nlos_max_m);
  return rng.Uniform(us.nlos_min_m, us.nlos_max_m);
}
}  // namespace

void SimulateFootUltrasound(const FloorPlan& plan, const Walk& walk, const std::string& agent,
                            const std::vector<Vec2>& beacons,
                            const std::vector<TimeS>& beacon_since, const UltrasoundOptions& us,
                            Random& us_rng, MissionData& m,
                            const std::function<bool(TimeS)>& audible) {
  auto position_at = [&](TimeS t) {
    const auto it = std::lower_bound(walk.truth.begin(), walk.truth.end(), t,
                                     [](const Walk::Sample& s, TimeS v) { return s.t < v; });
    if (it == walk.truth.begin()) return it->position;
    if (it == walk.truth.end()) return walk.truth.back().position;
    const auto prev = std::prev(it);
    const double a = (t - prev->t) / std::max(it->t - prev->t, 1e-9);
    return Vec2(prev->position + a * (it->position - prev->position));
  };
  const int B = static_cast<int>(beacons.size());
  for (TimeS t = walk.truth.front().t + 0.2; t <= walk.truth.back().t;
       t += us.pulse_period_s + us_rng.Uniform(-us.period_jitter_s, us.period_jitter_s)) {
    const TimeS tr = std::round(t * 1000) / 1000;
    if (audible && !audible(tr)) continue;
    const Vec2 foot = position_at(tr);
    for (int j = 0; j < B; ++j) {
      if (beacon_since[j] > tr) continue;
      const Vec2 rel = foot - beacons[j];
      const double d = rel.norm();
      if (d > us.max_range_m) continue;
      const double true_bearing = std::atan2(rel.y(), rel.x());
      double range, bearing;
      if (UltrasoundLineOfSight(plan, beacons[j], foot, us.max_range_m)) {
        const double p_detect =
            us.detection_near -
            (us.detection_near - us.detection_at_max_range) * d / us.max_range_m;
        if (us_rng.Uniform() > p_detect) continue;
        range = us_rng.Uniform() < us.nlos_probability ? d + LongBy(us, us_rng)
                                                       : d + us_rng.Normal(0, us.range_sigma_m);
        bearing = us_rng.Uniform() < us.bearing_outlier_probability
                      ? us_rng.Uniform(-kPi, kPi)
                      : true_bearing + us_rng.Normal(0, us.bearing_sigma_rad);
      } else {
        if (us_rng.Uniform() > us.corner_reflection_probability) continue;
        range = d + LongBy(us, us_rng);
        bearing = true_bearing + us_rng.Normal(0, 1.5 * us.bearing_sigma_rad);
      }
      if (range > us.max_range_m + us.nlos_max_m) continue;
      bearing = std::remainder(bearing, 2 * kPi);
      m.ranges.push_back({tr, BeaconId(j), agent, std::round(std::max(range, 0.02) * 1000) / 1000,
                          us.range_sigma_m, "ultrasound"});
      m.bearings.push_back(
          {tr, BeaconId(j), agent, std::round(bearing * 1000) / 1000, us.bearing_sigma_rad});
    }
  }
}

void SimulateBeaconRanging(const FloorPlan& plan, const std::vector<Vec2>& beacons,
                           const std::vector<TimeS>& beacon_since, const UltrasoundOptions& us,
                           TimeS t, int only, const std::function<bool(int, int)>& linked,
                           Random& us_rng, MissionData& m) {
  const int B = static_cast<int>(beacons.size());
  for (int i = 0; i < B; ++i) {
    for (int j = i + 1; j < B; ++j) {
      if (only >= 0 && i != only && j != only) continue;
      if (beacon_since[i] > t || beacon_since[j] > t || !linked(i, j)) continue;
      if (!UltrasoundLineOfSight(plan, beacons[i], beacons[j], us.max_range_m)) continue;
      const double d = (beacons[i] - beacons[j]).norm();
      for (int k = 0; k < us.beacon_ranging_burst; ++k) {
        const double r = us_rng.Uniform() < us.static_outlier_probability
                             ? d + LongBy(us, us_rng)
                             : d + us_rng.Normal(0, us.static_range_sigma_m);
        m.ranges.push_back({std::round((t + 0.05 * k) * 1000) / 1000, BeaconId(i), BeaconId(j),
                            std::round(std::max(r, 0.02) * 1000) / 1000, us.static_range_sigma_m,
                            "ultrasound"});
      }
    }
  }
}

BeaconLabOptions::BeaconLabOptions() {
  walker.speed_mps = 1.1;
  // Xsens MTx PDR (sec. 3.B): heading errors from magnetic disturbance dominate and grow
  // incrementally; individual steps stay accurate.
  pdr.heading_drift_sigma_rad_per_s = 0.003;
  pdr.heading_random_walk_rad = 0.01;
  pdr.turn_scale_error_sigma = 0.03;
  pdr.scale_error_sigma = 0.05;
}

const char* LabTraceName(LabTrace trace) {
  static const char* names[] = {"a", "b", "c", "d", "e", "f"};
  return names[static_cast<int>(trace)];
}

double LabTraceMinutes(LabTrace trace) {
  static const double minutes[] = {4, 5, 3, 6, 8, 7};  // "three till eight minutes" (sec. 7.A)
  return minutes[static_cast<int>(trace)];
}

FloorPlan BuildBeaconLab() {
  std::vector<Segment2> walls, doors;
  std::vector<Room> rooms;
  AddRectangle(walls, {0, 0}, {15, 9});
  doors.push_back({{0, kMid - 0.6}, {0, kMid + 0.6}});
  AddRectangle(walls, {3.0, 3.0}, {6.5, 6.0});   // bench block west
  AddRectangle(walls, {8.5, 3.0}, {12.0, 6.0});  // bench block east
  rooms.push_back({"lab", {{0, 0}, {15, 0}, {15, 9}, {0, 9}}, 0});
  return FloorPlan(std::move(walls), std::move(doors), std::move(rooms));
}

bool UltrasoundLineOfSight(const FloorPlan& plan, const Vec2& a, const Vec2& b, double range_m) {
  return (a - b).norm() <= range_m && !plan.Crosses(a, b);
}

std::vector<int> RetreatTargets(const FloorPlan& plan, const std::vector<Vec2>& beacons,
                                const Vec2& position, double range_m) {
  std::vector<int> targets;
  Vec2 at = position;
  int current = static_cast<int>(beacons.size());
  while (current > 0) {
    int smallest = -1;
    for (int j = 0; j < current; ++j) {
      if (UltrasoundLineOfSight(plan, beacons[j], at, range_m)) {
        smallest = j;
        break;
      }
    }
    if (smallest < 0) break;  // nothing smaller heard: stuck (reported by an empty/short list)
    targets.push_back(smallest);
    if (smallest == 0) break;
    at = beacons[smallest];
    current = smallest;
  }
  return targets;
}

SimulatedMission SimulateBeaconLab(const BeaconLabOptions& o, std::uint64_t seed) {
  Random rng(seed * 104729 + 17);
  Random walk_rng = rng.Fork(), deploy_rng = rng.Fork(), pdr_rng = rng.Fork(), us_rng = rng.Fork();
  SimulatedMission sim;
  sim.plan = BuildBeaconLab();
  const UltrasoundOptions& us = o.ultrasound;

  // The trail: the deployment rules applied on the deployment walk.
  const Route deploy_route = DeploymentRoute();
  const Walk deploy_walk = WalkRoute(deploy_route, o.walker, 0.0, walk_rng);
  const BeaconLayout layout =
      DeployBeacons(sim.plan, deploy_route, deploy_walk, o.deployment, us.max_range_m, deploy_rng);
  const int B = static_cast<int>(layout.beacons.size());

  // The walk of this mission.
  Walk walk;
  std::vector<TimeS> beacon_since(B, -1e300);  // surveyed: there from the start
  if (o.surveyed) {
    walk = WalkRoute(TraceRoute(o.trace, o.walker.speed_mps), o.walker, 0.0, walk_rng);
  } else {
    beacon_since = layout.drop_time_s;
    const TimeS t_trace = deploy_walk.truth.back().t;
    Walk trace = WalkRoute(TraceRoute(o.trace, o.walker.speed_mps), o.walker, t_trace, walk_rng);
    Route out;
    out.waypoints.push_back(trace.truth.back().position);
    for (int j : RetreatTargets(sim.plan, layout.beacons, out.waypoints.back(), us.max_range_m)) {
      out.waypoints.push_back(layout.beacons[j]);
    }
    out.waypoints.push_back(kEntryOutside);
    Walk retreat = WalkRoute(out, o.walker, trace.truth.back().t + 1.0, walk_rng);
    walk = Concatenate({deploy_walk, std::move(trace), std::move(retreat)});
  }
  sim.walks.emplace_back("ff1", walk);

  MissionData& m = sim.data;
  m.info.name = o.surveyed ? fmt::format("beacon-lab-{}", LabTraceName(o.trace)) : "beacon-trail";
  m.info.description = fmt::format(
      "{} x 9 m lab with {} ultrasound beacons placed by the deployment rules (ultrasound-beacons "
      "paper, sec. 4, 7); {}; trace {} ({} min); simulated, seed {}",
      15, B,
      o.surveyed ? "beacons surveyed" : "beacons dropped by ff1, then the trace and the retreat",
      LabTraceName(o.trace), LabTraceMinutes(o.trace), seed);
  const Vec2 start = walk.truth.front().position;
  const double start_heading = walk.truth.front().heading_rad;
  if (!o.surveyed)
    m.info.nodes.push_back(NodeInfo::Base("base", Vec3(kEntryOutside.x(), kEntryOutside.y(), 0)));
  m.info.nodes.push_back(
      NodeInfo::Agent("ff1", Vec3(start.x(), start.y(), 0), 0.1, start_heading, 0.05));
  for (int j = 0; j < B; ++j) {
    NodeInfo n;
    n.id = BeaconId(j);
    if (o.surveyed) {
      n.kind = NodeKind::kLandmark;
      n.position = Vec3(layout.beacons[j].x(), layout.beacons[j].y(), 0);
      n.position_sigma_m = 0.02;
    } else {
      n.kind = NodeKind::kCrumb;
    }
    m.info.nodes.push_back(n);
    m.truth.push_back({o.surveyed ? walk.truth.front().t : layout.drop_time_s[j], n.id,
                       Vec3(layout.beacons[j].x(), layout.beacons[j].y(), 0)});
    if (!o.surveyed) m.events.push_back({layout.drop_time_s[j], "ff1", "drop", n.id});
  }

  AddPdrSteps(walk, o.pdr, o.initial_heading_error_sigma_rad, pdr_rng, m);
  m.events.push_back({walk.truth.front().t, "ff1", "enter", ""});
  if (!o.surveyed) m.events.push_back({walk.truth.back().t, "ff1", "exit", ""});

  SimulateFootUltrasound(sim.plan, walk, "ff1", layout.beacons, beacon_since, us, us_rng, m);
  // Beacon <-> beacon ranging: each new beacon ranges the others at its drop, then every pair
  // periodically (static nodes, line of sight).
  const auto every_pair = [](int, int) { return true; };
  if (!o.surveyed) {
    for (int j = 0; j < B; ++j)
      SimulateBeaconRanging(sim.plan, layout.beacons, beacon_since, us,
                            layout.drop_time_s[j] + 0.5, j, every_pair, us_rng, m);
  }
  for (TimeS t = walk.truth.front().t + 0.1; t <= walk.truth.back().t;
       t += us.beacon_ranging_period_s) {
    SimulateBeaconRanging(sim.plan, layout.beacons, beacon_since, us, t, -1, every_pair, us_rng,
                          m);
  }
  SortByTime(m);
  return sim;
}

ShapedTrailOptions::ShapedTrailOptions() {
  const BeaconLabOptions lab;
  walker = lab.walker;
  pdr = lab.pdr;
  // NLOS ranges, always long, with a long tail; bearings with more outliers (issue 22).
  ultrasound.nlos_probability = 0.08;
  ultrasound.nlos_tail_mean_m = 1.0;
  ultrasound.nlos_max_m = 6.0;
  ultrasound.static_outlier_probability = 0.08;
  ultrasound.bearing_outlier_probability = 0.15;
}

SimulatedMission SimulateShapedTrail(const ShapedTrailOptions& o, std::uint64_t seed) {
  Random rng(seed * 7919 + 23);
  Random shape_rng = rng.Fork(), walk_rng = rng.Fork(), deploy_rng = rng.Fork(),
         pdr_rng = rng.Fork(), us_rng = rng.Fork();
  const bool u_shape = o.shape == ShapedTrailOptions::Shape::kRandom
                           ? shape_rng.Uniform() < 2.0 / 3
                           : o.shape == ShapedTrailOptions::Shape::kU;
  const double w = o.corridor_width_m, h = w / 2;
  const double L = shape_rng.Uniform(o.min_leg_m, o.max_leg_m);
  const double H = shape_rng.Uniform(o.min_across_m, o.max_across_m) + w;
  // The corridor as one polygon (counter-clockwise), its entry on the west of the south leg.
  std::vector<Vec2> outline =
      u_shape ? std::vector<Vec2>{{0, 0}, {L, 0}, {L, H}, {0, H}, {0, H - w}, {L - w, H - w},
                                  {L - w, w}, {0, w}}
              : std::vector<Vec2>{{0, 0}, {L, 0}, {L, H}, {L - w, H}, {L - w, w}, {0, w}};
  std::vector<Segment2> walls, doors;
  for (std::size_t i = 0; i < outline.size(); ++i)
    walls.push_back({outline[i], outline[(i + 1) % outline.size()]});
  doors.push_back({{0, h - 0.6}, {0, h + 0.6}});
  SimulatedMission sim;
  sim.plan = FloorPlan(std::move(walls), std::move(doors), {{"trail", outline, 0}});
  const UltrasoundOptions& us = o.ultrasound;

  const Vec2 outside(-1.0, h);
  Route deploy_route;
  deploy_route.waypoints = {outside, {1.0, h}, {L - h, h}};
  if (u_shape) {
    deploy_route.waypoints.push_back({L - h, H - h});
    deploy_route.waypoints.push_back({1.0, H - h});
  } else {
    deploy_route.waypoints.push_back({L - h, H - 1.0});
  }
  const Walk deploy_walk = WalkRoute(deploy_route, o.walker, 0.0, walk_rng);
  const BeaconLayout layout =
      DeployBeacons(sim.plan, deploy_route, deploy_walk, o.deployment, us.max_range_m, deploy_rng);
  const int B = static_cast<int>(layout.beacons.size());
  // Back to the entry and out again along the trail (a search), then the retreat.
  Route trace;
  trace.waypoints.assign(deploy_route.waypoints.rbegin(), deploy_route.waypoints.rend() - 1);
  trace.waypoints.insert(trace.waypoints.end(), deploy_route.waypoints.begin() + 2,
                         deploy_route.waypoints.end());
  Walk search = WalkRoute(trace, o.walker, deploy_walk.truth.back().t, walk_rng);
  Route out;
  out.waypoints.push_back(search.truth.back().position);
  for (int j : RetreatTargets(sim.plan, layout.beacons, out.waypoints.back(), us.max_range_m))
    out.waypoints.push_back(layout.beacons[j]);
  out.waypoints.push_back(outside);
  Walk retreat = WalkRoute(out, o.walker, search.truth.back().t + 1.0, walk_rng);
  const Walk walk = Concatenate({deploy_walk, std::move(search), std::move(retreat)});
  sim.walks.emplace_back("ff1", walk);

  // Anchors: `anchors` beacons spread over the trail's second half and end, none at the entry.
  std::vector<bool> anchor(B, false);
  for (int k = 0; k < o.anchors && B > 1; ++k) {
    const int j = std::clamp(static_cast<int>(std::lround((B - 1) * (k + 1.0) / o.anchors)), 1,
                             B - 1);
    anchor[j] = true;
  }
  MissionData& m = sim.data;
  m.info.name = "beacon-neighbour-trail";
  m.info.description = fmt::format(
      "{}-shaped corridor ({:.1f} x {:.1f} m, {:.1f} m wide) with {} ultrasound beacons dropped by "
      "the deployment rules, ranges between trail neighbours only, {} surveyed, NLOS {:.0f} % "
      "with a long tail, bearing outliers {:.0f} % (issue 22); simulated, seed {}",
      u_shape ? "U" : "L", L, H, w, B, o.anchors, 100 * us.nlos_probability,
      100 * us.bearing_outlier_probability, seed);
  const Vec2 start = walk.truth.front().position;
  m.info.nodes.push_back(NodeInfo::Base("base", Vec3(outside.x(), outside.y(), 0)));
  m.info.nodes.push_back(NodeInfo::Agent("ff1", Vec3(start.x(), start.y(), 0), 0.1,
                                         walk.truth.front().heading_rad, 0.05));
  std::vector<TimeS> since = layout.drop_time_s;
  for (int j = 0; j < B; ++j) {
    NodeInfo n;
    n.id = BeaconId(j);
    if (anchor[j]) {  // pre-installed and surveyed: there from the start
      n.kind = NodeKind::kLandmark;
      n.position = Vec3(layout.beacons[j].x(), layout.beacons[j].y(), 0);
      n.position_sigma_m = 0.05;
      since[j] = -1e300;
    } else {
      n.kind = NodeKind::kCrumb;
      m.events.push_back({layout.drop_time_s[j], "ff1", "drop", n.id});
    }
    m.info.nodes.push_back(n);
    m.truth.push_back({anchor[j] ? walk.truth.front().t : layout.drop_time_s[j], n.id,
                       Vec3(layout.beacons[j].x(), layout.beacons[j].y(), 0)});
  }
  AddPdrSteps(walk, o.pdr, o.initial_heading_error_sigma_rad, pdr_rng, m);
  m.events.push_back({walk.truth.front().t, "ff1", "enter", ""});
  m.events.push_back({walk.truth.back().t, "ff1", "exit", ""});
  SimulateFootUltrasound(sim.plan, walk, "ff1", layout.beacons, since, us, us_rng, m);
  // Links between trail neighbours only (deployment order), at each drop and periodically.
  const auto neighbours = [&](int i, int j) { return std::abs(i - j) <= o.neighbour_links; };
  for (int j = 0; j < B; ++j) {
    SimulateBeaconRanging(sim.plan, layout.beacons, since, us,
                          std::max(layout.drop_time_s[j], 0.0) + 0.5, j, neighbours, us_rng, m);
  }
  for (TimeS t = walk.truth.front().t + 0.1; t <= walk.truth.back().t;
       t += us.beacon_ranging_period_s) {
    SimulateBeaconRanging(sim.plan, layout.beacons, since, us, t, -1, neighbours, us_rng, m);
  }
  SortByTime(m);
  return sim;
}

}  // namespace trailmark

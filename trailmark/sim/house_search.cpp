// SPDX-License-Identifier: MIT
#include "trailmark/sim/house_search.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include "trailmark/core/random.h"

namespace trailmark {
namespace {

constexpr double kPi = std::numbers::pi;

// A wall from a to b with door openings [lo, hi] along it (metres from a).
void WallWithDoors(std::vector<Segment2>& walls, std::vector<Segment2>& doors, Vec2 a, Vec2 b,
                   std::vector<std::pair<double, double>> openings) {
  walls.push_back({a, b});
  const Vec2 u = (b - a).normalized();
  for (const auto& [lo, hi] : openings) doors.push_back({a + lo * u, a + hi * u});
}

void Furniture(std::vector<Segment2>& walls, Vec2 lo, Vec2 hi) { AddRectangle(walls, lo, hi); }

}  // namespace

HouseSearchOptions::HouseSearchOptions() {
  // A foot-mounted ZUPT INS (Xsens MTi-3 class): heading drift dominates.
  pdr.heading_drift_sigma_rad_per_s = 0.0015;
  pdr.turn_scale_error_sigma = 0.03;
  pdr.scale_error_sigma = 0.02;
  pdr.step_noise_m = 0.02;
  // Steps under 60 % of the nominal 0.5 m (edging round furniture) do not turn the gyro.
  pdr.turn_min_step_m = 0.3;
}

Vec2 HouseEntry(int house) { return house == 1 ? Vec2(1.5, 0.5) : Vec2(0.5, 5.5); }
double HouseEntryHeading(int house) { return house == 1 ? kPi / 2 : 0.0; }

FloorPlan BuildHouse(int house, bool with_furniture, bool map_error, bool furniture) {
  std::vector<Segment2> walls, doors;
  // The world a search walks in (with furniture) has the entry door shut behind the team.
  const bool entry_open = !with_furniture;
  std::vector<Room> rooms;
  if (house == 1) {
    // 12.5 x 10 m; the west part (x < 7) is searched, the east part is behind a door treated
    // as a wall (sec. V-A).
    WallWithDoors(walls, doors, {0, 0}, {12.5, 0},
                  entry_open ? std::vector<std::pair<double, double>>{{1.0, 2.0}}
                             : std::vector<std::pair<double, double>>{});  // entry
    walls.push_back({{12.5, 0}, {12.5, 10}});
    walls.push_back({{12.5, 10}, {0, 10}});
    walls.push_back({{0, 10}, {0, 0}});
    walls.push_back({{7, 0}, {7, 10}});  // door treated as wall
    WallWithDoors(walls, doors, {3.5, 0}, {3.5, 6},
                  {map_error ? std::make_pair(1.0, 2.0) : std::make_pair(3.0, 4.0)});
    WallWithDoors(walls, doors, {0, 6}, {7, 6}, {{0.8, 1.8}, {4.5, 5.5}});
    WallWithDoors(walls, doors, {7, 5}, {12.5, 5}, {{2.5, 3.5}});
    rooms.push_back({"hall", {{0, 0}, {3.5, 0}, {3.5, 6}, {0, 6}}, 0});
    rooms.push_back({"living", {{3.5, 0}, {7, 0}, {7, 6}, {3.5, 6}}, 0});
    rooms.push_back({"kitchen", {{0, 6}, {7, 6}, {7, 10}, {0, 10}}, 0});
    rooms.push_back({"bedroom-1", {{7, 0}, {12.5, 0}, {12.5, 5}, {7, 5}}, 0});
    rooms.push_back({"bedroom-2", {{7, 5}, {12.5, 5}, {12.5, 10}, {7, 10}}, 0});
    if (with_furniture && furniture) {
      Furniture(walls, {4.6, 1.8}, {5.8, 3.4});   // dining table
      Furniture(walls, {6.3, 0.9}, {7.0, 3.0});   // sofa against the wall
      Furniture(walls, {2.4, 7.8}, {4.4, 8.4});   // kitchen island
      Furniture(walls, {0.0, 9.4}, {2.8, 10.0});  // counter
      Furniture(walls, {8.0, 0.5}, {10.0, 2.5});  // beds
      Furniture(walls, {8.0, 7.5}, {10.0, 9.5});
    }
  } else {
    // 23 x 11 m: a corridor (y 4.5 .. 6.5) from the west entry, four rooms south and three
    // north of different sizes (a real house is not a row of identical rooms).
    walls.push_back({{0, 0}, {23, 0}});
    walls.push_back({{23, 0}, {23, 11}});
    walls.push_back({{23, 11}, {0, 11}});
    WallWithDoors(walls, doors, {0, 11}, {0, 0},
                  entry_open ? std::vector<std::pair<double, double>>{{5.0, 6.0}}
                             : std::vector<std::pair<double, double>>{});  // entry
    WallWithDoors(walls, doors, {0, 4.5}, {23, 4.5},
                  {{1.0, 2.0}, {9.5, 10.5}, {13.5, 14.5}, {20.0, 21.0}});
    WallWithDoors(walls, doors, {0, 6.5}, {23, 6.5}, {{6.5, 7.5}, {10.0, 11.0}, {19.0, 20.0}});
    for (double x : {5.0, 12.5, 16.0}) walls.push_back({{x, 0}, {x, 4.5}});
    for (double x : {9.0, 13.5}) walls.push_back({{x, 6.5}, {x, 11}});
    walls.push_back({{19.0, 0}, {19.0, 2.0}});   // a partition stub in the big south-east room
    walls.push_back({{3.0, 11.0}, {3.0, 9.0}});  // and one in the north-west room
    rooms.push_back({"corridor", {{0, 4.5}, {23, 4.5}, {23, 6.5}, {0, 6.5}}, 0});
    if (with_furniture && furniture) {
      Furniture(walls, {1.5, 1.5}, {3.0, 2.7});  // table
      Furniture(walls, {7.0, 0.0}, {9.0, 2.0});  // bed against the wall
      Furniture(walls, {13.0, 1.0}, {14.5, 2.5});
      Furniture(walls, {20.5, 0.0}, {22.5, 2.0});
      Furniture(walls, {5.5, 8.5}, {7.5, 9.5});
      Furniture(walls, {10.0, 8.0}, {12.0, 9.2});
      Furniture(walls, {21.3, 7.5}, {23.0, 10.0});
    }
  }
  return FloorPlan(std::move(walls), std::move(doors), std::move(rooms));
}

namespace {

// The door nearest to `x`, within `max_distance_m`; null when none.
const Segment2* NearestDoor(const FloorPlan& plan, const Vec2& x, double max_distance_m) {
  const Segment2* best = nullptr;
  double best_d = max_distance_m;
  for (const auto& door : plan.doors()) {
    const double d = DistanceToSegment(x, door);
    if (d <= best_d) best_d = d, best = &door;
  }
  return best;
}

// Walking in through `door` to `entry`: the direction from the door's middle to the entry.
std::optional<double> HeadingThroughDoor(const Segment2& door, const Vec2& entry) {
  const Vec2 away = entry - 0.5 * (door.a + door.b);
  if (away.norm() < 1e-6) return std::nullopt;
  return std::atan2(away.y(), away.x());
}

// The search itself, shared by the houses and any plan: the walker follows `world`'s walls
// from `entry`; `map` becomes the mission's floor plan. Name and description are the caller's.
SimulatedMission SimulateSearch(const FloorPlan& world, FloorPlan map, const Vec2& entry,
                                double heading, const HouseSearchOptions& o, Random& walk_rng,
                                Random& pdr_rng, Random& sweep_rng) {
  SimulatedMission sim;
  sim.plan = std::move(map);
  WallFollowOptions wf;
  wf.wall_offset_m = o.wall_offset_m;
  wf.max_length_m = o.duration_s * o.speed_mps * 1.05;
  Route route = FollowWall(world, entry, heading, o.hand, wf);
  // Sweeping: a small side-to-side motion while walking (never through a wall).
  const double phase = sweep_rng.Uniform(0, 2 * kPi);
  double along = 0;
  std::vector<Vec2> swept{route.waypoints.front()};
  for (std::size_t k = 1; k < route.waypoints.size(); ++k) {
    const Vec2 a = route.waypoints[k - 1], b = route.waypoints[k];
    along += (b - a).norm();
    const Vec2 t = (b - a).norm() > 1e-9 ? Vec2((b - a).normalized()) : Vec2(1, 0);
    const Vec2 p =
        b + Vec2(-t.y(), t.x()) * (o.sweep_amplitude_m * std::sin(2 * kPi * along / 1.6 + phase));
    swept.push_back(world.Crosses(swept.back(), p) || world.Crosses(b, p) ? b : p);
  }
  route.waypoints = std::move(swept);
  for (double s = o.pause_every_m; s < route.Length(); s += o.pause_every_m) {
    route.stops.push_back({s, o.pause_s * walk_rng.Uniform(0.5, 1.5)});
  }
  WalkerOptions wo;
  wo.speed_mps = o.speed_mps;
  wo.step_length_m = o.step_length_m;
  Walk walk = WalkRoute(route, wo, 0.0, walk_rng);
  // Cut at the search's duration.
  while (!walk.truth.empty() && walk.truth.back().t > o.duration_s) walk.truth.pop_back();
  while (!walk.steps.empty() && walk.steps.back().t1 > o.duration_s) walk.steps.pop_back();
  sim.walks.emplace_back("ff1", walk);

  MissionData& m = sim.data;
  m.info.floorplan = "floorplan.geojson";
  m.info.nodes.push_back(NodeInfo::Agent("ff1", Vec3(entry.x(), entry.y(), 0), 0.2, heading, 0.05));
  PdrErrorModel pdr(o.pdr, pdr_rng);
  AppendPdrWalk(pdr, walk, "ff1", m);
  m.events.push_back({0.0, "ff1", "enter", ""});
  for (const auto& st : walk.stops) {
    if (st.t_stop > o.duration_s) break;
    m.events.push_back({st.t_stop, "ff1", "stop", ""});
    m.events.push_back({std::min(st.t_go, o.duration_s), "ff1", "go", ""});
  }
  return sim;
}

}  // namespace

SimulatedMission SimulateHouseSearch(const HouseSearchOptions& o, std::uint64_t seed) {
  if (o.house != 1 && o.house != 2) throw std::invalid_argument("house must be 1 or 2");
  Random rng(seed * 2654435761ULL + static_cast<std::uint64_t>(o.house));
  Random walk_rng = rng.Fork(), pdr_rng = rng.Fork(), sweep_rng = rng.Fork();
  const FloorPlan world = BuildHouse(o.house, true, false, o.furniture);
  SimulatedMission sim =
      SimulateSearch(world, BuildHouse(o.house, false, o.map_error), HouseEntry(o.house),
                     HouseEntryHeading(o.house), o, walk_rng, pdr_rng, sweep_rng);
  MissionData& m = sim.data;
  m.info.name = fmt::format("house{}-search", o.house);
  m.info.description = fmt::format(
      "Map-aided search paper, data set {}: {} {}-hand directional search of {:.0f} s at {:.2f} "
      "m/s from the "
      "entry{}; furniture not on the map; simulated, seed {}",
      o.house, o.house == 1 ? "12.5 x 10 m house (west 70 m^2 searched)," : "23 x 11 m house,",
      o.hand == Hand::kLeft ? "left" : "right", o.duration_s, o.speed_mps,
      o.map_error ? "; the map shows the hall door 2 m from where it is" : "", seed);
  return sim;
}

SimulatedMission SimulateSearchOnPlan(const FloorPlan& plan, const Vec2& entry,
                                      std::optional<double> entry_heading_rad,
                                      const HouseSearchOptions& o, std::uint64_t seed) {
  if (plan.solid_walls().empty()) throw std::invalid_argument("the floor plan has no walls");
  const Box2 box = plan.Bounds();
  if (!entry.allFinite() || (entry.array() < box.min.array()).any() ||
      (entry.array() > box.max.array()).any())
    throw std::invalid_argument(fmt::format(
        "the entry ({:.2f}, {:.2f}) is not within the floor plan's bounds ({:.1f}, {:.1f}) .. "
        "({:.1f}, {:.1f})",
        entry.x(), entry.y(), box.min.x(), box.min.y(), box.max.x(), box.max.y()));
  if (!(o.duration_s > 0 && o.duration_s <= 24 * 3600))
    throw std::invalid_argument("the search must last more than 0 s and at most 24 h");
  // The door they came in by is shut behind them (else the left hand would lead back out).
  std::vector<Segment2> walls = plan.walls(), doors;
  const Segment2* entry_door = NearestDoor(plan, entry, 1.5);
  for (const auto& door : plan.doors()) {
    if (&door == entry_door)
      walls.push_back(door);
    else
      doors.push_back(door);
  }
  const FloorPlan world(std::move(walls), std::move(doors), plan.rooms());
  double heading = 0;
  if (entry_heading_rad) {
    heading = *entry_heading_rad;
  } else if (const auto from_door =
                 entry_door ? HeadingThroughDoor(*entry_door, entry) : std::nullopt) {
    heading = *from_door;
  } else {
    throw std::invalid_argument(
        "no door within 1.5 m of the entry to walk in from: give the entry heading");
  }
  double clearance = std::numeric_limits<double>::infinity();
  for (const auto& w : world.solid_walls())
    clearance = std::min(clearance, DistanceToSegment(entry, w));
  if (clearance < 0.2)
    throw std::invalid_argument(fmt::format(
        "the entry ({:.2f}, {:.2f}) is {:.2f} m from a wall: stand the team at least 0.2 m off it",
        entry.x(), entry.y(), clearance));
  Random rng(seed * 2654435761ULL + 7);
  Random walk_rng = rng.Fork(), pdr_rng = rng.Fork(), sweep_rng = rng.Fork();
  SimulatedMission sim =
      SimulateSearch(world, plan, entry, heading, o, walk_rng, pdr_rng, sweep_rng);
  if (sim.data.steps.size() < 2)
    throw std::invalid_argument(fmt::format(
        "no search could be walked from the entry ({:.2f}, {:.2f}) heading {:.0f} deg: walls "
        "all round it?",
        entry.x(), entry.y(), heading * 180 / kPi));
  sim.data.info.name = "search";
  sim.data.info.description = fmt::format(
      "a {}-hand directional search of {:.0f} s at {:.2f} m/s on a given floor plan, entering at "
      "({:.2f}, {:.2f}) heading {:.0f} deg{}; no furniture; simulated, seed {}",
      o.hand == Hand::kLeft ? "left" : "right", o.duration_s, o.speed_mps, entry.x(), entry.y(),
      heading * 180 / kPi, entry_door ? ", the entry door shut behind" : "", seed);
  return sim;
}

}  // namespace trailmark

// SPDX-License-Identifier: MIT
#include "trailmark/sim/scenarios.h"

#include <fmt/format.h>

#include "trailmark/sim/synthetic_incident.h"

#include "trailmark/sim/beacon_lab.h"
#include "trailmark/sim/house_search.h"
#include "trailmark/sim/landmark_corridor.h"
#include "trailmark/sim/landmark_office.h"
#include "trailmark/sim/multi_floor.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <optional>
#include <stdexcept>

namespace trailmark {

FloorPlan BuildOfficeFloor(const OfficeLoopOptions& o) {
  // Loop centre line: x in [-W, 0], y in [-H, 0]; base at (0, 0), the upper right corner.
  const double W = o.loop_width_m, H = o.loop_height_m, h = o.corridor_width_m / 2;
  const double depth = 6.0;  // office depth on the outside of the corridor
  std::vector<Segment2> walls, doors;
  std::vector<Room> rooms;
  AddRectangle(walls, {-W - h - depth, -H - h - depth}, {h + depth, h + depth});  // exterior
  AddRectangle(walls, {-W - h, -H - h}, {h, h});                                  // corridor outside
  AddRectangle(walls, {-W + h, -H + h}, {-h, -h});                                // corridor inside
  rooms.push_back({"corridor", {{-W - h, -H - h}, {h, -H - h}, {h, h}, {-W - h, h}}, 0});
  // Office partitions every 5 m along the long sides, doors of 1 m into the corridor.
  for (double x = -W + 5; x < 0; x += 5) {
    walls.push_back({{x, h}, {x, h + depth}});
    walls.push_back({{x, -H - h}, {x, -H - h - depth}});
    doors.push_back({{x - 3.0, h}, {x - 2.0, h}});
    doors.push_back({{x - 3.0, -H - h}, {x - 2.0, -H - h}});
  }
  for (double y = -H + 5; y < 0; y += 5) {
    walls.push_back({{h, y}, {h + depth, y}});
    walls.push_back({{-W - h, y}, {-W - h - depth, y}});
    doors.push_back({{h, y - 3.0}, {h, y - 2.0}});
    doors.push_back({{-W - h, y - 3.0}, {-W - h, y - 2.0}});
  }
  // Core: a meeting room and service rooms inside the loop, doors on the long sides.
  walls.push_back({{-W / 2, -h}, {-W / 2, -H + h}});
  walls.push_back({{-W + h, -H / 2}, {-W / 2, -H / 2}});
  doors.push_back({{-W / 4 - 0.5, -h}, {-W / 4 + 0.5, -h}});
  doors.push_back({{-3 * W / 4 - 0.5, -h}, {-3 * W / 4 + 0.5, -h}});
  doors.push_back({{-3 * W / 4 - 0.5, -H + h}, {-3 * W / 4 + 0.5, -H + h}});
  // Entrance from outside at the base corner.
  doors.push_back({{h + depth, -0.5}, {h + depth, 0.5}});
  walls.push_back({{h, -0.5 - 0.0}, {h + depth, -0.5}});
  walls.push_back({{h, 0.5}, {h + depth, 0.5}});
  doors.push_back({{h, -0.5}, {h, 0.5}});
  return FloorPlan(std::move(walls), std::move(doors), std::move(rooms));
}

SimulatedMission SimulateOfficeLoop(const OfficeLoopOptions& o, std::uint64_t seed) {
  Route route;
  const double W = o.loop_width_m, H = o.loop_height_m;
  route.waypoints.push_back({0, 0});
  for (int lap = 0; lap < o.laps; ++lap) {
    for (const Vec2& p : {Vec2(-W, 0), Vec2(-W, -H), Vec2(0, -H), Vec2(0, 0)}) {
      route.waypoints.push_back(p);
    }
  }
  SimulatedMission mission = SimulateAgents(BuildOfficeFloor(o), Vec2::Zero(),
                                            {{"ff1", route, 0.0, std::numbers::pi}}, o.sim, seed);
  mission.data.info.name = "office-loop";
  mission.data.info.description =
      "Office floor, 100 m corridor loop walked " + std::to_string(o.laps) +
      " times anti-clockwise from the base (breadcrumb paper sec. V-A); breadcrumbs dropped by "
      "a dispenser; simulated, seed " + std::to_string(seed);
  return mission;
}

TrainingBuildingOptions::TrainingBuildingOptions() {
  sim.walker.speed_mps = 0.8;  // smoke: slow "trail step" walking (sec. V-C)
  sim.walker.step_length_m = 0.6;
  sim.kick.probability = 0.3;
  sim.kick.max_kicks = 2;
}

FloorPlan BuildTrainingFloor(const TrainingBuildingOptions& o) {
  const double L = o.rooms_per_side * o.room_width_m, h = o.corridor_width_m / 2,
               D = o.room_depth_m;
  std::vector<Segment2> walls, doors;
  std::vector<Room> rooms;
  AddRectangle(walls, {0, -h - D}, {L, h + D});  // exterior
  walls.push_back({{0, h}, {L, h}});        // corridor walls
  walls.push_back({{0, -h}, {L, -h}});
  rooms.push_back({"corridor", {{0, -h}, {L, -h}, {L, h}, {0, h}}, 0});
  for (int k = 0; k < o.rooms_per_side; ++k) {
    const double x0 = k * o.room_width_m, x1 = x0 + o.room_width_m;
    if (k > 0) {
      walls.push_back({{x0, h}, {x0, h + D}});
      walls.push_back({{x0, -h}, {x0, -h - D}});
    }
    const double door = x0 + o.room_width_m / 2;
    doors.push_back({{door - 0.5, h}, {door + 0.5, h}});
    doors.push_back({{door - 0.5, -h}, {door + 0.5, -h}});
    rooms.push_back({"north-" + std::to_string(k + 1), {{x0, h}, {x1, h}, {x1, h + D}, {x0, h + D}}, 0});
    rooms.push_back({"south-" + std::to_string(k + 1), {{x0, -h}, {x1, -h}, {x1, -h - D}, {x0, -h - D}}, 0});
  }
  doors.push_back({{L, -0.5}, {L, 0.5}});  // the right entrance
  return FloorPlan(std::move(walls), std::move(doors), std::move(rooms));
}

SimulatedMission SimulateTrainingBuilding(const TrainingBuildingOptions& o, std::uint64_t seed) {
  const double L = o.rooms_per_side * o.room_width_m, h = o.corridor_width_m / 2,
               D = o.room_depth_m;
  const Vec2 base(L + 2.0, 0.0);
  auto search = [&](double side) {  // side +1: north rooms, -1: south rooms
    Route r;
    r.waypoints.push_back(base);
    r.waypoints.push_back({L - 1.0, 0.0});
    for (int k = o.rooms_per_side - 1; k >= 0; --k) {
      const double x0 = k * o.room_width_m, x1 = x0 + o.room_width_m;
      const double door = x0 + o.room_width_m / 2, m = 0.8;
      const double in = side * (h + m), back = side * (h + D - m);
      r.waypoints.push_back({door, 0.0});
      r.waypoints.push_back({door, in});
      // A directional search around the room, an arm's length off the walls.
      r.waypoints.push_back({x1 - m, in});
      r.waypoints.push_back({x1 - m, back});
      r.waypoints.push_back({x0 + m, back});
      r.waypoints.push_back({x0 + m, in});
      r.waypoints.push_back({door, in});
      Route::Stop stop;
      double length = 0;
      for (std::size_t i = 1; i < r.waypoints.size(); ++i) {
        length += (r.waypoints[i] - r.waypoints[i - 1]).norm();
      }
      stop.at_distance_m = length - (x1 - x0 - 2 * m) / 2;  // at the back wall's middle
      stop.duration_s = o.room_pause_s;
      r.stops.push_back(stop);
      r.waypoints.push_back({door, 0.0});
    }
    r.waypoints.push_back({L - 1.0, 0.0});
    r.waypoints.push_back(base);
    return r;
  };
  TrainingBuildingOptions opts = o;
  // The fire: the third north room from the entrance and the corridor in front of it.
  const double fx0 = (o.rooms_per_side - 3) * o.room_width_m;
  opts.sim.zones.push_back({"fire",
                            {{fx0, -h}, {fx0 + o.room_width_m, -h}, {fx0 + o.room_width_m, h + D},
                             {fx0, h + D}},
                            2.0,
                            3.0});
  SimulatedMission mission = SimulateAgents(
      BuildTrainingFloor(o), base,
      {{"ff1", search(+1), 0.0, std::numbers::pi}, {"ff2", search(-1), o.second_start_s, std::numbers::pi}},
      opts.sim, seed);
  mission.data.info.name = "training-building";
  mission.data.info.description =
      "Fire-training building, 3rd floor (breadcrumb paper sec. V-B): two firefighters search "
      "the rooms on both sides of a corridor from the right entrance, a fire attenuates links "
      "through one room, crumbs may be kicked; simulated, seed " + std::to_string(seed);
  return mission;
}

std::vector<ScenarioInfo> Scenarios() {
  return {{"office-loop",
           "default: office floor, 100 m corridor loop x 4 (400 m), one firefighter, base at the "
           "start, dispenser-dropped breadcrumbs, RSSI between all nodes in range"},
          {"office-loop-1lap", "the same floor, one lap (100 m): quick tests"},
          {"office-loop-kicked",
           "office loop x 4 where a walked-past breadcrumb may be kicked 1-2 m (sec. V-C)"},
          {"landmark-corridor",
           "radio-landmarks paper: 5 wake-up landmarks in a corridor (4 to be localized), a "
           "stop-and-go walk with 7 stops, wake-ups every 3 s while walking"},
          {"landmark-office",
           "issue 24: an office with 16 ceiling BLE landmarks (10 surveyed, 6 unknown), two "
           "firefighters searching its rooms with drifting PDR; no radio calibration, no stop/go "
           "events, walls, correlated shadowing, landmark and phone offsets, censoring"},
          {"training-building",
           "two firefighters search the rooms of a fire-training floor from the right entrance, "
           "a fire zone, kicked crumbs (sec. V-B)"},
          {"beacon-lab",
           "ultrasound-beacons paper: 15 x 9 m lab, ~21 surveyed ultrasound beacons placed by the "
           "deployment rules, walking trace a (4 min) with foot-node range/bearing and PDR steps"},
          {"house1-search",
           "map-aided search paper, data set 1: a left-hand directional search (4.5 min, slow, "
           "sweeping, furniture not on the map) of the 70 m^2 west part of a 125 m^2 house"},
          {"house2-search",
           "map-aided search paper, data set 2: a 10-minute left-hand search of a 253 m^2 house "
           "(corridor, seven rooms)"},
          {"beacon-trail",
           "ultrasound-beacons paper: a firefighter drops ultrasound beacons by the deployment "
           "rules (entry, signal loss, turns), walks trace c, then retreats to the exit by the "
           "smallest-id rule; beacon positions unknown (MDS)"},
          {"beacon-neighbour-trail",
           "a beacon trail laid out by someone else (issue 22): a U- or L-shaped corridor drawn "
           "from the seed, ranges between trail neighbours only, 3 surveyed beacons away from "
           "the entry, NLOS ranges with a long tail, 15 % bearing outliers"},
          {"incident-4h",
           "a long incident for soak and load tests: 20 firefighters for 4 hours, each in a "
           "30 m sector, 500 breadcrumbs dropped as they go, ~1 million steps and RSSI packets "
           "(the breadcrumb benchmark's synthetic incident; no floor plan, no truth)"},
          {"multi-floor",
           "floors (issue 26): a basement, a ground floor and two upper floors joined by a "
           "stairwell, storey heights drawn per seed; ff1 searches the upper floors, ff2 the "
           "ground floor and the basement; phone PDR steps without height, a foot IMU on the "
           "stairs, a barometer each (offset, weather, a ventilation fan, spikes)"},
          {"multi-floor-landmarks",
           "the multi-floor building with 3 surveyed radio landmarks at the ceiling of each "
           "level's corridor, heard by the phones through the floors (the building's floor "
           "loss, 10-20 dB), for the landmark pipelines' floor gate (issue 26, item 4)"},
          {"all-sources",
           "every source at once (issue 27): the multi-floor building with two firefighters, "
           "their breadcrumbs and a base, 3 surveyed radio landmarks per level, an ultrasound "
           "beacon exit trail dropped on the ground floor, foot IMUs, phone steps, barometers "
           "and every level's floor plan"},
          {"all-sources-4h",
           "the load of issue 27's must-hold: the all-sources building with 20 firefighters "
           "entering 20 s apart, tour after tour (a search of two levels, a rest in the street) "
           "for 4 hours; every source but the foot IMUs (phone steps; 28.8 M IMU samples would "
           "be 2 GB of CSV)"}};
}

namespace {
/// A variant of a scenario under the variant's name.
SimulatedMission Named(SimulatedMission sim, const std::string& name) {
  sim.data.info.name = name;
  return sim;
}
}  // namespace

MultiFloorOptions AllSourcesLoadOptions(int firefighters, double duration_s) {
  MultiFloorOptions o;
  o.landmarks_per_level = 3;
  o.beacon_trail = true;
  o.firefighters = firefighters;
  o.duration_s = duration_s;
  o.foot_imu = false;
  return o;
}

SimulatedMission SimulateAllSourcesLoad(std::uint64_t seed, int firefighters, double duration_s) {
  return Named(SimulateMultiFloor(AllSourcesLoadOptions(firefighters, duration_s), seed),
               "all-sources-4h");
}

SimulatedMission SimulateScenario(const std::string& name, std::uint64_t seed) {
  if (name == "office-loop") return SimulateOfficeLoop({}, seed);
  if (name == "office-loop-1lap") {
    OfficeLoopOptions o;
    o.laps = 1;
    return Named(SimulateOfficeLoop(o, seed), name);
  }
  if (name == "office-loop-kicked") {
    OfficeLoopOptions o;
    o.sim.kick.probability = 0.5;
    o.sim.kick.max_kicks = 2;
    return Named(SimulateOfficeLoop(o, seed), name);
  }
  if (name == "training-building") return SimulateTrainingBuilding({}, seed);
  if (name == "landmark-corridor") return SimulateLandmarkMission({}, seed);
  if (name == "landmark-office") return SimulateLandmarkOffice({}, seed);
  if (name == "beacon-lab") return SimulateBeaconLab({}, seed);
  if (name == "house1-search" || name == "house2-search") {
    HouseSearchOptions o;
    o.house = name == "house1-search" ? 1 : 2;
    o.duration_s = o.house == 1 ? 270 : 600;
    return SimulateHouseSearch(o, seed);
  }
  if (name == "beacon-trail") {
    BeaconLabOptions o;
    o.surveyed = false;
    o.trace = LabTrace::kC;
    return SimulateBeaconLab(o, seed);
  }
  if (name == "beacon-neighbour-trail") return SimulateShapedTrail({}, seed);
  if (name == "multi-floor") return SimulateMultiFloor({}, seed);
  if (name == "multi-floor-landmarks") {
    MultiFloorOptions o;
    o.landmarks_per_level = 3;
    return Named(SimulateMultiFloor(o, seed), name);
  }
  if (name == "all-sources") {
    MultiFloorOptions o;
    o.landmarks_per_level = 3;
    o.beacon_trail = true;
    return Named(SimulateMultiFloor(o, seed), name);
  }
  if (name == "all-sources-4h") return SimulateAllSourcesLoad(seed);
  if (name == "incident-4h") {
    const SyntheticIncident inc = MakeSyntheticIncident({}, seed);
    SimulatedMission sim;
    sim.data.info = inc.info;
    sim.data.info.name = name;
    sim.data.info.description = fmt::format(
        "synthetic incident: {} firefighters for 4 h, {} steps, {} RSSI packets, {} crumbs "
        "dropped; simulated, seed {}",
        inc.info.nodes.size() - 1, inc.steps, inc.packets, inc.drops, seed);
    for (const IncidentEvent& e : inc.events) {
      switch (e.kind) {
        case IncidentEvent::Kind::kStep: sim.data.steps.push_back(e.step); break;
        case IncidentEvent::Kind::kRssi: sim.data.rssi.push_back(e.rssi); break;
        case IncidentEvent::Kind::kDrop: sim.data.events.push_back(e.drop); break;
      }
    }
    return sim;
  }
  std::string known;
  for (const auto& s : Scenarios()) known += (known.empty() ? "" : ", ") + s.name;
  throw std::invalid_argument("unknown scenario '" + name + "' (known: " + known + ")");
}

}  // namespace trailmark

// SPDX-License-Identifier: MIT
#include "trailmark/sim/multi_floor.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <stdexcept>
#include <string>

#include "trailmark/sim/rssi_channel.h"

namespace trailmark {

namespace {

// The block: 24 x 12 m; a corridor y in [5, 7] from x = 0 to 20 with three rooms on each side;
// the stairwell x in [20, 24], open to the corridor; flights along y at x = 21 (down the page)
// and x = 23 (up the page), the half landing at y < 1.5.
constexpr double kWidth = 24, kDepth = 12, kCorridorLo = 5, kCorridorHi = 7, kStairX = 20;

/// The rooms of a level: three on each side of the corridor, between partitions at `x[0]` and
/// `x[1]`; their doors at `centre`. Levels differ (a plant room in the basement, an open office
/// on level 2), so that a map matcher that keeps one level's plan crosses walls on the others.
struct LevelLayout {
  double x[2];
  double centre[3];
};
LevelLayout LayoutOf(int level) {
  if (level < 0) return {{8.0, 14.0}, {4.0, 11.0, 17.0}};
  if (level >= 2) return {{5.0, 13.0}, {2.5, 9.0, 16.5}};
  return {{6.0, 12.0}, {3.0, 9.0, 16.0}};
}
const Vec2 kOutside(2.5, -4.0);  // the street, in front of the entrance
const Vec2 kBase(0.0, -6.0);     // the command post's radio, in the street

struct RouteBuilder {
  Route route;
  void To(double x, double y, double z) {
    route.waypoints.emplace_back(x, y);
    route.waypoint_z.push_back(z);
  }
  void Stop(double seconds) { route.stops.push_back({route.Length(), seconds}); }
  /// From the corridor in front of the stairwell at elevation z_from to the one at z_to: the
  /// flight at x = 21 to the half landing, the flight at x = 23 up from it (walked backwards on
  /// the way down). Each point: x, y and its height as 0 (bottom), 1 (half landing) or 2 (top).
  void Stairs(double z_from, double z_to) {
    struct Point {
      double x, y;
      int height;
    };
    static constexpr Point kUp[] = {{21.0, 6.0, 0}, {21.0, 4.5, 0}, {21.0, 1.5, 1},
                                    {21.5, 0.8, 1}, {22.5, 0.8, 1}, {23.0, 1.5, 1},
                                    {23.0, 4.5, 2}, {23.0, 6.0, 2}, {21.0, 6.0, 2}};
    const bool up = z_to > z_from;
    const double bottom = up ? z_from : z_to, top = up ? z_to : z_from;
    const double z_of[] = {bottom, 0.5 * (z_from + z_to), top};
    const std::size_t n = std::size(kUp);
    for (std::size_t i = 0; i < n; ++i) {
      const Point& p = kUp[up ? i : n - 1 - i];
      To(p.x, p.y, z_of[p.height]);
    }
  }
  /// A search of a level from the stairwell: every room, west along the corridor and back.
  void Search(int level, double z, Random& rng, bool north_first) {
    const LevelLayout layout = LayoutOf(level);
    To(19.5, 6.0, z);
    for (int i = 2; i >= 0; --i) {
      const double c = layout.centre[i] + rng.Uniform(-0.3, 0.3);
      for (const bool north : {north_first, !north_first}) {
        const double door_y = north ? kCorridorHi : kCorridorLo;
        const double inside = north ? 9.5 : 2.5;
        To(c, 6.0, z);
        To(c, door_y, z);
        To(c + rng.Uniform(-1.5, 1.5), inside + rng.Uniform(-0.8, 0.8), z);
        if (rng.Uniform() < 0.4) Stop(rng.Uniform(5, 20));  // a casualty check, a search
        To(c + rng.Uniform(-1.5, 1.5), inside + rng.Uniform(-0.8, 0.8), z);
        To(c, door_y, z);
        To(c, 6.0, z);
      }
    }
    To(19.5, 6.0, z);
    To(21.0, 6.0, z);
  }
  void Enter() {
    To(kOutside.x(), kOutside.y(), 0);
    To(2.5, 0.0, 0);
    To(3.0, 2.5, 0);
    To(3.0, kCorridorLo, 0);
    To(3.0, 6.0, 0);
  }
  void Leave() {
    To(3.0, 6.0, 0);
    To(3.0, kCorridorLo, 0);
    To(3.0, 2.5, 0);
    To(2.5, 0.0, 0);
    To(kOutside.x(), kOutside.y(), 0);
  }
};

bool Inside(const Vec2& p) { return p.x() > 0 && p.x() < kWidth && p.y() > 0 && p.y() < kDepth; }

/// The walk's truth at time t (linear between samples).
Walk::Sample TruthAt(const Walk& walk, TimeS t) {
  const auto& s = walk.truth;
  auto it = std::lower_bound(s.begin(), s.end(), t,
                             [](const Walk::Sample& a, TimeS v) { return a.t < v; });
  if (it == s.begin()) return s.front();
  if (it == s.end()) return s.back();
  const Walk::Sample& b = *it;
  const Walk::Sample& a = *(it - 1);
  const double f = (t - a.t) / std::max(b.t - a.t, 1e-9);
  Walk::Sample out = a;
  out.t = t;
  out.position = a.position + f * (b.position - a.position);
  out.z = a.z + f * (b.z - a.z);
  return out;
}

/// The walk up to t_end: steps ending by then, truth samples, stops begun by then.
void CutWalk(Walk& walk, TimeS t_end) {
  std::erase_if(walk.steps, [t_end](const TrueStep& s) { return s.t1 > t_end; });
  std::erase_if(walk.truth, [t_end](const Walk::Sample& s) { return s.t > t_end; });
  std::erase_if(walk.stops, [t_end](const Walk::StopInterval& s) { return s.t_stop > t_end; });
  for (Walk::StopInterval& s : walk.stops) s.t_go = std::min(s.t_go, t_end);
}

}  // namespace

MultiFloorOptions::MultiFloorOptions() {
  imu.rate_hz = 100.0;
  imu.grade = ImuGrade::Industrial();
  pdr.turn_min_step_m = 0.2;  // short shuffles are not turns (pdr_error_model.h)
}

FloorPlan BuildMultiFloorLevel(int level) {
  std::vector<Segment2> walls, doors;
  std::vector<Room> rooms;
  AddRectangle(walls, {0, 0}, {kWidth, kDepth});
  walls.push_back({{0, kCorridorLo}, {kStairX, kCorridorLo}});
  walls.push_back({{0, kCorridorHi}, {kStairX, kCorridorHi}});
  const LevelLayout layout = LayoutOf(level);
  for (const double x : layout.x) {
    walls.push_back({{x, 0}, {x, kCorridorLo}});
    walls.push_back({{x, kCorridorHi}, {x, kDepth}});
  }
  walls.push_back({{kStairX, 0}, {kStairX, kCorridorLo}});
  walls.push_back({{kStairX, kCorridorHi}, {kStairX, kDepth}});
  walls.push_back({{22.0, 1.5}, {22.0, 4.5}});  // between the two flights
  for (const double c : layout.centre) {
    doors.push_back({{c - 0.45, kCorridorLo}, {c + 0.45, kCorridorLo}});
    doors.push_back({{c - 0.45, kCorridorHi}, {c + 0.45, kCorridorHi}});
  }
  if (level == 0) doors.push_back({{2.0, 0.0}, {3.0, 0.0}});  // the entrance
  rooms.push_back({"corridor", {{0, kCorridorLo}, {kStairX, kCorridorLo}, {kStairX, kCorridorHi},
                                {0, kCorridorHi}},
                   level});
  rooms.push_back({"stairwell", {{kStairX, 0}, {kWidth, 0}, {kWidth, kDepth}, {kStairX, kDepth}},
                   level});
  return FloorPlan(std::move(walls), std::move(doors), std::move(rooms));
}

double StandardPressureHpa(double z_m, double p0_hpa) {
  return p0_hpa * std::pow(1.0 - 2.25577e-5 * z_m, 5.25588);
}

SimulatedMission SimulateMultiFloor(const MultiFloorOptions& o, std::uint64_t seed) {
  if (o.firefighters < 1 || !(o.duration_s >= 0) || !(o.rest_min_s >= 0) ||
      !(o.rest_max_s >= o.rest_min_s)) {
    throw std::invalid_argument(
        "multi-floor: need firefighters >= 1, duration_s >= 0, 0 <= rest_min_s <= rest_max_s");
  }
  Random rng(seed);
  // Storeys of another height in every building: 3.0-4.2 m, the basement 2.8-3.8 m.
  const double e1 = rng.Uniform(3.0, 4.2);
  const double e2 = e1 + rng.Uniform(3.0, 4.2);
  const double em1 = -rng.Uniform(2.8, 3.8);
  const std::vector<FloorLevel> floors{{-1, em1}, {0, 0.0}, {1, e1}, {2, e2}};

  // ff1 searches the two upper floors, ff2 the ground floor and the basement; ff3 as ff1 and so
  // on; on further tours (duration_s) each searches the other pair.
  std::vector<std::pair<std::string, Route>> agents;
  const double mean_speed_mps = 0.8 * o.walker.speed_mps;  // stops and stairs, roughly
  for (int k = 0; k < o.firefighters; ++k) {
    RouteBuilder r;
    const TimeS t_start = k * 20.0;
    // A mission that ends before a firefighter's turn to enter (20 s apart) does not have him:
    // he would have no sample at all. At least a second of walk for the ones it has.
    if (o.duration_s > 0 && t_start + 1.0 > o.duration_s) break;
    for (int tour = 0;; ++tour) {
      r.Enter();
      if ((k + tour) % 2 == 0) {
        r.To(19.5, 6.0, 0);
        r.To(21.0, 6.0, 0);
        r.Stairs(0, e1);
        r.Search(1, e1, rng, rng.Uniform() < 0.5);
        r.Stairs(e1, e2);
        r.Search(2, e2, rng, rng.Uniform() < 0.5);
        r.Stairs(e2, e1);
        r.Stairs(e1, 0);
      } else {
        r.Search(0, 0, rng, rng.Uniform() < 0.5);
        r.Stairs(0, em1);
        r.Search(-1, em1, rng, rng.Uniform() < 0.5);
        r.Stairs(em1, 0);
      }
      r.To(19.5, 6.0, 0);
      r.Leave();
      if (o.duration_s <= 0) break;
      double stopped_s = 0;
      for (const Route::Stop& st : r.route.stops) stopped_s += st.duration_s;
      if (t_start + r.route.Length() / mean_speed_mps + stopped_s > o.duration_s + 60.0) break;
      r.Stop(rng.Uniform(o.rest_min_s, o.rest_max_s));  // in the street: a new cylinder
    }
    agents.emplace_back(fmt::format("ff{}", k + 1), r.route);
  }

  SimulatedMission out;
  SimulatedMission& sim = out;
  MissionData& m = sim.data;
  m.info.name = "multi-floor";
  m.info.floors = floors;
  m.info.floorplan = "floorplan.geojson";
  const double start_heading = std::numbers::pi / 2;  // facing the entrance (north)
  for (const auto& [id, route] : agents) {
    m.info.nodes.push_back(
        NodeInfo::Agent(id, Vec3(kOutside.x(), kOutside.y(), 0.0), 0.3, start_heading, 0.05));
  }
  for (const int level : {-1, 0, 1, 2}) out.levels.emplace_back(level, BuildMultiFloorLevel(level));
  sim.plan = out.levels[1].second;

  // Weather shared by both, device offsets per barometer; the fan starts 1-4 min in.
  const double weather_rate_hpa_per_s = rng.Normal(0, o.baro.weather_drift_hpa_per_h) / 3600.0;
  const double ppv_start_s = rng.Uniform(60, 240);
  const double site_elevation_m = rng.Uniform(0, 300);
  for (std::size_t i = 0; i < agents.size(); ++i) {
    const auto& [id, route] = agents[i];
    const TimeS t_start = i * 20.0;
    Random walk_rng = rng.Fork();
    Walk walk = WalkRoute(route, o.walker, t_start, walk_rng);
    if (o.duration_s > 0) CutWalk(walk, o.duration_s);
    sim.walks.emplace_back(id, walk);
    // Truth: feet height and level.
    for (const auto& s : walk.truth) {
      m.truth.push_back({s.t, id, Vec3(s.position.x(), s.position.y(), s.z), LevelAt(floors, s.z)});
    }
    // A phone's PDR: horizontal steps with its errors; it does not measure height.
    PdrErrorModel pdr(o.pdr, rng.Fork());
    for (const auto& st : walk.steps) {
      const Vec2 d = pdr.Apply(st.to - st.from, st.t1 - st.t0);
      const double var = pdr.ReportedVariance((st.to - st.from).norm());
      m.steps.push_back({st.t0, st.t1, id, Vec3(d.x(), d.y(), 0.0), Vec3(var, var, 1.0)});
    }
    // The barometer.
    Random baro_rng = rng.Fork();
    const double offset_hpa = baro_rng.Normal(0, o.baro.device_offset_hpa);
    const double period = 1.0 / o.baro.rate_hz;
    const TimeS t_end = walk.truth.back().t;
    for (TimeS t = walk.truth.front().t; t <= t_end + 1e-9; t += period) {
      const Walk::Sample s = TruthAt(walk, t);
      double p = StandardPressureHpa(site_elevation_m + s.z,
                                     o.baro.sea_level_hpa + weather_rate_hpa_per_s * t);
      if (Inside(s.position) && t > ppv_start_s) {
        p += o.baro.ppv_overpressure_hpa * std::min(1.0, (t - ppv_start_s) / std::max(o.baro.ppv_rise_s, 1e-3));
      }
      p += offset_hpa + baro_rng.Normal(0, o.baro.noise_hpa);
      if (baro_rng.Uniform() < o.baro.spike_probability) p += baro_rng.Uniform(-2.0, 2.0);
      p = std::round(p / o.baro.resolution_hpa) * o.baro.resolution_hpa;
      m.baro.push_back({t, id, p});
    }
    if (o.foot_imu) {
      // The foot rests facing the agent's stated start heading, as AddFootImu has it.
      const NodeInfo* node = m.info.Find(id);
      const SimulatedImu imu = SimulateFootImu(walk, id, o.imu, rng.Fork(),
                                               node ? node->start_heading_rad : std::nullopt);
      m.imu.insert(m.imu.end(), imu.samples.begin(), imu.samples.end());
    }
  }
  // The radio last: the random streams above are those of the building without it.
  double floor_loss_db = 0;
  if (o.radio) {
    MissionSimOptions net = o.network;
    floor_loss_db = rng.Uniform(o.floor_loss_min_db, o.floor_loss_max_db);
    net.radio.floor_loss_db = floor_loss_db;
    m.info.nodes.push_back(NodeInfo::Base("base", Vec3(kBase.x(), kBase.y(), 0.0)));
    m.info.radio = RadioCalibration{"log-distance", net.radio.alpha_dbm,
                                    net.radio.path_loss_exponent, net.radio.shadowing_sigma_db};
    Random radio_rng = rng.Fork(), drop_rng = rng.Fork(), kick_rng = rng.Fork();
    SimulateCrumbNetwork(sim, Vec3(kBase.x(), kBase.y(), 0.0), floors, net, false, radio_rng,
                         drop_rng, kick_rng);
  }
  // The landmarks after the crumbs: the random streams above are those without them.
  if (o.landmarks_per_level > 0) {
    RssiChannelOptions radio = o.network.radio;
    radio.floor_loss_db = floor_loss_db > 0 ? floor_loss_db
                                            : rng.Uniform(o.floor_loss_min_db, o.floor_loss_max_db);
    floor_loss_db = radio.floor_loss_db;
    if (!o.radio) {
      m.info.radio = RadioCalibration{"log-distance", radio.alpha_dbm, radio.path_loss_exponent,
                                      radio.shadowing_sigma_db};
    }
    RssiChannel channel(radio, &sim.plan, {}, rng.Fork());
    struct Landmark {
      std::string id;
      Vec3 position;
      int level;
    };
    std::vector<Landmark> landmarks;
    for (const FloorLevel& f : floors) {
      for (int k = 0; k < o.landmarks_per_level; ++k) {
        const double x = kStairX * (k + 0.5) / o.landmarks_per_level;
        const Vec3 p(x, 0.5 * (kCorridorLo + kCorridorHi), f.elevation_m + o.landmark_height_m);
        // lmB1-1 in the basement, lm0-1 on the ground floor, lm2-3 on level 2.
        const std::string level_name =
            f.level < 0 ? fmt::format("B{}", -f.level) : fmt::format("{}", f.level);
        landmarks.push_back({fmt::format("lm{}-{}", level_name, k + 1), p, f.level});
        NodeInfo n;
        n.id = landmarks.back().id;
        n.kind = NodeKind::kLandmark;
        n.position = p;
        n.position_sigma_m = 0.2;
        m.info.nodes.push_back(n);
        m.truth.push_back({0.0, n.id, p, f.level});
      }
    }
    const FloorPlan* plan_of[4];
    for (int i = 0; i < 4; ++i) plan_of[i] = &out.levels[i].second;
    for (const auto& [id, walk] : sim.walks) {
      for (TimeS t = walk.truth.front().t; t <= walk.truth.back().t + 1e-9;
           t += 1.0 / o.landmark_rate_hz) {
        const Walk::Sample s = TruthAt(walk, t);
        const int level = LevelAt(floors, s.z);
        for (const Landmark& l : landmarks) {
          LinkLevels link;
          link.floors_crossed = std::abs(level - l.level);
          link.dz_m = s.z + o.phone_height_m - l.position.z();
          link.plan = plan_of[std::clamp(level + 1, 0, 3)];
          const auto rssi = channel.Sample(id, s.position, l.id, l.position.head<2>(), std::nullopt,
                                           std::nullopt, link);
          if (rssi) m.rssi.push_back({t, id, l.id, *rssi});
        }
      }
    }
  }
  // The beacon trail last: the random streams above are those without it.
  int beacons = 0;
  if (o.beacon_trail) {
    Random deploy_rng = rng.Fork(), us_rng = rng.Fork();
    const FloorPlan& ground = out.levels[1].second;
    const UltrasoundOptions& us = o.ultrasound;
    // ff1's way in from the entrance (the first rule drops a beacon just inside the door) to
    // the stairwell, and the route's turns (the third rule).
    const Walk& walk_in = sim.walks[0].second;
    Walk trail;
    for (const auto& s : walk_in.truth) {
      if (s.position.y() < 0.3) continue;  // still in the street
      if (s.position.x() > kStairX - 0.5) break;
      trail.truth.push_back(s);
    }
    RouteBuilder route;
    route.Enter();
    route.To(kStairX - 0.5, 6.0, 0);
    const BeaconLayout layout =
        DeployBeacons(ground, route.route, trail, o.deployment, us.max_range_m, deploy_rng);
    beacons = static_cast<int>(layout.beacons.size());
    for (int j = 0; j < beacons; ++j) {
      NodeInfo n;
      n.id = BeaconId(j);
      n.kind = NodeKind::kCrumb;
      m.info.nodes.push_back(n);
      const Vec3 p(layout.beacons[j].x(), layout.beacons[j].y(), 0.0);
      m.truth.push_back({layout.drop_time_s[j], n.id, p, 0});
      m.events.push_back({layout.drop_time_s[j], "ff1", "drop", n.id});
    }
    // Every foot node is heard on the ground floor only (the beacons' floor; not on the stairs
    // above the first steps).
    for (const auto& [id, walk] : sim.walks) {
      const Walk* w = &walk;
      SimulateFootUltrasound(ground, walk, id, layout.beacons, layout.drop_time_s, us, us_rng, m,
                             [w](TimeS t) { return std::abs(TruthAt(*w, t).z) < 0.4; });
    }
    const auto every_pair = [](int, int) { return true; };
    for (int j = 0; j < beacons; ++j) {
      SimulateBeaconRanging(ground, layout.beacons, layout.drop_time_s, us,
                            layout.drop_time_s[j] + 0.5, j, every_pair, us_rng, m);
    }
    TimeS t_end = 0;
    for (const auto& [id, walk] : sim.walks) t_end = std::max(t_end, walk.truth.back().t);
    for (TimeS t = layout.drop_time_s.front() + us.beacon_ranging_period_s; t <= t_end;
         t += us.beacon_ranging_period_s) {
      SimulateBeaconRanging(ground, layout.beacons, layout.drop_time_s, us, t, -1, every_pair,
                            us_rng, m);
    }
  }
  auto by_time = [](const auto& x, const auto& y) { return x.t < y.t; };
  std::stable_sort(m.ranges.begin(), m.ranges.end(), by_time);
  std::stable_sort(m.bearings.begin(), m.bearings.end(), by_time);
  std::stable_sort(m.events.begin(), m.events.end(), by_time);
  std::stable_sort(m.rssi.begin(), m.rssi.end(), by_time);
  std::stable_sort(m.truth.begin(), m.truth.end(), by_time);
  std::stable_sort(m.baro.begin(), m.baro.end(), by_time);
  std::stable_sort(m.imu.begin(), m.imu.end(), by_time);
  std::stable_sort(m.steps.begin(), m.steps.end(),
                   [](const Step& x, const Step& y) { return x.t1 < y.t1; });
  m.info.description = fmt::format(
      "Multi-storey block (issue 26): basement at {:.2f} m, ground floor 0, level 1 at {:.2f} m, "
      "level 2 at {:.2f} m, a switchback stairwell; {}phone PDR steps (no height), {}a barometer "
      "each at {:g} Hz (offset, weather {:+.2f} hPa/h, a ventilation fan from t = {:.0f} s); "
      "{}{}simulated, seed {}",
      em1, e1, e2,
      o.firefighters == 2 && o.duration_s <= 0
          ? std::string("ff1 searches levels 1 and 2, ff2 the ground floor and the basement; ")
          : fmt::format("{} firefighters entering 20 s apart, each searching two levels a tour "
                        "(levels 1 and 2, or the ground floor and the basement){}; ",
                        agents.size(),
                        o.duration_s > 0
                            ? fmt::format(", tour after tour with rests in the street until "
                                          "t = {:g} s",
                                          o.duration_s)
                            : std::string()),
      o.foot_imu ? fmt::format("a foot IMU at {:g} Hz, ", o.imu.rate_hz) : std::string(),
      o.baro.rate_hz, weather_rate_hpa_per_s * 3600, ppv_start_s,
      o.radio || o.landmarks_per_level > 0
          ? fmt::format(
                "{}{}RSSI losing {:.1f} dB per floor; ", o.radio ? "breadcrumbs and a base, " : "",
                o.landmarks_per_level > 0
                    ? fmt::format("{} surveyed landmarks on each level, ", o.landmarks_per_level)
                    : std::string(),
                floor_loss_db)
          : std::string(),
      beacons > 0 ? fmt::format("an exit trail of {} ultrasound beacons on the ground floor "
                                "dropped by ff1 on the way in; ",
                                beacons)
                  : std::string(),
      seed);
  return out;
}

}  // namespace trailmark

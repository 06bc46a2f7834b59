#include "trailmark/sim/scenarios.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <optional>
#include <stdexcept>

namespace trailmark {
namespace {

void AddRect(std::vector<Segment2>& walls, Vec2 lo, Vec2 hi) {
  walls.push_back({{lo.x(), lo.y()}, {hi.x(), lo.y()}});
  walls.push_back({{hi.x(), lo.y()}, {hi.x(), hi.y()}});
  walls.push_back({{hi.x(), hi.y()}, {lo.x(), hi.y()}});
  walls.push_back({{lo.x(), hi.y()}, {lo.x(), lo.y()}});
}

}  // namespace

FloorPlan BuildOfficeFloor(const OfficeLoopOptions& o) {
  // Loop centre line: x in [-W, 0], y in [-H, 0]; base at (0, 0), the upper right corner.
  const double W = o.loop_width_m, H = o.loop_height_m, h = o.corridor_width_m / 2;
  const double depth = 6.0;  // office depth on the outside of the corridor
  std::vector<Segment2> walls, doors;
  std::vector<Room> rooms;
  AddRect(walls, {-W - h - depth, -H - h - depth}, {h + depth, h + depth});  // exterior
  AddRect(walls, {-W - h, -H - h}, {h, h});                                  // corridor outside
  AddRect(walls, {-W + h, -H + h}, {-h, -h});                                // corridor inside
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
  Random rng(seed);
  Random walk_rng = rng.Fork();
  Random pdr_rng = rng.Fork();
  Random radio_rng = rng.Fork();
  Random drop_rng = rng.Fork();

  SimulatedMission sim;
  sim.plan = BuildOfficeFloor(o);
  MissionData& m = sim.data;
  const std::string agent = "ff1";
  m.info.name = "office-loop";
  m.info.description = "Office floor, 100 m corridor loop walked " + std::to_string(o.laps) +
                       " times anti-clockwise from the base (breadcrumb paper sec. V-A); "
                       "breadcrumbs dropped by a dispenser; simulated, seed " +
                       std::to_string(seed);
  m.info.nodes.push_back({.id = "base", .kind = NodeKind::kBase, .position = Vec3::Zero()});
  m.info.nodes.push_back({.id = agent,
                          .kind = NodeKind::kAgent,
                          .start = Vec3::Zero(),
                          .start_sigma_m = 0.1,
                          .start_heading_rad = std::numbers::pi,
                          .start_heading_sigma_rad = 0.02});
  m.info.radio = RadioCalibration{"log-distance", o.radio.alpha_dbm, o.radio.path_loss_exponent,
                                  o.radio.shadowing_sigma_db};
  m.info.floorplan = "floorplan.geojson";

  Route route;
  const double W = o.loop_width_m, H = o.loop_height_m;
  route.waypoints.push_back({0, 0});
  for (int lap = 0; lap < o.laps; ++lap) {
    for (const Vec2& p : {Vec2(-W, 0), Vec2(-W, -H), Vec2(0, -H), Vec2(0, 0)}) {
      route.waypoints.push_back(p);
    }
  }
  const Walk walk = WalkRoute(route, o.walker, 0.0, walk_rng);

  // PDR steps.
  PdrErrorModel pdr(o.pdr, pdr_rng);
  for (const auto& s : walk.steps) {
    const Vec2 measured = pdr.Apply(s.to - s.from, s.t1 - s.t0);
    const double var = pdr.ReportedVariance((s.to - s.from).norm());
    m.steps.push_back({s.t0, s.t1, agent, Vec3(measured.x(), measured.y(), 0.0),
                       Vec3(var, var, 1e-4)});
  }

  // Radio and the dispenser, ticking with the agent's beacons.
  RssiChannel channel(o.radio, &sim.plan, {}, radio_rng);
  struct Deployed {
    std::string id;
    Vec2 position;
    double ema = 0;
    bool heard = false;
  };
  std::vector<Deployed> chain{{"base", Vec2::Zero()}};
  m.truth.push_back({walk.truth.front().t, "base", Vec3::Zero()});
  m.events.push_back({walk.truth.front().t, agent, "enter", ""});
  int dropped = 0;
  Vec2 last_drop = Vec2::Zero();
  double next_packet = walk.truth.front().t;
  double next_crumb_packet = next_packet;
  std::optional<double> weak_since;
  std::size_t stop_idx = 0;
  for (const auto& sample : walk.truth) {
    while (stop_idx < walk.stops.size() && walk.stops[stop_idx].t_stop <= sample.t) {
      m.events.push_back({walk.stops[stop_idx].t_stop, agent, "stop", ""});
      m.events.push_back({walk.stops[stop_idx].t_go, agent, "go", ""});
      ++stop_idx;
    }
    m.truth.push_back({sample.t, agent, Vec3(sample.position.x(), sample.position.y(), 0.0)});
    if (sample.t + 1e-9 < next_packet) continue;
    next_packet += o.packet_period_s;
    double best = -1e9;
    for (auto& node : chain) {
      // Node -> agent (the dispenser hears the chain) and agent -> node.
      if (auto r = channel.Sample(agent, sample.position, node.id, node.position,
                                  sample.heading_rad, std::nullopt)) {
        m.rssi.push_back({sample.t, agent, node.id, *r});
        node.ema = node.heard ? (1 - o.dispenser.smoothing) * node.ema + o.dispenser.smoothing * *r
                              : *r;
        node.heard = true;
      } else if (node.heard) {
        node.ema = (1 - o.dispenser.smoothing) * node.ema +
                   o.dispenser.smoothing * o.radio.sensitivity_dbm;
      }
      if (auto r = channel.Sample(node.id, node.position, agent, sample.position, std::nullopt,
                                  sample.heading_rad)) {
        m.rssi.push_back({sample.t, node.id, agent, *r});
      }
      if (node.heard) best = std::max(best, node.ema);
    }
    if (sample.t + 1e-9 >= next_crumb_packet) {
      next_crumb_packet += o.crumb_packet_period_s;
      for (const auto& rx : chain) {
        for (const auto& tx : chain) {
          if (rx.id == tx.id) continue;
          if (auto r = channel.Sample(rx.id, rx.position, tx.id, tx.position, std::nullopt,
                                      std::nullopt)) {
            m.rssi.push_back({sample.t, rx.id, tx.id, *r});
          }
        }
      }
    }
    if (best >= o.dispenser.drop_threshold_dbm) {
      weak_since.reset();
    } else if (!weak_since) {
      weak_since = sample.t;
    }
    if (weak_since && sample.t - *weak_since >= o.dispenser.below_for_s &&
        dropped < o.dispenser.capacity &&
        (sample.position - last_drop).norm() >= o.dispenser.min_spacing_m) {
      weak_since.reset();
      const std::string id = "c" + std::to_string(++dropped);
      const Vec2 where = sample.position + Vec2(drop_rng.Normal(0, o.dispenser.drop_scatter_m),
                                                drop_rng.Normal(0, o.dispenser.drop_scatter_m));
      chain.push_back({id, where});
      last_drop = sample.position;
      m.events.push_back({sample.t, agent, "drop", id});
      m.truth.push_back({sample.t, id, Vec3(where.x(), where.y(), 0.0)});
    }
  }
  m.events.push_back({walk.truth.back().t, agent, "exit", ""});
  auto by_time = [](const auto& a, const auto& b) { return a.t < b.t; };
  std::stable_sort(m.events.begin(), m.events.end(), by_time);
  std::stable_sort(m.truth.begin(), m.truth.end(), by_time);
  return sim;
}

std::vector<ScenarioInfo> Scenarios() {
  return {{"office-loop",
           "default: office floor, 100 m corridor loop x 4 (400 m), one firefighter, base at the "
           "start, dispenser-dropped breadcrumbs, RSSI between all nodes in range"},
          {"office-loop-1lap", "the same floor, one lap (100 m): quick tests"}};
}

SimulatedMission SimulateScenario(const std::string& name, std::uint64_t seed) {
  if (name == "office-loop") return SimulateOfficeLoop({}, seed);
  if (name == "office-loop-1lap") {
    OfficeLoopOptions o;
    o.laps = 1;
    SimulatedMission sim = SimulateOfficeLoop(o, seed);
    sim.data.info.name = name;
    return sim;
  }
  std::string known;
  for (const auto& s : Scenarios()) known += (known.empty() ? "" : ", ") + s.name;
  throw std::invalid_argument("unknown scenario '" + name + "' (known: " + known + ")");
}

}  // namespace trailmark

// SPDX-License-Identifier: MIT
#include "trailmark/sim/landmark_corridor.h"

#include <cmath>

#include "trailmark/core/random.h"
#include "trailmark/sim/mission_sim.h"
#include "trailmark/sim/pdr_error_model.h"
#include "trailmark/sim/walker.h"

#include <algorithm>
#include <numbers>

namespace trailmark {

LandmarkCorridor SimulateLandmarkCorridor(const LandmarkCorridorOptions& o, std::uint64_t seed) {
  Random rng(seed);
  LandmarkCorridor c;
  const double length = o.landmark_spacing_m * (o.landmarks - 1);
  for (int j = 0; j < o.landmarks; ++j) {
    c.landmarks.emplace_back(j * o.landmark_spacing_m + rng.Normal(0, 0.3),
                             (j % 2 == 0 ? 1 : -1) * o.corridor_half_width_m);
  }
  for (int p = 0; p < o.standing_positions; ++p) {
    const double x = o.standing_positions > 1 ? length * p / (o.standing_positions - 1) : 0.0;
    c.standing.emplace_back(x, (p % 2 == 0 ? 1 : -1) * o.standing_zigzag_m);
    c.standing_from_imu.push_back(
        c.standing.back() + Vec2(rng.Normal(0, o.standing_sigma_m), rng.Normal(0, o.standing_sigma_m)));
  }
  for (const auto& h : c.standing) {
    std::vector<std::optional<double>> row;
    for (const auto& s : c.landmarks) {
      const double d = std::max((h - s).norm(), 0.1);
      double mean = o.alpha_dbm - 10 * o.path_loss_exponent * std::log10(d) +
                    rng.Normal(0, o.shadowing_sigma_db);
      if (rng.Uniform(0, 1) < o.nlos_probability) mean -= o.nlos_loss_db;
      double sum = 0;
      int heard = 0;
      for (int k = 0; k < o.packets_per_stop; ++k) {
        const double r = mean + rng.Normal(0, o.fast_fading_sigma_db);
        if (r >= o.sensitivity_dbm) sum += r, ++heard;
      }
      row.push_back(heard > 0 ? std::optional<double>(sum / heard) : std::nullopt);
    }
    c.rssi_dbm.push_back(row);
  }
  return c;
}

}  // namespace trailmark

namespace trailmark {

SimulatedMission SimulateLandmarkMission(const LandmarkCorridorOptions& o, std::uint64_t seed) {
  const LandmarkCorridor c = SimulateLandmarkCorridor(o, seed);
  Random rng(seed * 7919 + 1);
  Random walk_rng = rng.Fork(), pdr_rng = rng.Fork(), radio_rng = rng.Fork();
  SimulatedMission sim;
  const double length = o.landmark_spacing_m * (o.landmarks - 1);
  const double h = o.corridor_half_width_m + 0.05;
  std::vector<Segment2> walls = {{{-3, h}, {length + 3, h}}, {{-3, -h}, {length + 3, -h}},
                                 {{length + 3, -h}, {length + 3, h}}};
  sim.plan = FloorPlan(walls, {}, {});
  MissionData& m = sim.data;
  m.info.name = "landmark-corridor";
  m.info.description =
      "Corridor with 5 wake-up radio landmarks at 868 MHz (radio-landmarks paper, Fig. 11): "
      "stop-and-go walk with 7 stops, wake-ups every 3 s while walking; simulated, seed " +
      std::to_string(seed);
  const Vec2 start(-2.0, 0.0);
  // start_heading: the walk's, set below.
  m.info.nodes.push_back(NodeInfo::Agent("ff1", Vec3(start.x(), start.y(), 0), 0.05, 0.0, 0.02));
  for (int j = 0; j < o.landmarks; ++j) {
    NodeInfo n;
    n.id = "lm" + std::to_string(j + 1);
    n.kind = NodeKind::kLandmark;
    if (j == 0) {  // one surveyed landmark (e.g. the smoke detector at the entrance)
      n.position = Vec3(c.landmarks[0].x(), c.landmarks[0].y(), o.landmark_height_m);
      n.position_sigma_m = 0.2;
    }
    m.info.nodes.push_back(n);
  }
  m.info.radio = RadioCalibration{"log-distance", o.alpha_dbm, o.path_loss_exponent,
                                  std::hypot(o.shadowing_sigma_db, o.fast_fading_sigma_db)};
  Route route;
  route.waypoints.push_back(start);
  double along = 0;
  Vec2 prev = start;
  for (const auto& stop : c.standing) {
    along += (stop - prev).norm();
    route.waypoints.push_back(stop);
    route.stops.push_back({along, 5.0});
    prev = stop;
  }
  route.waypoints.push_back(start);
  WalkerOptions wo;
  const Walk walk = WalkRoute(route, wo, 0.0, walk_rng);
  // The start heading is the walk's own (it was written as 0 while the first leg heads ~13°
  // off the x axis: the INS of an --imu-only mission aligned its yaw 13° off, 4 m at the far end).
  m.info.nodes.front().start_heading_rad = walk.truth.front().heading_rad;
  sim.walks.emplace_back("ff1", walk);
  PdrErrorModel pdr(PdrErrorOptions{}, pdr_rng);
  for (const auto& st : walk.steps) {
    const Vec2 d = pdr.Apply(st.to - st.from, st.t1 - st.t0);
    const double var = pdr.ReportedVariance((st.to - st.from).norm());
    m.steps.push_back({st.t0, st.t1, "ff1", Vec3(d.x(), d.y(), 0), Vec3(var, var, 1e-4)});
  }
  for (const auto& s : walk.truth) m.truth.push_back({s.t, "ff1", Vec3(s.position.x(), s.position.y(), 0)});
  for (int j = 0; j < o.landmarks; ++j) {
    m.truth.push_back({walk.truth.front().t, "lm" + std::to_string(j + 1),
                       Vec3(c.landmarks[j].x(), c.landmarks[j].y(), o.landmark_height_m)});
  }
  m.events.push_back({walk.truth.front().t, "ff1", "enter", ""});
  for (const auto& st : walk.stops) {
    m.events.push_back({st.t_stop, "ff1", "stop", ""});
    m.events.push_back({st.t_go, "ff1", "go", ""});
  }
  m.events.push_back({walk.truth.back().t, "ff1", "exit", ""});
  // Wake-ups: every 3 s while walking, every 0.5 s while stopped; per-link shadowing fixed
  // per stop (a standing handheld), drawn afresh while walking.
  std::vector<double> link_shadow(o.landmarks);
  std::size_t stop_idx = 0;
  bool stopped = false;
  double next_wake = walk.truth.front().t + 3.0;
  for (const auto& s : walk.truth) {
    bool in_stop = false;
    for (const auto& st : walk.stops) in_stop = in_stop || (s.t >= st.t_stop && s.t < st.t_go);
    if (in_stop && !stopped) {
      for (auto& v : link_shadow) v = radio_rng.Normal(0, o.shadowing_sigma_db);
      next_wake = s.t;
      ++stop_idx;
    }
    stopped = in_stop;
    if (s.t + 1e-9 < next_wake) continue;
    next_wake = s.t + (in_stop ? 0.5 : 3.0);
    m.events.push_back({s.t, "ff1", "wake", ""});
    for (int j = 0; j < o.landmarks; ++j) {
      const double d = std::max((s.position - c.landmarks[j]).norm(), 0.1);
      double rssi = o.alpha_dbm - 10 * o.path_loss_exponent * std::log10(d) +
                    (in_stop ? link_shadow[j] : radio_rng.Normal(0, o.shadowing_sigma_db)) +
                    radio_rng.Normal(0, o.fast_fading_sigma_db);
      if (radio_rng.Uniform(0, 1) < o.nlos_probability) rssi -= o.nlos_loss_db;
      if (rssi >= o.sensitivity_dbm) {
        m.rssi.push_back({s.t, "ff1", "lm" + std::to_string(j + 1), std::round(rssi * 2) / 2});
      }
    }
  }
  (void)stop_idx;
  auto by_time = [](const auto& a, const auto& b) { return a.t < b.t; };
  std::stable_sort(m.events.begin(), m.events.end(), by_time);
  std::stable_sort(m.truth.begin(), m.truth.end(), by_time);
  return sim;
}

}  // namespace trailmark

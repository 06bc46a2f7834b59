// SPDX-License-Identifier: MIT
#include "trailmark/sim/walker.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

namespace trailmark {

double Route::Length() const {
  double len = 0;
  for (std::size_t i = 1; i < waypoints.size(); ++i) len += (waypoints[i] - waypoints[i - 1]).norm();
  return len;
}

Vec2 Route::PointAt(double s) const {
  if (waypoints.empty()) return Vec2::Zero();
  if (s <= 0) return waypoints.front();
  for (std::size_t i = 1; i < waypoints.size(); ++i) {
    const double seg = (waypoints[i] - waypoints[i - 1]).norm();
    if (s <= seg && seg > 0) return waypoints[i - 1] + (waypoints[i] - waypoints[i - 1]) * (s / seg);
    s -= seg;
  }
  return waypoints.back();
}

double Route::ZAt(double s) const {
  if (waypoint_z.empty() || waypoints.empty()) return 0.0;
  if (waypoint_z.size() != waypoints.size()) {
    throw std::invalid_argument("Route: waypoint_z must have one height per waypoint");
  }
  if (s <= 0) return waypoint_z.front();
  for (std::size_t i = 1; i < waypoints.size(); ++i) {
    const double seg = (waypoints[i] - waypoints[i - 1]).norm();
    if (s <= seg && seg > 0) return waypoint_z[i - 1] + (waypoint_z[i] - waypoint_z[i - 1]) * (s / seg);
    s -= seg;
  }
  return waypoint_z.back();
}

Walk WalkRoute(const Route& route, const WalkerOptions& o, TimeS t_start, Random& rng) {
  Walk walk;
  const double total = route.Length();
  std::vector<Route::Stop> stops = route.stops;
  std::sort(stops.begin(), stops.end(),
            [](const auto& a, const auto& b) { return a.at_distance_m < b.at_distance_m; });
  std::size_t next_stop = 0;

  // Piecewise-linear (time, distance) knots; truth is sampled from them afterwards.
  std::vector<std::pair<TimeS, double>> knots{{t_start, 0.0}};
  double s = 0, t = t_start;
  while (s < total - 1e-9) {
    if (next_stop < stops.size() && stops[next_stop].at_distance_m <= s + 1e-9) {
      walk.stops.push_back({t, t + stops[next_stop].duration_s});
      t += stops[next_stop].duration_s;
      knots.emplace_back(t, s);
      ++next_stop;
      continue;
    }
    double len = o.step_length_m * std::max(0.5, 1.0 + o.step_length_jitter * rng.Normal());
    // Stairs ahead (a rise of more than 0.2 m per metre): one tread per step, slower.
    const bool stairs = std::abs(route.ZAt(s + 0.05) - route.ZAt(s)) > 0.2 * 0.05;
    if (stairs) len = o.stairs_step_length_m;
    if (next_stop < stops.size()) len = std::min(len, stops[next_stop].at_distance_m - s);
    len = std::min(len, total - s);
    if (len <= 1e-9) len = std::min(o.step_length_m, total - s);
    const double dt = len / (stairs ? o.stairs_speed_mps : o.speed_mps);
    walk.steps.push_back({t, t + dt, route.PointAt(s), route.PointAt(s + len), route.ZAt(s),
                          route.ZAt(s + len)});
    s += len;
    t += dt;
    knots.emplace_back(t, s);
  }

  const double period = 1.0 / o.truth_rate_hz;
  std::size_t k = 0;
  double last_heading = 0;
  if (route.waypoints.size() >= 2) {
    const Vec2 d = route.waypoints[1] - route.waypoints[0];
    last_heading = std::atan2(d.y(), d.x());
  }
  const auto n = static_cast<long>(std::floor((t - t_start) / period));
  for (long i = 0; i <= n; ++i) {
    const TimeS ti = t_start + i * period;
    while (k + 1 < knots.size() && knots[k + 1].first < ti) ++k;
    double si = knots[k].second;
    if (k + 1 < knots.size() && knots[k + 1].first > knots[k].first) {
      const double a = (ti - knots[k].first) / (knots[k + 1].first - knots[k].first);
      si += std::clamp(a, 0.0, 1.0) * (knots[k + 1].second - knots[k].second);
    }
    const Vec2 p = route.PointAt(si);
    const Vec2 ahead = route.PointAt(si + 0.3) - p;
    if (ahead.norm() > 1e-6) last_heading = std::atan2(ahead.y(), ahead.x());
    walk.truth.push_back({ti, p, last_heading, route.ZAt(si)});
  }
  return walk;
}

Route FollowWall(const FloorPlan& plan, const Vec2& start, double heading_rad, Hand hand,
                 const WallFollowOptions& o) {
  const SegmentIndex& walls = plan.index();
  const double side_sign = hand == Hand::kLeft ? 1.0 : -1.0;  // + = left of heading
  const double d = o.wall_offset_m;
  const double probe = 4.0 * d;
  Route route;
  route.waypoints.push_back(start);
  Vec2 p = start;
  double psi = heading_rad;
  double walked = 0;
  auto dir = [](double a) { return Vec2(std::cos(a), std::sin(a)); };
  auto range = [&](double a, double max) { return walls.RayCast(p, dir(a), max).value_or(max); };
  int corner_turns = 0;  // turns since the last move
  const long max_iterations = 64 * static_cast<long>(o.max_length_m / o.probe_step_m) + 1024;
  for (long iteration = 0; walked < o.max_length_m && iteration < max_iterations; ++iteration) {
    const double front = range(psi, probe);
    const double side = range(psi + side_sign * std::numbers::pi / 2, probe);
    if (front < d + o.probe_step_m) {
      // Wall ahead: turn away from the followed hand until the way is clear.
      psi -= side_sign * std::numbers::pi / 8;
      if (++corner_turns > 16) break;  // boxed in
      continue;
    }
    double steer;
    if (side >= probe - 1e-9) {
      // Lost the wall (open corner or doorway): turn towards the hand side gradually.
      steer = side_sign * std::numbers::pi / 8;
    } else {
      // Steer to hold the wall at distance d (proportional, limited rate).
      steer = side_sign * std::clamp(0.8 * (side - d), -0.3, 0.3);
    }
    Vec2 next = p + dir(psi + steer) * o.probe_step_m;
    if (!walls.Intersects({p, next})) {
      psi += steer;
    } else {
      // The steered step touches a wall (a door frame, a table corner): go straight on if
      // that is free, else turn away from the hand.
      next = p + dir(psi) * o.probe_step_m;
      if (walls.Intersects({p, next})) {
        psi -= side_sign * std::numbers::pi / 8;
        if (++corner_turns > 16) break;  // boxed in (or standing on a wall)
        continue;
      }
    }
    p = next;
    corner_turns = 0;
    walked += o.probe_step_m;
    route.waypoints.push_back(p);
  }
  return route;
}

}  // namespace trailmark

// SPDX-License-Identifier: MIT
#pragma once
/// A pedestrian walking a route: steps at a realistic length and cadence, stops, and the true
/// trajectory sampled at a fixed rate. Wall following builds routes from a floor plan.

#include <string>
#include <vector>

#include "trailmark/core/random.h"
#include "trailmark/core/types.h"
#include "trailmark/geometry/floor_plan.h"

namespace trailmark {

struct Route {
  std::vector<Vec2> waypoints;  ///< polyline walked in order
  struct Stop {
    double at_distance_m = 0;   ///< distance along the route where the walker stops
    double duration_s = 0;
  };
  std::vector<Stop> stops;
  /// The height (m, z of the feet) at each waypoint, linear between them; empty: 0 everywhere.
  /// A stretch rising more than 0.2 m per metre is walked as stairs (WalkerOptions).
  std::vector<double> waypoint_z;
  double Length() const;
  /// Point at distance s along the polyline (clamped to its ends).
  Vec2 PointAt(double distance_m) const;
  /// Height at distance s along the polyline (clamped to its ends).
  double ZAt(double distance_m) const;
};

/// One true step: foot displacement between two consecutive stances.
struct TrueStep {
  TimeS t0 = 0, t1 = 0;
  Vec2 from = Vec2::Zero(), to = Vec2::Zero();
  double z0 = 0, z1 = 0;  ///< height of the feet before and after
};

struct WalkerOptions {
  /// Walking speed and step length of an adult at normal pace: 1.2-1.4 m/s and 0.65-0.75 m
  /// (Bohannon 1997, "Comfortable and maximum walking speed of adults aged 20-79 years").
  double speed_mps = 1.2;
  double step_length_m = 0.7;
  double step_length_jitter = 0.05;  ///< relative per-step variation (1 sigma)
  double truth_rate_hz = 10.0;
  /// On stairs: one riser per step, a tread of 0.28-0.30 m (building codes), climbed at about
  /// 1.5 steps per second (Fujiyama & Tyler 2010: 0.4-0.5 m/s horizontally).
  double stairs_step_length_m = 0.3;
  double stairs_speed_mps = 0.45;
};

struct Walk {
  std::vector<TrueStep> steps;
  struct Sample {
    TimeS t;
    Vec2 position;
    double heading_rad;
    double z = 0;  ///< height of the feet
  };
  std::vector<Sample> truth;  ///< at truth_rate_hz, including stops
  struct StopInterval {
    TimeS t_stop, t_go;
  };
  std::vector<StopInterval> stops;
};

/// Walks `route` from time t_start. Deterministic given `rng`.
Walk WalkRoute(const Route& route, const WalkerOptions& options, TimeS t_start, Random& rng);

enum class Hand { kLeft, kRight };

struct WallFollowOptions {
  double wall_offset_m = 0.6;   ///< distance kept to the followed wall (arm's length)
  double probe_step_m = 0.25;   ///< integration step of the follower
  double max_length_m = 500.0;  ///< route length limit
};

/// Left- or right-hand directional search: starting at `start` with `heading_rad`, keep the
/// wall on the given hand, turning away at walls ahead and around open corners, as firefighters
/// are trained to do. Returns the followed route (waypoints every probe step, simplified).
Route FollowWall(const FloorPlan& plan, const Vec2& start, double heading_rad, Hand hand,
                 const WallFollowOptions& options);

}  // namespace trailmark

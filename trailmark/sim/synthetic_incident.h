// SPDX-License-Identifier: MIT
#pragma once
/// A large synthetic incident for benchmarks (issue 8, item 7): many firefighters, each working
/// its own sector of a big building for hours, dropping breadcrumbs and hearing the nearest ones.
/// Measurements are PDR steps, RSSI packets (log-distance + shadowing) and drop events, in time
/// order. Not a realistic walk (random waypoints), but the sizes and rates of a real incident.
/// No I/O.

#include <cstdint>
#include <string>
#include <vector>

#include "trailmark/core/mission.h"
#include "trailmark/core/online_estimator.h"

namespace trailmark {

struct IncidentOptions {
  int agents = 20;
  int crumbs = 500;
  double duration_s = 4 * 3600.0;
  std::size_t measurements = 1'000'000;  ///< steps + RSSI packets, approximately
  double sector_m = 30.0;                ///< each agent works in a square sector of this size
  double step_period_s = 0.6;
  double step_length_m = 0.7;
  double crumb_drop_period_s = 120.0;    ///< crumbs are dropped this often until all are out
  double hearing_range_m = 12.0;
  int heard_per_packet = 2;              ///< nearest crumbs heard per packet burst
  double alpha_dbm = -40.0, path_loss_exponent = 2.3, sigma_db = 4.0;
};

/// One time-ordered input of the estimator.
struct IncidentEvent {
  enum class Kind { kStep, kRssi, kDrop } kind = Kind::kStep;
  Step step;
  RssiPacket rssi;
  MissionEvent drop;
  TimeS t() const { return kind == Kind::kStep ? step.t1 : kind == Kind::kRssi ? rssi.t : drop.t; }
};

struct SyntheticIncident {
  MissionInfo info;  ///< a base plus the agents, with starts
  std::vector<IncidentEvent> events;
  std::size_t steps = 0, packets = 0, drops = 0;
};

SyntheticIncident MakeSyntheticIncident(const IncidentOptions& options, std::uint64_t seed);

/// A large landmark incident for benchmarks (issue 24: "a 4-hour, 20-firefighter landmark
/// incident in the benchmark"): the same sectors and random-waypoint walks, under radio landmarks
/// on the ceiling on a square grid over the whole site; every landmark within hearing range
/// answers every firefighter's phone once per answer period (log-distance + shadowing, packets
/// below the receiver's sensitivity lost). A share of the landmarks is declared without a
/// position (placed by the estimator). Steps carry a white heading error per step and a heading
/// error that walks (a gyro's drift: ~0.2 rad in 30 minutes). Truth per step.
struct LandmarkIncidentOptions {
  int agents = 20;
  double duration_s = 4 * 3600.0;
  double sector_m = 30.0;  ///< each firefighter searches a square sector of this size
  double step_period_s = 0.6;
  double step_length_m = 0.7;
  double step_heading_sigma_rad = 0.02;  ///< white, per step
  double heading_walk_rad = 0.004;       ///< the steps' heading error walks this much per step
  double landmark_spacing_m = 12.0;      ///< the ceiling grid
  double landmark_height_m = 2.5;
  double unknown_share = 0.25;  ///< landmarks declared without a position, every k-th
  double surveyed_sigma_m = 0.2;
  double answer_period_s = 1.0;
  double hearing_range_m = 20.0;
  double alpha_dbm = -60.0, path_loss_exponent = 2.0, sigma_db = 4.0;  ///< BLE-like
  double sensitivity_dbm = -92.0;
};

struct LandmarkIncident {
  MissionInfo info;                ///< the agents (with starts) and the landmarks, radio given
  std::vector<MissionRow> rows;    ///< steps and packets in time order
  std::vector<TruthSample> truth;  ///< each firefighter at each step's end
  std::vector<TruthSample> landmark_truth;  ///< every landmark where it is (t 0)
  std::size_t steps = 0, packets = 0, landmarks = 0, unknown = 0;
};

LandmarkIncident MakeLandmarkIncident(const LandmarkIncidentOptions& options, std::uint64_t seed);

}  // namespace trailmark

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

}  // namespace trailmark

#pragma once
/// Simulated missions with truth. Deterministic per seed. No I/O: io/mission_writer writes them.

#include <cstdint>
#include <string>
#include <vector>

#include "trailmark/core/mission.h"
#include "trailmark/geometry/floor_plan.h"
#include "trailmark/sim/pdr_error_model.h"
#include "trailmark/sim/rssi_channel.h"
#include "trailmark/sim/walker.h"

namespace trailmark {

struct SimulatedMission {
  MissionData data;
  FloorPlan plan;
};

/// Breadcrumb dispenser (breadcrumb paper sec. III; Liu et al. MobiSys'10): drop a crumb when
/// the best smoothed link from the wearer to any node of the chain falls below a threshold.
struct DispenserOptions {
  double drop_threshold_dbm = -72.0;  ///< smoothed RSSI below which a crumb is dropped
  double smoothing = 0.3;             ///< EMA weight of a new packet
  double min_spacing_m = 4.0;         ///< no two drops closer than this along the walk
  double below_for_s = 1.5;           ///< the link must stay weak this long (fading hysteresis)
  int capacity = 12;                  ///< crumbs carried
  double drop_scatter_m = 0.2;        ///< where the crumb lands around the foot (1 sigma)
};

struct OfficeLoopOptions {
  int laps = 4;                       ///< breadcrumb paper sec. V-A: 100 m loop walked 4 times
  double corridor_width_m = 2.0;
  double loop_width_m = 30.0;         ///< 2 x (30 + 20) = 100 m loop
  double loop_height_m = 20.0;
  double packet_period_s = 0.5;       ///< agent <-> chain beacons
  double crumb_packet_period_s = 2.0; ///< crumb <-> crumb and base <-> crumb
  WalkerOptions walker;
  PdrErrorOptions pdr;
  RssiChannelOptions radio;
  DispenserOptions dispenser;
};

/// The office floor of the breadcrumb paper's experiment (sec. V-A, Fig. 9a): a rectangular
/// corridor loop with offices on both sides; the base station at the upper right corner.
FloorPlan BuildOfficeFloor(const OfficeLoopOptions& options);

/// One firefighter walks the loop anti-clockwise `laps` times from the base; a dispenser drops
/// crumbs; RSSI between all nodes in range; PDR steps with errors; truth at 10 Hz.
SimulatedMission SimulateOfficeLoop(const OfficeLoopOptions& options, std::uint64_t seed);

struct ScenarioInfo {
  std::string name;
  std::string description;
};
std::vector<ScenarioInfo> Scenarios();
/// Throws std::invalid_argument for an unknown name.
SimulatedMission SimulateScenario(const std::string& name, std::uint64_t seed);

}  // namespace trailmark

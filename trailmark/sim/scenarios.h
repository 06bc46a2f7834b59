// SPDX-License-Identifier: MIT
#pragma once
/// Simulated missions with truth. Deterministic per seed. No I/O: io/mission_writer writes them.

#include <cstdint>
#include <string>
#include <vector>

#include "trailmark/core/mission.h"
#include "trailmark/geometry/floor_plan.h"
#include "trailmark/sim/mission_sim.h"
#include "trailmark/sim/multi_floor.h"
#include "trailmark/sim/pdr_error_model.h"
#include "trailmark/sim/rssi_channel.h"
#include "trailmark/sim/walker.h"

namespace trailmark {

struct OfficeLoopOptions {
  int laps = 4;                       ///< breadcrumb paper sec. V-A: 100 m loop walked 4 times
  double corridor_width_m = 2.0;
  double loop_width_m = 30.0;         ///< 2 x (30 + 20) = 100 m loop
  double loop_height_m = 20.0;
  MissionSimOptions sim;              ///< walker, PDR errors, radio, dispenser, kicks
};

/// The office floor of the breadcrumb paper's experiment (sec. V-A, Fig. 9a): a rectangular
/// corridor loop with offices on both sides; the base station at the upper right corner.
FloorPlan BuildOfficeFloor(const OfficeLoopOptions& options);

/// One firefighter walks the loop anti-clockwise `laps` times from the base; a dispenser drops
/// crumbs; RSSI between all nodes in range; PDR steps with errors; truth at 10 Hz.
SimulatedMission SimulateOfficeLoop(const OfficeLoopOptions& options, std::uint64_t seed);

/// The two-firefighter experiment of the breadcrumb paper (sec. V-B, Fig. 10): the 3rd floor
/// of a fire-training building, a corridor with rooms on both sides, the base at the right
/// entrance; ff1 searches the north rooms, ff2 the south rooms, slowly (smoke); a fire in one
/// room attenuates the links through it (Fig. 8); a crumb may be kicked.
struct TrainingBuildingOptions {
  int rooms_per_side = 6;
  double room_width_m = 6.0;
  double room_depth_m = 7.0;
  double corridor_width_m = 2.0;
  double second_start_s = 20.0;
  double room_pause_s = 15.0;
  MissionSimOptions sim;
  TrainingBuildingOptions();
};
FloorPlan BuildTrainingFloor(const TrainingBuildingOptions& options);
SimulatedMission SimulateTrainingBuilding(const TrainingBuildingOptions& options,
                                          std::uint64_t seed);

struct ScenarioInfo {
  std::string name;
  std::string description;
};
std::vector<ScenarioInfo> Scenarios();
/// Throws std::invalid_argument for an unknown name.
SimulatedMission SimulateScenario(const std::string& name, std::uint64_t seed);
/// `all-sources-4h` with another crew or length (issue 27's load; `simulate all-sources-4h
/// --firefighters N --minutes M`).
SimulatedMission SimulateAllSourcesLoad(std::uint64_t seed, int firefighters = 20,
                                        double duration_s = 4 * 3600.0);
/// The building options of that load: the all-sources building, a crew on tours until
/// duration_s, phone steps only (no foot IMU).
MultiFloorOptions AllSourcesLoadOptions(int firefighters, double duration_s);

}  // namespace trailmark

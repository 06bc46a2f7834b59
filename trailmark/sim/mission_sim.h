// SPDX-License-Identifier: MIT
#pragma once
/// The mission simulator engine: agents walking routes on a floor plan with PDR errors, each
/// with a breadcrumb dispenser, one shared network of dropped crumbs and a base; RSSI between
/// every pair of nodes in range; fire/water zones; crumbs kicked when walked past. Truth at the
/// walkers' rate; a kicked crumb gets a second truth row. Deterministic per seed. No I/O.

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
  /// The true walk of every agent (for sensor simulations made afterwards, e.g. a foot IMU).
  std::vector<std::pair<std::string, Walk>> walks;
  /// A multi-floor building: every level's plan (`plan` is then the ground floor's); empty for
  /// a single floor.
  std::vector<std::pair<int, FloorPlan>> levels;
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

/// Crumbs kicked by a passing firefighter (sec. V-C: "usually within 1 to 2 meters").
struct KickOptions {
  double probability = 0.0;   ///< per pass within pass_distance_m of a crumb
  double pass_distance_m = 0.5;
  double min_m = 1.0, max_m = 2.0;
  double antenna_gain_sigma_db = 4.0;  ///< the crumb lands at another antenna angle
  double min_age_s = 20.0;    ///< not right after it was dropped
  int max_kicks = 3;
};

struct AgentPlan {
  std::string id;
  Route route;
  TimeS start_s = 0;
  double start_heading_rad = 0;  ///< written to mission.json (known at the entrance)
};

struct MissionSimOptions {
  double packet_period_s = 0.5;        ///< agent <-> every node
  double crumb_packet_period_s = 2.0;  ///< crumb <-> crumb and base <-> crumb
  WalkerOptions walker;
  PdrErrorOptions pdr;
  RssiChannelOptions radio;
  DispenserOptions dispenser;
  KickOptions kick;
  std::vector<AttenuationZone> zones;
};

/// The radio of a mission whose walks are simulated (`sim.walks`, `sim.plan`): a base at
/// `base_n`, every agent's dispenser dropping crumbs ("drop" events, the crumbs' truth), RSSI
/// between every pair of nodes in range, crumbs kicked. `floors` (a multi-floor building,
/// `sim.levels` its plans): a node's level is its z's (a crumb's its dropper's at the drop),
/// walls count on the receiver's level and every floor between the ends costs
/// `options.radio.floor_loss_db`; the crumbs' truth then has z and level. `agent_truth`: also
/// the agents' truth at every tick (SimulateAgents). The random streams: the channel's, the
/// drops' and the kicks'.
void SimulateCrumbNetwork(SimulatedMission& sim, const Vec3& base_n,
                          const std::vector<FloorLevel>& floors, const MissionSimOptions& options,
                          bool agent_truth, Random radio_rng, Random& drop_rng, Random& kick_rng);

/// Simulates the agents on `plan` from a base at `base_n` (a node "base" with known position).
SimulatedMission SimulateAgents(FloorPlan plan, const Vec2& base_n,
                                const std::vector<AgentPlan>& agents,
                                const MissionSimOptions& options, std::uint64_t seed);

}  // namespace trailmark

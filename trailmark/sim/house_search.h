// SPDX-License-Identifier: MIT
#pragma once
/// The map-aided search paper's experiments (sec. V-A) as simulations: two houses and a
/// firefighter doing directional (left- or right-hand) searches — following the walls at
/// arm's length, going round furniture that is not on the map, sweeping, pausing at doors —
/// slowly, with odometry from a foot-mounted INS whose heading drifts. No I/O.
///
/// House 1 (data set 1): a 12.5 x 10 m house (125 m^2, the navigation area); the firefighter
/// searches its west part (7 x 10 m = 70 m^2, the paper's VICON area: hall, living room,
/// kitchen); the door to the east part is treated as a wall, on the map too (as in the paper).
/// House 2 (data set 2): 23 x 11 m (253 m^2), a corridor with seven rooms; left-hand searches
/// of ~10 minutes through the whole house.

#include <cstdint>
#include <optional>

#include "trailmark/sim/mission_sim.h"
#include "trailmark/sim/pdr_error_model.h"
#include "trailmark/sim/walker.h"

namespace trailmark {

struct HouseSearchOptions {
  int house = 1;  ///< 1 or 2
  Hand hand = Hand::kLeft;
  double duration_s = 270;  ///< data set 1: 73 min over 16 searches; data set 2: ~10 min each
  double speed_mps = 0.45;  ///< primary search: slow (sec. II)
  double step_length_m = 0.5;
  double wall_offset_m = 0.55;      ///< arm's length along the wall
  double sweep_amplitude_m = 0.15;  ///< side-to-side while sweeping with the free foot/hand
  double pause_every_m = 12;        ///< kneel/check at doors and corners every so often
  double pause_s = 4;
  bool map_error = false;  ///< the map shows a door elsewhere than it is (sec. V-E)
  bool furniture = true;   ///< furniture in the world (never on the map)
  PdrErrorOptions pdr;
  HouseSearchOptions();
};

/// The house as the world is for a search under way (`with_furniture`; the entry door shut
/// behind the team) or as the map shows it.
FloorPlan BuildHouse(int house, bool with_furniture, bool map_error = false, bool furniture = true);

/// Where the firefighters enter, and the direction they face.
Vec2 HouseEntry(int house);
double HouseEntryHeading(int house);

/// One search: the mission's floor plan is the map (no furniture; with the moved door when
/// map_error); steps from the odometry; truth at 10 Hz.
SimulatedMission SimulateHouseSearch(const HouseSearchOptions& options, std::uint64_t seed);

/// The same directional search on any floor plan (e.g. one floor of a converted building):
/// the firefighter enters at `entry`, facing `entry_heading_rad` or, when not given, away from
/// the plan's nearest door within 1.5 m (that door is shut behind the team, as in the houses);
/// the plan is both the world and the map (no furniture). Throws std::invalid_argument for a
/// plan without walls, an entry outside its bounds or within 0.2 m of a wall, no heading and no
/// door near the entry, a duration outside (0 s, 24 h], or an entry no search can leave.
/// `options.house`, `map_error` and `furniture` are not used.
SimulatedMission SimulateSearchOnPlan(const FloorPlan& plan, const Vec2& entry,
                                      std::optional<double> entry_heading_rad,
                                      const HouseSearchOptions& options, std::uint64_t seed);

}  // namespace trailmark

// SPDX-License-Identifier: MIT
#pragma once
/// The ultrasound-beacon experiment (ultrasound-beacons paper, sec. 4 and 7): a 15 x 9 m lab
/// whose beacons are placed by the paper's deployment rules, a foot-mounted ultrasound node
/// ranging the beacons while walking, and PDR steps from an Xsens-like foot IMU (heading
/// dominated by magnetic disturbance). No I/O.

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "trailmark/sim/mission_sim.h"
#include "trailmark/sim/pdr_error_model.h"
#include "trailmark/sim/walker.h"

namespace trailmark {

/// Ultrasound between a moving foot node and a beacon (sec. 3.B): moving-node errors are much
/// larger than the 10 cm / 30 deg of static setups (Hazas et al. 2005).
struct UltrasoundOptions {
  double max_range_m = 5.0;         ///< Relate hardware (sec. 4)
  double pulse_period_s = 1.0 / 3;  ///< "approximately three times per second" (sec. 6)
  double period_jitter_s = 0.03;
  double range_sigma_m = 0.30;  ///< line of sight, moving foot
  /// Multipath / partly blocked: the first detected pulse is a reflection, so the range is long
  /// by U(min, max) (sec. 3.B). With these values the 90th percentile of |range error| is
  /// ~0.9 m (paper: below 1 m).
  double nlos_probability = 0.10;
  double nlos_min_m = 0.2, nlos_max_m = 2.5;
  /// > 0: NLOS excess min + Exp(mean), capped at max (a long tail) instead of U(min, max).
  double nlos_tail_mean_m = 0;
  /// Bearing (angle of arrival from the spread of peak values): sigma such that the 90th
  /// percentile of |error| is 60 deg (sec. 3.B), plus uniform outliers.
  double bearing_sigma_rad = 0.57;
  double bearing_outlier_probability = 0.05;
  /// Detection probability of a pulse by a beacon in line of sight: `detection_near` at the
  /// node, falling linearly to `detection_at_max_range`. Chosen so that the tracker receives
  /// ~5 measurements per second in the lab, the rate the paper reports (sec. 7.C: "ultrasound
  /// measurements are sampled only every 5 Hz approximately").
  double detection_near = 0.42;
  double detection_at_max_range = 0.10;
  /// Around a corner (no line of sight) a reflected pulse is still heard with this probability
  /// (range long as above); otherwise nothing.
  double corner_reflection_probability = 0.10;
  /// Beacon <-> beacon ranging (static nodes): after every drop and then periodically.
  double static_range_sigma_m = 0.10;
  double static_outlier_probability = 0.03;
  double beacon_ranging_period_s = 30.0;
  int beacon_ranging_burst = 3;
};

/// Deployment rules (sec. 4): (i) a beacon at the entry; (ii) one where the last deployed
/// beacon's signal drops below the receive threshold (modelled as distance beyond
/// `receive_threshold_m` or line of sight lost); (iii) one at every major turn. Ids in
/// deployment order ("b01", "b02", ...).
struct DeploymentOptions {
  double receive_threshold_m = 2.0;      ///< ~21 beacons in the lab, as the paper's
  double major_turn_rad = 0.785;         ///< 45 deg
  double skip_if_beacon_within_m = 1.5;  ///< a spot already marked (walking a trail again)
  double drop_scatter_m = 0.10;
};

/// The six walking traces of Fig. 3 (our routes through the lab, 3 to 8 minutes).
enum class LabTrace { kA, kB, kC, kD, kE, kF };
const char* LabTraceName(LabTrace trace);
double LabTraceMinutes(LabTrace trace);

struct BeaconLabOptions {
  LabTrace trace = LabTrace::kA;
  /// Surveyed: the beacons are pre-deployed and surveyed (landmarks with positions, as in the
  /// paper's Table 1); the mission is the trace only. Deployed: the firefighter enters, drops
  /// the beacons by the rules (crumbs, "drop" events), walks the trace, then retreats to the
  /// exit by the smallest-id rule.
  bool surveyed = true;
  UltrasoundOptions ultrasound;
  DeploymentOptions deployment;
  WalkerOptions walker;
  PdrErrorOptions pdr;
  double initial_heading_error_sigma_rad = 0.14;  ///< ~8 deg: magnetometer-based heading
  BeaconLabOptions();
};

/// The lab: 15 x 9 m, two blocks of benches leaving a ring and a cross aisle; entry on the west.
FloorPlan BuildBeaconLab();

/// Beacon positions placed by the deployment rules along the lab's deployment walk.
struct BeaconLayout {
  std::vector<Vec2> beacons;       ///< in deployment order
  std::vector<TimeS> drop_time_s;  ///< on the deployment walk
};

/// True when the ultrasound of a node at `a` can reach `b` directly (range and line of sight).
bool UltrasoundLineOfSight(const FloorPlan& plan, const Vec2& a, const Vec2& b, double range_m);

/// Way back out (sec. 4): from `position`, the beacons visited by always walking to the smallest
/// id heard (line of sight within range), until the first beacon. Empty when none is heard.
std::vector<int> RetreatTargets(const FloorPlan& plan, const std::vector<Vec2>& beacons,
                                const Vec2& position, double range_m);

/// The building blocks of a beacon trail, for other scenarios (the all-sources incident):
/// beacon j's id ("b01" for j = 0);
std::string BeaconId(int j);
/// the three deployment rules applied along `walk` (the walk of `route`) in `plan`;
BeaconLayout DeployBeacons(const FloorPlan& plan, const Route& route, const Walk& walk,
                           const DeploymentOptions& options, double range_m, Random& rng);
/// the pulses of `agent`'s foot node received by the beacons placed by then (`beacon_since`):
/// a range and a bearing (from the beacon to the foot) each, appended to `m`; `audible`, when
/// given, says whether the foot can be heard at time t at all (on the beacons' floor);
void SimulateFootUltrasound(const FloorPlan& plan, const Walk& walk, const std::string& agent,
                            const std::vector<Vec2>& beacons,
                            const std::vector<TimeS>& beacon_since, const UltrasoundOptions& us,
                            Random& rng, MissionData& m,
                            const std::function<bool(TimeS)>& audible = {});
/// beacon <-> beacon ranging at time t: a burst for each pair in line of sight that `linked`
/// allows (only the pairs with beacon `only` when >= 0).
void SimulateBeaconRanging(const FloorPlan& plan, const std::vector<Vec2>& beacons,
                           const std::vector<TimeS>& beacon_since, const UltrasoundOptions& us,
                           TimeS t, int only, const std::function<bool(int, int)>& linked,
                           Random& rng, MissionData& m);

SimulatedMission SimulateBeaconLab(const BeaconLabOptions& options, std::uint64_t seed);

/// A beacon trail laid out by someone else (issue 22): a U- or L-shaped corridor, beacons
/// dropped by the deployment rules, ranges only between trail neighbours (each beacon with the
/// `neighbour_links` deployed before it, line of sight allowed), `anchors` of them surveyed
/// (landmarks with a position, none at the entry), NLOS ranges long with a long tail, bearings
/// with uniform outliers. The firefighter lays the trail, walks back to the entry and out again,
/// then retreats by the smallest-id rule. Shape and sizes are drawn from the seed.
struct ShapedTrailOptions {
  enum class Shape { kRandom, kU, kL };
  Shape shape = Shape::kRandom;  ///< random: U two times in three
  double corridor_width_m = 2.4;
  double min_leg_m = 14, max_leg_m = 22;         ///< the long legs
  double min_across_m = 6.5, max_across_m = 10;  ///< the U's legs apart / the L's short leg
  int neighbour_links = 2;
  int anchors = 3;
  UltrasoundOptions ultrasound;
  DeploymentOptions deployment;
  WalkerOptions walker;
  PdrErrorOptions pdr;
  double initial_heading_error_sigma_rad = 0.14;
  ShapedTrailOptions();
};

SimulatedMission SimulateShapedTrail(const ShapedTrailOptions& options, std::uint64_t seed);

}  // namespace trailmark

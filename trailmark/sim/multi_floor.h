// SPDX-License-Identifier: MIT
#pragma once
/// A multi-storey building for the floors issue (issue 26): a basement, a ground floor and two
/// upper floors of an office block, a switchback stairwell joining them, and two firefighters
/// who walk in from the street — one searches the two upper floors, the other the basement and
/// the ground floor; the rooms' partitions differ between levels — with a phone-class PDR (steps
/// that do not measure height), a foot IMU that climbs the stairs, and a barometer each (noise,
/// device offset, weather drift, the building's overpressure from a ventilation fan, rare spikes),
/// and a breadcrumb dispenser each with a base in the street: RSSI through walls and floors (10-20
/// dB per floor). Storey heights, room visits, stops, the weather and the floors' loss are drawn
/// per seed. Optionally radio landmarks on every level and an ultrasound beacon exit trail on the
/// ground floor: the all-sources incident of the fusion issue (issue 27). No I/O.

#include <cstdint>
#include <utility>
#include <vector>

#include "trailmark/sim/beacon_lab.h"
#include "trailmark/sim/imu_sim.h"
#include "trailmark/sim/mission_sim.h"
#include "trailmark/sim/pdr_error_model.h"
#include "trailmark/sim/walker.h"

namespace trailmark {

/// A barometer as a phone or a boot sensor has it.
struct BaroSimOptions {
  double rate_hz = 5.0;
  /// White noise, hPa rms (Bosch BMP390: 0.02-0.03 hPa rms; phones' sensors of the 0.1 hPa
  /// relative-accuracy class).
  double noise_hpa = 0.04;
  double resolution_hpa = 0.01;       ///< the value as the sensor reports it
  double device_offset_hpa = 1.0;     ///< 1 sigma per device (absolute accuracy +-1 hPa)
  /// Weather: a drift rate per mission, 1 sigma (0.5 hPa/h: a front passing; storms 1-2).
  double weather_drift_hpa_per_h = 0.5;
  /// Positive-pressure ventilation: the fan raises the inside pressure by this much (20-50 Pa
  /// of a PPV fan), started at a random time; walking through the door crosses it.
  double ppv_overpressure_hpa = 0.3;
  /// ... over this rise time once the fan runs (s). A slow rise (several seconds) is a descent
  /// of stairs to a barometer and steps that do not measure height: see docs/floors.md.
  double ppv_rise_s = 1.0;
  double spike_probability = 0.002;   ///< per reading: a reading off by up to +-2 hPa
  double sea_level_hpa = 1013.25;
};

struct MultiFloorOptions {
  WalkerOptions walker;
  /// The breadcrumb radio (SimulateCrumbNetwork): each firefighter's dispenser, a base in the
  /// street; a floor between two nodes costs a loss drawn per building.
  bool radio = true;
  MissionSimOptions network;
  double floor_loss_min_db = 10.0, floor_loss_max_db = 20.0;
  /// Pre-installed radio landmarks (issue 26, item 4): this many on each level, surveyed, on
  /// the corridor's wall, each heard by the firefighters' phones through the same channel (a
  /// floor between costs the building's floor loss); 0: none (the scenario `multi-floor`;
  /// `multi-floor-landmarks` has 3).
  int landmarks_per_level = 0;
  double landmark_rate_hz = 1.0;      ///< packets per second from each landmark
  /// Above its level's floor. The format gives a node its level from z alone, a point less
  /// than 1 m below a floor belonging to it (spec 1.1): a ceiling at 2.6 m in a 3.3 m storey
  /// would put the landmark on the level above. 1.8 m stays on its level in any storey >= 2.8 m.
  double landmark_height_m = 1.8;
  double phone_height_m = 1.2;        ///< the receiving phone above the feet
  /// An ultrasound beacon exit trail (issue 27: the all-sources incident): ff1 drops beacons by
  /// the deployment rules of the ultrasound-beacons paper on the way in, from the entrance to
  /// the foot of the stairwell; both firefighters' foot nodes range them (range and bearing)
  /// whenever they walk the ground floor, the beacons range each other (line of sight, 5 m).
  bool beacon_trail = false;
  UltrasoundOptions ultrasound;
  DeploymentOptions deployment;
  PdrErrorOptions pdr;
  BaroSimOptions baro;
  ImuSimOptions imu;          ///< the foot IMU (100 Hz, industrial grade by default)
  bool foot_imu = true;
  /// Firefighters (ff1, ff2, ...), entering 20 s apart. Each searches two levels on a tour:
  /// ff1 levels 1 and 2, ff2 the ground floor and the basement, ff3 as ff1, and so on.
  int firefighters = 2;
  /// > 0: every firefighter goes on tour after tour (in, a search, out; then a rest of
  /// `rest_min_s`-`rest_max_s` in the street, a cylinder change, the next tour searching the
  /// other two levels) until this mission time, where the walk is cut (the 20-firefighter,
  /// 4-hour incident of issue 27's must-hold). 0: one tour each. A firefighter whose turn to
  /// enter comes less than a second before this time is not in the mission.
  double duration_s = 0.0;
  double rest_min_s = 60.0, rest_max_s = 300.0;
  MultiFloorOptions();
};

/// The building's plan on one level (the entrance door on level 0 only).
FloorPlan BuildMultiFloorLevel(int level);

/// Pressure (hPa) at height z (m above the sea-level reference) in the standard atmosphere:
/// p0 (1 - 2.25577e-5 z)^5.25588, the inverse of PressureAltitudeM.
double StandardPressureHpa(double z_m, double p0_hpa = 1013.25);

/// The mission with every level's plan in `levels` (`plan`: the ground floor).
SimulatedMission SimulateMultiFloor(const MultiFloorOptions& options, std::uint64_t seed);

}  // namespace trailmark

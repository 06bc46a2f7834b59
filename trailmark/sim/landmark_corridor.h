// SPDX-License-Identifier: MIT
#pragma once
/// The stop-and-go experiment of the radio-landmarks paper (sec. 6.1-6.2, Fig. 11): 5 landmarks
/// in a corridor (smoke-detector style, alternating walls), a handheld that stops at 7 positions
/// and averages the RSSI of every landmark it wakes. 868 MHz channel with the paper's corridor
/// path-loss exponent (n = 7.1), per-link log-normal shadowing that averaging cannot remove,
/// fast fading that it does, and a fraction of NLOS links (a person or door in the way). No I/O.

#include <cstdint>
#include <optional>
#include <vector>

#include "trailmark/core/types.h"

namespace trailmark {

struct LandmarkCorridorOptions {
  int landmarks = 5;
  int standing_positions = 7;
  double landmark_spacing_m = 5.0;
  double corridor_half_width_m = 1.0;   ///< landmarks on alternating walls
  double standing_zigzag_m = 0.5;       ///< stops alternate this far off the centre line
  double alpha_dbm = -30.0;             ///< at 1 m (868 MHz with the CC1190 front end)
  double path_loss_exponent = 7.1;      ///< the paper's corridor fit (sec. 6.1)
  double shadowing_sigma_db = 3.0;      ///< per link, constant while standing
  double fast_fading_sigma_db = 3.0;    ///< per packet
  int packets_per_stop = 10;            ///< averaged (sec. 5.2)
  double sensitivity_dbm = -115.0;
  double nlos_probability = 0.1;
  double nlos_loss_db = 8.0;
  double standing_sigma_m = 0.1;        ///< how well the IMU knows the stops (sec. 6.2)
  /// The landmarks' z in the mission: mounted at the handheld's height, so that the simulated
  /// channel (horizontal distance) is also the 3-D one (the format's agent z is at the feet).
  double landmark_height_m = 1.2;
};

struct LandmarkCorridor {
  std::vector<Vec2> landmarks, standing;        ///< truth
  std::vector<Vec2> standing_from_imu;          ///< truth + IMU error
  /// Averaged RSSI [stop][landmark]; empty when no packet was received.
  std::vector<std::vector<std::optional<double>>> rssi_dbm;
};

LandmarkCorridor SimulateLandmarkCorridor(const LandmarkCorridorOptions& options, std::uint64_t seed);

/// The same corridor as a mission (scenario "landmark-corridor"): the responder ("ff1") enters
/// at the corridor's start, walks to the 7 stops in turn (5 s each, 10 wake-ups per stop) and
/// back to the start, waking the landmarks every 3 s while walking (events "wake"; one answer
/// per landmark in range). Landmarks are declared without positions (to be estimated) except
/// the first, surveyed (position_sigma 0.2 m). Steps from the PDR error model; truth at 10 Hz.
struct SimulatedMission;
SimulatedMission SimulateLandmarkMission(const LandmarkCorridorOptions& options, std::uint64_t seed);

}  // namespace trailmark

// SPDX-License-Identifier: MIT
#pragma once
/// An office with pre-installed BLE radio landmarks on the ceiling, for the landmark trackers
/// (issue 24): the fire-training floor's rooms and corridor (scenarios.h), two firefighters
/// searching them with phone-class PDR (heading drift, scale), 16 ceiling landmarks (one per
/// room, four in the corridor), 10 of them surveyed, 6 unknown; mission.json has no radio model
/// and no stop/go events. The channel is BLE-like and not the trackers' model: walls cost
/// 3.5 dB each, shadowing is spatially correlated, every landmark and every phone has its own
/// offset, weak packets are censored (a wake-up receiver's threshold).

#include <cstdint>

#include "trailmark/sim/mission_sim.h"

namespace trailmark {

struct LandmarkOfficeOptions {
  int landmarks_surveyed = 10;          ///< of 16; which ones is drawn per seed
  double landmark_height_m = 2.7;       ///< ceiling
  double phone_height_m = 1.2;          ///< the phone above the feet
  double packet_period_s = 1.0;         ///< each landmark answers each phone once a second
  double surveyed_sigma_m = 0.1;        ///< stated and drawn (the survey's error)
  double landmark_offset_sigma_db = 3.0;  ///< per landmark (transmit power, mounting)
  double phone_offset_sigma_db = 5.0;     ///< per phone (about 10 dB between two phones)
  RssiChannelOptions radio = [] {
    RssiChannelOptions r;
    r.alpha_dbm = -62.0;               ///< BLE at 1 m
    r.path_loss_exponent = 2.0;
    r.shadowing_sigma_db = 6.0;
    r.fast_fading_sigma_db = 3.0;
    r.shadowing_corr_distance_m = 3.0;
    r.wall_loss_db = 3.5;
    r.body_loss_db = 0.0;              ///< the phone is held in front
    r.sensitivity_dbm = -92.0;         ///< censoring
    return r;
  }();
};

/// Scenario "landmark-office".
SimulatedMission SimulateLandmarkOffice(const LandmarkOfficeOptions& options, std::uint64_t seed);

}  // namespace trailmark

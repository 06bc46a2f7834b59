// SPDX-License-Identifier: MIT
#pragma once
/// Randomized scenario families (issue 21, item 1): a variant of a simulated mission that breaks
/// an assumption our own simulator makes and an estimator may silently rely on. A variant is
/// drawn from (family, K) alone and applied to the mission after every sensor is simulated, so a
/// mission is deterministic per (scenario seed, K). Everything the mission format allows is fair;
/// nothing is changed that the format forbids (every variant passes `trailmark validate`).
/// No I/O: the writing quirks (CSV comments, column order, extra columns, multi-vertex walls) are
/// carried in `MissionWriteStyle` and applied by io/mission_io's writer.

#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "trailmark/sim/mission_sim.h"

namespace trailmark {

/// A rigid motion of the navigation frame about the z axis: p' = R(angle) p + shift.
struct FrameMotion {
  double angle_rad = 0;
  Vec2 shift_m = Vec2::Zero();
  Vec2 Point(const Vec2& p) const;
  Vec3 Point(const Vec3& p) const;
  Vec3 Direction(const Vec3& d) const;
  Vec2 Back(const Vec2& p) const;  ///< the inverse motion
};

/// The same mission drawn in another frame: node positions, starts, start headings, steps,
/// bearings, truth, walks and the floor plan (every level's; foot-IMU samples are in the body frame: the start
/// heading carries the rotation). Per-axis step variances are not rotation-invariant; they
/// become isotropic with the same horizontal total.
SimulatedMission DrawnInFrame(SimulatedMission sim, const FrameMotion& f);

enum class VariationFamily {
  kFrame,   ///< rotation, origin, door convention, multi-vertex walls, the foot IMU's mounting
  kRadio,   ///< band, path-loss parameters, offsets, correlated shadowing, censoring, stated model
  kRanges,  ///< NLOS long-tailed ranges, neighbour-only link graphs
  kNodes,   ///< surveyed positions drawn with their stated sigma (one error shared by all uses)
  kPdr,     ///< heading offset and drift also while standing, zero-length steps, gyro bias
  kEvents,  ///< stop/go/wake events absent, or every event absent
  kStart,   ///< start heading not given, a start up to 10 m outside
  kCsv,     ///< comments, column order, extra columns
  /// hand-held phone steps: carrying-mode heading jumps, scale, missed/phantom steps (after the
  /// others: a family's number seeds its draws, so the older families keep their variants)
  kPhone,
  /// steps.csv replaced by a foot IMU's imu.csv (the pipelines run the ZUPT INS): grade, rate
  /// and a small mounting turn drawn. Not part of `all` (its variants keep their steps).
  kImu,
  kAll,  ///< every family at once (but imu)
};
std::vector<std::pair<VariationFamily, std::string>> VariationFamilies();
/// Throws std::invalid_argument naming the known families.
VariationFamily ParseVariationFamily(const std::string& name);
std::string ToString(VariationFamily family);

enum class RadioBand { k868MHz, kBle2G4, kUwb };
enum class StatedRadio { kTrue, kNominal, kAbsent };
enum class EventsKept { kAll, kDropsOnly, kNone };

/// One drawn variant. Defaults change nothing.
struct Variation {
  VariationFamily family = VariationFamily::kAll;
  std::uint64_t k = 0;

  // frame
  FrameMotion frame;
  bool doors_across_gaps = false;  ///< walls drawn with gaps, doors across them (spec 1.1)
  /// The foot IMU mounted another way (imu.csv is in "the body frame", axes unstated): turned
  /// about its vertical by this, and upside down (z down, an x-forward NED body frame) or not.
  double imu_mount_yaw_rad = 0;
  bool imu_z_down = false;

  // radio (applied to rssi.csv; the simulator's own model is the reference it is moved from)
  bool radio = false;
  RadioBand band = RadioBand::kBle2G4;
  double alpha_dbm = -40.0, path_loss_exponent = 2.3, shadowing_sigma_db = 4.0;
  double node_offset_max_db = 0;   ///< per node: uniform in +-max, added on its rx and tx side
  double correlated_shadowing_db = 0;  ///< spatially consistent extra shadowing, 1 sigma
  double shadowing_length_m = 5.0;     ///< its correlation length
  std::optional<double> censor_below_dbm;  ///< packets weaker than this are not received
  StatedRadio stated_radio = StatedRadio::kTrue;

  // ranges
  double nlos_fraction = 0;     ///< share of ultrasound/uwb ranges with a positive NLOS excess
  double nlos_mean_m = 0;       ///< mean of the exponential excess
  bool neighbour_only_links = false;  ///< crumb-crumb ranges only between drop-order neighbours
  /// Every ultrasound range x this (its NLOS excess too): the air's speed of sound against the
  /// one the devices assume — a room at 0-60 deg C for devices calibrated at 20 deg C.
  double ultrasound_range_scale = 1.0;

  // nodes
  bool survey_error = false;  ///< positions with a stated sigma are moved by a draw of it

  // pdr
  double heading_offset_rad = 0;       ///< added to every step's direction
  double heading_drift_rad_per_s = 0;  ///< accrues with time, also while standing
  bool zero_length_steps = false;      ///< zero steps every 0.5 s while standing (> 1 s gaps)
  double gyro_bias_z_rad_per_s = 0;    ///< added to the foot IMU's z gyro

  // phone (steps.csv replaced by what a hand-held phone's PDR would report of the same walk)
  bool phone = false;
  double phone_scale = 1.0;              ///< step-length scale of the phone's model (shared)
  double phone_first_offset_rad = 0;     ///< heading offset of the first carrying mode
  double phone_mode_period_s = 60.0;     ///< mean time between carrying-mode changes

  // imu (only as its own family)
  bool foot_imu = false;
  std::string imu_grade = "industrial";  ///< ImuGrade::ByName
  double imu_rate_hz = 100.0;
  double imu_turn_rad = 0;  ///< the IMU turned about its vertical on the foot (toe-out, strap)
  double imu_landing_anticipation = 0;  ///< the gait (ImuSimOptions::landing_anticipation)

  // events, start
  EventsKept events = EventsKept::kAll;
  bool drop_start_heading = false;
  /// The responder starts this far outside (0: where the scenario starts, inside at the entry)
  /// and walks straight in along the direction of its first 2 m; mission.json's start is the
  /// outside point. Missions with a foot IMU keep their start (its samples are not extended).
  double start_outside_m = 0;

  MissionWriteStyle write;  ///< applied by the writer (io/mission_io)

  /// What was drawn, as (key, value) lines for variation.json and the simulate summary.
  std::vector<std::pair<std::string, std::string>> Describe() const;
};

/// The variant K of a family (documented in docs/simulator.md). Deterministic.
Variation DrawVariation(VariationFamily family, std::uint64_t k);

/// Applies every part of `v` except its write style; returns notes of what could not apply
/// (e.g. "no rssi.csv: radio variation not applied").
std::vector<std::string> ApplyVariation(const Variation& v, SimulatedMission& sim);

}  // namespace trailmark

// SPDX-License-Identifier: MIT
#pragma once
/// Foot-mounted IMU simulation: the instrumented foot's true motion from a walk (stance while the
/// other foot swings, then a swing to the next footprint two steps ahead), turned into specific
/// force and angular rate in the sensor frame, with the errors of a stated MEMS grade. No I/O.
///
/// Swing (duration of one step): minimum-jerk progress along the stride (Flash & Hogan 1985),
/// a foot lift of lift_m, and a heel-off/toe-strike pitch excursion; the heading turns to the new
/// stride direction during the swing. Stops: the foot rests. Motion types: walking, crawling
/// (short, low strides and long stances) and stairs (each stride also climbs 2 risers).
///
/// Sensor model per axis (IEEE Std 952 terms): white noise from the noise density
/// (sigma = density * sqrt(rate)), bias = turn-on bias (constant per run) + bias instability
/// (first-order Gauss-Markov, correlation time tau), scale-factor error, and axis misalignment
/// (a fixed small rotation). Gyro rates come from the exact rotation between samples, so that a
/// noise-free run matches the INS's exponential-map mechanization.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "trailmark/core/measurements.h"
#include "trailmark/core/random.h"
#include "trailmark/sim/mission_sim.h"
#include "trailmark/sim/walker.h"

namespace trailmark {

struct ImuGrade {
  std::string name;
  double accel_noise_density = 0;    ///< m/s^2/sqrt(Hz)
  double gyro_noise_density = 0;     ///< rad/s/sqrt(Hz)
  double accel_turn_on_bias = 0;     ///< m/s^2, 1 sigma per axis
  double gyro_turn_on_bias = 0;      ///< rad/s, 1 sigma per axis
  double accel_bias_instability = 0; ///< m/s^2 (Gauss-Markov steady-state sigma)
  double gyro_bias_instability = 0;  ///< rad/s
  double bias_correlation_s = 100.0;
  double accel_scale_sigma = 0;      ///< relative
  double gyro_scale_sigma = 0;
  double misalignment_sigma_rad = 0;

  /// No errors at all.
  static ImuGrade Perfect();
  /// Tactical-grade MEMS (ADIS16495-class datasheet: gyro 0.8 deg/h in-run, ARW 0.12 deg/sqrt(h);
  /// accelerometer 3.2 ug in-run, VRW 0.012 m/s/sqrt(h)).
  static ImuGrade Tactical();
  /// Industrial MEMS of foot-mounted research units (MicroStrain 3DM-GX5-25 class).
  static ImuGrade Industrial();
  /// Consumer MEMS (MPU-9250 class: gyro 0.01 deg/s/sqrt(Hz), +-5 deg/s turn-on; accelerometer
  /// 300 ug/sqrt(Hz), +-60 mg turn-on).
  static ImuGrade Consumer();
  /// "perfect", "tactical", "industrial", "consumer"; throws std::invalid_argument otherwise.
  static ImuGrade ByName(const std::string& name);
};

enum class FootMotion { kWalk, kCrawl, kStairs };

struct ImuSimOptions {
  double rate_hz = 200.0;
  ImuGrade grade = ImuGrade::Industrial();
  FootMotion motion = FootMotion::kWalk;
  double lift_m = 0.12;               ///< swing foot clearance (walking); crawling 0.03
  double pitch_amplitude_rad = 0.5;   ///< heel-off / toe-strike excursion (~30 deg)
  double riser_m = 0.17;              ///< stairs: height of one step
  double gravity_mps2 = 9.8029;
  double rest_before_s = 1.0;         ///< at rest before the first step (INS alignment)
  /// The gait: how far the foot has already turned toward its next stride when it lands, as a
  /// share of the turn between this stride and the next (0: it lands pointing along its own
  /// stride, a pivot on the standing foot; 0.5: half way, the stride a chord of an arc whose
  /// headings the foot follows). The `imu` family draws it (issue 21: the simulator's one gait).
  double landing_anticipation = 0.0;
};

struct SimulatedImu {
  std::vector<ImuSample> samples;
  std::vector<TruthSample> foot_truth;  ///< the foot's true position at every sample
  std::vector<bool> stance;             ///< true stance label of every sample
  /// Each landing of the foot (truth): when, where and the foot's heading then (rad).
  struct Landing {
    TimeS t = 0;
    Vec2 position_n = Vec2::Zero();
    double yaw_rad = 0;
  };
  std::vector<Landing> landings;
};

/// The walk's steps alternate feet; the instrumented foot (agent `agent`) lands on every
/// second footprint. The foot rests facing `start_yaw_rad` (the mission's stated start heading:
/// an INS aligns its yaw to it) and turns toward its strides from its first swing on; without
/// it, facing the first step. Deterministic given `rng`.
SimulatedImu SimulateFootImu(const Walk& walk, const std::string& agent,
                             const ImuSimOptions& options, Random rng,
                             std::optional<double> start_yaw_rad = std::nullopt);

/// Adds a foot IMU to every walking agent of a simulated mission (`data.imu`, in time order),
/// each foot resting at first as the agent's stated start heading says. Deterministic given
/// `seed`.
void AddFootImu(SimulatedMission& sim, const ImuSimOptions& options, std::uint64_t seed);

/// The IMU mounted another way on the foot: `imu_in_foot` holds the IMU's axes in the foot's frame
/// (x forward, z up), so each sample, a foot-frame vector v, reads imu_in_foot^T v (imu.csv's
/// axes are unstated by the spec: another axis forward, upside down, tilted).
void MountImu(std::vector<ImuSample>& samples, const Eigen::Matrix3d& imu_in_foot);
/// That rotation from yaw (about z), then pitch (about y), then roll (about x), in radians:
/// Rz(yaw) Ry(pitch) Rx(roll).
Eigen::Matrix3d ImuMounting(double yaw_rad, double roll_rad = 0, double pitch_rad = 0);

}  // namespace trailmark

// SPDX-License-Identifier: MIT
#pragma once
/// Zero-velocity-aided inertial navigation for a foot-mounted IMU (Foxlin 2005; Skog et al.
/// 2010; Nilsson et al. 2014, "Foot-mounted inertial navigation made easy" — OpenShoe).
///
/// Nominal state: position p_n, velocity v_n (navigation frame: x east, y north, z up, metres),
/// attitude q_nb (body to navigation, Eigen quaternion), accelerometer and gyroscope biases.
/// Error state (15): dp, dv, dtheta (navigation-frame rotation error: R = (I + [dtheta]x) R_hat),
/// dba, dbg. Continuous error dynamics (Solà, "Quaternion kinematics for the error-state KF",
/// 2017, sec. 5.3.3 with global angular error):
///   dp' = dv,  dv' = -[R f_b]x dtheta - R dba,  dtheta' = -R dbg,  dba' = w_ba,  dbg' = w_bg
/// discretized to first order, Phi = I + F dt (as OpenShoe and PyShoe do).
/// Updates during stance: ZUPT (v_n = 0) and ZARU (w_b - b_g = 0). Roll and pitch are observable
/// through ZUPTs; yaw is not (no magnetometer: unreliable in steel buildings). Yaw drift is held
/// down by estimating the gyro bias in stance (ZARU); an optional magnetometer would be one more
/// update in stance, heading = atan2 of the levelled field, gated on field magnitude and dip.
///
/// Initial alignment: roll and pitch from the mean specific force over the first stationary
/// samples (alignment_s); yaw from the mission's start heading (else 0).
/// Steps: one per stance phase, emitted at the end of the stance (when the ZUPTs have corrected
/// the position): displacement since the previous stance end, with the growth of the filter's
/// position covariance as its variance.
/// Streaming, constant memory. No I/O.

#include <Eigen/Geometry>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "trailmark/core/measurements.h"
#include "trailmark/ins/mount_yaw.h"
#include "trailmark/ins/zupt_detectors.h"

namespace trailmark::ins {

struct InsOptions {
  DetectorOptions detector;
  double gravity_mps2 = 9.8029;       ///< PyShoe/OpenShoe value (mid latitudes)
  // Process noise, per-sample sigmas as PyShoe's EKF (accelerometer 0.5 m/s^2, gyro 0.5 deg/s):
  double accel_noise_mps2 = 0.5;
  double gyro_noise_radps = 0.5 * 3.14159265358979 / 180.0;
  /// Accelerometer and gyro bias states (the gyro's starting from its mean over the alignment);
  /// false: the IMU is taken as unbiased (calibrated), nothing is subtracted.
  bool estimate_biases = true;
  double accel_bias_rw = 1e-4;        ///< m/s^2 per sqrt(s)
  double gyro_bias_rw = 1e-5;         ///< rad/s per sqrt(s)
  double accel_bias_sigma0 = 0.05;    ///< m/s^2
  double gyro_bias_sigma0 = 2e-3;     ///< rad/s
  double zupt_sigma_mps = 0.01;
  /// Zero angular rate updates in stance, gated (a stance the detector accepted may still
  /// rotate). Ungated they cost accuracy on the PyShoe trials (0.134 -> 0.15 m ARMSE); gated
  /// they help on every recorded set (docs/ins.md).
  bool zaru = true;
  double zaru_sigma_radps = 0.01;
  double zaru_gate_chi2 = 11.3;       ///< 99 % of chi-square with 3 degrees of freedom
  /// A gate that refuses every ZARU for this much stance (s) refuses a bias, not a rotation: the
  /// bias estimate is wrong beyond its covariance (an ambiguous start, a turn-on bias or a jump
  /// the prior did not allow), and nothing else would ever correct it. Its covariance then grows
  /// by the refused residuals' mean m (m m^T) and the attitude's by the heading that bias error
  /// turned meanwhile, so that the next ZARU is taken. 1 s: two to three strides' stances, a
  /// second of standing. 0: never (the gate alone, before 2026-12-07).
  double zaru_recover_s = 1.0;
  /// The IMU's mounting about the vertical found from the strides (mount_yaw.h; used by
  /// MultiAgentIns for an agent whose start heading the mission states).
  MountYawOptions mount_yaw;
  double alignment_s = 0.1;           ///< stationary start used for roll/pitch (and gyro bias)
  double initial_yaw_rad = 0.0;
  Vec3 initial_position_n = Vec3::Zero();
  double initial_attitude_sigma_rad = 0.01;
  double initial_yaw_sigma_rad = 0.01;
  // steps
  int min_stance_samples = 3;
  double min_step_length_m = 0.02;    ///< shorter displacements between stances are no step
  /// When a step ends: at the foot's landing (its stance detected, `min_stance_samples` in),
  /// or at its lift-off (the end of the stance, the previous behaviour). The displacement is
  /// the foot's from stance to stance either way; at lift-off the walker's body is already a
  /// step ahead of the resting foot, so a step stamped there lags the walk by one step (DR of
  /// the INS's steps 1.2 m mean against the INS's own 0.3 m on all-sources seed 1).
  bool step_at_landing = true;
  /// Also a step half way through each swing (half the last swing's samples after lift-off):
  /// a foot IMU on one foot lands once a stride, and there the swinging foot passes the other,
  /// under the walker — the walker's own steps, twice a stride.
  bool mid_swing_steps = true;
  /// Textbook dense arithmetic: Phi as a full 15x15 matrix (P = Phi P Phi^T + Q), the Kalman
  /// update with the full H (P = P - K H P, then symmetrized), the detector's window summed
  /// anew. Slow; the reference the structured arithmetic is tested against (same results to
  /// rounding).
  bool reference_arithmetic = false;
  /// Window >= 1 sample, noises and sigmas > 0, alignment >= 0.
  bool IsValid(std::string* why) const;
};

/// Filter output at one processed sample.
struct InsState {
  TimeS t = 0;
  Vec3 position_n = Vec3::Zero();
  Vec3 velocity_n = Vec3::Zero();
  Eigen::Quaterniond q_nb = Eigen::Quaterniond::Identity();
  Eigen::Matrix3d position_cov = Eigen::Matrix3d::Zero();
  bool stance = false;
};

struct InsSummary {
  std::size_t samples = 0, stance_samples = 0, steps = 0;
  std::size_t gaps = 0, zero_dt = 0, zaru_gated = 0;
  std::size_t zaru_recoveries = 0;  ///< times the bias's covariance grew after refused ZARUs
  std::size_t saturated = 0;  ///< samples with an axis stuck at its extreme (clipped)
  double distance_m = 0;
  Vec3 gyro_bias = Vec3::Zero(), accel_bias = Vec3::Zero();
  std::vector<std::string> warnings;
};

class ZuptIns {
 public:
  explicit ZuptIns(InsOptions options = {});
  std::function<void(const InsState&)> on_state;  ///< every processed sample
  std::function<void(const Step&)> on_step;        ///< every step (agent id from the samples)

  /// Samples in non-decreasing time, one agent. Throws std::invalid_argument on input that
  /// cannot be a foot IMU in SI units (g instead of m/s^2, deg/s instead of rad/s, NaN).
  void Add(const ImuSample& sample);
  /// The same with an external stance decision for this sample (reference labels, another
  /// detector); the internal detector is bypassed.
  void AddWithStance(const ImuSample& sample, bool stance);
  /// End of data: processes the samples the detector still holds.
  void Finish();
  const InsSummary& summary() const { return summary_; }
  const InsOptions& options() const { return options_; }
  /// A lower bound on t1 of every step still to come: any step emitted from now on ends at or
  /// after it (nullopt before the first sample). Lets a consumer that needs steps in time order
  /// release other rows that are older.
  std::optional<TimeS> EarliestNextStepEnd() const;
  /// The latest processed state (nullopt before alignment).
  std::optional<InsState> LastState() const {
    return have_last_ ? std::optional<InsState>(last_state_) : std::nullopt;
  }

  /// Whether the IMU holds the filter's stated noise model, as far as the alignment can tell:
  /// its gyro bias at rest within kOwnErrorsBiasSigmas x gyro_bias_sigma0 on every axis (true
  /// before the alignment and without bias states). Only then do its steps carry the filter's
  /// heading variance (Step::heading_var_rad2). 3 sigma: a priori.
  bool OwnErrorsHold() const { return own_errors_hold_; }
  static constexpr double kOwnErrorsBiasSigmas = 3.0;
  /// A resting gyro's mean over the alignment (alignment_s) below this (rad/s, 2.9 deg/s) is its
  /// bias, the estimate's start. Above it the mean may be a bias or a foot still settling: the
  /// alignment goes on to kAmbiguousAlignmentS and the quietest window's mean is the bias (up to
  /// kRestGyroMaxRadps; beyond, the IMU is not at rest or in deg/s: zero and a warning).
  static constexpr double kRestGyroBiasRadps = 0.05;
  static constexpr double kAmbiguousAlignmentS = 1.0;
  static constexpr double kRestGyroMaxRadps = 0.3;
  static constexpr double kRestGyroSpreadRadps = 0.05;
  /// Offsets of the error-state blocks (each 3 wide): dp, dv, dtheta, dba, dbg.
  static constexpr int kPos = 0, kVel = 3, kAtt = 6, kAccelBias = 9, kGyroBias = 12;
  static constexpr int kErrorStateSize = 15;

 private:
  using Mat15 = Eigen::Matrix<double, kErrorStateSize, kErrorStateSize>;
  using ErrorVector = Eigen::Matrix<double, kErrorStateSize, 1>;
  void Align();
  /// A sample without its agent (the INS holds one agent's samples).
  struct Sample {
    TimeS t = 0;
    Vec3 accel_b = Vec3::Zero(), gyro_b = Vec3::Zero();
  };
  void Process(const Sample& s, bool stance);
  void Propagate(const Vec3& accel_b, const Vec3& gyro_b, double dt);
  void PropagateCovariance(const Eigen::Matrix3d& R, const Vec3& f_n, double dt);
  void PropagateCovarianceDense(const Eigen::Matrix3d& R, const Vec3& f_n, double dt);
  void UpdateZupt();
  void UpdateZaru(const Vec3& gyro_b, TimeS t);
  /// Whether the samples buffered for the alignment (up to `t`) are enough to align on.
  bool AlignmentComplete(TimeS t);
  /// The gyro's mean over `n` buffered alignment samples from `first`.
  Vec3 AlignmentGyroMean(std::size_t first, std::size_t n) const;
  template <int Offset>
  void Update3(const Vec3& innovation, double sigma);
  void Inject(const ErrorVector& dx);
  /// P's upper triangle of its first n rows and columns copied into the lower.
  void MirrorUpper(int n);
  /// After each processed sample (last_state_ is its state; `previous`, the sample's before).
  void StanceBookkeeping(bool stance, const InsState& previous);
  /// The step from the last step's end to `end` (none when shorter than min_step_length_m).
  void EmitStep(const InsState& end, bool horizontal_only = false);

  InsOptions options_;
  ZuptDetector detector_;
  std::vector<ImuSample> alignment_;   ///< buffered until aligned
  /// Samples waiting for their detector decision: a ring of Delay() + 1 slots.
  std::vector<Sample> delay_;
  std::size_t delay_head_ = 0, delay_size_ = 0;
  void PushDelayed(const Sample& s);
  Sample PopDelayed();
  const Sample& NewestDelayed() const {
    return delay_[(delay_head_ + delay_size_ - 1) % delay_.size()];
  }
  std::vector<bool> alignment_stance_; ///< external decisions of the buffered samples
  bool external_ = false;
  bool aligned_ = false;
  std::string agent_;
  // nominal state
  Vec3 p_ = Vec3::Zero(), v_ = Vec3::Zero(), ba_ = Vec3::Zero(), bg_ = Vec3::Zero();
  Eigen::Quaterniond q_ = Eigen::Quaterniond::Identity();
  Mat15 P_ = Mat15::Zero();
  TimeS t_last_ = 0;
  bool have_last_ = false;
  double median_dt_ = 0;
  std::size_t alignment_window_ = 0;  ///< samples in the first alignment_s (0: not yet)
  /// The ZARUs refused since the last one taken: how many, their residuals' sum, the first's t.
  std::size_t zaru_refused_run_ = 0;
  Vec3 zaru_refused_sum_ = Vec3::Zero();
  Vec3 zaru_refused_sum2_ = Vec3::Zero();  ///< of the residuals' squares (their spread)
  TimeS zaru_refused_since_ = 0;
  // steps
  int stance_run_ = 0;
  bool in_stance_phase_ = false;
  std::optional<TimeS> last_stance_end_t_;
  Vec3 last_stance_end_p_ = Vec3::Zero();
  Eigen::Matrix3d last_stance_end_cov_ = Eigen::Matrix3d::Zero();
  double last_stance_end_yaw_var_ = 0;  ///< rad^2, the filter's yaw variance at that end
  /// The state at alignment (the start): the first step's reference when the INS moved before
  /// its first stance (a detector that does not see the first rest, EmitStep).
  std::optional<InsState> aligned_state_;
  double aligned_yaw_var_ = 0;
  bool own_errors_hold_ = true;         ///< OwnErrorsHold()
  bool swinging_ = false;        ///< between a lift-off and the next landing
  long swing_samples_ = 0;       ///< samples since the lift-off
  long last_swing_samples_ = 0;  ///< the last swing's length in samples
  bool mid_swing_done_ = false;
  InsState last_state_;
  // saturation: an axis repeating the same large value (a clipped sensor)
  Eigen::Matrix<double, 6, 1> last_raw_ = Eigen::Matrix<double, 6, 1>::Zero();
  Eigen::Matrix<int, 6, 1> repeat_ = Eigen::Matrix<int, 6, 1>::Zero();
  void CheckSaturation(const Sample& s);
  InsSummary summary_;
};

}  // namespace trailmark::ins

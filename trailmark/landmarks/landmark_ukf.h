// SPDX-License-Identifier: MIT
#pragma once
/// Unscented Kalman filter of the radio-landmarks paper (sec. 5.4, eqs. 18-22): state
/// x = (M, V, A) — position, velocity, acceleration in 2-D (eq. 18); the Wiener-process
/// acceleration model (Bar-Shalom et al. 2001, eqs. 19-20) with intensity tau; RSSI updates
///   z_i = alpha - 10 n log10 |M - S_i| + rho,  rho ~ N(0, sigma_r^2)          (eq. 21)
/// through the unscented transform, and acceleration updates z = A + v (eq. 22). When the foot
/// is still, velocity and acceleration are zeroed (Woodman & Harle 2008).
///
/// Deviation from the text, stated: the transition uses dt^2/2 for the position-acceleration
/// term (the kinematically exact Wiener-process model; eq. 20 prints dt^2). Beyond the paper:
/// landmark positions may be uncertain (their covariance is added to the RSSI innovation through
/// the sigma points' range), RSSI may also be used while standing (the paper only fuses while
/// moving), and velocity pseudo-measurements from ZUPT-INS steps (ours) replace the raw foot
/// acceleration when available. Covariances are kept symmetric positive definite. No I/O.

#include <Eigen/Core>
#include <functional>
#include <vector>

#include "trailmark/core/types.h"
#include "trailmark/radio/path_loss.h"

namespace trailmark::landmarks {

struct LandmarkUkfOptions {
  double tau = 1.0;                  ///< Wiener-process acceleration intensity (m^2/s^5)
  double rssi_sigma_db = 6.0;        ///< one wake-up answer (the paper inflates it, sec. 6.3)
  double accel_sigma_mps2 = 1.0;     ///< eq. (22) noise
  double velocity_sigma_mps = 0.15;  ///< ZUPT-step velocity pseudo-measurements (ours)
  double gate_sigma = 4.0;           ///< RSSI innovations beyond this are rejected
  double initial_sigma_m = 1.0;
  // unscented transform (Van der Merwe scaled; alpha = 1, beta = 0, kappa = 0 keeps W0 >= 0)
  double ut_alpha = 1.0, ut_beta = 0.0, ut_kappa = 0.0;
};

class LandmarkUkf {
 public:
  using State = Eigen::Matrix<double, 6, 1>;   ///< (Mx, My, Vx, Vy, Ax, Ay)
  using Cov = Eigen::Matrix<double, 6, 6>;

  LandmarkUkf(const Vec2& start, radio::LogDistanceModel radio, LandmarkUkfOptions options = {});
  /// Eqs. (19)-(20) over dt seconds.
  void Predict(double dt_s);
  /// Eq. (21) through the unscented transform; landmark with position covariance. `admit`,
  /// when given, sees the update's normalized innovation squared (nu^2 / S, 1 dof) before it
  /// is committed and may refuse it (the integrity monitor, integrity/consistency.h). Returns
  /// false when refused or gated out.
  bool UpdateRssi(const Vec2& landmark, const Mat2& landmark_cov, double rssi_dbm,
                  const std::function<bool(double nis)>& admit = nullptr);
  /// Eq. (22): a horizontal acceleration measurement (navigation frame, gravity removed).
  void UpdateAcceleration(const Vec2& accel_n);
  /// Velocity pseudo-measurement (e.g. a ZUPT-INS step divided by its duration).
  void UpdateVelocity(const Vec2& velocity_n, double sigma_mps);
  /// The foot is still: V = A = 0 with small uncertainty.
  void ZeroMotion();
  /// Ours: the ZUPT INS as the motion model — the position moves by the INS displacement
  /// `delta_n` since the last call, with that displacement's covariance (its drift).
  void PredictWithDisplacement(const Vec2& delta_n, const Mat2& cov);

  /// Replaces the RSSI model (e.g. after an online re-calibration).
  void SetRadioModel(const radio::LogDistanceModel& radio) { radio_ = radio; }

  const State& state() const { return x_; }
  const Cov& covariance() const { return P_; }
  Vec2 position() const { return x_.head<2>(); }
  Mat2 position_cov() const { return P_.topLeftCorner<2, 2>(); }
  const LandmarkUkfOptions& options() const { return options_; }

  /// The linear-Gaussian parts as matrices (tests compare them with a plain Kalman filter).
  static Cov Transition(double dt);
  static Cov ProcessNoise(double dt, double tau);

 private:
  void LinearUpdate(const Eigen::Matrix<double, 2, 6>& H, const Vec2& z, const Mat2& R);
  void Symmetrize();

  radio::LogDistanceModel radio_;
  LandmarkUkfOptions options_;
  State x_ = State::Zero();
  Cov P_ = Cov::Zero();
};

}  // namespace trailmark::landmarks

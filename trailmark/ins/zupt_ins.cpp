// SPDX-License-Identifier: MIT
#include "trailmark/ins/zupt_ins.h"

#include <fmt/format.h>

#include <cmath>
#include <stdexcept>

namespace trailmark::ins {

namespace {

Eigen::Matrix3d Skew(const Vec3& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

/// Quaternion of the rotation vector phi (exponential map).
Eigen::Quaterniond Exp(const Vec3& phi) {
  const double angle = phi.norm();
  if (angle < 1e-12) return Eigen::Quaterniond(1.0, 0.5 * phi.x(), 0.5 * phi.y(), 0.5 * phi.z());
  return Eigen::Quaterniond(Eigen::AngleAxisd(angle, phi / angle));
}

/// Y += X M for 15x3 blocks of a column-major matrix and a 3x3 M: three axpys on contiguous
/// 15-long columns per output column (vectorized; Eigen's lazy product of these blocks is not).
template <class Dst, class Src>
[[gnu::always_inline]] inline void AddProduct(Dst&& Y, const Src& X, const Eigen::Matrix3d& M) {
  for (int j = 0; j < 3; ++j) {
    Y.col(j) += X.col(0) * M(0, j) + X.col(1) * M(1, j) + X.col(2) * M(2, j);
  }
}

}  // namespace

bool InsOptions::IsValid(std::string* why) const {
  const char* problem = nullptr;
  if (detector.window < 1) problem = "the detector window must be >= 1 sample";
  else if (!(detector.window_s >= 0)) problem = "the detector window must be >= 0 s";
  else if (!(zupt_sigma_mps > 0) || !(zaru_sigma_radps > 0)) problem = "ZUPT/ZARU sigmas must be > 0";
  else if (!(accel_noise_mps2 > 0) || !(gyro_noise_radps > 0)) problem = "noises must be > 0";
  else if (!(alignment_s >= 0)) problem = "alignment_s must be >= 0";
  else if (!(zaru_recover_s >= 0) || !std::isfinite(zaru_recover_s))
    problem = "zaru_recover_s must be >= 0 and finite";
  else if (!(gravity_mps2 > 0)) problem = "gravity must be > 0";
  if (problem && why) *why = problem;
  return problem == nullptr && mount_yaw.IsValid(why);
}

ZuptIns::ZuptIns(InsOptions options) : options_(options), detector_(options.detector) {
  options_.detector.gravity_mps2 = options_.gravity_mps2;
  options_.detector.reference_arithmetic =
      options_.detector.reference_arithmetic || options_.reference_arithmetic;
  detector_ = ZuptDetector(options_.detector);
  delay_.resize(static_cast<std::size_t>(detector_.Delay()) + 1);
}

void ZuptIns::PushDelayed(const Sample& s) {
  // The detector decides once it holds Delay() + 1 samples: the ring never holds more.
  if (delay_size_ == delay_.size()) throw std::logic_error("ZuptIns: detector delay exceeded");
  delay_[(delay_head_ + delay_size_) % delay_.size()] = s;
  ++delay_size_;
}

ZuptIns::Sample ZuptIns::PopDelayed() {
  const Sample s = delay_[delay_head_];
  delay_head_ = (delay_head_ + 1) % delay_.size();
  --delay_size_;
  return s;
}

void ZuptIns::Add(const ImuSample& s) {
  if (!s.accel_b.allFinite() || !s.gyro_b.allFinite()) {
    throw std::invalid_argument(fmt::format("IMU sample at t={} is not finite", s.t));
  }
  // 2000 deg/s is the largest range of MEMS gyros: beyond it the data is in deg/s.
  if (s.gyro_b.cwiseAbs().maxCoeff() > 40.0) {
    throw std::invalid_argument(fmt::format(
        "gyro reads {:.1f} at t={}: above any MEMS range in rad/s (2000 deg/s = 34.9 rad/s); "
        "the data looks like deg/s — convert to rad/s",
        s.gyro_b.cwiseAbs().maxCoeff(), s.t));
  }
  if (agent_.empty()) agent_ = s.agent;
  if (!aligned_) {
    alignment_.push_back(s);
    if (AlignmentComplete(s.t)) Align();
    return;
  }
  const double dt = have_last_ || delay_size_ > 0
                       ? s.t - (delay_size_ == 0 ? t_last_ : NewestDelayed().t)
                       : 0.0;
  PushDelayed({s.t, s.accel_b, s.gyro_b});
  if (auto decision = detector_.Add(s.accel_b, s.gyro_b, dt)) {
    Process(PopDelayed(), decision->stance);
  }
}

void ZuptIns::AddWithStance(const ImuSample& s, bool stance) {
  external_ = true;
  if (!s.accel_b.allFinite() || !s.gyro_b.allFinite()) {
    throw std::invalid_argument(fmt::format("IMU sample at t={} is not finite", s.t));
  }
  if (agent_.empty()) agent_ = s.agent;
  if (!aligned_) {
    alignment_.push_back(s);
    alignment_stance_.push_back(stance);
    if (AlignmentComplete(s.t)) Align();
    return;
  }
  Process({s.t, s.accel_b, s.gyro_b}, stance);
}

Vec3 ZuptIns::AlignmentGyroMean(std::size_t first, std::size_t n) const {
  Vec3 w = Vec3::Zero();
  for (std::size_t j = first; j < first + n; ++j) w += alignment_[j].gyro_b;
  return w / static_cast<double>(n);
}

bool ZuptIns::AlignmentComplete(TimeS t) {
  if (alignment_.size() < 5 || t - alignment_.front().t < options_.alignment_s) return false;
  if (alignment_window_ == 0) {  // the first window is complete: is its gyro mean ambiguous?
    alignment_window_ = alignment_.size();
    if (!options_.estimate_biases ||
        AlignmentGyroMean(0, alignment_window_).norm() < kRestGyroBiasRadps) {
      return true;
    }
  }
  return t - alignment_.front().t >= std::max(options_.alignment_s, kAmbiguousAlignmentS);
}

void ZuptIns::Align() {
  // Roll, pitch and the gyro's mean from the first window (alignment_s; all of a shorter start).
  const std::size_t window =
      alignment_window_ > 0 ? std::min(alignment_window_, alignment_.size()) : alignment_.size();
  Vec3 f = Vec3::Zero();
  for (std::size_t k = 0; k < window; ++k) f += alignment_[k].accel_b;
  f /= static_cast<double>(window);
  const Vec3 w = AlignmentGyroMean(0, window);
  const double m = f.norm();
  if (m > 0.5 && m < 1.5) {
    throw std::invalid_argument(fmt::format(
        "specific force at rest is {:.3f}: the accelerometer is in g, not m/s^2 (multiply by "
        "9.80665)", m));
  }
  if (std::abs(m - options_.gravity_mps2) > 2.0) {
    throw std::invalid_argument(fmt::format(
        "specific force over the first {:.2f} s is {:.2f} m/s^2, not ~{:.2f}: the IMU is not "
        "at rest at the start (needed for alignment) or the units are wrong",
        options_.alignment_s, m, options_.gravity_mps2));
  }
  if (options_.detector.window_s > 0 && alignment_.size() >= 2) {
    const double dt = (alignment_.back().t - alignment_.front().t) / (alignment_.size() - 1);
    if (dt > 0) {
      options_.detector.window =
          std::max(3, static_cast<int>(std::lround(options_.detector.window_s / dt)));
      detector_ = ZuptDetector(options_.detector);
      delay_.assign(static_cast<std::size_t>(detector_.Delay()) + 1, Sample{});
      delay_head_ = delay_size_ = 0;
    }
  }
  // Roll and pitch from gravity: at rest f_b = R_nb^T (0, 0, g).
  const double roll = std::atan2(f.y(), f.z());
  const double pitch = std::atan2(-f.x(), std::sqrt(f.y() * f.y() + f.z() * f.z()));
  q_ = Eigen::AngleAxisd(options_.initial_yaw_rad, Vec3::UnitZ()) *
       Eigen::AngleAxisd(pitch, Vec3::UnitY()) * Eigen::AngleAxisd(roll, Vec3::UnitX());
  q_.normalize();
  p_ = options_.initial_position_n;
  v_.setZero();
  ba_.setZero();
  // A resting gyro reads its bias: the estimate's start, with its prior covariance below. Without
  // bias states the IMU is taken as unbiased (an alignment estimate subtracted for good would be
  // an error the covariance never learns of: mean NEES 380 on the exact-model test).
  // Above kRestGyroBiasRadps the first window's mean is ambiguous: an uncalibrated gyro's bias (a
  // consumer MEMS's turn-on bias reaches +-5 deg/s) or a foot still settling (the LLIO walks: 6
  // deg/s over the first 0.1 s, 0.6 deg/s half a second later). The alignment then went on
  // (AlignmentComplete) and the bias is the quietest window's mean: a bias reads in every window,
  // a settling foot's turn not in all. Before 2026-12-07 such a start left the bias at zero, and
  // the gate refused a consumer gyro's 3 deg/s at every stance (the yaw drifted 170 deg/min).
  // A window counts if the foot rests in it: every reading within kRestGyroSpreadRadps of the
  // window's mean (a swing's turn is not steady).
  Vec3 rest_w = w;
  if (w.norm() >= kRestGyroBiasRadps && alignment_.size() > window) {
    const std::size_t hop = std::max<std::size_t>(1, window / 2);
    for (std::size_t k = hop; k + window <= alignment_.size(); k += hop) {
      const Vec3 wk = AlignmentGyroMean(k, window);
      bool steady = true;
      for (std::size_t j = k; j < k + window && steady; ++j) {
        steady = (alignment_[j].gyro_b - wk).norm() < kRestGyroSpreadRadps;
      }
      if (steady && wk.norm() < rest_w.norm()) rest_w = wk;
    }
  }
  if (rest_w.norm() > kRestGyroMaxRadps) {
    summary_.warnings.push_back(fmt::format(
        "mean gyro over the alignment is {:.2f} rad/s: not at rest, or deg/s instead of rad/s",
        rest_w.norm()));
  }
  bg_ = options_.estimate_biases && rest_w.norm() < kRestGyroMaxRadps ? rest_w : Vec3::Zero();
  // The IMU checked against the noise model the filter states: a resting gyro's bias beyond
  // kOwnErrorsBiasSigmas of its stated sigma (an uncalibrated consumer gyro: degrees per second)
  // says the filter's own covariance, its yaw's included, is not this device's. Its steps then
  // carry no heading variance of their own, and consumers take them with a PDR's errors.
  own_errors_hold_ =
      !options_.estimate_biases ||
      rest_w.cwiseAbs().maxCoeff() <= kOwnErrorsBiasSigmas * options_.gyro_bias_sigma0;
  if (!own_errors_hold_) {
    summary_.warnings.push_back(fmt::format(
        "gyro bias at rest {:.3f} deg/s, beyond {:g} sigma of the stated {:.3f} deg/s: the INS's "
        "own errors are not this device's (its steps go on with a PDR's errors)",
        rest_w.cwiseAbs().maxCoeff() * 180 / M_PI, kOwnErrorsBiasSigmas,
        options_.gyro_bias_sigma0 * 180 / M_PI));
  }
  P_.setZero();
  P_.block<3, 3>(kVel, kVel) = Eigen::Matrix3d::Identity() * 1e-4;
  const double sa = options_.initial_attitude_sigma_rad, sy = options_.initial_yaw_sigma_rad;
  P_.block<3, 3>(kAtt, kAtt) = Vec3(sa * sa, sa * sa, sy * sy).asDiagonal();
  if (options_.estimate_biases) {
    P_.block<3, 3>(kAccelBias, kAccelBias) =
        Eigen::Matrix3d::Identity() * std::pow(options_.accel_bias_sigma0, 2);
    P_.block<3, 3>(kGyroBias, kGyroBias) =
        Eigen::Matrix3d::Identity() * std::pow(options_.gyro_bias_sigma0, 2);
  }
  aligned_ = true;
  aligned_state_ = InsState{};
  aligned_state_->t = alignment_.front().t;
  aligned_state_->position_n = p_;
  aligned_state_->q_nb = q_;
  aligned_state_->position_cov = P_.block<3, 3>(kPos, kPos);
  aligned_yaw_var_ = P_(kAtt + 2, kAtt + 2);
  const std::vector<ImuSample> buffered = std::move(alignment_);
  const std::vector<bool> stance = std::move(alignment_stance_);
  alignment_.clear();
  alignment_stance_.clear();
  for (std::size_t k = 0; k < buffered.size(); ++k) {
    if (external_) {
      Process({buffered[k].t, buffered[k].accel_b, buffered[k].gyro_b}, stance[k]);
    } else {
      Add(buffered[k]);
    }
  }
}

void ZuptIns::Propagate(const Vec3& accel_b, const Vec3& gyro_b, double dt) {
  const Vec3 w = gyro_b - bg_;
  const Vec3 f = accel_b - ba_;
  const Eigen::Matrix3d R0 = q_.toRotationMatrix();
  q_ = (q_ * Exp(w * dt)).normalized();
  const Eigen::Matrix3d R1 = q_.toRotationMatrix();
  const Eigen::Matrix3d R = 0.5 * (R0 + R1);
  const Vec3 f_n = R * f;
  const Vec3 v1 = v_ + (f_n - Vec3(0, 0, options_.gravity_mps2)) * dt;
  p_ += 0.5 * (v_ + v1) * dt;
  v_ = v1;
  if (options_.reference_arithmetic) {
    PropagateCovarianceDense(R, f_n, dt);
  } else {
    PropagateCovariance(R, f_n, dt);
  }
  const double qa = options_.accel_noise_mps2 * dt, qg = options_.gyro_noise_radps * dt;
  P_.block<3, 3>(kVel, kVel).diagonal().array() += qa * qa;
  P_.block<3, 3>(kAtt, kAtt).diagonal().array() += qg * qg;
  if (options_.estimate_biases) {
    P_.block<3, 3>(kAccelBias, kAccelBias).diagonal().array() +=
        options_.accel_bias_rw * options_.accel_bias_rw * dt;
    P_.block<3, 3>(kGyroBias, kGyroBias).diagonal().array() +=
        options_.gyro_bias_rw * options_.gyro_bias_rw * dt;
  }
}

void ZuptIns::PropagateCovarianceDense(const Eigen::Matrix3d& R, const Vec3& f_n, double dt) {
  // Phi = I + F dt with the continuous error dynamics of the header (Sola 2017, sec. 5.3.3).
  Mat15 F = Mat15::Zero();
  F.block<3, 3>(kPos, kVel) = Eigen::Matrix3d::Identity();
  F.block<3, 3>(kVel, kAtt) = -Skew(f_n);
  if (options_.estimate_biases) {
    F.block<3, 3>(kVel, kAccelBias) = -R;
    F.block<3, 3>(kAtt, kGyroBias) = -R;
  }
  const Mat15 Phi = Mat15::Identity() + F * dt;
  P_ = (Phi * P_ * Phi.transpose()).eval();
}

void ZuptIns::PropagateCovariance(const Eigen::Matrix3d& R, const Vec3& f_n, double dt) {
  // P = Phi P Phi^T, Phi = I + F dt, from Phi's blocks besides the identity (all 3x3):
  //   Phi_pv = dt I,  Phi_vtheta = B = -dt [f_n]x,  Phi_va = C = -dt R,  Phi_thetag = C.
  // First N = P Phi^T: only N's column blocks p, v, theta change (p += dt v, v += theta B^T +
  // a C^T, theta += g C^T, in this order, in place: contiguous 15x3 blocks of the column-major
  // P). Then P = Phi N: in each column only the rows p, v, theta change, the same way. The
  // result is symmetric to rounding; Process makes it exactly symmetric once per sample.
  const Eigen::Matrix3d B = -dt * Skew(f_n), Bt = B.transpose();
  const Eigen::Matrix3d C = -dt * R, Ct = C.transpose();
  const bool biases = options_.estimate_biases;
  P_.middleCols<3>(kPos) += dt * P_.middleCols<3>(kVel);
  AddProduct(P_.middleCols<3>(kVel), P_.middleCols<3>(kAtt), Bt);
  if (biases) {
    AddProduct(P_.middleCols<3>(kVel), P_.middleCols<3>(kAccelBias), Ct);
    AddProduct(P_.middleCols<3>(kAtt), P_.middleCols<3>(kGyroBias), Ct);
  }
  // Phi's bias rows are the identity's: P's bias rows are N's, and by symmetry its bias columns
  // their transpose. Only the columns p, v, theta need the left product.
  for (int j = 0; j < kAccelBias; ++j) {
    auto n = P_.col(j);
    n.segment<3>(kPos) += dt * n.segment<3>(kVel);
    if (biases) {
      n.segment<3>(kVel) += B * n.segment<3>(kAtt) + C * n.segment<3>(kAccelBias);
      n.segment<3>(kAtt) += C * n.segment<3>(kGyroBias);
    } else {
      n.segment<3>(kVel) += B * n.segment<3>(kAtt);
    }
  }
  if (biases) P_.block<kAccelBias, 6>(0, kAccelBias) = P_.block<6, kAccelBias>(kAccelBias, 0).transpose();
}

template <int Offset>
void ZuptIns::Update3(const Vec3& innovation, double sigma) {
  // H selects the error-state rows Offset..Offset+2; K = P H^T (H P H^T + R)^-1.
  const Eigen::Matrix3d S =
      P_.block<3, 3>(Offset, Offset) + Eigen::Matrix3d::Identity() * sigma * sigma;
  const Eigen::Matrix3d S_inv = S.inverse();  // 3x3: closed form (cofactors)
  if (options_.reference_arithmetic) {
    Eigen::Matrix<double, 3, kErrorStateSize> H = Eigen::Matrix<double, 3, kErrorStateSize>::Zero();
    H.middleCols<3>(Offset).setIdentity();
    const Eigen::Matrix<double, kErrorStateSize, 3> K = P_ * H.transpose() * S_inv;
    const ErrorVector dx = K * innovation;
    P_ = (P_ - K * H * P_).eval();
    P_ = 0.5 * (P_ + P_.transpose());
    Inject(dx);
    return;
  }
  // P H^T is P's columns Offset..: K = P H^T S^-1, P -= K (P H^T)^T column by column (P's
  // column j loses K times row j of P H^T), on and above the diagonal only, then mirrored.
  const Eigen::Matrix<double, kErrorStateSize, 3> PHt = P_.middleCols<3>(Offset);
  Eigen::Matrix<double, kErrorStateSize, 3> K = Eigen::Matrix<double, kErrorStateSize, 3>::Zero();
  AddProduct(K, PHt, S_inv);
  const ErrorVector dx = K.col(0) * innovation(0) + K.col(1) * innovation(1) + K.col(2) * innovation(2);
  const int columns = options_.estimate_biases ? kErrorStateSize : kAccelBias;
  for (int j = 0; j < columns; ++j) {
    P_.col(j).head(j + 1) -= K.topRows(j + 1) * PHt.row(j).transpose();
  }
  MirrorUpper(columns);
  Inject(dx);
}

void ZuptIns::MirrorUpper(int n) {
  for (int j = 1; j < n; ++j) P_.row(j).head(j) = P_.col(j).head(j).transpose();
}

void ZuptIns::Inject(const ErrorVector& dx) {
  p_ += dx.segment<3>(kPos);
  v_ += dx.segment<3>(kVel);
  q_ = (Exp(dx.segment<3>(kAtt)) * q_).normalized();  // global (navigation-frame) angle error
  if (options_.estimate_biases) {
    ba_ += dx.segment<3>(kAccelBias);
    bg_ += dx.segment<3>(kGyroBias);
  }
}

void ZuptIns::UpdateZupt() { Update3<kVel>(-v_, options_.zupt_sigma_mps); }

void ZuptIns::UpdateZaru(const Vec3& gyro_b, TimeS t) {
  if (!options_.estimate_biases) return;
  // At rest the gyro reads its bias. Gated (chi-square, 3 dof): a "stance" that still rotates
  // (the detector accepted a slow roll-over) must not be read as bias.
  const Vec3 y = gyro_b - bg_;
  const Eigen::Matrix3d S = P_.block<3, 3>(kGyroBias, kGyroBias) +
                            Eigen::Matrix3d::Identity() * options_.zaru_sigma_radps * options_.zaru_sigma_radps;
  if (y.dot(S.inverse() * y) > options_.zaru_gate_chi2) {  // 3x3 SPD: closed-form inverse
    ++summary_.zaru_gated;
    if (zaru_refused_run_++ == 0) {
      zaru_refused_sum_.setZero();
      zaru_refused_sum2_.setZero();
      zaru_refused_since_ = t;
    }
    zaru_refused_sum_ += y;
    zaru_refused_sum2_ += y.cwiseAbs2();
    // Refused over zaru_recover_s of stance, and steadily (a bias reads the same at every
    // stance; a foot rolling on its stance does not): a bias the covariance does not allow.
    const double n = static_cast<double>(zaru_refused_run_);
    if (!(options_.zaru_recover_s > 0 && median_dt_ > 0 && n * median_dt_ >= options_.zaru_recover_s))
      return;
    const Vec3 m = zaru_refused_sum_ / n;
    const double spread = (zaru_refused_sum2_ / n - m.cwiseAbs2()).cwiseMax(0.0).sum();
    if (spread < m.squaredNorm() / 9) {
      const Vec3 turned = q_.toRotationMatrix() * m * (t - zaru_refused_since_);
      P_.block<3, 3>(kGyroBias, kGyroBias) += m * m.transpose();
      P_.block<3, 3>(kAtt, kAtt) += turned * turned.transpose();
      zaru_refused_run_ = 0;
      if (++summary_.zaru_recoveries <= 3) {
        summary_.warnings.push_back(fmt::format(
            "ZARU refused for {:.1f} s of stance before t={:.2f} (gyro {:.2f} deg/s off the bias "
            "estimate): the bias's covariance grown to take it",
            options_.zaru_recover_s, t, m.norm() * 180 / M_PI));
      }
    }
    return;
  }
  zaru_refused_run_ = 0;
  Update3<kGyroBias>(y, options_.zaru_sigma_radps);
}

void ZuptIns::CheckSaturation(const Sample& s) {
  // A clipped axis repeats its full-scale value: >= 3 identical readings beyond 4 g or
  // 5 rad/s (every MEMS range is larger than a walking foot's normal signal below these).
  Eigen::Matrix<double, 6, 1> raw;
  raw << s.accel_b, s.gyro_b;
  bool clipped = false;
  for (int i = 0; i < 6; ++i) {
    const double limit = i < 3 ? 4 * 9.80665 : 5.0;
    repeat_(i) = (raw(i) == last_raw_(i) && std::abs(raw(i)) > limit) ? repeat_(i) + 1 : 0;
    clipped = clipped || repeat_(i) >= 2;
  }
  last_raw_ = raw;
  if (clipped && ++summary_.saturated == 1) {
    summary_.warnings.push_back(fmt::format(
        "t={}: an IMU axis is stuck at {:.2f}: the sensor saturates (clipped motion is lost; "
        "use a larger range)", s.t, raw.cwiseAbs().maxCoeff()));
  }
}

void ZuptIns::Process(const Sample& s, bool stance) {
  ++summary_.samples;
  CheckSaturation(s);
  if (have_last_) {
    const double dt = s.t - t_last_;
    if (dt <= 0) {
      ++summary_.zero_dt;
    } else {
      if (median_dt_ > 0 && dt > 5.0 * median_dt_) {
        if (++summary_.gaps <= 3) {
          summary_.warnings.push_back(fmt::format(
              "gap of {:.3f} s before t={} ({:.0f}x the sample period): dead reckoning across it",
              dt, s.t, dt / median_dt_));
        }
      }
      median_dt_ = median_dt_ > 0 ? 0.99 * median_dt_ + 0.01 * std::min(dt, 3 * median_dt_) : dt;
      Propagate(s.accel_b, s.gyro_b, dt);
    }
  }
  t_last_ = s.t;
  have_last_ = true;
  if (stance) {
    ++summary_.stance_samples;
    UpdateZupt();
    if (options_.zaru) UpdateZaru(s.gyro_b, s.t);
  }
  // The propagation leaves its p, v, theta block symmetric to rounding (an update mirrors all).
  if (!options_.reference_arithmetic && !stance) MirrorUpper(kAccelBias);
  InsState state;
  state.t = s.t;
  state.position_n = p_;
  state.velocity_n = v_;
  state.q_nb = q_;
  state.position_cov = P_.block<3, 3>(kPos, kPos);
  state.stance = stance;
  // A step's end state is the agent's latest (State()) when the step is emitted: this sample's
  // at a landing, the previous sample's at a lift-off.
  if (options_.step_at_landing) {
    const InsState previous = last_state_;
    last_state_ = state;
    StanceBookkeeping(stance, previous);
  } else {
    StanceBookkeeping(stance, last_state_);
    last_state_ = state;
  }
  if (on_state) on_state(state);
}

void ZuptIns::StanceBookkeeping(bool stance, const InsState& previous) {
  // (At a landing last_state_ is this sample's state; `previous` the one before.)
  stance_run_ = stance ? stance_run_ + 1 : 0;
  if (stance && stance_run_ >= options_.min_stance_samples && !in_stance_phase_) {
    in_stance_phase_ = true;
    if (swinging_) last_swing_samples_ = swing_samples_;
    swinging_ = false;
    // The foot has landed: a step ends here (its position ZUPT-corrected by the stance so far).
    if (options_.step_at_landing) EmitStep(last_state_);
  }
  if (swinging_) ++swing_samples_;
  // (Counted in samples, not seconds: the same steps whatever the clock's origin.)
  if (!stance && !in_stance_phase_ && options_.mid_swing_steps && swinging_ && !mid_swing_done_ &&
      last_swing_samples_ > 0 && 2 * swing_samples_ >= last_swing_samples_) {
    // Half way through the swing the foot passes the other, resting one, under the walker: a
    // step ends here too (the swing's first half, dead-reckoned by the INS alone).
    mid_swing_done_ = true;
    EmitStep(last_state_, /*horizontal_only=*/true);
  }
  if (stance || !in_stance_phase_) return;
  // The stance phase ended at the previous sample: its position is ZUPT-corrected.
  in_stance_phase_ = false;
  swinging_ = true;
  swing_samples_ = 0;
  mid_swing_done_ = false;
  if (!options_.step_at_landing) EmitStep(previous);
}

void ZuptIns::EmitStep(const InsState& end, bool horizontal_only) {
  if (!last_stance_end_t_) {
    // The first stance end is the steps' reference (the rest at the start). A detector that
    // did not see that rest as stance (an uncalibrated consumer gyro reads degrees per second
    // at rest, above the detector's threshold until the bias is estimated) first ends a stance
    // metres into the walk: the walk to it would be in no step, and every consumer of the steps
    // would start that far behind the INS (imu family, corridor K 1: 1.4 m for the whole walk).
    // Then the first step starts at the alignment's state, the start.
    constexpr double kMovedBeforeFirstStanceM = 0.1;
    if (aligned_state_ &&
        (end.position_n - aligned_state_->position_n).head<2>().norm() > kMovedBeforeFirstStanceM) {
      last_stance_end_t_ = aligned_state_->t;
      last_stance_end_p_ = aligned_state_->position_n;
      last_stance_end_cov_ = aligned_state_->position_cov;
      last_stance_end_yaw_var_ = aligned_yaw_var_;
    } else {
      last_stance_end_t_ = end.t;
      last_stance_end_p_ = end.position_n;
      last_stance_end_cov_ = end.position_cov;
      last_stance_end_yaw_var_ = P_(kAtt + 2, kAtt + 2);
      return;
    }
  }
  Vec3 delta = end.position_n - last_stance_end_p_;
  // A step that ends in the air keeps the foot's lift out of the height: the landing's carries
  // the whole climb.
  if (horizontal_only) delta.z() = 0.0;
  if (delta.head<2>().norm() < options_.min_step_length_m) return;  // shuffling, not a step
  const Vec3 var = (end.position_cov.diagonal() - last_stance_end_cov_.diagonal()).cwiseMax(1e-6);
  // The yaw's variance growth over the step (the attitude error is in the navigation frame:
  // its z is the heading's): the INS's own heading error, for the consumers' motion models.
  const double yaw_var = P_(kAtt + 2, kAtt + 2);
  Step step{*last_stance_end_t_, end.t, agent_, delta, var};
  if (own_errors_hold_) step.heading_var_rad2 = std::max(0.0, yaw_var - last_stance_end_yaw_var_);
  ++summary_.steps;
  summary_.distance_m += delta.head<2>().norm();
  last_stance_end_t_ = end.t;
  last_stance_end_p_.head<2>() = end.position_n.head<2>();
  if (!horizontal_only) last_stance_end_p_.z() = end.position_n.z();
  last_stance_end_cov_ = end.position_cov;
  last_stance_end_yaw_var_ = yaw_var;
  if (on_step) on_step(step);
}

std::optional<TimeS> ZuptIns::EarliestNextStepEnd() const {
  // A step ends at the last sample of a stance: the last processed sample at the earliest (the
  // stance it is in may end there), else the first sample still buffered.
  if (have_last_) return t_last_;
  if (!alignment_.empty()) return alignment_.front().t;
  if (delay_size_ > 0) return delay_[delay_head_].t;
  return std::nullopt;
}

void ZuptIns::Finish() {
  if (!aligned_ && !alignment_.empty()) {
    if (alignment_.size() < 5) {
      throw std::invalid_argument("fewer than 5 IMU samples: nothing to align on");
    }
    Align();
  }
  const auto decisions = detector_.Flush();
  for (std::size_t k = 0; k < decisions.size() && delay_size_ > 0; ++k) {
    Process(PopDelayed(), decisions[k].stance);
  }
  while (delay_size_ > 0) Process(PopDelayed(), false);  // (only when the window never filled)
  if (in_stance_phase_) StanceBookkeeping(false, last_state_);  // the last state ends a stance
  summary_.accel_bias = ba_;
  summary_.gyro_bias = bg_;
}

}  // namespace trailmark::ins

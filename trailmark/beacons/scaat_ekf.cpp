// SPDX-License-Identifier: MIT
#include "trailmark/beacons/scaat_ekf.h"

#include <fmt/format.h>

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

namespace trailmark::beacons {
namespace {

Mat2 Rotation(double a) { return Eigen::Rotation2Dd(a).toRotationMatrix(); }
// d R(a) / d a = R(a + pi/2)
Mat2 RotationDerivative(double a) { return Eigen::Rotation2Dd(a + std::numbers::pi / 2).toRotationMatrix(); }

}  // namespace

double UltrasoundRange(const Vec2& p, const Vec2& b, Eigen::RowVector2d* H) {
  const Vec2 d = p - b;
  const double r = d.norm();
  if (H != nullptr)
    *H = r > 1e-9 ? Eigen::RowVector2d(d.transpose() / r) : Eigen::RowVector2d::Zero();
  return r;
}

double UltrasoundBearing(const Vec2& p, const Vec2& b, Eigen::RowVector2d* H) {
  const Vec2 d = p - b;
  const double r2 = d.squaredNorm();
  if (H != nullptr)
    *H = r2 > 1e-18 ? Eigen::RowVector2d(-d.y() / r2, d.x() / r2) : Eigen::RowVector2d::Zero();
  return std::atan2(d.y(), d.x());
}

void PolarToPosition(const BeaconPosition& beacon, double r, double b, double sr, double sb,
                     Vec2* z, Mat2* R) {
  const double c = std::cos(b), s = std::sin(b);
  *z = beacon.position_n + r * Vec2(c, s);
  Mat2 J;
  J << c, -r * s, s, r * c;
  *R = J * Eigen::Vector2d(sr * sr, sb * sb).asDiagonal() * J.transpose() + beacon.cov;
  *R = 0.5 * (*R + R->transpose()) + Mat2::Identity() * 1e-6;
}

bool ScaatEkfOptions::IsValid(std::string* why) const {
  auto fail = [&](const char* w) {
    if (why) *why = w;
    return false;
  };
  if (!(initial_position_sigma_m > 0) || !(initial_heading_sigma_rad > 0) ||
      !(initial_scale_sigma > 0)) {
    return fail("initial sigmas must be > 0");
  }
  if (!(heading_walk_rad_per_sqrt_m >= 0) || !(scale_walk_per_sqrt_m >= 0) ||
      !(step_sigma_floor_m >= 0)) {
    return fail("process noises must be >= 0");
  }
  if (!(range_sigma_m > 0) || !(bearing_sigma_rad > 0))
    return fail("measurement sigmas must be > 0");
  if (!(gate_sigma > 0) || !(gate_chi2_2dof > 0)) return fail("gates must be > 0");
  if (!(scale_min > 0) || !(scale_max > scale_min)) return fail("need 0 < scale_min < scale_max");
  if (!(range_scale_sigma >= 0) || !std::isfinite(range_scale_sigma))
    return fail("range_scale_sigma must be finite and >= 0");
  if (!(range_scale_min > 0) || !(range_scale_max > range_scale_min) ||
      !(range_scale_min <= 1 && range_scale_max >= 1)) {
    return fail("need 0 < range_scale_min <= 1 <= range_scale_max");
  }
  if (max_considered_beacons < 1) return fail("max_considered_beacons must be >= 1");
  if (!(range_outlier_probability >= 0 && range_outlier_probability < 1) ||
      !(bearing_outlier_probability >= 0 && bearing_outlier_probability < 1)) {
    return fail("outlier probabilities must be in [0, 1)");
  }
  if (!(range_outlier_span_m > 0)) return fail("range_outlier_span_m must be > 0");
  if (!(min_inlier_probability >= 0 && min_inlier_probability < 1))
    return fail("min_inlier_probability must be in [0, 1)");
  return true;
}

std::string ScaatEkfSummary::BriefReport() const {
  return fmt::format(
      "SCAAT EKF: {} steps, {} range / {} bearing / {} position updates ({} down-weighted as "
      "likely outliers), {} gated, {} skipped, {} refused by the integrity check{}",
      steps, range_updates, bearing_updates, position_updates, down_weighted, gated, skipped,
      refused,
      beacons_marginalized > 0
          ? fmt::format("; {} considered beacon(s) marginalized out", beacons_marginalized)
          : "");
}

ScaatEkf::ScaatEkf(const Vec2& position_n, const Mat2& position_cov, double psi_rad,
                   double psi_sigma_rad, double scale, double scale_sigma, Options options)
    : options_(options) {
  std::string why;
  if (!options_.IsValid(&why)) throw std::invalid_argument("ScaatEkf options: " + why);
  x_ << position_n, psi_rad, scale, 1.0;
  P_.setZero();
  P_.topLeftCorner<2, 2>() = 0.5 * (position_cov + position_cov.transpose());
  P_(kPsi, kPsi) = psi_sigma_rad * psi_sigma_rad;
  P_(kScale, kScale) = scale_sigma * scale_sigma;
  P_(kRangeScale, kRangeScale) = options_.range_scale_sigma * options_.range_scale_sigma;
  Condition();
}

ScaatEkf::ScaatEkf(const Vec2& position_n, Options options)
    : ScaatEkf(
          position_n,
          Mat2::Identity() * options.initial_position_sigma_m * options.initial_position_sigma_m,
          0.0, options.initial_heading_sigma_rad, 1.0, options.initial_scale_sigma, options) {}

ScaatEkf::ScaatEkf(const State& x, const Cov& P, Options options)
    : options_(options), x_(x), P_(P) {
  std::string why;
  if (!options_.IsValid(&why)) throw std::invalid_argument("ScaatEkf options: " + why);
  Condition();
}

ScaatEkf StartFromInit(const InitResult& init, const Vec2& pdr_n, const ScaatEkfOptions& options) {
  // p = o + R(psi) D: Jacobian in (o, psi).
  Eigen::Matrix3d J = Eigen::Matrix3d::Identity();
  J.block<2, 1>(0, 2) = RotationDerivative(init.psi_rad) * pdr_n;
  const Eigen::Matrix3d C = J * init.cov * J.transpose();
  ScaatEkf::State x;
  x << init.Map(pdr_n), init.psi_rad, 1.0, 1.0;
  ScaatEkf::Cov P = ScaatEkf::Cov::Zero();
  P.topLeftCorner<3, 3>() = C;
  P(ScaatEkf::kScale, ScaatEkf::kScale) = options.initial_scale_sigma * options.initial_scale_sigma;
  P(ScaatEkf::kRangeScale, ScaatEkf::kRangeScale) =
      options.range_scale_sigma * options.range_scale_sigma;
  return ScaatEkf(x, P, options);
}

void ScaatEkf::PredictStep(const Vec2& d, const Mat2& delta_cov, double fraction) {
  const double psi = x_(kPsi), s = x_(kScale);
  const Mat2 R = Rotation(psi);
  // p <- p + s R(psi) d  (sec. 6: step heading corrected by psi, step length by scale)
  Cov F = Cov::Identity();
  F.block<2, 1>(0, kPsi) = s * RotationDerivative(psi) * d;
  F.block<2, 1>(0, kScale) = R * d;
  x_.head<2>() += s * R * d;
  const Mat2 G = s * R;
  const double floor2 =
      options_.step_sigma_floor_m * options_.step_sigma_floor_m * std::clamp(fraction, 0.0, 1.0);
  Cov Q = Cov::Zero();
  Q.topLeftCorner<2, 2>() = G * (delta_cov + Mat2::Identity() * floor2) * G.transpose();
  const double length = d.norm();
  Q(kPsi, kPsi) =
      options_.heading_walk_rad_per_sqrt_m * options_.heading_walk_rad_per_sqrt_m * length;
  Q(kScale, kScale) = options_.scale_walk_per_sqrt_m * options_.scale_walk_per_sqrt_m * length;
  P_ = F * P_ * F.transpose() + Q;
  if (!slots_.empty()) cross_ = F * cross_;  // the beacons do not move
  step_fraction_ += fraction;  // a step split at measurements counts once
  if (step_fraction_ >= 1.0 - 1e-9) ++summary_.steps, step_fraction_ = 0;
  Condition();
}

double ScaatEkf::InlierProbability(double y, double S, double outlier_density,
                                   double outlier_probability) const {
  if (!(outlier_density > 0) || !(outlier_probability > 0)) return 1.0;
  // (1 - p) N(y; 0, S) / ((1 - p) N(y; 0, S) + p c), computed in logs (a far outlier underflows)
  const double log_in = std::log1p(-outlier_probability) - 0.5 * y * y / S -
                        0.5 * std::log(2 * std::numbers::pi * S);
  const double log_out = std::log(outlier_probability * outlier_density);
  return 1.0 / (1.0 + std::exp(std::min(log_out - log_in, 700.0)));
}

template <int M>
UpdateResult ScaatEkf::Update(const Eigen::Matrix<double, M, 1>& y,
                              const Eigen::Matrix<double, M, kDim>& H,
                              const Eigen::Matrix<double, M, M>& R, double gate, const Admit& admit,
                              double outlier_density, double outlier_probability) {
  const Eigen::Matrix<double, M, M> S = H * P_ * H.transpose() + R;
  const Eigen::LDLT<Eigen::Matrix<double, M, M>> ldlt(S);
  if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > 0)) {
    ++summary_.skipped;
    return UpdateResult::kSkipped;
  }
  last_nis_ = y.dot(ldlt.solve(y));
  if (!std::isfinite(last_nis_)) {
    ++summary_.skipped;
    return UpdateResult::kSkipped;
  }
  if (admit && !admit(last_nis_, M)) {
    ++summary_.refused;
    return UpdateResult::kRefused;
  }
  const bool mixture = M == 1 && outlier_density > 0;
  const double w =
      mixture ? InlierProbability(y(0), S(0, 0), outlier_density, outlier_probability) : 1.0;
  if (mixture ? w < options_.min_inlier_probability : last_nis_ > gate) {
    ++summary_.gated;
    return UpdateResult::kGated;
  }
  const Eigen::Matrix<double, kDim, M> K =
      ldlt.solve(H * P_).transpose();  // P H^T S^-1 (S, P symmetric)
  const State dx = K * y;
  const Cov IKH = Cov::Identity() - K * H;
  const Cov P_updated = IKH * P_ * IKH.transpose() + K * R * K.transpose();  // Joseph form
  // Mixture: w N(x + dx, P_updated) + (1 - w) N(x, P), collapsed to its two moments.
  x_ += w * dx;
  P_ = w * P_updated + (1 - w) * P_ + w * (1 - w) * dx * dx.transpose();
  if (!slots_.empty()) cross_ -= w * (K * H * cross_);
  summary_.down_weighted += w < 0.5;
  Condition();
  return UpdateResult::kAccepted;
}

int ScaatEkf::AppendBeacon(int key) {
  if (static_cast<int>(slots_.size()) >= options_.max_considered_beacons) {
    // Marginalize out the least recently used beacon (exact: drop its rows and columns); the
    // last slot moves into its place.
    const int j = static_cast<int>(std::min_element(last_used_.begin(), last_used_.end()) -
                                   last_used_.begin());
    const int last = static_cast<int>(slots_.size()) - 1;
    considered_.erase(slots_[j]);
    if (j != last) {
      cross_.middleCols<2>(2 * j) = cross_.middleCols<2>(2 * last);
      beacons_.middleCols<2>(2 * j) = beacons_.middleCols<2>(2 * last);
      beacons_.middleRows<2>(2 * j) = beacons_.middleRows<2>(2 * last);
      slots_[j] = slots_[last];
      last_used_[j] = last_used_[last];
      considered_[slots_[j]] = j;
    }
    slots_.pop_back();
    last_used_.pop_back();
    cross_.conservativeResize(kDim, 2 * last);
    beacons_.conservativeResize(2 * last, 2 * last);
    ++summary_.beacons_marginalized;
  }
  const int n = static_cast<int>(slots_.size());
  cross_.conservativeResize(kDim, 2 * n + 2);
  beacons_.conservativeResize(2 * n + 2, 2 * n + 2);
  cross_.rightCols<2>().setZero();
  beacons_.rightCols<2>().setZero();
  beacons_.bottomRows<2>().setZero();
  slots_.push_back(key);
  last_used_.push_back(++uses_);
  considered_[key] = n;
  return n;
}

int ScaatEkf::Consider(int key, const Mat2& beacon_cov) {
  const Mat2 b = 0.5 * (beacon_cov + beacon_cov.transpose());
  const auto it = considered_.find(key);
  if (it == considered_.end()) {
    const int j = AppendBeacon(key);
    beacons_.block<2, 2>(2 * j, 2 * j) = b;
    return j;
  }
  const int j = it->second;
  last_used_[j] = ++uses_;
  const Mat2 old = beacons_.block<2, 2>(2 * j, 2 * j);
  if ((old - b).norm() > 1e-12 * (1 + b.norm())) {
    // Symmetric square roots (not Cholesky factors, which depend on the frame's axes).
    const Eigen::SelfAdjointEigenSolver<Mat2> eo(old), en(b);
    if (eo.info() == Eigen::Success && en.info() == Eigen::Success &&
        eo.eigenvalues().minCoeff() > 0 && en.eigenvalues().minCoeff() >= 0) {
      const Mat2 T = eo.operatorInverseSqrt() * en.operatorSqrt();  // B_old^-1/2 B_new^1/2
      cross_.middleCols<2>(2 * j) = cross_.middleCols<2>(2 * j) * T;
      beacons_.middleCols<2>(2 * j) = beacons_.middleCols<2>(2 * j) * T;
      beacons_.middleRows<2>(2 * j) = T.transpose() * beacons_.middleRows<2>(2 * j);
    }
    beacons_.block<2, 2>(2 * j, 2 * j) = b;  // exact (and the fallback: correlations kept)
  }
  return j;
}

void ScaatEkf::ConsiderDrop(int key, double drop_sigma_m) {
  if (!options_.consider_beacons) return;
  const auto it = considered_.find(key);
  const int j = it != considered_.end() ? it->second : AppendBeacon(key);
  if (it != considered_.end()) last_used_[j] = ++uses_;
  // b = p + drop noise: cov(x, b) = P(:, p), cov(b, b_i) = cov(p, b_i), cov(b) = P_pp + drop^2.
  const Cross px = P_.leftCols<2>();
  const Eigen::MatrixXd pb = cross_.topRows<2>();
  cross_.middleCols<2>(2 * j) = px;
  beacons_.middleRows<2>(2 * j) = pb;
  beacons_.middleCols<2>(2 * j) = pb.transpose();
  beacons_.block<2, 2>(2 * j, 2 * j) =
      P_.topLeftCorner<2, 2>() + Mat2::Identity() * drop_sigma_m * drop_sigma_m;
}

Eigen::Matrix<double, ScaatEkf::kDim, 2> ScaatEkf::BeaconCrossCovariance(int beacon_key) const {
  const auto it = considered_.find(beacon_key);
  return it == considered_.end() ? Cross::Zero() : Cross(cross_.middleCols<2>(2 * it->second));
}

UpdateResult ScaatEkf::UpdateConsider(double y, const Eigen::Matrix<double, 1, kDim>& H,
                                      const Eigen::RowVector2d& H_b, double r, int key,
                                      const BeaconPosition& beacon, double gate, const Admit& admit,
                                      double outlier_density, double outlier_probability) {
  const int j = Consider(key, beacon.cov);
  // Schmidt-Kalman update (Schmidt 1966; Simon, Optimal State Estimation, sec. 7.5): the
  // measurement h(x, b); the gain and covariance of x use cov(x, b), b itself is not updated.
  const Cross C = cross_.middleCols<2>(2 * j);
  const Mat2 B = beacons_.block<2, 2>(2 * j, 2 * j);
  const State PHt = P_ * H.transpose() + C * H_b.transpose();
  const double S = (H * PHt)(0) + (H_b * C.transpose() * H.transpose())(0) +
                   (H_b * B * H_b.transpose())(0) + r;
  if (!(S > 0) || !std::isfinite(S)) {
    ++summary_.skipped;
    return UpdateResult::kSkipped;
  }
  last_nis_ = y * y / S;
  if (!std::isfinite(last_nis_)) {
    ++summary_.skipped;
    return UpdateResult::kSkipped;
  }
  if (admit && !admit(last_nis_, 1)) {
    ++summary_.refused;
    return UpdateResult::kRefused;
  }
  const bool mixture = outlier_density > 0;
  const double w = mixture ? InlierProbability(y, S, outlier_density, outlier_probability) : 1.0;
  if (mixture ? w < options_.min_inlier_probability : last_nis_ > gate) {
    ++summary_.gated;
    return UpdateResult::kGated;
  }
  const State K = PHt / S;
  // cov(z, beacons) = H cross + H_b cov(b_j, beacons)
  const Eigen::RowVectorXd zb = H * cross_ + H_b * beacons_.middleRows<2>(2 * j);
  // Mixture (w = 1 without one): w N(x + K y, P - K S K^T) + (1 - w) N(x, P), collapsed; the
  // beacons are not updated in either hypothesis, so their cross-covariance mixes linearly.
  const State dx = K * y;
  x_ += w * dx;
  P_ += -w * K * S * K.transpose() + w * (1 - w) * dx * dx.transpose();
  cross_ -= w * K * zb;
  summary_.down_weighted += w < 0.5;
  Condition();
  return UpdateResult::kAccepted;
}

UpdateResult ScaatEkf::UpdateRange(const BeaconPosition& beacon, double range_m, double sigma_m,
                                   const Admit& admit, int beacon_key) {
  if (!std::isfinite(range_m) || range_m < 0) {
    ++summary_.skipped;
    return UpdateResult::kSkipped;
  }
  const double s = sigma_m > 0 ? sigma_m : options_.range_sigma_m;
  Eigen::RowVector2d Hp;
  const double distance = UltrasoundRange(position(), beacon.position_n, &Hp);
  if (Hp.squaredNorm() == 0) {
    ++summary_.skipped;
    return UpdateResult::kSkipped;
  }
  // h = k |p - B| (the range scale k: the speed of sound the device assumes over the room's).
  const double k = x_(kRangeScale);
  const double predicted = k * distance;
  Hp *= k;
  Eigen::Matrix<double, 1, kDim> H = Eigen::Matrix<double, 1, kDim>::Zero();
  H.head<2>() = Hp;
  H(kRangeScale) = distance;
  const double gate = options_.gate_sigma * options_.gate_sigma;
  const double range_density =
      options_.mixture_updates ? 1.0 / options_.range_outlier_span_m : 0.0;  // uniform outliers
  UpdateResult r;
  if (options_.consider_beacons && beacon_key >= 0) {
    r = UpdateConsider(range_m - predicted, H, -Hp, s * s, beacon_key, beacon, gate, admit,
                       range_density, options_.range_outlier_probability);
  } else {
    Eigen::Matrix<double, 1, 1> R;
    R(0, 0) = s * s + Hp * beacon.cov * Hp.transpose();  // the beacon's uncertainty (H_b = -H_p)
    Eigen::Matrix<double, 1, 1> y;
    y(0) = range_m - predicted;
    r = Update<1>(y, H, R, gate, admit, range_density, options_.range_outlier_probability);
  }
  summary_.range_updates += r == UpdateResult::kAccepted;
  return r;
}

UpdateResult ScaatEkf::UpdateBearing(const BeaconPosition& beacon, double bearing_rad,
                                     double sigma_rad, const Admit& admit, int beacon_key) {
  if (!std::isfinite(bearing_rad) ||
      (position() - beacon.position_n).norm() < options_.min_range_for_bearing_m) {
    ++summary_.skipped;
    return UpdateResult::kSkipped;
  }
  const double s = sigma_rad > 0 ? sigma_rad : options_.bearing_sigma_rad;
  Eigen::RowVector2d Hp;
  const double predicted = UltrasoundBearing(position(), beacon.position_n, &Hp);
  Eigen::Matrix<double, 1, kDim> H = Eigen::Matrix<double, 1, kDim>::Zero();
  H.head<2>() = Hp;
  const double gate = options_.gate_sigma * options_.gate_sigma;
  const double bearing_density =
      options_.mixture_updates ? 0.5 / std::numbers::pi : 0.0;  // uniform on the circle
  UpdateResult r;
  if (options_.consider_beacons && beacon_key >= 0) {
    r = UpdateConsider(WrapAngle(bearing_rad - predicted), H, -Hp, s * s, beacon_key, beacon,
                       gate, admit, bearing_density, options_.bearing_outlier_probability);
  } else {
    Eigen::Matrix<double, 1, 1> R;
    R(0, 0) = s * s + Hp * beacon.cov * Hp.transpose();
    Eigen::Matrix<double, 1, 1> y;
    y(0) = WrapAngle(bearing_rad - predicted);
    r = Update<1>(y, H, R, gate, admit, bearing_density, options_.bearing_outlier_probability);
  }
  summary_.bearing_updates += r == UpdateResult::kAccepted;
  return r;
}

UpdateResult ScaatEkf::UpdatePosition(const BeaconPosition& beacon, double range_m,
                                      double bearing_rad, double range_sigma_m,
                                      double bearing_sigma_rad, const Admit& admit) {
  if (!std::isfinite(range_m) || range_m < 0 || !std::isfinite(bearing_rad)) {
    ++summary_.skipped;
    return UpdateResult::kSkipped;
  }
  Vec2 z;
  Mat2 R;
  PolarToPosition(beacon, range_m, bearing_rad,
                  range_sigma_m > 0 ? range_sigma_m : options_.range_sigma_m,
                  bearing_sigma_rad > 0 ? bearing_sigma_rad : options_.bearing_sigma_rad, &z, &R);
  Eigen::Matrix<double, 2, kDim> H = Eigen::Matrix<double, 2, kDim>::Zero();
  H.leftCols<2>().setIdentity();
  const Vec2 y = z - position();
  const UpdateResult r = Update<2>(y, H, R, options_.gate_chi2_2dof, admit);
  summary_.position_updates += r == UpdateResult::kAccepted;
  return r;
}

UpdateResult ScaatEkf::UpdateHeadingCorrection(double psi_rad, double sigma_rad) {
  if (!std::isfinite(psi_rad) || !(sigma_rad > 0)) {
    ++summary_.skipped;
    return UpdateResult::kSkipped;
  }
  Eigen::Matrix<double, 1, kDim> H = Eigen::Matrix<double, 1, kDim>::Zero();
  H(kPsi) = 1;
  Eigen::Matrix<double, 1, 1> R, y;
  R(0, 0) = sigma_rad * sigma_rad;
  y(0) = WrapAngle(psi_rad - x_(kPsi));
  return Update<1>(y, H, R, options_.gate_sigma * options_.gate_sigma);
}

double ScaatEkf::RangeScaleNis() const {
  const double prior = options_.range_scale_sigma * options_.range_scale_sigma;
  const double learnt = prior - P_(kRangeScale, kRangeScale);
  if (!(prior > 0) || !(learnt >= 0.5 * prior)) return 0;
  const double d = x_(kRangeScale) - 1.0;
  return d * d / learnt;
}

void ScaatEkf::Condition() {
  x_(kPsi) = WrapAngle(x_(kPsi));
  x_(kScale) = std::clamp(x_(kScale), options_.scale_min, options_.scale_max);
  x_(kRangeScale) = std::clamp(x_(kRangeScale), options_.range_scale_min, options_.range_scale_max);
  P_ = 0.5 * (P_ + P_.transpose());
  for (int i = 0; i < kDim; ++i) P_(i, i) = std::max(P_(i, i), 1e-15);
}

// ---------------------------------------------------------------------------------------------

UltrasoundOnlyKf::UltrasoundOnlyKf(const Vec2& position_n, TimeS t, Options options)
    : options_(options), t_(t) {
  x_ << position_n, 0, 0;
  P_.setZero();
  P_.topLeftCorner<2, 2>() = Mat2::Identity() * std::pow(options_.initial_position_sigma_m, 2);
  P_.bottomRightCorner<2, 2>() =
      Mat2::Identity() * std::pow(options_.initial_velocity_sigma_mps, 2);
}

void UltrasoundOnlyKf::PredictTo(TimeS t) {
  const double dt = t - t_;
  if (!(dt > 0)) return;
  Eigen::Matrix4d F = Eigen::Matrix4d::Identity();
  F(0, 2) = F(1, 3) = dt;
  const double q = options_.accel_sigma_mps2 * options_.accel_sigma_mps2;
  Eigen::Matrix4d Q = Eigen::Matrix4d::Zero();
  for (int i = 0; i < 2; ++i) {
    Q(i, i) = q * dt * dt * dt / 3;
    Q(i, i + 2) = Q(i + 2, i) = q * dt * dt / 2;
    Q(i + 2, i + 2) = q * dt;
  }
  x_ = F * x_;
  P_ = F * P_ * F.transpose() + Q;
  P_ = 0.5 * (P_ + P_.transpose());
  t_ = t;
}

UpdateResult UltrasoundOnlyKf::UpdatePosition(TimeS t, const BeaconPosition& beacon, double range_m,
                                              double bearing_rad, double range_sigma_m,
                                              double bearing_sigma_rad) {
  if (!std::isfinite(range_m) || range_m < 0 || !std::isfinite(bearing_rad))
    return UpdateResult::kSkipped;
  PredictTo(t);
  Vec2 z;
  Mat2 R;
  PolarToPosition(beacon, range_m, bearing_rad,
                  range_sigma_m > 0 ? range_sigma_m : options_.range_sigma_m,
                  bearing_sigma_rad > 0 ? bearing_sigma_rad : options_.bearing_sigma_rad, &z, &R);
  const Mat2 S = P_.topLeftCorner<2, 2>() + R;
  const Vec2 y = z - x_.head<2>();
  const Eigen::LDLT<Mat2> ldlt(S);
  if (ldlt.info() != Eigen::Success) return UpdateResult::kSkipped;
  if (y.dot(ldlt.solve(y)) > options_.gate_chi2_2dof) {
    ++gated_;
    return UpdateResult::kGated;
  }
  const Eigen::Matrix<double, 4, 2> K = P_.leftCols<2>() * S.inverse();
  x_ += K * y;
  Eigen::Matrix<double, 2, 4> H = Eigen::Matrix<double, 2, 4>::Zero();
  H.leftCols<2>().setIdentity();
  const Eigen::Matrix4d IKH = Eigen::Matrix4d::Identity() - K * H;
  P_ = IKH * P_ * IKH.transpose() + K * R * K.transpose();
  P_ = 0.5 * (P_ + P_.transpose());
  ++accepted_;
  return UpdateResult::kAccepted;
}

// ---------------------------------------------------------------------------------------------

Vec2 InitResult::Map(const Vec2& pdr_n) const { return origin_n + Rotation(psi_rad) * pdr_n; }

namespace {

struct Solved {
  Eigen::Vector3d theta;  // origin x, origin y, psi
  double cost = 0;
  double rms = 0;
  Eigen::Matrix3d info = Eigen::Matrix3d::Zero();
};

// Robust Gauss-Newton (IRLS with Huber weights) from `theta`.
Solved SolveFrom(const std::vector<InitMeasurement>& ms, Eigen::Vector3d theta, double k,
                 const std::optional<OriginPrior>& origin) {
  Solved out;
  for (int it = 0; it < 30; ++it) {
    Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
    Eigen::Vector3d g = Eigen::Vector3d::Zero();
    double cost = 0, sq = 0;
    int n = 0;
    const Mat2 R = Rotation(theta(2)), dR = RotationDerivative(theta(2));
    auto add = [&](double e, const Eigen::RowVector2d& Hp, const Vec2& d_pdr) {
      Eigen::RowVector3d J;
      J << Hp, Hp * dR * d_pdr;
      const double a = std::abs(e);
      const double w = a <= k ? 1.0 : k / a;
      cost += a <= k ? 0.5 * e * e : k * (a - 0.5 * k);
      sq += e * e;
      ++n;
      A += w * J.transpose() * J;
      g += w * J.transpose() * e;
    };
    if (origin) {  // (o - mu) / sigma per axis, no robust loss
      const double w = 1.0 / origin->sigma_m;
      for (int axis = 0; axis < 2; ++axis) {
        const double e = (theta(axis) - origin->position_n(axis)) * w;
        Eigen::RowVector3d J = Eigen::RowVector3d::Zero();
        J(axis) = w;
        cost += 0.5 * e * e;
        A += J.transpose() * J;
        g += J.transpose() * e;
      }
    }
    for (const auto& m : ms) {
      const Vec2 p = theta.head<2>() + R * m.pdr_n;
      Eigen::RowVector2d Hp;
      const double r = UltrasoundRange(p, m.beacon_n, &Hp);
      add((r - m.range_m) / m.range_sigma_m, Hp / m.range_sigma_m, m.pdr_n);
      if (m.bearing_rad && r > 0.3) {
        const double b = UltrasoundBearing(p, m.beacon_n, &Hp);
        add(WrapAngle(b - *m.bearing_rad) / m.bearing_sigma_rad, Hp / m.bearing_sigma_rad, m.pdr_n);
      }
    }
    out.theta = theta;
    out.cost = cost;
    out.rms = n ? std::sqrt(sq / n) : 0;
    out.info = A;
    const Eigen::Vector3d step = (A + Eigen::Matrix3d::Identity() * 1e-6).ldlt().solve(-g);
    if (!step.allFinite()) break;
    theta += step;
    theta(2) = WrapAngle(theta(2));
    if (step.head<2>().norm() < 1e-5 && std::abs(step(2)) < 1e-6) break;
  }
  return out;
}

}  // namespace

InitResult InitializeFromUltrasound(const std::vector<InitMeasurement>& ms, const InitOptions& o,
                                    const std::optional<OriginPrior>& origin) {
  if (origin && (!origin->position_n.allFinite() || !(origin->sigma_m > 0)))
    throw std::invalid_argument("InitializeFromUltrasound: the origin prior needs a finite "
                                "position and a sigma > 0");
  InitResult result;
  if (static_cast<int>(ms.size()) < o.min_measurements) {
    result.why = fmt::format("{} of {} measurements", ms.size(), o.min_measurements);
    return result;
  }
  std::vector<Vec2> beacons;
  double track = 0;
  for (const auto& m : ms) {
    if (std::none_of(beacons.begin(), beacons.end(),
                     [&](const Vec2& b) { return (b - m.beacon_n).norm() < 1e-6; })) {
      beacons.push_back(m.beacon_n);
    }
    track = std::max(track, m.pdr_n.norm());
  }
  if ((static_cast<int>(beacons.size()) < o.min_beacons && track < o.min_track_m) ||
      track < o.min_heading_track_m) {
    result.why = fmt::format("{} beacon(s) heard over {:.1f} m of walk", beacons.size(), track);
    return result;
  }
  std::vector<Solved> solutions;
  for (int g = 0; g < o.heading_grid; ++g) {
    const double psi = -std::numbers::pi + 2 * std::numbers::pi * g / o.heading_grid;
    const Mat2 R = Rotation(psi);
    // Origin guess: each fix (with bearing) or beacon, moved back along the rotated track.
    Vec2 sum = Vec2::Zero();
    for (const auto& m : ms) {
      const Vec2 fix = m.bearing_rad ? Vec2(m.beacon_n + m.range_m * Vec2(std::cos(*m.bearing_rad),
                                                                          std::sin(*m.bearing_rad)))
                                     : m.beacon_n;
      sum += fix - R * m.pdr_n;
    }
    const Vec2 guess = origin ? origin->position_n : Vec2(sum / static_cast<double>(ms.size()));
    solutions.push_back(
        SolveFrom(ms, Eigen::Vector3d(guess.x(), guess.y(), psi), o.huber_k, origin));
  }
  std::sort(solutions.begin(), solutions.end(),
            [](const Solved& a, const Solved& b) { return a.cost < b.cost; });
  const Solved& best = solutions.front();
  // A distinct solution that explains the data almost as well: wait for more measurements.
  for (std::size_t i = 1; i < solutions.size(); ++i) {
    const Solved& s = solutions[i];
    const bool distinct = (s.theta.head<2>() - best.theta.head<2>()).norm() > 1.0 ||
                          std::abs(WrapAngle(s.theta(2) - best.theta(2))) > 0.5;
    if (distinct && s.cost < best.cost + 3.0) {
      result.why =
          fmt::format("ambiguous: two solutions {:.1f} m / {:.0f} deg apart fit as well",
                      (s.theta.head<2>() - best.theta.head<2>()).norm(),
                      std::abs(WrapAngle(s.theta(2) - best.theta(2))) * 180 / std::numbers::pi);
      return result;
    }
  }
  if (best.rms > o.max_rms_normalized) {
    result.why = fmt::format("residuals too large (rms {:.2f} sigma)", best.rms);
    return result;
  }
  const Eigen::LDLT<Eigen::Matrix3d> ldlt(best.info);
  if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > 1e-9)) {
    result.why = "geometry does not fix position and heading";
    return result;
  }
  result.ok = true;
  result.origin_n = best.theta.head<2>();
  result.psi_rad = best.theta(2);
  result.cov = ldlt.solve(Eigen::Matrix3d::Identity());
  result.cov = 0.5 * (result.cov + result.cov.transpose());
  result.rms_normalized = best.rms;
  return result;
}

}  // namespace trailmark::beacons

// SPDX-License-Identifier: MIT
#include "trailmark/landmarks/landmark_ukf.h"

#include <Eigen/Cholesky>
#include <Eigen/Dense>
#include <cmath>

namespace trailmark::landmarks {

LandmarkUkf::LandmarkUkf(const Vec2& start, radio::LogDistanceModel radio,
                         LandmarkUkfOptions options)
    : radio_(radio), options_(options) {
  x_.head<2>() = start;
  P_.setZero();
  P_.topLeftCorner<2, 2>() = Mat2::Identity() * options.initial_sigma_m * options.initial_sigma_m;
  P_.block<2, 2>(2, 2) = Mat2::Identity() * 0.25;
  P_.block<2, 2>(4, 4) = Mat2::Identity() * 1.0;
}

LandmarkUkf::Cov LandmarkUkf::Transition(double dt) {
  Cov F = Cov::Identity();
  for (int k = 0; k < 2; ++k) {
    F(k, 2 + k) = dt;
    F(k, 4 + k) = 0.5 * dt * dt;  // eq. (20) prints dt^2; dt^2/2 is the exact kinematics
    F(2 + k, 4 + k) = dt;
  }
  return F;
}

LandmarkUkf::Cov LandmarkUkf::ProcessNoise(double dt, double tau) {
  const double d2 = dt * dt, d3 = d2 * dt, d4 = d3 * dt, d5 = d4 * dt;
  Eigen::Matrix3d q;
  q << d5 / 20, d4 / 8, d3 / 6, d4 / 8, d3 / 3, d2 / 2, d3 / 6, d2 / 2, dt;  // eq. (20)
  Cov Q = Cov::Zero();
  for (int k = 0; k < 2; ++k) {
    const int idx[3] = {k, 2 + k, 4 + k};
    for (int a = 0; a < 3; ++a) {
      for (int b = 0; b < 3; ++b) Q(idx[a], idx[b]) = tau * q(a, b);
    }
  }
  return Q;
}

void LandmarkUkf::Symmetrize() { P_ = 0.5 * (P_ + P_.transpose()); }

void LandmarkUkf::Predict(double dt) {
  if (!(dt > 0)) return;
  // eq. (19): the model is linear, so the unscented prediction equals the Kalman one.
  const Cov F = Transition(dt);
  x_ = F * x_;
  P_ = F * P_ * F.transpose() + ProcessNoise(dt, options_.tau);
  Symmetrize();
}

bool LandmarkUkf::UpdateRssi(const Vec2& landmark, const Mat2& landmark_cov, double rssi_dbm,
                             const std::function<bool(double nis)>& admit) {
  constexpr int n = 6;
  const double a = options_.ut_alpha, k = options_.ut_kappa;
  const double lambda = a * a * (n + k) - n;
  const double wm0 = lambda / (n + lambda), wc0 = wm0 + (1 - a * a + options_.ut_beta);
  const double wi = 1.0 / (2 * (n + lambda));
  Eigen::LLT<Cov> llt((n + lambda) * P_);
  if (llt.info() != Eigen::Success) {
    P_ += Cov::Identity() * 1e-9;
    llt.compute((n + lambda) * P_);
    if (llt.info() != Eigen::Success) return false;
  }
  const Cov L = llt.matrixL();
  auto h = [&](const State& s) {  // eq. (21)
    const double d = std::max((s.head<2>() - landmark).norm(), 0.1);
    return radio_.alpha_dbm - 10 * radio_.path_loss_exponent * std::log10(d);
  };
  State sigma[2 * n + 1];
  double z[2 * n + 1];
  sigma[0] = x_;
  for (int i = 0; i < n; ++i) {
    sigma[1 + i] = x_ + L.col(i);
    sigma[1 + n + i] = x_ - L.col(i);
  }
  double z_hat = 0;
  for (int i = 0; i < 2 * n + 1; ++i) {
    z[i] = h(sigma[i]);
    z_hat += (i == 0 ? wm0 : wi) * z[i];
  }
  // Landmark position uncertainty, to first order along the line of sight.
  const Vec2 los = x_.head<2>() - landmark;
  const double d = std::max(los.norm(), 0.1);
  const double slope = 10 * radio_.path_loss_exponent / (std::log(10.0) * d);
  const Vec2 u = los.norm() > 1e-9 ? Vec2(los / los.norm()) : Vec2(1, 0);
  double S = options_.rssi_sigma_db * options_.rssi_sigma_db + slope * slope * u.dot(landmark_cov * u);
  State Pxz = State::Zero();
  for (int i = 0; i < 2 * n + 1; ++i) {
    const double w = i == 0 ? wc0 : wi;
    S += w * (z[i] - z_hat) * (z[i] - z_hat);
    Pxz += w * (sigma[i] - x_) * (z[i] - z_hat);
  }
  const double nu = rssi_dbm - z_hat;
  if (admit && !admit(nu * nu / S)) return false;
  if (std::abs(nu) > options_.gate_sigma * std::sqrt(S)) return false;
  const State K = Pxz / S;
  x_ += K * nu;
  P_ -= K * S * K.transpose();
  Symmetrize();
  return true;
}

void LandmarkUkf::LinearUpdate(const Eigen::Matrix<double, 2, 6>& H, const Vec2& z, const Mat2& R) {
  const Mat2 S = H * P_ * H.transpose() + R;
  const Eigen::Matrix<double, 6, 2> K = P_ * H.transpose() * S.inverse();
  x_ += K * (z - H * x_);
  // Joseph form: stays symmetric positive definite.
  const Cov I_KH = Cov::Identity() - K * H;
  P_ = I_KH * P_ * I_KH.transpose() + K * R * K.transpose();
  Symmetrize();
}

void LandmarkUkf::UpdateAcceleration(const Vec2& accel_n) {
  Eigen::Matrix<double, 2, 6> H = Eigen::Matrix<double, 2, 6>::Zero();
  H(0, 4) = H(1, 5) = 1;  // eq. (22)
  const double s = options_.accel_sigma_mps2;
  LinearUpdate(H, accel_n, Mat2::Identity() * s * s);
}

void LandmarkUkf::UpdateVelocity(const Vec2& velocity_n, double sigma_mps) {
  Eigen::Matrix<double, 2, 6> H = Eigen::Matrix<double, 2, 6>::Zero();
  H(0, 2) = H(1, 3) = 1;
  LinearUpdate(H, velocity_n, Mat2::Identity() * sigma_mps * sigma_mps);
}

void LandmarkUkf::PredictWithDisplacement(const Vec2& delta_n, const Mat2& cov) {
  x_.head<2>() += delta_n;
  P_.topLeftCorner<2, 2>() += cov;
  Symmetrize();
}

void LandmarkUkf::ZeroMotion() {
  x_.tail<4>().setZero();
  P_.bottomRows<4>().setZero();
  P_.rightCols<4>().setZero();
  P_.bottomRightCorner<4, 4>() = Eigen::Matrix4d::Identity() * 1e-6;
}

}  // namespace trailmark::landmarks

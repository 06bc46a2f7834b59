// SPDX-License-Identifier: MIT
#pragma once
// Helpers of the landmark tracker's tests (landmark_tracker_test.cpp, tracker_bank_test.cpp):
// a step, the tracker's RSSI model written out, and a central-difference gradient.

#include <Eigen/Core>
#include <cmath>
#include <functional>

#include "trailmark/core/measurements.h"
#include "trailmark/landmarks/landmark_tracker.h"

namespace trailmark::landmarks::testing {

/// ff1's step of `d` ending at `t` (0.5 s long), 0.004 m^2 per horizontal axis.
inline Step MakeStep(TimeS t, const Vec2& d) {
  Step s;
  s.t0 = t - 0.5;
  s.t1 = t;
  s.agent = "ff1";
  s.delta_n = Vec3(d.x(), d.y(), 0);
  s.variance_m2 = Vec3(0.004, 0.004, 1e-4);
  return s;
}

/// The tracker's measurement model for a test: h(x) at the state's first kFixed entries plus
/// the bias state `b`, the landmark at `landmark` (dz above the handheld).
inline double Model(const Eigen::VectorXd& x, const Vec2& landmark, double dz, int b) {
  const double d = std::sqrt((x.head<2>() - landmark).squaredNorm() + dz * dz);
  return x(LandmarkTracker::kAlpha) - 10 * x(LandmarkTracker::kExponent) * std::log10(d) + x(b);
}

/// d f / d x by central differences (step 1e-6).
inline Eigen::VectorXd NumericGradient(const std::function<double(const Eigen::VectorXd&)>& f,
                                       const Eigen::VectorXd& x) {
  Eigen::VectorXd g(x.size());
  for (int i = 0; i < x.size(); ++i) {
    Eigen::VectorXd xp = x, xm = x;
    xp(i) += 1e-6;
    xm(i) -= 1e-6;
    g(i) = (f(xp) - f(xm)) / 2e-6;
  }
  return g;
}

/// The model's Jacobian at x, numerically.
inline Eigen::VectorXd NumericJacobian(const Eigen::VectorXd& x, const Vec2& landmark, double dz,
                                       int b) {
  return NumericGradient([&](const Eigen::VectorXd& v) { return Model(v, landmark, dz, b); }, x);
}

}  // namespace trailmark::landmarks::testing

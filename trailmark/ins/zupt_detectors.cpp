// SPDX-License-Identifier: MIT
#include "trailmark/ins/zupt_detectors.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace trailmark::ins {

DetectorKind ParseDetectorKind(const std::string& name) {
  if (name == "shoe") return DetectorKind::kShoe;
  if (name == "are") return DetectorKind::kAre;
  if (name == "mv") return DetectorKind::kMv;
  if (name == "mag") return DetectorKind::kMag;
  if (name == "adaptive") return DetectorKind::kAdaptive;
  throw std::invalid_argument("unknown zero-velocity detector '" + name +
                              "' (known: shoe, are, mv, mag, adaptive)");
}

std::string ToString(DetectorKind kind) {
  switch (kind) {
    case DetectorKind::kShoe: return "shoe";
    case DetectorKind::kAre: return "are";
    case DetectorKind::kMv: return "mv";
    case DetectorKind::kMag: return "mag";
    case DetectorKind::kAdaptive: return "adaptive";
  }
  return "?";
}

double DefaultGamma(DetectorKind kind) {
  switch (kind) {
    case DetectorKind::kShoe: return 8.5e7;   // PyShoe's fixed threshold (W = 5, 200 Hz)
    case DetectorKind::kAre: return 7.2e7;    // PyShoe's ARED 0.55 (rad/s)^2 / sigma_g^2
    case DetectorKind::kMv: return 1.0e6;     // 0.96 (m/s^2)^2 / sigma_a^2 (chosen on PyShoe VICON)
    case DetectorKind::kMag: return 3.0e6;    // 2.9 (m/s^2)^2 / sigma_a^2 (chosen on PyShoe VICON)
    case DetectorKind::kAdaptive: return 8.5e7;
  }
  return 8.5e7;
}

ZuptDetector::ZuptDetector(DetectorOptions options)
    : options_(options), gamma_(options.gamma.value_or(DefaultGamma(options.kind))) {
  if (options_.window < 1) throw std::invalid_argument("ZuptDetector: window must be >= 1");
}

double ZuptDetector::Statistic(std::size_t begin, std::size_t end) const {
  const double n = static_cast<double>(end - begin);
  Vec3 a_mean = Vec3::Zero();
  for (std::size_t k = begin; k < end; ++k) a_mean += window_[k].first;
  a_mean /= n;
  const double inv_a = 1.0 / (options_.sigma_a_mps2 * options_.sigma_a_mps2);
  const double inv_g = 1.0 / (options_.sigma_g_radps * options_.sigma_g_radps);
  const double g = options_.gravity_mps2;
  double t = 0;
  switch (options_.kind) {
    case DetectorKind::kShoe:
    case DetectorKind::kAdaptive: {
      const Vec3 up = a_mean.norm() > 1e-9 ? Vec3(a_mean.normalized()) : Vec3::UnitZ();
      for (std::size_t k = begin; k < end; ++k) {
        t += (window_[k].first - g * up).squaredNorm() * inv_a +
             window_[k].second.squaredNorm() * inv_g;  // Skog 2010, eq. (10)
      }
      break;
    }
    case DetectorKind::kAre:
      for (std::size_t k = begin; k < end; ++k) t += window_[k].second.squaredNorm() * inv_g;
      break;
    case DetectorKind::kMv:
      for (std::size_t k = begin; k < end; ++k) t += (window_[k].first - a_mean).squaredNorm() * inv_a;
      break;
    case DetectorKind::kMag:
      for (std::size_t k = begin; k < end; ++k) {
        const double m = window_[k].first.norm() - g;
        t += m * m * inv_a;
      }
      break;
  }
  return t / n;
}

ZuptDetector::Decision ZuptDetector::Decide(double statistic, double dt_s) {
  double threshold = gamma_;
  if (options_.kind == DetectorKind::kAdaptive) {
    // Track the swing energy (a decaying peak of the statistic) and scale the threshold.
    swing_energy_ = std::max(statistic, swing_energy_ * std::exp(-dt_s / options_.adaptive_tau_s));
    const double scale = std::clamp(
        std::pow(std::max(swing_energy_, 1.0) / options_.adaptive_reference, options_.adaptive_power),
        options_.adaptive_min_scale, options_.adaptive_max_scale);
    threshold = gamma_ * scale;
  }
  return {statistic < threshold, statistic, threshold};
}

std::optional<ZuptDetector::Decision> ZuptDetector::Add(const Vec3& accel_b, const Vec3& gyro_b,
                                                        double dt_s) {
  last_dt_ = dt_s > 0 ? dt_s : last_dt_;
  window_.emplace_back(accel_b, gyro_b);
  ++seen_;
  const auto W = static_cast<std::size_t>(options_.window);
  if (window_.size() > W) window_.pop_front();
  if (window_.size() < W) {
    // Centred window: the first decisions use a window truncated at the start.
    if (window_.size() <= static_cast<std::size_t>(Delay())) return std::nullopt;
    return Decide(Statistic(0, window_.size()), last_dt_);
  }
  return Decide(Statistic(0, W), last_dt_);
}

std::vector<ZuptDetector::Decision> ZuptDetector::Flush() {
  std::vector<Decision> out;
  // The last Delay() samples: windows truncated at the end.
  const std::size_t W = window_.size();
  const std::size_t pending = std::min<std::size_t>(static_cast<std::size_t>(Delay()), W);
  for (std::size_t k = 0; k < pending; ++k) {
    const std::size_t begin = k + 1;
    if (begin >= W) break;
    out.push_back(Decide(Statistic(begin, W), last_dt_));
  }
  return out;
}

}  // namespace trailmark::ins

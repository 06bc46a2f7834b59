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

namespace {
struct DetectorNormalizers {
  double inv_a, inv_g, g;  ///< 1 / sigma_a^2, 1 / sigma_g^2, gravity
};
DetectorNormalizers Normalizers(const DetectorOptions& o) {
  return {1.0 / (o.sigma_a_mps2 * o.sigma_a_mps2), 1.0 / (o.sigma_g_radps * o.sigma_g_radps),
          o.gravity_mps2};
}
}  // namespace

ZuptDetector::ZuptDetector(DetectorOptions options)
    : options_(options), gamma_(options.gamma.value_or(DefaultGamma(options.kind))) {
  if (options_.window < 1) throw std::invalid_argument("ZuptDetector: window must be >= 1");
  ring_.resize(static_cast<std::size_t>(options_.window));
}

double ZuptDetector::Statistic(std::size_t begin, std::size_t end) const {
  // The statistics as the paper writes them, each sample's term summed.
  const double n = static_cast<double>(end - begin);
  Vec3 a_mean = Vec3::Zero();
  for (std::size_t k = begin; k < end; ++k) a_mean += At(k).first;
  a_mean /= n;
  const auto [inv_a, inv_g, g] = Normalizers(options_);
  double t = 0;
  switch (options_.kind) {
    case DetectorKind::kShoe:
    case DetectorKind::kAdaptive: {
      const Vec3 up = a_mean.norm() > 1e-9 ? Vec3(a_mean.normalized()) : Vec3::UnitZ();
      for (std::size_t k = begin; k < end; ++k) {
        t += (At(k).first - g * up).squaredNorm() * inv_a +
             At(k).second.squaredNorm() * inv_g;  // Skog 2010, eq. (10)
      }
      break;
    }
    case DetectorKind::kAre:  // eq. (13)
      for (std::size_t k = begin; k < end; ++k) t += At(k).second.squaredNorm() * inv_g;
      break;
    case DetectorKind::kMv:  // eq. (11)
      for (std::size_t k = begin; k < end; ++k) t += (At(k).first - a_mean).squaredNorm() * inv_a;
      break;
    case DetectorKind::kMag:  // eq. (12)
      for (std::size_t k = begin; k < end; ++k) {
        const double m = At(k).first.norm() - g;
        t += m * m * inv_a;
      }
      break;
  }
  return t / n;
}

double ZuptDetector::RunningStatistic() const {
  return FromSums(static_cast<double>(size_), sum_a_, sum_aa_, sum_norm_a_, sum_ww_);
}

double ZuptDetector::FromSums(double n, const Vec3& sum_a, double sum_aa, double sum_norm_a,
                              double sum_ww) const {
  const auto [inv_a, inv_g, g] = Normalizers(options_);
  double t = 0;
  switch (options_.kind) {
    case DetectorKind::kShoe:
    case DetectorKind::kAdaptive: {
      // Skog 2010, eq. (10): sum |a_k - g u|^2 with u the mean's direction (z when it is ~0),
      // expanded: sum |a_k|^2 - 2 g u . sum a_k + n g^2.
      const double norm = sum_a.norm();
      const double u_dot_sum = norm > 1e-9 * n ? norm : sum_a.z();
      t = (sum_aa - 2 * g * u_dot_sum + n * g * g) * inv_a + sum_ww * inv_g;
      break;
    }
    case DetectorKind::kAre:  // eq. (13)
      t = sum_ww * inv_g;
      break;
    case DetectorKind::kMv:  // eq. (11): sum |a_k - a_mean|^2 = sum |a_k|^2 - |sum a_k|^2 / n
      t = (sum_aa - sum_a.squaredNorm() / n) * inv_a;
      break;
    case DetectorKind::kMag:  // eq. (12): sum (|a_k| - g)^2
      t = (sum_aa - 2 * g * sum_norm_a + n * g * g) * inv_a;
      break;
  }
  // Each term is a sum of squares: >= 0 (the expanded form may round to a tiny negative).
  return std::max(0.0, t / n);
}

void ZuptDetector::Resum() {
  sum_a_.setZero();
  sum_aa_ = sum_norm_a_ = sum_ww_ = 0;
  for (std::size_t k = 0; k < size_; ++k) {
    const auto& [a, w] = At(k);
    sum_a_ += a;
    sum_aa_ += a.squaredNorm();
    sum_norm_a_ += a.norm();
    sum_ww_ += w.squaredNorm();
  }
  since_resum_ = 0;
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
  ++seen_;
  const std::size_t W = ring_.size();
  if (size_ == W) {  // the oldest sample leaves the window
    const auto& [a, w] = ring_[head_];
    sum_a_ -= a;
    sum_aa_ -= a.squaredNorm();
    sum_norm_a_ -= a.norm();
    sum_ww_ -= w.squaredNorm();
    ring_[head_] = {accel_b, gyro_b};
    head_ = (head_ + 1) % W;
  } else {
    ring_[(head_ + size_) % W] = {accel_b, gyro_b};
    ++size_;
  }
  sum_a_ += accel_b;
  sum_aa_ += accel_b.squaredNorm();
  sum_norm_a_ += accel_b.norm();
  sum_ww_ += gyro_b.squaredNorm();
  if (++since_resum_ >= W) Resum();  // bounds the rounding of the running sums
  // Centred window: the first decisions use a window truncated at the start.
  if (size_ < W && size_ <= static_cast<std::size_t>(Delay())) return std::nullopt;
  return Decide(options_.reference_arithmetic ? Statistic(0, size_) : RunningStatistic(), last_dt_);
}

std::vector<ZuptDetector::Decision> ZuptDetector::Flush() {
  std::vector<Decision> out;
  // The last Delay() samples: windows truncated at the end.
  const std::size_t W = size_;
  const std::size_t pending = std::min<std::size_t>(static_cast<std::size_t>(Delay()), W);
  for (std::size_t k = 0; k < pending; ++k) {
    const std::size_t begin = k + 1;
    if (begin >= W) break;
    out.push_back(Decide(Statistic(begin, W), last_dt_));
  }
  return out;
}

}  // namespace trailmark::ins

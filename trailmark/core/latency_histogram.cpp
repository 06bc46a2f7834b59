// SPDX-License-Identifier: MIT
#include "trailmark/core/latency_histogram.h"

#include <algorithm>
#include <cmath>

namespace trailmark {

namespace {
std::size_t Bucket(double value) {
  if (!(value >= LatencyHistogram::kMin)) return 0;  // also NaN
  const double b = std::log2(value / LatencyHistogram::kMin) * LatencyHistogram::kPerDoubling;
  return 1 + static_cast<std::size_t>(std::min(b, 1e6));
}
}  // namespace

void LatencyHistogram::Add(double value) {
  if (std::isnan(value)) value = 0;
  const std::size_t b = Bucket(value);
  if (b >= buckets_.size()) buckets_.resize(b + 1, 0);
  ++buckets_[b];
  ++count_;
  max_ = std::max(max_, value);
}

double LatencyHistogram::Percentile(double q) const {
  if (count_ == 0) return 0;
  if (q >= 100) return max_;
  const auto rank = static_cast<std::uint64_t>(std::max(q, 0.0) / 100.0 * (count_ - 1));
  std::uint64_t seen = 0;
  for (std::size_t b = 0; b < buckets_.size(); ++b) {
    seen += buckets_[b];
    if (seen > rank) {
      // Bucket b >= 1 holds [kMin 2^((b-1)/k), kMin 2^(b/k)): its geometric centre.
      const double centre =
          b == 0 ? kMin / 2 : kMin * std::exp2((static_cast<double>(b) - 0.5) / kPerDoubling);
      return std::min(centre, max_);
    }
  }
  return max_;
}

}  // namespace trailmark

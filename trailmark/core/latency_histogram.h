// SPDX-License-Identifier: MIT
#pragma once
/// Percentiles of many durations (or any non-negative values) in fixed memory: log-spaced
/// buckets, kPerDoubling to each doubling from kMin, so that a percentile is the centre of the
/// bucket holding the exact one — within half a bucket, 1.1 % — and the exact largest value.
/// A per-row latency kept as a vector of every value grew by 4 bytes a row (96 MB over a
/// 4-hour incident's 24 M rows) and each summary copied and partially sorted it. No I/O.

#include <cstddef>
#include <cstdint>
#include <vector>

namespace trailmark {

class LatencyHistogram {
 public:
  static constexpr double kMin = 1e-3;     ///< values below (and negative ones) share bucket 0
  static constexpr int kPerDoubling = 32;  ///< bucket width 2^(1/32): 2.2 %

  /// Adds one value; NaN is counted as 0.
  void Add(double value);
  std::size_t count() const { return count_; }
  /// The largest value added (0 when none).
  double max() const { return max_; }
  /// The q-th percentile (q in [0, 100]) as the sample of rank floor(q / 100 x (count - 1)) in
  /// ascending order, to within half a bucket (the centre of its bucket; never above max());
  /// q = 100 is max() exactly; 0 when empty.
  double Percentile(double q) const;

 private:
  std::vector<std::uint64_t> buckets_;
  std::size_t count_ = 0;
  double max_ = 0;
};

}  // namespace trailmark

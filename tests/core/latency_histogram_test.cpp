// SPDX-License-Identifier: MIT
#include "trailmark/core/latency_histogram.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

namespace trailmark {
namespace {

// The reference: the sample of rank floor(q/100 (n-1)) of the sorted values.
double Exact(std::vector<double> v, double q) {
  const auto k = static_cast<std::size_t>(q / 100.0 * (v.size() - 1));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

TEST(LatencyHistogram, PercentilesAreTheExactOnesWithinHalfABucket) {
  std::mt19937_64 rng(7);
  // Latencies of a few microseconds with a long tail (log-normal), and a mixture with a cluster
  // of slow rows.
  std::lognormal_distribution<double> body(std::log(2.0), 1.0), tail(std::log(3000.0), 0.5);
  std::uniform_real_distribution<double> u(0, 1);
  for (const double slow_share : {0.0, 0.02}) {
    LatencyHistogram h;
    std::vector<double> v;
    for (int i = 0; i < 200000; ++i) {
      const double x = u(rng) < slow_share ? tail(rng) : body(rng);
      v.push_back(x);
      h.Add(x);
    }
    ASSERT_EQ(h.count(), v.size());
    const double half_bucket = std::exp2(0.5 / LatencyHistogram::kPerDoubling) - 1;  // 1.1 %
    for (const double q : {0.0, 1.0, 25.0, 50.0, 90.0, 99.0, 99.9}) {
      const double exact = Exact(v, q);
      EXPECT_NEAR(h.Percentile(q), exact, half_bucket * exact * (1 + 1e-9))
          << q << " " << slow_share;
    }
    EXPECT_EQ(h.Percentile(100), *std::max_element(v.begin(), v.end()));
    EXPECT_EQ(h.max(), *std::max_element(v.begin(), v.end()));
  }
}

TEST(LatencyHistogram, SmallEmptyAndOddValues) {
  LatencyHistogram h;
  EXPECT_EQ(h.Percentile(50), 0.0);
  EXPECT_EQ(h.count(), 0u);
  h.Add(5.0);
  EXPECT_NEAR(h.Percentile(0), 5.0, 5.0 * 0.012);
  EXPECT_EQ(h.Percentile(100), 5.0);
  // Below kMin, negative and NaN share the lowest bucket; none is above the maximum.
  h.Add(0.0);
  h.Add(-1.0);
  h.Add(std::numeric_limits<double>::quiet_NaN());
  EXPECT_EQ(h.count(), 4u);
  EXPECT_LE(h.Percentile(0), LatencyHistogram::kMin);
  EXPECT_EQ(h.max(), 5.0);
  // A huge value does not need a huge table beyond its bucket, and is the max exactly.
  h.Add(1e12);
  EXPECT_EQ(h.Percentile(100), 1e12);
  EXPECT_NEAR(h.Percentile(99), 5.0, 5.0 * 0.012);  // rank 3 of 0, 0, 0, 5, 1e12
}

}  // namespace
}  // namespace trailmark

// SPDX-License-Identifier: MIT
#include "trailmark/integrity/consistency.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace trailmark::integrity {
namespace {

TEST(ChiSquareQuantile, MatchesPublishedTables) {
  // Reference: NIST/SEMATECH e-Handbook, table 1.3.6.7.4 (upper critical values).
  EXPECT_NEAR(ChiSquareQuantile(1, 0.95), 3.841, 1e-3);
  EXPECT_NEAR(ChiSquareQuantile(2, 0.95), 5.991, 1e-3);
  EXPECT_NEAR(ChiSquareQuantile(2, 0.999), 13.816, 1e-3);
  EXPECT_NEAR(ChiSquareQuantile(10, 0.999), 29.588, 1e-3);
  EXPECT_NEAR(ChiSquareQuantile(100, 0.99), 135.807, 1e-3);
  EXPECT_THROW(ChiSquareQuantile(0, 0.5), std::invalid_argument);
  EXPECT_THROW(ChiSquareQuantile(3, 1.0), std::invalid_argument);
}

/// NIS of a scalar update whose error is `scale` times what the estimator believes.
double Nis(std::mt19937& rng, double scale) {
  std::normal_distribution<double> n(0, 1);
  const double v = scale * n(rng);
  return v * v;
}

TEST(ConsistencyMonitor, AnHonestSourceIsAlmostNeverRefused) {
  std::mt19937 rng(11);
  ConsistencyMonitor monitor("landmark");
  std::size_t updates = 0;
  for (int source = 0; source < 50; ++source) {
    for (int k = 0; k < 3000; ++k, ++updates) {  // 10 min at 5 Hz each
      monitor.Record("L" + std::to_string(source), 0.2 * k, Nis(rng, 1.0), 1);
    }
  }
  // Overlapping windows are tested at every update: the share refused stays far below 1 %.
  EXPECT_LT(static_cast<double>(monitor.refused_updates()) / updates, 0.005);
}

TEST(ConsistencyMonitor, ASourceTwiceAsNoisyAsStatedIsExcludedWithinAWindow) {
  for (const double scale : {2.0, 3.0, 10.0}) {
    std::mt19937 rng(5);
    ConsistencyMonitor monitor("beacon");
    double flagged_at = -1;
    for (int k = 0; k < 1000; ++k) {
      const double t = 0.1 * k;
      monitor.Record("honest", t, Nis(rng, 1.0), 1);
      const bool used = monitor.Record("liar", t, Nis(rng, scale), 1);
      if (!used && flagged_at < 0) flagged_at = t;
    }
    EXPECT_GE(flagged_at, 0) << scale;
    EXPECT_LT(flagged_at, 20.0) << scale;  // one window (20 s) of 10 Hz updates
    EXPECT_EQ(monitor.verdict("liar"), Verdict::kInconsistent) << scale;
    EXPECT_EQ(monitor.verdict("honest"), Verdict::kConsistent) << scale;
    EXPECT_EQ(monitor.flagged_sources(), 1u);
    ASSERT_FALSE(monitor.notes().empty());
    EXPECT_EQ(monitor.notes().front().action, "excluded");
    EXPECT_EQ(monitor.notes().front().source, "beacon liar");
  }
}

TEST(ConsistencyMonitor, ASourceThatStopsLyingIsReadmittedAfterAWindow) {
  std::mt19937 rng(3);
  ConsistencyMonitor monitor("crumb");
  double readmitted_at = -1;
  for (int k = 0; k < 1200; ++k) {
    const double t = 0.1 * k;
    const bool lying = t < 40;
    const bool used = monitor.Record("C1", t, Nis(rng, lying ? 5.0 : 1.0), 1);
    if (!lying && used && readmitted_at < 0) readmitted_at = t;
  }
  // Not used again before its window holds honest updates only (20 s), soon after that.
  EXPECT_GT(readmitted_at, 40.0 + 0.5 * 20.0);
  EXPECT_LT(readmitted_at, 40.0 + 20.0 + 1.0);
  ASSERT_EQ(monitor.notes().size(), 2u);
  EXPECT_EQ(monitor.notes()[1].action, "readmitted");
}

TEST(ConsistencyMonitor, OneGrossOutlierAloneFlagsNothing) {
  std::mt19937 rng(9);
  ConsistencyMonitor monitor("device");
  for (int k = 0; k < 400; ++k) {
    const double nis = k == 200 ? 1e6 : Nis(rng, 1.0);
    EXPECT_TRUE(monitor.Record("phone", 0.1 * k, nis, 1)) << k;
  }
  EXPECT_EQ(monitor.flagged_sources(), 0u);
}

TEST(ConsistencyMonitor, NoVerdictOnTooFewUpdatesAndNonFiniteNisCountsAsBeyondTheGate) {
  ConsistencyOptions options;
  options.min_updates = 4;
  ConsistencyMonitor monitor("landmark", options);
  EXPECT_TRUE(monitor.Record("L1", 0, NAN, 2));
  EXPECT_TRUE(monitor.Record("L1", 1, INFINITY, 2));
  EXPECT_EQ(monitor.verdict("L1"), Verdict::kUnknown);
  EXPECT_TRUE(monitor.Record("L1", 2, -1, 2));
  // Four updates at the 2-dof gate (13.8 each) exceed the 8-dof threshold (26.1).
  EXPECT_FALSE(monitor.Record("L1", 3, NAN, 2));
  EXPECT_EQ(monitor.verdict("L1"), Verdict::kInconsistent);
  EXPECT_GT(monitor.ratio("L1"), 1.0);
  EXPECT_EQ(monitor.verdict("never"), Verdict::kUnknown);
  EXPECT_THROW(monitor.Record("L1", 4, 1, 0), std::invalid_argument);
  ConsistencyOptions bad;
  bad.window_s = 0;
  EXPECT_THROW(ConsistencyMonitor("x", bad), std::invalid_argument);
}

TEST(ConsistencyMonitor, ReportsCountsAndNotesInTheSummary) {
  std::mt19937 rng(1);
  ConsistencyMonitor monitor("landmark");
  for (int k = 0; k < 300; ++k) monitor.Record("L9", 0.1 * k, Nis(rng, 4.0), 1);
  EstimatorSummary summary;
  monitor.Report(summary);
  EXPECT_EQ(summary.numbers.at("integrity.landmark.flagged"), 1.0);
  EXPECT_GT(summary.numbers.at("integrity.landmark.refused"), 200.0);
  ASSERT_EQ(summary.integrity.size(), 1u);
  EXPECT_NE(summary.integrity[0].message.find("landmark L9 excluded"), std::string::npos);
}

TEST(RepeatDetector, AFrozenStreamIsExcludedUntilItChangesAgain) {
  RepeatDetector detector("device", 20);
  std::mt19937 rng(2);
  std::normal_distribution<double> rssi(-70, 4);
  for (int k = 0; k < 100; ++k) EXPECT_TRUE(detector.Record("ff1", k, rssi(rng)));
  int refused = 0;
  for (int k = 0; k < 50; ++k) refused += detector.Record("ff1", 100 + k, -71.5) ? 0 : 1;
  EXPECT_EQ(refused, 50 - 19);  // the 20th repeat and every one after it
  EXPECT_TRUE(detector.Record("ff1", 151, -64.0));
  ASSERT_EQ(detector.notes().size(), 2u);
  EXPECT_EQ(detector.notes()[0].action, "repeats");
  EXPECT_EQ(detector.notes()[1].action, "readmitted");
  // Integer-valued readings repeat by nature; a short run of equal ones is not a freeze.
  for (int k = 0; k < 10; ++k) EXPECT_TRUE(detector.Record("ff2", k, -70));
  // A reading of several values repeats only when all of them do.
  RepeatDetector imu("imu", 3);
  const double a[3] = {0.1, 9.8, 0.0}, b[3] = {0.1, 9.8, 0.001};
  EXPECT_TRUE(imu.Record("ff1", 0, a));
  EXPECT_TRUE(imu.Record("ff1", 1, a));
  EXPECT_FALSE(imu.Record("ff1", 2, a));
  EXPECT_TRUE(imu.Record("ff1", 3, b));
}

}  // namespace
}  // namespace trailmark::integrity

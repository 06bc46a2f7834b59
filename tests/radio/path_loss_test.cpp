// SPDX-License-Identifier: MIT
// Radio model: exact recovery of the log-distance (+ body) parameters, trimming, encounter and
// link-change detectors.
#include "trailmark/radio/path_loss.h"

#include <gtest/gtest.h>

#include <cmath>

#include "trailmark/core/random.h"

namespace trailmark::radio {
namespace {

TEST(PathLoss, RangeIsTheInverseOfTheMeanAndSigmaMatchesFirstOrder) {
  const LogDistanceModel m{-41.0, 2.7, 4.0};
  for (double d : {0.5, 1.0, 7.0, 30.0}) {
    EXPECT_NEAR(m.Distance(m.MeanRssi(d)), d, 1e-9 * d);
    // sigma_d = |dd/drssi| * sigma: finite difference of Distance()
    const double dd = (m.Distance(m.MeanRssi(d) - 1e-4) - m.Distance(m.MeanRssi(d) + 1e-4)) / 2e-4;
    EXPECT_NEAR(m.DistanceSigma(d), dd * m.sigma_db, 1e-5 * d);
  }
  const auto r = ToRange(m, -41.0);
  EXPECT_NEAR(r.range_m, 1.0, 1e-12);
}

TEST(PathLoss, FitRecoversParametersExactlyFromNoiseFreePairs) {
  std::vector<CalibrationPair> pairs;
  for (double d = 1.0; d <= 30.0; d += 0.5) pairs.push_back({d, -38.0 - 10 * 3.1 * std::log10(d)});
  const PathLossFit fit = FitLogDistance(pairs, 0.0);
  EXPECT_NEAR(fit.model.alpha_dbm, -38.0, 1e-9);
  EXPECT_NEAR(fit.model.path_loss_exponent, 3.1, 1e-9);
  EXPECT_NEAR(fit.residual_sigma_db, 0.0, 1e-9);
}

TEST(PathLoss, TrimmingRemovesOutliersPerDistance) {
  Random rng(5);
  std::vector<CalibrationPair> pairs;
  for (int rep = 0; rep < 40; ++rep) {
    for (double d : {1.0, 2.0, 4.0, 8.0, 16.0}) {
      double rssi = -40.0 - 23.0 * std::log10(d) + rng.Normal(0, 1.0);
      if (rep == 0) rssi -= 40;  // one gross NLOS outlier per distance (2.5 %)
      if (rep == 1) rssi += 40;
      pairs.push_back({d, rssi});
    }
  }
  const PathLossFit raw = FitLogDistance(pairs, 0.0, 0.5);
  const PathLossFit trimmed = FitLogDistance(pairs, 0.05, 0.5);
  EXPECT_GT(raw.residual_sigma_db, 5.0);
  EXPECT_LT(trimmed.residual_sigma_db, 1.3);
  EXPECT_NEAR(trimmed.model.path_loss_exponent, 2.3, 0.1);
  EXPECT_NEAR(trimmed.model.alpha_dbm, -40.0, 0.5);
  EXPECT_THROW(FitLogDistance({{1, -40}, {1, -41}, {1, -42}}, 0.0), std::invalid_argument);
  EXPECT_THROW(FitLogDistance({{0, -40}, {1, -41}, {2, -42}}), std::invalid_argument);
}

TEST(PathLoss, FitWithBodyRecoversTheBodyLoss) {
  std::vector<CalibrationPair> pairs;
  for (double d = 1.0; d <= 20.0; d += 1.0) {
    for (double b : {0.0, 0.3, 0.7, 1.0}) pairs.push_back({d, -41.0 - 25.0 * std::log10(d) - 6.5 * b, b});
  }
  const PathLossFit fit = FitLogDistanceWithBody(pairs, 0.0);
  EXPECT_NEAR(fit.model.alpha_dbm, -41.0, 1e-9);
  EXPECT_NEAR(fit.model.path_loss_exponent, 2.5, 1e-9);
  EXPECT_NEAR(fit.model.body_loss_db, 6.5, 1e-9);
  EXPECT_DOUBLE_EQ(BodyFactor({0, 0}, 0.0, {-3, 0}), 1.0);  // straight behind
  EXPECT_DOUBLE_EQ(BodyFactor({0, 0}, 0.0, {3, 0}), 0.0);   // ahead
  EXPECT_NEAR(BodyFactor({0, 0}, 0.0, {-1, 1}), std::sqrt(0.5), 1e-12);
}

TEST(Encounter, OnePeakPerPassAboveTheThresholdOnly) {
  // Walking at 1.2 m/s past a node 0.5 m off the path, packets at 2 Hz.
  auto pass = [](double offset_m, double t0) {
    std::vector<std::pair<double, double>> packets;
    for (int k = 0; k <= 40; ++k) {
      const double t = t0 + 0.5 * k, x = -12.0 + 1.2 * 0.5 * k;
      packets.emplace_back(t, -40.0 - 23.0 * std::log10(std::hypot(x, offset_m)));
    }
    return packets;
  };
  EncounterDetector det;
  std::vector<double> found;
  for (const auto& [t, r] : pass(0.5, 0.0)) {
    if (auto e = det.Add(t, r)) found.push_back(*e);
  }
  ASSERT_EQ(found.size(), 1u);
  EXPECT_NEAR(found[0], 10.0, 0.5);  // closest approach at x = 0
  EncounterDetector far;
  for (const auto& [t, r] : pass(4.0, 100.0)) EXPECT_FALSE(far.Add(t, r));
}

TEST(LinkChange, DetectsALastingStepNotNoise) {
  Random rng(9);
  LinkChangeDetector steady;
  for (int k = 0; k < 400; ++k) EXPECT_FALSE(steady.Add(-70 + rng.Normal(0, 1.0))) << k;
  LinkChangeDetector kicked;
  std::optional<double> change;
  for (int k = 0; k < 30; ++k) kicked.Add(-70 + rng.Normal(0, 1.0));
  for (int k = 0; k < 10 && !change; ++k) change = kicked.Add(-76 + rng.Normal(0, 1.0));
  ASSERT_TRUE(change);
  EXPECT_LT(*change, -3.0);
}

}  // namespace
}  // namespace trailmark::radio

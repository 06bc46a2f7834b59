// SPDX-License-Identifier: MIT
// Dead reckoning first (integrity/dead_reckoning_first.h): the verdict is the dead reckoning's
// squared Mahalanobis distance under the estimator's own covariance against two chi-square
// quantiles, written out here; the blend and its covariance are the mixture's, exactly.
#include "trailmark/integrity/dead_reckoning_first.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "trailmark/integrity/consistency.h"

namespace trailmark::integrity {
namespace {

TEST(DeadReckoningFirst, WritesDeadReckoningInsideTheEstimatorsRegionTheEstimateOutsideAndBlends) {
  DeadReckoningFirst first({});
  const double accept = ChiSquareQuantile(2, 0.99), reject = ChiSquareQuantile(2, 0.9999);
  const Mat2 own = Vec2(0.25, 1.0).asDiagonal();  // sigma 0.5 m along x, 1 m along y
  const Mat2 reported = own + Mat2::Identity() * 0.5, dr_cov = Mat2::Identity() * 4.0;
  const Vec2 dr(10.0, -3.0);
  EXPECT_TRUE(first.WritesDeadReckoning());
  // d2 = dx^2 / 0.25 below the accept quantile: the dead reckoning, exactly.
  Vec2 est = dr + Vec2(0.5 * std::sqrt(accept) * 0.9, 0);
  EXPECT_FALSE(first.Test(1.0, "ff1", "the filter", est, own, dr).has_value());
  EXPECT_EQ(first.doubt(), 0.0);
  EXPECT_EQ(first.Position(est, dr), dr);
  EXPECT_EQ(first.Covariance(est, reported, dr, dr_cov), dr_cov);
  // Halfway between the quantiles (along y: sigma 1 m): a blend, not yet a rejection.
  const double d2 = 0.5 * (accept + reject);
  est = dr + Vec2(0, std::sqrt(d2));
  EXPECT_FALSE(first.Test(2.0, "ff1", "the filter", est, own, dr).has_value());
  const double w = (d2 - accept) / (reject - accept);
  EXPECT_NEAR(first.doubt(), w, 1e-12);
  EXPECT_NEAR((first.Position(est, dr) - (dr + w * (est - dr))).norm(), 0, 1e-12);
  const Vec2 d = est - dr;
  const Mat2 mix = (1 - w) * dr_cov + w * reported + w * (1 - w) * d * d.transpose();
  EXPECT_NEAR((first.Covariance(est, reported, dr, dr_cov) - mix).norm(), 0, 1e-12);
  // Beyond the reject quantile: the estimate, exactly, and a note that says so.
  est = dr + Vec2(0, std::sqrt(reject) * 1.01);
  const auto rejected = first.Test(3.0, "ff1", "the filter", est, own, dr);
  ASSERT_TRUE(rejected.has_value());
  EXPECT_EQ(rejected->action, "resumed");
  EXPECT_EQ(rejected->node, "ff1");
  EXPECT_NE(rejected->message.find("left the filter's 99.99 % region"), std::string::npos)
      << rejected->message;
  EXPECT_EQ(first.Position(est, dr), est);
  EXPECT_EQ(first.Covariance(est, reported, dr, dr_cov), reported);
  // Back between the quantiles: still doubted (a blend), no note; inside: accepted, a note.
  est = dr + Vec2(0, std::sqrt(d2));
  EXPECT_FALSE(first.Test(4.0, "ff1", "the filter", est, own, dr).has_value());
  EXPECT_GT(first.doubt(), 0.0);
  est = dr + Vec2(0, 0.1);
  const auto accepted = first.Test(5.0, "ff1", "the filter", est, own, dr);
  ASSERT_TRUE(accepted.has_value());
  EXPECT_EQ(accepted->action, "fallback");
  EXPECT_TRUE(first.WritesDeadReckoning());
  // A covariance that is not positive definite changes nothing.
  EXPECT_FALSE(first.Test(6.0, "ff1", "the filter", dr + Vec2(50, 50), Mat2::Zero(), dr));
  EXPECT_TRUE(first.WritesDeadReckoning());
  // Counting what was written.
  first.Count();
  first.Count();
  EXPECT_EQ(first.share_not_dead_reckoning(), 0.0);
}

TEST(DeadReckoningFirst, AbandonedItWritesTheEstimateFromThenOnWithOneNote) {
  DeadReckoningFirst first({});
  const Mat2 own = Mat2::Identity(), reported = Mat2::Identity() * 2, dr_cov = Mat2::Identity();
  const Vec2 dr(1.0, 2.0), est(1.2, 2.1);
  EXPECT_FALSE(first.Test(1.0, "ff1", "the network", est, own, dr).has_value());
  EXPECT_TRUE(first.WritesDeadReckoning());
  const auto note = first.Abandon(2.0, "ff1", "the network");
  ASSERT_TRUE(note.has_value());
  EXPECT_EQ(note->action, "resumed");
  EXPECT_NE(note->message.find("mounting not found"), std::string::npos) << note->message;
  EXPECT_FALSE(first.Abandon(3.0, "ff1", "the network").has_value());  // once
  // The dead reckoning inside the region again: still the estimate, and no note.
  EXPECT_FALSE(first.Test(4.0, "ff1", "the network", est, own, dr).has_value());
  EXPECT_EQ(first.doubt(), 1.0);
  EXPECT_EQ(first.Position(est, dr), est);
  EXPECT_EQ(first.Covariance(est, reported, dr, dr_cov), reported);
}

TEST(DeadReckoningFirst, RefusesThresholdsThatAreNotOrdered) {
  EXPECT_THROW(DeadReckoningFirst({0.9, 0.99}), std::invalid_argument);
  EXPECT_THROW(DeadReckoningFirst({0.99, 0.99}), std::invalid_argument);
  EXPECT_THROW(DeadReckoningFirst({1.0, 0.5}), std::invalid_argument);
  EXPECT_THROW(DeadReckoningFirst({std::numeric_limits<double>::quiet_NaN(), 0.5}),
               std::invalid_argument);
}

}  // namespace
}  // namespace trailmark::integrity

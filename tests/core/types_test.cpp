// SPDX-License-Identifier: MIT
#include <gtest/gtest.h>

#include <numbers>

#include "trailmark/core/random.h"
#include "trailmark/core/types.h"

namespace trailmark {
namespace {

TEST(NodeId, FollowsTheSpecAlphabet) {
  EXPECT_TRUE(IsValidNodeId("ff1"));
  EXPECT_TRUE(IsValidNodeId("crumb_3.b-2"));
  EXPECT_FALSE(IsValidNodeId(""));
  EXPECT_FALSE(IsValidNodeId("a b"));
  EXPECT_FALSE(IsValidNodeId("a,b"));
  EXPECT_FALSE(IsValidNodeId("é"));
}

TEST(NodeKind, ParsesAndPrints) {
  for (auto k : {NodeKind::kAgent, NodeKind::kCrumb, NodeKind::kLandmark, NodeKind::kBase}) {
    EXPECT_EQ(ParseNodeKind(ToString(k)), k);
  }
  EXPECT_FALSE(ParseNodeKind("Agent").has_value());
}

TEST(WrapAngle, MapsIntoHalfOpenInterval) {
  EXPECT_NEAR(WrapAngle(3 * std::numbers::pi), std::numbers::pi, 1e-12);
  EXPECT_NEAR(WrapAngle(-std::numbers::pi), std::numbers::pi, 1e-12);
  EXPECT_NEAR(WrapAngle(0.5), 0.5, 1e-15);
  EXPECT_NEAR(WrapAngle(-7.0), -7.0 + 2 * std::numbers::pi, 1e-12);
}

TEST(Random, SameSeedSameSequenceAndSaneMoments) {
  Random a(42), b(42), c(43);
  EXPECT_EQ(a.Normal(), b.Normal());
  EXPECT_NE(a.Uniform(), c.Uniform());
  Random r(1);
  double sum = 0, sum2 = 0;
  const int n = 200000;
  for (int i = 0; i < n; ++i) {
    const double x = r.Normal();
    sum += x;
    sum2 += x * x;
  }
  EXPECT_NEAR(sum / n, 0.0, 0.01);
  EXPECT_NEAR(sum2 / n, 1.0, 0.01);
}

}  // namespace
}  // namespace trailmark

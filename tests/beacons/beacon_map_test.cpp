// SPDX-License-Identifier: MIT
// The online beacon map (MDS + anchoring) and the way back out.
#include "trailmark/beacons/beacon_map.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>

#include "trailmark/core/random.h"

namespace trailmark::beacons {
namespace {

// A trail of beacons zig-zagging along a corridor, every pair within 4.5 m linked.
std::vector<Vec2> Trail(int n) {
  std::vector<Vec2> b;
  for (int i = 0; i < n; ++i) b.emplace_back(2.0 * i, i % 2 ? 1.0 : -1.0);
  return b;
}

BeaconMap Linked(const std::vector<Vec2>& truth, double noise, Random& rng) {
  BeaconMap map;
  for (std::size_t i = 0; i < truth.size(); ++i) map.Add("b" + std::to_string(i));
  for (std::size_t i = 0; i < truth.size(); ++i) {
    for (std::size_t j = i + 1; j < truth.size(); ++j) {
      const double d = (truth[i] - truth[j]).norm();
      if (d < 4.5)
        EXPECT_TRUE(
            map.AddRange(static_cast<int>(i), static_cast<int>(j), d + noise * rng.Normal()));
    }
  }
  return map;
}

TEST(BeaconMap, ExactRangesAndThreeSurveyedBeaconsGiveTheExactLayout) {
  Random rng(1);
  const auto truth = Trail(10);
  BeaconMap map = Linked(truth, 0.0, rng);
  for (int i : {0, 4, 9}) map.SetSurveyed(i, truth[i], 0.01);
  map.Solve();
  for (int i = 0; i < 10; ++i) {
    const auto p = map.Position(i);
    ASSERT_TRUE(p.has_value());
    EXPECT_LT((p->position_n - truth[i]).norm(), 1e-6) << i;
    const Eigen::SelfAdjointEigenSolver<Mat2> eig(p->cov);
    EXPECT_GT(eig.eigenvalues().minCoeff(), 0) << i;
  }
  EXPECT_EQ(map.summary().from_mds, 7u);
  EXPECT_EQ(map.summary().from_survey, 3u);
}

TEST(BeaconMap, DropEstimatesAnchorAndUnflipTheLayout) {
  // No survey: anchors are noisy estimates of where each beacon was dropped (0.3 m). The layout
  // must come out the right way round and closer than the anchors themselves.
  Random rng(2);
  const auto truth = Trail(12);
  BeaconMap map = Linked(truth, 0.05, rng);
  double hint_err = 0, err = 0;
  for (int i = 0; i < 12; ++i) {
    const Vec2 hint = truth[i] + Vec2(rng.Normal(0, 0.3), rng.Normal(0, 0.3));
    hint_err += (hint - truth[i]).norm() / 12;
    map.SetAnchorHint(i, hint, Mat2::Identity() * 0.09);
  }
  map.Solve();
  for (int i = 0; i < 12; ++i) err += (map.Position(i)->position_n - truth[i]).norm() / 12;
  // A rigid fit to 12 anchors of 0.3 m noise leaves ~0.2 m (3 dof over 12 points); the
  // layout must do better than the anchors themselves and not be mirrored.
  EXPECT_LT(err, hint_err);
  auto cross = [](const Vec2& a, const Vec2& b, const Vec2& c) {
    const Vec2 u = b - a, v = c - a;
    return u.x() * v.y() - u.y() * v.x();
  };
  EXPECT_GT(cross(map.Position(0)->position_n, map.Position(5)->position_n,
                  map.Position(11)->position_n) *
                cross(truth[0], truth[5], truth[11]),
            0);
}

TEST(BeaconMap, BeaconsWithoutLinksFallBackToTheirHintAndImplausibleRangesAreRefused) {
  BeaconMap map;
  const int a = map.Add("a"), b = map.Add("b");
  EXPECT_EQ(map.Add("a"), a);
  EXPECT_FALSE(map.AddRange(a, b, -1.0));
  EXPECT_FALSE(map.AddRange(a, b, std::nan("")));
  EXPECT_FALSE(map.AddRange(a, a, 1.0));
  EXPECT_FALSE(map.AddRange(a, b, 50.0));
  map.SetAnchorHint(a, Vec2(1, 2), Mat2::Identity());
  map.Solve();
  ASSERT_TRUE(map.Position(a).has_value());
  EXPECT_EQ(map.Position(a)->position_n, Vec2(1, 2));
  EXPECT_FALSE(map.Position(b).has_value());
  EXPECT_EQ(map.summary().unknown, 1u);
}

TEST(WayOut, FollowsTheSmallestRankHeardToTheEntry) {
  // 0 - 1 - 2 - 3 - 4 along a corridor, 4 also hears 2 (a short cut), 5 a side branch of 3.
  const std::vector<std::vector<int>> nb = {{1}, {0, 2}, {1, 3, 4}, {2, 4, 5}, {2, 3}, {3}};
  const std::vector<int> rank = {0, 1, 2, 3, 4, 5};
  std::string why;
  EXPECT_EQ(WayOut(nb, rank, {5}, &why), (std::vector<int>{5, 3, 2, 1, 0}));
  EXPECT_TRUE(why.empty());
  EXPECT_EQ(WayOut(nb, rank, {4, 5}), (std::vector<int>{4, 2, 1, 0}));
  // Ranks are deployment order, not indices.
  const std::vector<int> reversed = {5, 4, 3, 2, 1, 0};
  EXPECT_EQ(WayOut(nb, reversed, {0}), (std::vector<int>{0, 1, 2, 4}));  // 4 hears nothing smaller
  EXPECT_TRUE(WayOut(nb, rank, {}, &why).empty());
  EXPECT_EQ(why, "no beacon heard");
  // A broken trail is reported.
  const std::vector<std::vector<int>> broken = {{}, {2}, {1}};
  EXPECT_EQ(WayOut(broken, {0, 1, 2}, {2}, &why), (std::vector<int>{2, 1}));
  EXPECT_NE(why.find("trail broken"), std::string::npos);
}

}  // namespace
}  // namespace trailmark::beacons

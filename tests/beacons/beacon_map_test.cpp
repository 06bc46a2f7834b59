// SPDX-License-Identifier: MIT
// The online beacon map (MDS + anchoring) and the way back out.
#include "trailmark/beacons/beacon_map.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <stdexcept>

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

TEST(BeaconMap, ARelativeDropPriorWhoseIncrementIsNoCovarianceFallsBackToTheDrop) {
  // relative_drop_priors (an ablation, off by default): the prior between two drops is the
  // difference of the dead reckoning's covariances there, which is no covariance where the walk
  // comes back towards its start (found by a review, 2026-12-06: the solve threw, and from the
  // map's worker thread that ends the process). Such a drop keeps its absolute prior.
  BeaconMapOptions o;
  o.relative_drop_priors = true;
  BeaconMap map(o);
  Random rng(3);
  const auto truth = Trail(6);
  for (std::size_t i = 0; i < truth.size(); ++i) map.Add("b" + std::to_string(i));
  for (std::size_t i = 0; i + 1 < truth.size(); ++i)
    EXPECT_TRUE(map.AddRange(static_cast<int>(i), static_cast<int>(i + 1),
                             (truth[i] - truth[i + 1]).norm()));
  MapTrack track;
  track.cov = TrackVec(0.01, 1e-6, 1e-4, 1e-4).asDiagonal();
  const int t = map.AddTrack(track);
  for (int i = 0; i < 6; ++i) {
    TrackLever along = TrackLever::Zero();
    along.col(0) = Vec2(-truth[i].y(), truth[i].x());
    Mat2 increment = Mat2::Identity() * 0.02;
    if (i == 3) increment = Vec2(-0.3, 0.05).asDiagonal();  // the walk came back
    map.SetTrackHint(i, t, truth[i] + Vec2(rng.Normal(0, 0.1), rng.Normal(0, 0.1)),
                     Mat2::Identity() * 0.04, along, i > 0 ? i - 1 : -1, increment);
  }
  EXPECT_NO_THROW(map.Solve());
  for (int i = 0; i < 6; ++i) {
    const auto p = map.Position(i);
    ASSERT_TRUE(p.has_value());
    EXPECT_LT((p->position_n - truth[i]).norm(), 0.5) << i;
  }
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

TEST(RunningMedian, EqualsTheSortedMiddleAfterEveryValue) {
  // The reference: std::nth_element over everything so far — the element at n/2, and for an
  // even count the mean of it and the largest below it.
  Random rng(7);
  RunningMedian median;
  std::vector<double> all;
  for (int k = 0; k < 2000; ++k) {
    // Ties and long tails: values on a 5 cm grid, one in ten a long NLOS range.
    const double x = std::round(rng.Normal(4.0, 0.3) / 0.05) * 0.05 + (k % 10 == 3 ? 6.0 : 0.0);
    median.Add(x);
    all.push_back(x);
    std::vector<double> copy = all;
    const auto middle = copy.begin() + copy.size() / 2;
    std::nth_element(copy.begin(), middle, copy.end());
    const double expected =
        copy.size() % 2 ? *middle : 0.5 * (*middle + *std::max_element(copy.begin(), middle));
    ASSERT_EQ(median.Median(), expected) << k;
    ASSERT_EQ(median.size(), all.size());
  }
}

// Two trails of beacons far apart, each with three surveyed beacons: two parts of the map.
BeaconMap TwoParts(const std::vector<Vec2>& a, const std::vector<Vec2>& b, Random& rng,
                   BeaconMap::Options options = {}) {
  BeaconMap map(options);
  const int na = static_cast<int>(a.size());
  for (int i = 0; i < na + static_cast<int>(b.size()); ++i) map.Add("b" + std::to_string(i));
  for (int part = 0; part < 2; ++part) {
    const auto& truth = part == 0 ? a : b;
    const int first = part == 0 ? 0 : na;
    for (std::size_t i = 0; i < truth.size(); ++i) {
      for (std::size_t j = i + 1; j < truth.size(); ++j) {
        const double d = (truth[i] - truth[j]).norm();
        if (d < 4.5) map.AddRange(first + static_cast<int>(i), first + static_cast<int>(j), d + 0.02 * rng.Normal());
      }
    }
    for (int i : {0, 3, 6}) map.SetSurveyed(first + i, truth[i], 0.05);
  }
  return map;
}

TEST(BeaconMap, OnlyThePartThatChangedIsSolvedAgain) {
  Random rng(11);
  std::vector<Vec2> a = Trail(8), b = Trail(8);
  for (Vec2& p : b) p += Vec2(100, 50);
  BeaconMap map = TwoParts(a, b, rng);
  map.Solve();
  EXPECT_EQ(map.summary().part_solves, 2u);
  EXPECT_EQ(map.summary().components, 2u);
  std::vector<BeaconPosition> before;
  for (int i = 0; i < 16; ++i) before.push_back(*map.Position(i));
  // A new pair in part b only: part a keeps its solution bit for bit, part b moves.
  EXPECT_TRUE(map.AddRange(8, 10, (b[0] - b[2]).norm() + 0.5));
  EXPECT_TRUE(map.dirty());
  map.Solve();
  EXPECT_EQ(map.summary().part_solves, 3u);
  EXPECT_EQ(map.summary().components, 2u);
  for (int i = 0; i < 8; ++i) {
    EXPECT_EQ(map.Position(i)->position_n, before[i].position_n) << i;
    EXPECT_EQ(map.Position(i)->cov, before[i].cov) << i;
  }
  double moved = 0;
  for (int i = 8; i < 16; ++i) moved += (map.Position(i)->position_n - before[i].position_n).norm();
  EXPECT_GT(moved, 1e-4);
  // Nothing new: nothing solved, the summary as it was.
  const BeaconMapSummary last = map.summary();
  map.Solve();
  EXPECT_EQ(map.summary().part_solves, 3u);
  EXPECT_EQ(map.summary().components, last.components);
  EXPECT_EQ(map.summary().chi2_per_dof, last.chi2_per_dof);
  EXPECT_EQ(map.summary().anchor_rms_m, last.anchor_rms_m);
  // A link joining the parts: one part, solved.
  EXPECT_TRUE(map.AddRange(7, 8, 6.0));
  map.Solve();
  EXPECT_EQ(map.summary().part_solves, 4u);
  EXPECT_EQ(map.summary().components, 1u);
}

TEST(BeaconMap, ASolveOnAWorkerGivesTheSameMapAndTakesWhatArrivesMeanwhileForTheNext) {
  // Solve() against BeginSolve(on a worker) ... EndSolve() on the same calls: bit for bit. In
  // between, the previous solution stands and new ranges wait for the next solve.
  std::vector<Vec2> a = Trail(8), b = Trail(8);
  for (Vec2& p : b) p += Vec2(100, 50);
  Random rng_a(14), rng_b(14);
  BeaconMap inline_map = TwoParts(a, b, rng_a);
  BeaconMap worker_map = TwoParts(a, b, rng_b);
  inline_map.Solve();
  worker_map.BeginSolve(/*on_worker=*/true);
  EXPECT_TRUE(worker_map.solving());
  EXPECT_FALSE(worker_map.dirty());
  EXPECT_EQ(worker_map.summary().solves, 0u);  // nothing in place yet
  EXPECT_FALSE(worker_map.Position(1));  // not surveyed, no hint: placed by the solve only
  // A range of part b arrives while the worker solves: not in this solve, in the next.
  const double r = (b[0] - b[2]).norm() + 0.5;
  EXPECT_TRUE(worker_map.AddRange(8, 10, r));
  EXPECT_TRUE(worker_map.dirty());
  worker_map.EndSolve();
  ASSERT_TRUE(worker_map.Position(1));
  EXPECT_FALSE(worker_map.solving());
  EXPECT_TRUE(worker_map.dirty());
  for (int i = 0; i < 16; ++i) {
    EXPECT_EQ(worker_map.Position(i)->position_n, inline_map.Position(i)->position_n) << i;
    EXPECT_EQ(worker_map.Position(i)->cov, inline_map.Position(i)->cov) << i;
  }
  EXPECT_EQ(worker_map.summary().part_solves, inline_map.summary().part_solves);
  EXPECT_EQ(worker_map.summary().chi2_per_dof, inline_map.summary().chi2_per_dof);
  // The next solve, on a worker again, takes the range: as the inline map given it now.
  EXPECT_TRUE(inline_map.AddRange(8, 10, r));
  inline_map.Solve();
  const BeaconPosition first_solution = *worker_map.Position(9);
  worker_map.BeginSolve(true);
  EXPECT_EQ(worker_map.Position(9)->position_n, first_solution.position_n);  // until EndSolve
  worker_map.EndSolve();
  EXPECT_NE(worker_map.Position(9)->position_n, first_solution.position_n);
  EXPECT_EQ(worker_map.summary().part_solves, 3u);  // part b only
  for (int i = 0; i < 16; ++i)
    EXPECT_EQ(worker_map.Position(i)->position_n, inline_map.Position(i)->position_n) << i;
  // A solve begun while one is pending puts that one in place first.
  EXPECT_TRUE(worker_map.AddRange(7, 8, 6.0));
  worker_map.BeginSolve(true);
  worker_map.BeginSolve(true);
  worker_map.EndSolve();
  EXPECT_EQ(worker_map.summary().solves, 4u);
  EXPECT_EQ(worker_map.summary().components, 1u);
}

TEST(BeaconMap, TheSamePartSolvedWholeOrStepByStepAgrees) {
  // The incremental map (a Solve() after each part's ranges) against one Solve() of everything:
  // the same positions (the least squares converged from different starts: to 1e-6 m).
  Random rng_a(12), rng_b(12);
  std::vector<Vec2> a = Trail(8), b = Trail(8);
  for (Vec2& p : b) p += Vec2(40, -20);
  BeaconMap whole = TwoParts(a, b, rng_a);
  whole.Solve();
  BeaconMap steps = TwoParts(a, b, rng_b);
  steps.Solve();
  for (BeaconMap* map : {&whole, &steps}) EXPECT_TRUE(map->AddRange(1, 2, (a[1] - a[2]).norm() + 0.01));
  steps.Solve();
  BeaconMap fresh = TwoParts(a, b, rng_a = Random(12));
  EXPECT_TRUE(fresh.AddRange(1, 2, (a[1] - a[2]).norm() + 0.01));
  fresh.Solve();
  for (int i = 0; i < 16; ++i)
    EXPECT_LT((steps.Position(i)->position_n - fresh.Position(i)->position_n).norm(), 1e-6) << i;
}

TEST(BeaconMap, RangesThatChangeNothingMaterialWaitForTheNextMaterialOne) {
  Random rng(13);
  std::vector<Vec2> a = Trail(8), b = Trail(8);
  for (Vec2& p : b) p += Vec2(100, 50);
  const double d01 = (a[0] - a[1]).norm();
  // Equal ranges on pair (0, 1), which has one: its median stays, so only the count decides,
  // n >= 1.25 x the count last used: material at 2, 3, 4, 5, 7, 9, 12.
  {
    BeaconMap map = TwoParts(a, b, rng);
    map.Solve();
    ASSERT_EQ(map.summary().part_solves, 2u);
    std::vector<int> material;
    for (int n = 2; n <= 12; ++n) {
      EXPECT_TRUE(map.AddRange(0, 1, d01));
      if (map.dirty()) material.push_back(n);
      map.Solve();
    }
    EXPECT_EQ(material, (std::vector<int>{2, 3, 4, 5, 7, 9, 12}));
    EXPECT_EQ(map.summary().part_solves, 2u + material.size());
  }
  // The median's move alone (the count rule off): more than half the median's sigma.
  {
    BeaconMap::Options options;
    options.resolve_count_growth = 1e9;
    Random rng2(13);
    BeaconMap map = TwoParts(a, b, rng2, options);
    map.Solve();
    const double first = (a[0] - a[3]).norm();  // a pair TwoParts left unlinked (6.3 m)
    EXPECT_TRUE(map.AddRange(0, 3, first));           // a new pair: material
    EXPECT_TRUE(map.dirty());
    map.Solve();
    EXPECT_TRUE(map.AddRange(0, 3, first + 0.2));     // median (upper of 2) moves 0.2 > 0.05
    EXPECT_TRUE(map.dirty());
    map.Solve();
    EXPECT_TRUE(map.AddRange(0, 3, first));           // back by 0.2 > 0.035
    EXPECT_TRUE(map.dirty());
    map.Solve();
    EXPECT_TRUE(map.AddRange(0, 3, first + 0.01));    // 0.01 < 0.036: waits
    EXPECT_FALSE(map.dirty());
  }
  // Solved again on every range when asked (the thresholds at 1 and 0).
  BeaconMap::Options every;
  every.resolve_count_growth = 1;
  every.resolve_median_shift_sigma = 0;
  Random rng3(13);
  BeaconMap eager = TwoParts(a, b, rng3, every);
  eager.Solve();
  for (int k = 0; k < 5; ++k) {
    EXPECT_TRUE(eager.AddRange(0, 1, d01));
    EXPECT_TRUE(eager.dirty());
    eager.Solve();
  }
  EXPECT_EQ(eager.summary().part_solves, 7u);
  // Invalid thresholds are refused.
  BeaconMap::Options bad;
  bad.resolve_count_growth = 0.5;
  EXPECT_THROW(BeaconMap{bad}, std::invalid_argument);
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

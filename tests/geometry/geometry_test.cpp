// SPDX-License-Identifier: MIT
#include <gtest/gtest.h>

#include "trailmark/core/random.h"
#include "trailmark/geometry/floor_plan.h"
#include "trailmark/geometry/segment_index.h"

namespace trailmark {
namespace {

TEST(Segments, IntersectionCases) {
  EXPECT_TRUE(SegmentsIntersect({{0, 0}, {2, 2}}, {{0, 2}, {2, 0}}));   // proper crossing
  EXPECT_TRUE(SegmentsIntersect({{0, 0}, {1, 0}}, {{1, 0}, {1, 1}}));   // touching end
  EXPECT_TRUE(SegmentsIntersect({{0, 0}, {2, 0}}, {{1, 0}, {3, 0}}));   // collinear overlap
  EXPECT_FALSE(SegmentsIntersect({{0, 0}, {1, 0}}, {{2, 0}, {3, 0}}));  // collinear apart
  EXPECT_FALSE(SegmentsIntersect({{0, 0}, {1, 1}}, {{0, 1}, {0.4, 0.6001}}));
  EXPECT_NEAR(*FirstIntersection({{0, 0}, {4, 0}}, {{1, -1}, {1, 1}}), 0.25, 1e-12);
  EXPECT_NEAR(DistanceToSegment({1, 1}, {{0, 0}, {2, 0}}), 1.0, 1e-12);
  EXPECT_NEAR(DistanceToSegment({3, 0}, {{0, 0}, {2, 0}}), 1.0, 1e-12);
}

TEST(Box2, SquaredDistanceIsZeroInsideAndExactOutside) {
  Box2 b;
  b.Extend({0, 0});
  b.Extend({2, 1});
  EXPECT_EQ(b.SquaredDistanceTo({1, 0.5}), 0.0);
  EXPECT_EQ(b.SquaredDistanceTo({2, 0}), 0.0);      // on the boundary
  EXPECT_EQ(b.SquaredDistanceTo({-3, 0.5}), 9.0);   // left of it
  EXPECT_EQ(b.SquaredDistanceTo({5, 5}), 25.0);     // off a corner: 3^2 + 4^2
  EXPECT_EQ(b.SquaredDistanceTo({1, -0.5}), 0.25);  // below it
}

TEST(Polygons, AreaAndContainment) {
  const std::vector<Vec2> square{{0, 0}, {2, 0}, {2, 2}, {0, 2}};
  EXPECT_DOUBLE_EQ(PolygonArea(square), 4.0);
  EXPECT_TRUE(PointInPolygon({1, 1}, square));
  EXPECT_FALSE(PointInPolygon({3, 1}, square));
}

// The grid index must answer exactly like brute force on random segments.
TEST(SegmentIndex, MatchesBruteForce) {
  Random rng(3);
  std::vector<Segment2> walls;
  for (int i = 0; i < 400; ++i) {
    const Vec2 a(rng.Uniform(-50, 50), rng.Uniform(-30, 30));
    const Vec2 d(rng.Uniform(-4, 4), rng.Uniform(-4, 4));
    walls.push_back({a, a + d});
  }
  const SegmentIndex index(walls, {.cell_size_m = 1.5});
  for (int q = 0; q < 3000; ++q) {
    const Vec2 a(rng.Uniform(-55, 55), rng.Uniform(-35, 35));
    const Vec2 d(rng.Uniform(-3, 3), rng.Uniform(-3, 3));
    const Segment2 query{a, a + d};
    int brute = 0;
    for (const auto& w : walls) brute += SegmentsIntersect(query, w);
    ASSERT_EQ(index.CountIntersections(query), brute) << q;
    // Ray cast against brute force.
    const Vec2 dir = d.normalized();
    std::optional<double> best;
    for (const auto& w : walls) {
      if (auto s = FirstIntersection({a, a + dir * 20.0}, w)) {
        if (!best || *s * 20.0 < *best) best = *s * 20.0;
      }
    }
    const auto got = index.RayCast(a, dir, 20.0);
    ASSERT_EQ(got.has_value(), best.has_value());
    if (got) ASSERT_NEAR(*got, *best, 1e-9);
  }
}

TEST(SegmentIndex, EmptyAndOutsideQueries) {
  const SegmentIndex empty;
  EXPECT_FALSE(empty.Intersects({{0, 0}, {1, 1}}));
  const SegmentIndex one({{{0, 0}, {1, 0}}});
  EXPECT_FALSE(one.Intersects({{100, 100}, {101, 101}}));
  EXPECT_FALSE(one.RayCast({0, 1}, {0, 1}, 10).has_value());
  EXPECT_NEAR(*one.RayCast({0.5, 1}, {0, -1}, 10), 1.0, 1e-12);
}

TEST(FloorPlan, DoorsCutWalls) {
  const auto pieces = CutDoors({{0, 0}, {10, 0}}, {{{2, 0.05}, {3, 0.05}}, {{7, 0}, {8, 0}}}, 0.25);
  ASSERT_EQ(pieces.size(), 3u);
  EXPECT_NEAR(pieces[0].b.x(), 2.0, 1e-12);
  EXPECT_NEAR(pieces[1].a.x(), 3.0, 1e-12);
  EXPECT_NEAR(pieces[2].b.x(), 10.0, 1e-12);
  // A door far from the wall does not cut it.
  EXPECT_EQ(CutDoors({{0, 0}, {10, 0}}, {{{2, 1}, {3, 1}}}, 0.25).size(), 1u);
  const FloorPlan plan({{{0, 0}, {10, 0}}}, {{{4, 0}, {5, 0}}}, {});
  EXPECT_FALSE(plan.Crosses({4.5, -1}, {4.5, 1}));
  EXPECT_TRUE(plan.Crosses({1, -1}, {1, 1}));
  EXPECT_EQ(plan.WallsBetween({1, -1}, {1, 1}), 1);
}

}  // namespace
}  // namespace trailmark

// SPDX-License-Identifier: MIT
// The walls' distance field against the exact point-to-segment distance.
#include "trailmark/geometry/distance_field.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>

#include "trailmark/core/random.h"

namespace trailmark {
namespace {

double ExactDistance(const std::vector<Segment2>& walls, const Vec2& x) {
  double d = std::numeric_limits<double>::infinity();
  for (const auto& w : walls) d = std::min(d, DistanceToSegment(x, w));
  return d;
}

TEST(DistanceField, MatchesTheExactDistanceWithinHalfACellDiagonalAndIsClamped) {
  // A room with a slanted partition and a free-standing wall.
  const std::vector<Segment2> walls = {{{0, 0}, {8, 0}}, {{8, 0}, {8, 6}},   {{8, 6}, {0, 6}},
                                       {{0, 6}, {0, 0}}, {{2, 1}, {5, 4.5}}, {{6.5, 2}, {6.5, 2}}};
  DistanceField::Options o;
  o.cell_m = 0.1;
  o.max_distance_m = 1.5;
  const DistanceField field(walls, o);
  Random rng(7);
  const double half_diagonal = 0.5 * std::sqrt(2.0) * o.cell_m;
  for (int k = 0; k < 5000; ++k) {
    const Vec2 x(rng.Uniform(-1.5, 9.5), rng.Uniform(-1.5, 7.5));
    const double exact = std::min(ExactDistance(walls, x), o.max_distance_m);
    // The value is the exact distance at the nearest cell centre: within half a cell diagonal.
    EXPECT_NEAR(field.At(x), exact, half_diagonal + 1e-6) << x.transpose();
    EXPECT_LE(field.At(x), o.max_distance_m + 1e-9);
  }
  // On a wall: within half a diagonal of zero; far from every wall: the clamp.
  EXPECT_LE(field.At({4, 0.0}), half_diagonal);
  EXPECT_DOUBLE_EQ(field.At({100, 100}), o.max_distance_m);
  EXPECT_DOUBLE_EQ(field.At({std::nan(""), 1}), o.max_distance_m);
}

TEST(DistanceField, ARasterAlongTheWallsGivesTheSameValuesWhereverThePlanIsDrawn) {
  // Issue 23: the same room drawn rotated by 33 degrees and moved a kilometre, its raster along
  // the rotated axes, reads what the room drawn along the axes reads at the same places (the
  // cells count from the walls' box, not from the frame's origin); with the raster along the
  // frame's axes the values differ by up to a cell diagonal.
  const std::vector<Segment2> walls = {
      {{0, 0}, {8, 0}}, {{8, 0}, {8, 6}}, {{8, 6}, {0, 6}}, {{0, 6}, {0, 0}}, {{3, 0}, {3, 2.5}}};
  const double angle = 33.0 * std::acos(-1.0) / 180.0;
  const Mat2 R = Eigen::Rotation2Dd(angle).toRotationMatrix();
  const Vec2 shift(1000.0, -500.0);
  std::vector<Segment2> moved;
  for (const auto& w : walls) moved.push_back({R * w.a + shift, R * w.b + shift});
  DistanceField::Options along;
  along.axis_rad = angle;
  const DistanceField a(walls), b(moved, along), c(moved);
  Random rng(3);
  double largest_along = 0, largest_frame = 0;
  for (int k = 0; k < 5000; ++k) {
    // Away from cell boundaries of the first raster (a point on one may round either way).
    const Vec2 x(std::floor(rng.Uniform(-1.5, 9.5) * 10) / 10 + 0.05 + rng.Uniform(-0.04, 0.04),
                 std::floor(rng.Uniform(-1.5, 7.5) * 10) / 10 + 0.05 + rng.Uniform(-0.04, 0.04));
    largest_along = std::max(largest_along, std::abs(a.At(x) - b.At(R * x + shift)));
    largest_frame = std::max(largest_frame, std::abs(a.At(x) - c.At(R * x + shift)));
  }
  EXPECT_LT(largest_along, 1e-5);  // float storage
  EXPECT_GT(largest_frame, 0.03);
}

TEST(DistanceField, NoWallsIsFarEverywhereAndBadOptionsOrHugePlansAreRefused) {
  const DistanceField empty(std::vector<Segment2>{});
  EXPECT_DOUBLE_EQ(empty.At({0, 0}), DistanceField::Options().max_distance_m);
  DistanceField::Options bad;
  bad.cell_m = 0;
  EXPECT_THROW(DistanceField({{{0, 0}, {1, 0}}}, bad), std::invalid_argument);
  // A wall a million kilometres long (a unit error): refused, not allocated.
  EXPECT_THROW(DistanceField({{{0, 0}, {1e9, 0}}, {{0, 0}, {0, 1e9}}}), std::invalid_argument);
}

}  // namespace
}  // namespace trailmark

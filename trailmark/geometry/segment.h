// SPDX-License-Identifier: MIT
#pragma once
/// 2-D segments and the predicates the floor plan needs. No I/O.

#include <limits>
#include <optional>
#include <vector>

#include "trailmark/core/types.h"

namespace trailmark {

struct Segment2 {
  Vec2 a = Vec2::Zero();
  Vec2 b = Vec2::Zero();
  double Length() const { return (b - a).norm(); }
};

/// True when the closed segments p and q share at least one point.
bool SegmentsIntersect(const Segment2& p, const Segment2& q);

/// Parameter s in [0,1] along p of the first point p shares with q (proper or touching
/// crossings; for collinear overlap, the first overlapping point). Empty when disjoint.
std::optional<double> FirstIntersection(const Segment2& p, const Segment2& q);

/// Euclidean distance from point x to segment s.
double DistanceToSegment(const Vec2& x, const Segment2& s);

/// Axis-aligned bounding box.
struct Box2 {
  Vec2 min = Vec2::Constant(std::numeric_limits<double>::infinity());
  Vec2 max = Vec2::Constant(-std::numeric_limits<double>::infinity());
  void Extend(const Vec2& p) {
    min = min.cwiseMin(p);
    max = max.cwiseMax(p);
  }
  bool Empty() const { return min.x() > max.x(); }
  /// Squared distance from p to the box (0 inside).
  double SquaredDistanceTo(const Vec2& p) const {
    const Vec2 out = (min - p).cwiseMax(p - max).cwiseMax(0.0);
    return out.squaredNorm();
  }
};

/// Signed area of a simple polygon (positive when counter-clockwise).
double PolygonArea(const std::vector<Vec2>& ring);
/// Point-in-polygon by ray crossing (boundary counts as inside for convex corners only).
bool PointInPolygon(const Vec2& x, const std::vector<Vec2>& ring);

}  // namespace trailmark

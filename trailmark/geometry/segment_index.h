// SPDX-License-Identifier: MIT
#pragma once
/// Uniform-grid spatial index over 2-D segments for "does this step cross a wall?" and
/// ray-casting queries. Walls of a building are short and evenly spread, so a grid with
/// ~1 m cells answers a step query by looking at a handful of cells; it is tested against
/// brute force (tests/geometry). An R-tree would add a dependency
/// without a measurable gain on floor plans of this size. Queries reuse a scratch buffer:
/// one index must not be queried from two threads at once (copy it per thread).

#include <cstdint>
#include <functional>
#include <optional>
#include <vector>

#include "trailmark/geometry/segment.h"

namespace trailmark {

struct SegmentIndexOptions {
  double cell_size_m = 1.0;   ///< grid cell edge; ~ typical step length
  int max_cells = 4'000'000;  ///< cap on grid size; the cell grows to respect it
};

class SegmentIndex {
 public:
  using Options = SegmentIndexOptions;

  SegmentIndex() = default;
  explicit SegmentIndex(std::vector<Segment2> segments, Options options = {});

  const std::vector<Segment2>& segments() const { return segments_; }
  bool empty() const { return segments_.empty(); }

  /// True when the query segment touches any indexed segment.
  bool Intersects(const Segment2& query) const;
  /// Number of indexed segments the query touches (each counted once).
  int CountIntersections(const Segment2& query) const;
  /// Distance along the ray from `origin` in unit direction `dir` to the first segment hit,
  /// or empty when nothing is hit within max_range_m.
  std::optional<double> RayCast(const Vec2& origin, const Vec2& dir, double max_range_m) const;
  /// Calls visit(i) once for every segment whose cells the query's box overlaps.
  void ForEachCandidate(const Box2& box, const std::function<void(std::size_t)>& visit) const;

 private:
  std::int64_t CellOf(double v, int axis) const;

  std::vector<Segment2> segments_;
  Box2 bounds_;
  double cell_ = 1.0;
  std::int64_t nx_ = 0;
  std::int64_t ny_ = 0;
  std::vector<std::uint32_t> cell_start_;  ///< CSR layout: cell -> [start, end) in items_
  std::vector<std::uint32_t> items_;
  mutable std::vector<std::uint32_t> stamp_;  ///< de-duplication of candidates per query
  mutable std::uint32_t query_id_ = 0;
};

}  // namespace trailmark

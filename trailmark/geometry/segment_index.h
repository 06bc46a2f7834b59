// SPDX-License-Identifier: MIT
#pragma once
/// Uniform-grid spatial index over 2-D segments for "does this step cross a wall?" and
/// ray-casting queries. Walls of a building are short and evenly spread, so a grid with
/// ~1 m cells answers a step query by looking at a handful of cells; it is tested against
/// brute force (tests/geometry). An R-tree would add a dependency
/// without a measurable gain on floor plans of this size. Queries reuse a scratch buffer:
/// one index must not be queried from two threads at once (copy it per thread).

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <optional>
#include <type_traits>
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
  /// Calls visit(i) once for every segment whose cells the query's box overlaps; a visit that
  /// returns bool ends the query when it returns false.
  template <class Visit>
  void ForEachCandidate(const Box2& box, Visit&& visit) const;

 private:
  std::int64_t CellOf(double v, int axis) const {
    const double lo = axis == 0 ? bounds_.min.x() : bounds_.min.y();
    const std::int64_t n = axis == 0 ? nx_ : ny_;
    const double c = std::floor((v - lo) / cell_);
    if (!(c >= 0)) return 0;  // also catches NaN
    return std::min<std::int64_t>(static_cast<std::int64_t>(std::min(c, 9e15)), n - 1);
  }

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

template <class Visit>
void SegmentIndex::ForEachCandidate(const Box2& box, Visit&& visit) const {
  if (segments_.empty() || box.Empty()) return;
  if (box.max.x() < bounds_.min.x() || box.max.y() < bounds_.min.y() ||
      box.min.x() > bounds_.max.x() || box.min.y() > bounds_.max.y()) {
    return;
  }
  if (++query_id_ == 0) {  // wrapped: reset stamps
    std::fill(stamp_.begin(), stamp_.end(), 0);
    query_id_ = 1;
  }
  const std::int64_t x0 = CellOf(box.min.x(), 0), x1 = CellOf(box.max.x(), 0);
  const std::int64_t y0 = CellOf(box.min.y(), 1), y1 = CellOf(box.max.y(), 1);
  for (std::int64_t y = y0; y <= y1; ++y) {
    for (std::int64_t x = x0; x <= x1; ++x) {
      const std::size_t c = static_cast<std::size_t>(y * nx_ + x);
      for (std::uint32_t k = cell_start_[c]; k < cell_start_[c + 1]; ++k) {
        const std::uint32_t i = items_[k];
        if (stamp_[i] == query_id_) continue;
        stamp_[i] = query_id_;
        if constexpr (std::is_same_v<decltype(visit(std::size_t{i})), bool>) {
          if (!visit(std::size_t{i})) return;
        } else {
          visit(std::size_t{i});
        }
      }
    }
  }
}

}  // namespace trailmark

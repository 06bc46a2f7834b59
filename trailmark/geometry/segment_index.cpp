// SPDX-License-Identifier: MIT
#include "trailmark/geometry/segment_index.h"

#include <algorithm>
#include <cmath>

namespace trailmark {

SegmentIndex::SegmentIndex(std::vector<Segment2> segments, Options options)
    : segments_(std::move(segments)), cell_(options.cell_size_m) {
  if (segments_.empty()) return;
  for (const auto& s : segments_) {
    bounds_.Extend(s.a);
    bounds_.Extend(s.b);
  }
  const Vec2 extent = (bounds_.max - bounds_.min).cwiseMax(Vec2::Constant(1e-9));
  while ((std::ceil(extent.x() / cell_) + 1) * (std::ceil(extent.y() / cell_) + 1) >
         options.max_cells) {
    cell_ *= 2.0;
  }
  nx_ = static_cast<std::int64_t>(std::floor(extent.x() / cell_)) + 1;
  ny_ = static_cast<std::int64_t>(std::floor(extent.y() / cell_)) + 1;

  // Two passes (count, fill) over the cells each segment's box covers.
  std::vector<std::uint32_t> counts(static_cast<std::size_t>(nx_ * ny_) + 1, 0);
  auto for_cells = [&](const Segment2& s, auto&& fn) {
    const std::int64_t x0 = CellOf(std::min(s.a.x(), s.b.x()), 0);
    const std::int64_t x1 = CellOf(std::max(s.a.x(), s.b.x()), 0);
    const std::int64_t y0 = CellOf(std::min(s.a.y(), s.b.y()), 1);
    const std::int64_t y1 = CellOf(std::max(s.a.y(), s.b.y()), 1);
    for (std::int64_t y = y0; y <= y1; ++y) {
      for (std::int64_t x = x0; x <= x1; ++x) fn(static_cast<std::size_t>(y * nx_ + x));
    }
  };
  for (const auto& s : segments_) for_cells(s, [&](std::size_t c) { ++counts[c + 1]; });
  for (std::size_t c = 1; c < counts.size(); ++c) counts[c] += counts[c - 1];
  cell_start_ = counts;
  items_.resize(cell_start_.back());
  std::vector<std::uint32_t> fill(cell_start_.begin(), cell_start_.end() - 1);
  for (std::uint32_t i = 0; i < segments_.size(); ++i) {
    for_cells(segments_[i], [&](std::size_t c) { items_[fill[c]++] = i; });
  }
  stamp_.assign(segments_.size(), 0);
}

bool SegmentIndex::Intersects(const Segment2& query) const {
  Box2 box;
  box.Extend(query.a);
  box.Extend(query.b);
  bool hit = false;
  ForEachCandidate(box, [&](std::size_t i) {
    hit = SegmentsIntersect(query, segments_[i]);
    return !hit;  // the first crossing answers
  });
  return hit;
}

int SegmentIndex::CountIntersections(const Segment2& query) const {
  Box2 box;
  box.Extend(query.a);
  box.Extend(query.b);
  int count = 0;
  ForEachCandidate(box, [&](std::size_t i) {
    if (SegmentsIntersect(query, segments_[i])) ++count;
  });
  return count;
}

std::optional<double> SegmentIndex::RayCast(const Vec2& origin, const Vec2& dir,
                                            double max_range_m) const {
  const Segment2 ray{origin, origin + dir * max_range_m};
  Box2 box;
  box.Extend(ray.a);
  box.Extend(ray.b);
  std::optional<double> best;
  ForEachCandidate(box, [&](std::size_t i) {
    if (auto s = FirstIntersection(ray, segments_[i])) {
      const double d = *s * max_range_m;
      if (!best || d < *best) best = d;
    }
  });
  return best;
}

}  // namespace trailmark

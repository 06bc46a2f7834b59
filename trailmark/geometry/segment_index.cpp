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

std::int64_t SegmentIndex::CellOf(double v, int axis) const {
  const double lo = axis == 0 ? bounds_.min.x() : bounds_.min.y();
  const std::int64_t n = axis == 0 ? nx_ : ny_;
  const double c = std::floor((v - lo) / cell_);
  if (!(c >= 0)) return 0;  // also catches NaN
  return std::min<std::int64_t>(static_cast<std::int64_t>(std::min(c, 9e15)), n - 1);
}

void SegmentIndex::ForEachCandidate(const Box2& box,
                                    const std::function<void(std::size_t)>& visit) const {
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
        visit(i);
      }
    }
  }
}

bool SegmentIndex::Intersects(const Segment2& query) const {
  return CountIntersections(query) > 0;
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

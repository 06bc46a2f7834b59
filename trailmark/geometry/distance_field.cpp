// SPDX-License-Identifier: MIT
#include "trailmark/geometry/distance_field.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace trailmark {

bool DistanceFieldOptions::IsValid(std::string* why) const {
  if (!(cell_m > 0) || !(max_distance_m > 0)) {
    if (why) *why = "cell_m and max_distance_m must be > 0";
    return false;
  }
  return true;
}

DistanceField::DistanceField(const std::vector<Segment2>& walls, Options options)
    : options_(options) {
  std::string why;
  if (!options_.IsValid(&why)) throw std::invalid_argument("DistanceField: " + why);
  to_raster_ = Eigen::Rotation2Dd(-options_.axis_rad).toRotationMatrix();
  std::vector<Segment2> local;
  local.reserve(walls.size());
  Box2 box;
  for (const auto& w : walls) {
    local.push_back({to_raster_ * w.a, to_raster_ * w.b});
    box.Extend(local.back().a), box.Extend(local.back().b);
  }
  if (box.Empty()) return;  // no walls: every lookup is "far"
  const double h = options_.cell_m;
  const double r = options_.max_distance_m;
  // Beyond r of every wall the field is the clamp: the grid need not reach further.
  origin_ = box.min - Vec2::Constant(r);
  const Vec2 size = box.max + Vec2::Constant(r) - origin_;
  // A floor plan of a few hundred metres at 0.1 m is a few million cells; refuse absurd sizes
  // rather than allocate gigabytes for a plan in the wrong units.
  const double cells = std::ceil(size.x() / h) * std::ceil(size.y() / h);
  if (!(cells <= 5e7)) {
    throw std::invalid_argument("DistanceField: the floor plan spans " + std::to_string(size.x()) +
                                " x " + std::to_string(size.y()) + " m, too large for a grid of " +
                                std::to_string(h) + " m");
  }
  nx_ = static_cast<int>(std::ceil(size.x() / h));
  ny_ = static_cast<int>(std::ceil(size.y() / h));
  const float far = static_cast<float>(options_.max_distance_m);
  d_.assign(static_cast<std::size_t>(nx_) * ny_, far);
  for (const auto& w : local) {
    const int i0 = std::max(
        0, static_cast<int>(std::floor((std::min(w.a.x(), w.b.x()) - r - origin_.x()) / h)));
    const int i1 = std::min(
        nx_ - 1, static_cast<int>(std::ceil((std::max(w.a.x(), w.b.x()) + r - origin_.x()) / h)));
    const int j0 = std::max(
        0, static_cast<int>(std::floor((std::min(w.a.y(), w.b.y()) - r - origin_.y()) / h)));
    const int j1 = std::min(
        ny_ - 1, static_cast<int>(std::ceil((std::max(w.a.y(), w.b.y()) + r - origin_.y()) / h)));
    for (int j = j0; j <= j1; ++j) {
      for (int i = i0; i <= i1; ++i) {
        const Vec2 c = origin_ + Vec2((i + 0.5) * h, (j + 0.5) * h);
        float& cell = d_[static_cast<std::size_t>(j) * nx_ + i];
        cell = std::min(cell, static_cast<float>(std::min(r, DistanceToSegment(c, w))));
      }
    }
  }
}

double DistanceField::At(const Vec2& x) const {
  if (d_.empty() || !std::isfinite(x.x()) || !std::isfinite(x.y())) return options_.max_distance_m;
  const Vec2 q = to_raster_ * x;
  const int i = static_cast<int>(std::floor((q.x() - origin_.x()) / options_.cell_m));
  const int j = static_cast<int>(std::floor((q.y() - origin_.y()) / options_.cell_m));
  if (i < 0 || j < 0 || i >= nx_ || j >= ny_) return options_.max_distance_m;
  return d_[static_cast<std::size_t>(j) * nx_ + i];
}

}  // namespace trailmark

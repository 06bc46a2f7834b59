// SPDX-License-Identifier: MIT
#pragma once
/// The distance to the nearest wall, sampled on a square grid over a floor plan and clamped
/// at `max_distance_m` (a wall farther than that counts as "far"). Built by visiting, for each
/// wall, only the cells within max_distance_m of it: cost ~ total wall length x max distance,
/// not cells x walls. Lookups are O(1) (nearest cell centre); outside the grid the distance is
/// max_distance_m. The grid covers the walls' bounding box grown by max_distance_m, its cells
/// counted from that box's corner along axes at `axis_rad`: the same raster, relative to the walls,
/// wherever and however rotated a plan is drawn (issue 23). No I/O.

#include <string>
#include <vector>

#include "trailmark/geometry/segment.h"

namespace trailmark {

struct DistanceFieldOptions {
  double cell_m = 0.1;          ///< sampling step (m)
  double max_distance_m = 2.0;  ///< distances are clamped here (m)
  double axis_rad = 0;          ///< direction of the raster's x axis in the walls' frame (rad)
  bool IsValid(std::string* why) const;
};

class DistanceField {
 public:
  using Options = DistanceFieldOptions;
  DistanceField() = default;
  /// Throws std::invalid_argument on bad options.
  explicit DistanceField(const std::vector<Segment2>& walls, Options options = {});

  /// Distance (m) from x to the nearest wall, clamped at max_distance_m; accurate to half a
  /// cell diagonal (the value at the nearest cell centre).
  double At(const Vec2& x) const;
  const Options& options() const { return options_; }

 private:
  Options options_;
  Vec2 origin_ = Vec2::Zero();  ///< corner of cell (0, 0), in the raster's axes
  Mat2 to_raster_ = Mat2::Identity();
  int nx_ = 0, ny_ = 0;
  std::vector<float> d_;
};

}  // namespace trailmark

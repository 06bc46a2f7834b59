// SPDX-License-Identifier: MIT
#pragma once
/// A floor plan in the navigation frame: walls, doors (openings in walls) and rooms, with a
/// spatial index over the solid wall pieces. No I/O (io/floor_plan_geojson reads the file).

#include <string>
#include <utility>
#include <vector>

#include "trailmark/geometry/segment_index.h"

namespace trailmark {

struct Room {
  std::string name;
  std::vector<Vec2> ring;  ///< outer ring, not repeated at the end
  int level = 0;
};

struct FloorPlanOptions {
  double door_snap_m = 0.25;  ///< a door cuts a wall when both ends lie this close to it
  double index_cell_m = 1.0;  ///< SegmentIndex cell size
};

class FloorPlan {
 public:
  using Options = FloorPlanOptions;

  FloorPlan() = default;
  /// Walls and doors as drawn; doors are removed from the walls they lie on.
  FloorPlan(std::vector<Segment2> walls, std::vector<Segment2> doors, std::vector<Room> rooms,
            Options options = {});

  const std::vector<Segment2>& walls() const { return walls_; }          ///< as drawn
  const std::vector<Segment2>& doors() const { return doors_; }
  const std::vector<Room>& rooms() const { return rooms_; }
  const std::vector<Segment2>& solid_walls() const { return index_.segments(); }
  const SegmentIndex& index() const { return index_; }
  Box2 Bounds() const;
  bool empty() const { return walls_.empty(); }

  /// True when going straight from a to b passes through a solid wall.
  bool Crosses(const Vec2& a, const Vec2& b) const { return index_.Intersects({a, b}); }
  /// Number of solid wall pieces between a and b (for per-wall radio attenuation).
  int WallsBetween(const Vec2& a, const Vec2& b) const {
    return index_.CountIntersections({a, b});
  }

 private:
  std::vector<Segment2> walls_;
  std::vector<Segment2> doors_;
  std::vector<Room> rooms_;
  SegmentIndex index_;
};

/// The plans of a multi-level building: (level, that level's plan), by level.
using LevelPlans = std::vector<std::pair<int, FloorPlan>>;

/// Whether a room connects levels: a stairwell or staircase (its name contains "stair", any
/// case). Map matching moves a belief between levels only there.
bool IsStairwell(const Room& room);

/// Appends the four walls of the axis-aligned rectangle [lo, hi] (for simulated floor plans).
void AddRectangle(std::vector<Segment2>& walls, const Vec2& lo, const Vec2& hi);

/// Splits `wall` into the pieces not covered by any door lying along it.
std::vector<Segment2> CutDoors(const Segment2& wall, const std::vector<Segment2>& doors,
                               double snap_m);

}  // namespace trailmark

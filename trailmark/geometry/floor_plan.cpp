// SPDX-License-Identifier: MIT
#include "trailmark/geometry/floor_plan.h"

#include <algorithm>
#include <cctype>
#include <cmath>

namespace trailmark {

std::vector<Segment2> CutDoors(const Segment2& wall, const std::vector<Segment2>& doors,
                               double snap_m) {
  const Vec2 d = wall.b - wall.a;
  const double len = d.norm();
  if (len <= 0.0) return {};
  const Vec2 u = d / len;
  std::vector<std::pair<double, double>> gaps;  // in metres along the wall
  for (const auto& door : doors) {
    if (DistanceToSegment(door.a, wall) > snap_m && DistanceToSegment(door.b, wall) > snap_m) {
      continue;
    }
    // Both door ends must lie close to the wall's line.
    const Vec2 n(-u.y(), u.x());
    if (std::abs((door.a - wall.a).dot(n)) > snap_m || std::abs((door.b - wall.a).dot(n)) > snap_m) {
      continue;
    }
    double s0 = (door.a - wall.a).dot(u);
    double s1 = (door.b - wall.a).dot(u);
    if (s0 > s1) std::swap(s0, s1);
    s0 = std::max(s0, 0.0);
    s1 = std::min(s1, len);
    if (s1 > s0) gaps.emplace_back(s0, s1);
  }
  std::sort(gaps.begin(), gaps.end());
  std::vector<Segment2> pieces;
  double cursor = 0.0;
  for (const auto& [g0, g1] : gaps) {
    if (g0 > cursor + 1e-9) pieces.push_back({wall.a + u * cursor, wall.a + u * g0});
    cursor = std::max(cursor, g1);
  }
  if (len > cursor + 1e-9) pieces.push_back({wall.a + u * cursor, wall.b});
  return pieces;
}

FloorPlan::FloorPlan(std::vector<Segment2> walls, std::vector<Segment2> doors,
                     std::vector<Room> rooms, Options options)
    : walls_(std::move(walls)), doors_(std::move(doors)), rooms_(std::move(rooms)) {
  std::vector<Segment2> solid;
  solid.reserve(walls_.size());
  for (const auto& w : walls_) {
    for (auto& piece : CutDoors(w, doors_, options.door_snap_m)) solid.push_back(piece);
  }
  index_ = SegmentIndex(std::move(solid), {.cell_size_m = options.index_cell_m});
}

Box2 FloorPlan::Bounds() const {
  Box2 box;
  for (const auto& w : walls_) {
    box.Extend(w.a);
    box.Extend(w.b);
  }
  for (const auto& r : rooms_) {
    for (const auto& p : r.ring) box.Extend(p);
  }
  return box;
}

bool IsStairwell(const Room& room) {
  std::string lower = room.name;
  for (char& c : lower) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return lower.find("stair") != std::string::npos;
}

void AddRectangle(std::vector<Segment2>& walls, const Vec2& lo, const Vec2& hi) {
  walls.push_back({{lo.x(), lo.y()}, {hi.x(), lo.y()}});
  walls.push_back({{hi.x(), lo.y()}, {hi.x(), hi.y()}});
  walls.push_back({{hi.x(), hi.y()}, {lo.x(), hi.y()}});
  walls.push_back({{lo.x(), hi.y()}, {lo.x(), lo.y()}});
}

}  // namespace trailmark

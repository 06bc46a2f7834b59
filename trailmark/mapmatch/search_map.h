// SPDX-License-Identifier: MIT
#pragma once
/// The floor plan as the map-aided search paper uses it (sec. IV-B, IV-C): walls as a
/// topological graph, a square grid over the building, and the node sequences of directional
/// searches along the grid, from which the search patterns are cut. No I/O.
///
/// Directional search on the grid: a right-hand search keeps a wall on its right — at every
/// node it turns right if it can, else goes straight, else turns left, else turns back (the
/// wall-follower rule); a move is possible when the segment between the two grid nodes crosses
/// no wall and both nodes are inside the building. The walk starts at the inside node closest
/// to the entry, facing along the wall so that the wall is on its right, and stops when it
/// returns to its first state. A left-hand search is the same sequence walked backwards
/// (Fig. 1), so one sequence serves both. Inner walls not connected to the outer walls get
/// their own sequence (Fig. 3, grey).
///
/// Inside: the grid nodes that cannot be reached from outside the building's bounding box with
/// every door closed (the walls as drawn); the entry door is thereby closed too, so a search
/// never leaves the building.
///
/// The grid (ours, issue 23) lies along the walls' dominant direction, turned by a quarter turn
/// the plan itself defines, its offsets counted from the plan's corner (`GridAxis`): a plan
/// drawn rotated by any angle and moved anywhere gets the same nodes relative to its walls, so
/// the same sequences and patterns. The paper's plans are drawn along their axes, where this is
/// the paper's grid.

#include <optional>
#include <string>
#include <vector>

#include "trailmark/geometry/floor_plan.h"
#include "trailmark/geometry/segment_index.h"

namespace trailmark::mapmatch {

/// Walls as a topological graph: nodes are wall end points (merged within `snap_m`), edges
/// are walls; `component[e]` groups walls that touch (shared ends or T-junctions).
struct WallGraph {
  std::vector<Vec2> nodes;
  std::vector<std::pair<int, int>> edges;
  std::vector<int> component;
  int components = 0;
  static WallGraph Build(const std::vector<Segment2>& walls, double snap_m = 0.05);
};

/// What is wrong or doubtful in a floor plan, for the pipeline's diagnostics.
struct MapProblem {
  std::string message;
  bool fatal = false;  ///< pattern extraction cannot work (e.g. nothing enclosed)
};
/// Zero-length walls, overlapping collinear walls, wall ends that touch nothing (a gap, or a
/// free-standing partition), no walls at all.
std::vector<MapProblem> CheckFloorPlan(const FloorPlan& plan, double snap_m = 0.05);

struct SearchGridOptions {
  double spacing_m = 1.0;  ///< grid spacing (sec. V-B: 1 m, "small enough for narrow hallways")
  /// Ours (issue 23): the grid's axes along the walls' dominant direction (`GridAxis`),
  /// so that a building drawn rotated in its frame gets the same grid, patterns and inside as
  /// when drawn along the axes. false: the map's x/y axes (the paper, whose plans are drawn so).
  bool align_to_walls = true;
  bool IsValid(std::string* why) const;
};

/// The walls' dominant direction modulo 90 degrees, in [-pi/4, pi/4): the argument of the
/// length-weighted sum of exp(4 i phi) over the walls, divided by 4 (the circular mean of a
/// direction with four-fold symmetry). 0 when the walls have no dominant direction.
double DominantWallAxis(const std::vector<Segment2>& walls);

/// The search grid's x axis for a plan (rad; ours, issue 23): the dominant direction of its
/// solid walls (doors cut out: the same for both door conventions), turned by the quarter turn
/// that points it closest to the walls' length-weighted centroid as seen from the centre of the
/// plan's bounding rectangle in those axes — a direction that turns with the plan, so that the
/// plan drawn rotated by any angle gets the same grid, node for node. A plan with no such
/// direction (symmetric: the two points within 1e-6 of its size) keeps the dominant direction
/// in [-pi/4, pi/4).
double GridAxis(const FloorPlan& plan);

class SearchGrid {
 public:
  using Options = SearchGridOptions;
  SearchGrid(const FloorPlan& plan, Options options = {});

  struct Cell {
    int ix = 0, iy = 0;
    bool operator==(const Cell& o) const { return ix == o.ix && iy == o.iy; }
  };
  /// 0 east, 1 north, 2 west, 3 south.
  static Cell Step(const Cell& c, int dir);

  bool Inside(const Cell& c) const;
  Vec2 Center(const Cell& c) const;
  /// The grid's x axis direction in the navigation frame (rad; 0 for the map's own axes).
  double axis_rad() const { return axis_rad_; }
  /// A vector given in the grid's axes, in the navigation frame.
  Vec2 ToNavigation(const Vec2& v_grid) const { return axes_ * v_grid; }
  /// A point of the navigation frame in the grid's own frame (its axes, from the centre of cell
  /// (0, 0); metres): the same for the plan drawn rotated or shifted.
  Vec2 ToGrid(const Vec2& p_n) const { return axes_.transpose() * p_n - origin_; }
  /// Whether a searcher can move from c in direction dir.
  bool CanMove(const Cell& c, int dir) const;
  /// Whether `p` lies inside the building: it reaches an inside node of its cell or of the eight
  /// around it without crossing a wall or a door (doors closed, as for the inside nodes). Exact
  /// up to the grid's reach: a point in a niche narrower than the spacing with no node of its
  /// own counts as outside. (Ours, issue 23: the paper's cells of 1 m counted 7.5 % of the true
  /// positions of a house drawn at 33 degrees as outside.)
  bool Contains(const Vec2& p) const;
  /// The cell containing `p` (may be outside the grid or the building).
  Cell CellOf(const Vec2& p) const;
  /// The inside cell closest to `p` (empty when nothing is inside).
  std::optional<Cell> Nearest(const Vec2& p) const;
  std::size_t inside_count() const { return inside_count_; }
  double spacing() const { return options_.spacing_m; }
  const FloorPlan& plan() const { return *plan_; }
  /// All inside cell centres (for uniform initialization).
  std::vector<Vec2> InsideCenters() const;

 private:
  int Index(const Cell& c) const { return c.iy * nx_ + c.ix; }
  const FloorPlan* plan_;
  Options options_;
  Vec2 origin_ = Vec2::Zero();  ///< centre of cell (0, 0), in the grid's axes
  double axis_rad_ = 0;
  Mat2 axes_ = Mat2::Identity();  ///< grid axes -> navigation frame
  int nx_ = 0, ny_ = 0;
  std::vector<char> inside_;
  SegmentIndex closed_;  ///< the walls and doors as drawn (every door closed)
  std::size_t inside_count_ = 0;
};

/// One directional-search node sequence (closed: the last node is adjacent to the first).
struct NodeSequence {
  std::vector<Vec2> nodes;
  bool around_inner_walls = false;  ///< an extra sequence: inner walls not on the outer walls,
                                    ///< or an enclosed part the first search never enters
  double grid_axis_rad = 0;         ///< the direction of the grid it was walked on (its moves
                                    ///< are along this axis or at right angles to it)
};

struct SearchSequenceOptions {
  SearchGridOptions grid;
  double wall_snap_m = 0.05;
  int max_extra_sequences = 20;
  /// An entry outside the building enters by the nearest door within this distance (ours: a
  /// responder may start up to 10 m in front of the building, issue 21).
  double entry_door_reach_m = 15.0;
};

/// The right-hand sequence from the node closest to `entry_n`, plus one sequence around every
/// group of inner walls the first one never passes, and one in every enclosed part it never
/// enters (a closed-off room). An entry outside the building (a responder who starts in front
/// of it) enters by the door nearest to it. Throws std::invalid_argument when nothing is
/// enclosed near the entry or near that door.
std::vector<NodeSequence> ExtractSearchSequences(const FloorPlan& plan, const Vec2& entry_n,
                                                 const SearchSequenceOptions& options = {});

/// The inner doors (the building's inside on both sides: exterior doors are closed for the
/// searches) that no search sequence passes through, as indices into the plan's doors: a room
/// behind one has no pattern that enters it, so a responder who searches it is not recognized
/// there (issue 23, item 2). A sequence passes a door when one of its moves crosses the door.
std::vector<std::size_t> DoorsNotTraversed(const SearchGrid& grid,
                                           const std::vector<NodeSequence>& sequences);

/// What a reviewer looks at of the search map (issue 23, item 2; `trailmark patterns` and the
/// HTML report): the grid's axis and inside nodes, the sequences from the entry and the inner
/// doors none passes.
struct SearchPatterns {
  double grid_axis_rad = 0;
  double grid_spacing_m = 1.0;
  Vec2 entry_n = Vec2::Zero();
  bool entry_is_corner = false;  ///< no entry given: the inside node nearest the plan's corner
  std::vector<Vec2> inside_n;    ///< the inside grid nodes' centres
  std::vector<NodeSequence> sequences;
  std::vector<std::size_t> doors_not_traversed;  ///< indices into the plan's doors
};

/// The search patterns of `plan` from `entry_n` (empty: the inside node nearest the plan's
/// lower-left corner, as an inspection of a plan needs no entry). Throws std::invalid_argument
/// as ExtractSearchSequences does.
SearchPatterns BuildSearchPatterns(const FloorPlan& plan, const std::optional<Vec2>& entry_n,
                                   const SearchSequenceOptions& options = {});

/// The right-hand walk on the grid from `start` facing `dir` until it repeats a state.
std::vector<Vec2> RightHandWalk(const SearchGrid& grid, SearchGrid::Cell start, int dir);

}  // namespace trailmark::mapmatch

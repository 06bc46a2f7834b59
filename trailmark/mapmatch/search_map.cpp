// SPDX-License-Identifier: MIT
#include "trailmark/mapmatch/search_map.h"

#include <fmt/format.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <numbers>
#include <numeric>
#include <stdexcept>
#include <unordered_set>

#include "trailmark/geometry/segment_index.h"

namespace trailmark::mapmatch {
namespace {

struct UnionFind {
  explicit UnionFind(int n) : parent(n) { std::iota(parent.begin(), parent.end(), 0); }
  int Find(int x) { return parent[x] == x ? x : parent[x] = Find(parent[x]); }
  void Unite(int a, int b) { parent[Find(a)] = Find(b); }
  std::vector<int> parent;
};

double Cross(const Vec2& a, const Vec2& b) { return a.x() * b.y() - a.y() * b.x(); }

/// The box around a segment (or a point: a == b), grown by `margin` on every side.
Box2 BoxAround(const Vec2& a, const Vec2& b, double margin) {
  Box2 box;
  box.Extend(a);
  box.Extend(b);
  box.min -= Vec2::Constant(margin);
  box.max += Vec2::Constant(margin);
  return box;
}

/// The indices of the indexed segments near a box, ascending (the order a scan over every
/// segment would visit them: results and messages stay those of the scan, issue 30 item 5 —
/// the scans were every wall against every wall).
std::vector<std::size_t> Near(const SegmentIndex& index, const Box2& box) {
  std::vector<std::size_t> out;
  index.ForEachCandidate(box, [&](std::size_t i) { out.push_back(i); });
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace

WallGraph WallGraph::Build(const std::vector<Segment2>& walls, double snap_m) {
  WallGraph g;
  // Nodes hashed by cells of snap_m: the first node (lowest index) within snap_m of p is in
  // p's cell or a neighbour.
  const double cell = std::max(snap_m, 1e-9);
  std::map<std::pair<long long, long long>, std::vector<int>> cells;
  auto key = [cell](const Vec2& p) {
    return std::pair{static_cast<long long>(std::floor(p.x() / cell)),
                     static_cast<long long>(std::floor(p.y() / cell))};
  };
  auto node_of = [&](const Vec2& p) {
    const auto [cx, cy] = key(p);
    int best = -1;
    for (long long dx = -1; dx <= 1; ++dx) {
      for (long long dy = -1; dy <= 1; ++dy) {
        const auto it = cells.find({cx + dx, cy + dy});
        if (it == cells.end()) continue;
        for (const int i : it->second) {
          if ((best < 0 || i < best) && (g.nodes[i] - p).norm() <= snap_m) best = i;
        }
      }
    }
    if (best >= 0) return best;
    g.nodes.push_back(p);
    cells[key(p)].push_back(static_cast<int>(g.nodes.size()) - 1);
    return static_cast<int>(g.nodes.size()) - 1;
  };
  std::vector<Segment2> kept;
  for (const auto& w : walls) {
    if (w.Length() <= snap_m) continue;
    g.edges.emplace_back(node_of(w.a), node_of(w.b));
    kept.push_back(w);
  }
  const int E = static_cast<int>(kept.size());
  UnionFind uf(E);
  std::vector<int> edge_of_node(g.nodes.size(), -1);
  for (int e = 0; e < E; ++e) {
    for (int n : {g.edges[e].first, g.edges[e].second}) {
      if (edge_of_node[n] >= 0) uf.Unite(e, edge_of_node[n]);
      edge_of_node[n] = e;
    }
  }
  const SegmentIndex index(kept);
  for (int i = 0; i < E; ++i) {  // T-junctions and crossings
    for (const std::size_t jj : Near(index, BoxAround(kept[i].a, kept[i].b, snap_m))) {
      const int j = static_cast<int>(jj);
      if (j <= i || uf.Find(i) == uf.Find(j)) continue;
      if (DistanceToSegment(kept[i].a, kept[j]) <= snap_m ||
          DistanceToSegment(kept[i].b, kept[j]) <= snap_m ||
          DistanceToSegment(kept[j].a, kept[i]) <= snap_m ||
          DistanceToSegment(kept[j].b, kept[i]) <= snap_m || SegmentsIntersect(kept[i], kept[j])) {
        uf.Unite(i, j);
      }
    }
  }
  std::map<int, int> label;
  for (int e = 0; e < E; ++e) {
    const int root = uf.Find(e);
    if (!label.count(root)) label[root] = static_cast<int>(label.size());
    g.component.push_back(label[root]);
  }
  g.components = static_cast<int>(label.size());
  return g;
}

std::vector<MapProblem> CheckFloorPlan(const FloorPlan& plan, double snap_m) {
  std::vector<MapProblem> problems;
  const auto& walls = plan.walls();
  if (walls.empty()) {
    problems.push_back({"the floor plan has no walls", true});
    return problems;
  }
  int zero = 0;
  for (std::size_t i = 0; i < walls.size(); ++i) {
    if (walls[i].Length() <= snap_m) {
      if (zero++ == 0) {
        problems.push_back({fmt::format("wall {} at ({:.2f}, {:.2f}) has zero length: ignored", i,
                                        walls[i].a.x(), walls[i].a.y()),
                            false});
      }
    }
  }
  if (zero > 1)
    problems.push_back({fmt::format("{} zero-length walls in all: ignored", zero), false});
  int overlaps = 0;
  const SegmentIndex index(walls);
  for (std::size_t i = 0; i < walls.size(); ++i) {
    const Vec2 u = walls[i].b - walls[i].a;
    const double len = u.norm();
    if (len <= snap_m) continue;
    for (const std::size_t j : Near(index, BoxAround(walls[i].a, walls[i].b, snap_m))) {
      if (j <= i) continue;
      const Vec2 v = walls[j].b - walls[j].a;
      if (v.norm() <= snap_m || std::abs(Cross(u, v)) > 1e-6 * len * v.norm()) continue;
      if (std::abs(Cross(u / len, walls[j].a - walls[i].a)) > snap_m) continue;  // parallel, apart
      const double s0 = (walls[j].a - walls[i].a).dot(u) / len,
                   s1 = (walls[j].b - walls[i].a).dot(u) / len;
      const double overlap = std::min(len, std::max(s0, s1)) - std::max(0.0, std::min(s0, s1));
      if (overlap > snap_m && overlaps++ == 0) {
        problems.push_back(
            {fmt::format("walls {} and {} overlap over {:.2f} m (drawn twice?)", i, j, overlap),
             false});
      }
    }
  }
  if (overlaps > 1)
    problems.push_back({fmt::format("{} overlapping wall pairs in all", overlaps), false});
  // Wall ends that touch no other wall: a gap in the outline, or a free-standing partition. A
  // jamb of a door drawn across the gap (spec 1.1) touches the door: not a gap.
  const SegmentIndex door_index(plan.doors());
  int dangling = 0;
  std::string first;
  for (std::size_t i = 0; i < walls.size(); ++i) {
    if (walls[i].Length() <= snap_m) continue;
    for (const Vec2& end : {walls[i].a, walls[i].b}) {
      bool touches = false;
      for (const std::size_t j : Near(index, BoxAround(end, end, snap_m))) {
        touches = touches ||
                  (j != i && walls[j].Length() > snap_m && DistanceToSegment(end, walls[j]) <= snap_m);
      }
      door_index.ForEachCandidate(BoxAround(end, end, snap_m), [&](std::size_t d) {
        touches = touches || DistanceToSegment(end, door_index.segments()[d]) <= snap_m;
      });
      if (!touches && dangling++ == 0) first = fmt::format("({:.2f}, {:.2f})", end.x(), end.y());
    }
  }
  if (dangling > 0) {
    problems.push_back(
        {fmt::format("{} wall end(s) touch no other wall, first at {}: a gap in a wall, or a "
                     "free-standing partition",
                     dangling, first),
         false});
  }
  // A door must lie along a wall or across a gap between walls (spec 1.1): both its ends on a
  // wall. One whose end touches no wall is a door with no wall (issue 23).
  const auto& doors = plan.doors();
  int loose = 0;
  std::string first_door;
  for (std::size_t k = 0; k < doors.size(); ++k) {
    for (const Vec2& end : {doors[k].a, doors[k].b}) {
      bool on_wall = false;
      for (const std::size_t j : Near(index, BoxAround(end, end, snap_m))) {
        on_wall = on_wall || DistanceToSegment(end, walls[j]) <= snap_m;
      }
      if (!on_wall && loose++ == 0) {
        first_door = fmt::format(
            "door {} from ({:.2f}, {:.2f}) to ({:.2f}, {:.2f}), its end at "
            "({:.2f}, {:.2f})",
            k, doors[k].a.x(), doors[k].a.y(), doors[k].b.x(), doors[k].b.y(), end.x(), end.y());
      }
    }
  }
  if (loose > 0) {
    problems.push_back({fmt::format("{} door end(s) touch no wall, first {}: a door with no wall "
                                    "(a door lies along a wall or across a gap between walls)",
                                    loose, first_door),
                        false});
  }
  return problems;
}

bool SearchGridOptions::IsValid(std::string* why) const {
  if (!(spacing_m >= 0.1 && spacing_m <= 10.0)) {
    if (why) *why = "grid spacing must be within 0.1 .. 10 m";
    return false;
  }
  return true;
}

double DominantWallAxis(const std::vector<Segment2>& walls) {
  // Sum of len exp(4 i phi): a wall and one at right angles to it add up, opposite
  // directions of one wall are the same.
  double c = 0, s = 0;
  for (const auto& w : walls) {
    const Vec2 d = w.b - w.a;
    const double len = d.norm();
    if (!(len > 0)) continue;
    const double phi = std::atan2(d.y(), d.x());
    c += len * std::cos(4 * phi);
    s += len * std::sin(4 * phi);
  }
  double total = 0;
  for (const auto& w : walls) total += w.Length();
  if (!(std::hypot(c, s) > 1e-9 * total)) return 0.0;
  const double axis = std::atan2(s, c) / 4;  // (-pi/4, pi/4]
  return axis >= std::numbers::pi / 4 ? axis - std::numbers::pi / 2 : axis;
}

double GridAxis(const FloorPlan& plan) {
  const auto& walls = plan.solid_walls();
  const double axis = DominantWallAxis(walls);
  const Mat2 to_axes = Eigen::Rotation2Dd(-axis).toRotationMatrix();
  Box2 box;  // the bounding rectangle in these axes: the same for each quarter turn of them
  Vec2 centroid = Vec2::Zero();
  double total = 0;
  for (const auto& w : walls) {
    box.Extend(to_axes * w.a), box.Extend(to_axes * w.b);
    centroid += w.Length() * (to_axes * (0.5 * (w.a + w.b)));
    total += w.Length();
  }
  if (!(total > 0)) return axis;
  const Vec2 v = centroid / total - 0.5 * (box.min + box.max);
  if (!(v.norm() > 1e-6 * (box.max - box.min).norm())) return axis;  // symmetric: no direction
  // The quarter turn closest to v (v is in the axes' frame; ties to the lower turn).
  int turn = 0;
  double best = v.x();
  const double along[4] = {v.x(), v.y(), -v.x(), -v.y()};
  for (int k = 1; k < 4; ++k) {
    if (along[k] > best) best = along[k], turn = k;
  }
  return axis + turn * std::numbers::pi / 2;
}

SearchGrid::SearchGrid(const FloorPlan& plan, Options options) : plan_(&plan), options_(options) {
  std::string why;
  if (!options_.IsValid(&why)) throw std::invalid_argument("SearchGrid: " + why);
  if (plan.Bounds().Empty()) return;
  if (options_.align_to_walls) {
    axis_rad_ = GridAxis(plan);
    axes_ = Eigen::Rotation2Dd(axis_rad_).toRotationMatrix();
  }
  // The plan in the grid's axes (the identity for a plan drawn along its axes: the same
  // numbers as the map's own).
  const Mat2 to_grid = axes_.transpose();
  Box2 box;
  for (const auto& w : plan.walls()) box.Extend(to_grid * w.a), box.Extend(to_grid * w.b);
  for (const auto& r : plan.rooms()) {
    for (const auto& p : r.ring) box.Extend(to_grid * p);
  }
  const double s = options_.spacing_m;
  // Grid offset per axis: the nodes as far as possible from the walls parallel to the grid's
  // axes (a node on a wall line would block its doorway; buildings are mostly rectangular,
  // sec. IV-D).
  std::vector<double> xs, ys;
  for (const auto& w : plan.walls()) {
    const Vec2 a = to_grid * w.a, b = to_grid * w.b;
    const double tol = 1e-9 + 1e-9 * (b - a).norm();
    if (std::abs(a.x() - b.x()) < tol) xs.push_back(a.x());
    if (std::abs(a.y() - b.y()) < tol) ys.push_back(a.y());
  }
  // The candidate offsets count from the plan's corner (not the frame's origin: a plan drawn
  // shifted gets the same nodes relative to its walls).
  auto best_offset = [s](const std::vector<double>& coords, double corner) {
    double best = corner + 0.5 * s, best_score = -1;
    for (int k = 0; k < 100; ++k) {
      const double o = corner + s * k / 100.0;  // node positions o + n s
      double score = 0.5 * s;
      for (double c : coords) {
        const double r = std::remainder(c - o, s);  // [-s/2, s/2]
        score = std::min(score, std::abs(r));
      }
      if (score > best_score + 1e-12) best_score = score, best = o;
    }
    return best;
  };
  const Vec2 offset(best_offset(xs, box.min.x()), best_offset(ys, box.min.y()));
  origin_ = Vec2(offset.x() + s * std::floor((box.min.x() - s - offset.x()) / s),
                 offset.y() + s * std::floor((box.min.y() - s - offset.y()) / s));
  const double nx = std::ceil((box.max.x() - origin_.x()) / s) + 2, ny = std::ceil((box.max.y() - origin_.y()) / s) + 2;
  if (!(nx * ny <= 2e7)) {
    throw std::invalid_argument(fmt::format("the floor plan spans {:.0f} x {:.0f} m: too large for a {} m search grid "
                                            "(at most 2e7 nodes; a wall far away?)",
                                            box.max.x() - box.min.x(), box.max.y() - box.min.y(), s));
  }
  nx_ = static_cast<int>(nx);
  ny_ = static_cast<int>(ny);
  // Flood fill from the border with every door closed: what is not reached is inside. A door is
  // drawn along its wall or across a gap between wall ends (spec 1.1): closing it means adding
  // its segment to the walls as drawn (for the first convention that changes nothing).
  std::vector<Segment2> closed = plan.walls();
  closed.insert(closed.end(), plan.doors().begin(), plan.doors().end());
  closed_ = SegmentIndex(std::move(closed));
  const SegmentIndex& drawn = closed_;
  std::vector<char> outside(static_cast<std::size_t>(nx_) * ny_, 0);
  std::vector<Cell> stack;
  for (int ix = 0; ix < nx_; ++ix) stack.push_back({ix, 0}), stack.push_back({ix, ny_ - 1});
  for (int iy = 0; iy < ny_; ++iy) stack.push_back({0, iy}), stack.push_back({nx_ - 1, iy});
  for (const Cell& c : stack) outside[Index(c)] = 1;
  while (!stack.empty()) {
    const Cell c = stack.back();
    stack.pop_back();
    for (int d = 0; d < 4; ++d) {
      const Cell n = Step(c, d);
      if (n.ix < 0 || n.iy < 0 || n.ix >= nx_ || n.iy >= ny_ || outside[Index(n)]) continue;
      if (drawn.Intersects({Center(c), Center(n)})) continue;
      outside[Index(n)] = 1;
      stack.push_back(n);
    }
  }
  inside_.resize(outside.size());
  for (int iy = 0; iy < ny_; ++iy) {
    for (int ix = 0; ix < nx_; ++ix) {
      const std::size_t i = Index({ix, iy});
      if (outside[i]) continue;
      // A node lying on a wall is not a place to stand (walls at the grid's half spacing).
      const Vec2 c = Center({ix, iy});
      Box2 box;
      box.Extend(c - Vec2::Constant(1e-6));
      box.Extend(c + Vec2::Constant(1e-6));
      bool on_wall = false;
      drawn.ForEachCandidate(box, [&](std::size_t k) {
        on_wall = on_wall || DistanceToSegment(c, drawn.segments()[k]) < 1e-6;
      });
      inside_[i] = !on_wall;
      inside_count_ += inside_[i];
    }
  }
}

SearchGrid::Cell SearchGrid::Step(const Cell& c, int dir) {
  static const int dx[] = {1, 0, -1, 0}, dy[] = {0, 1, 0, -1};
  return {c.ix + dx[dir], c.iy + dy[dir]};
}

bool SearchGrid::Inside(const Cell& c) const {
  return c.ix >= 0 && c.iy >= 0 && c.ix < nx_ && c.iy < ny_ && inside_[Index(c)];
}

Vec2 SearchGrid::Center(const Cell& c) const {
  return axes_ * (origin_ + Vec2(c.ix * options_.spacing_m, c.iy * options_.spacing_m));
}

bool SearchGrid::CanMove(const Cell& c, int dir) const {
  const Cell n = Step(c, dir);
  return Inside(c) && Inside(n) && !plan_->Crosses(Center(c), Center(n));
}

bool SearchGrid::Contains(const Vec2& p) const {
  if (!std::isfinite(p.x()) || !std::isfinite(p.y())) return false;
  const Cell at = CellOf(p);
  if (Inside(at) && !closed_.Intersects({p, Center(at)})) return true;  // the usual case
  for (int dy = -1; dy <= 1; ++dy) {
    for (int dx = -1; dx <= 1; ++dx) {
      const Cell n{at.ix + dx, at.iy + dy};
      if ((dx != 0 || dy != 0) && Inside(n) && !closed_.Intersects({p, Center(n)})) return true;
    }
  }
  return false;
}

SearchGrid::Cell SearchGrid::CellOf(const Vec2& p) const {
  const Vec2 q = (axes_.transpose() * p - origin_) / options_.spacing_m;
  return {static_cast<int>(std::lround(q.x())), static_cast<int>(std::lround(q.y()))};
}

std::optional<SearchGrid::Cell> SearchGrid::Nearest(const Vec2& p) const {
  std::optional<Cell> best;
  double best_d = 1e300;
  for (int iy = 0; iy < ny_; ++iy) {
    for (int ix = 0; ix < nx_; ++ix) {
      if (!inside_[iy * nx_ + ix]) continue;
      const double d = (Center({ix, iy}) - p).squaredNorm();
      if (d < best_d) best_d = d, best = Cell{ix, iy};
    }
  }
  return best;
}

std::vector<Vec2> SearchGrid::InsideCenters() const {
  std::vector<Vec2> out;
  for (int iy = 0; iy < ny_; ++iy) {
    for (int ix = 0; ix < nx_; ++ix) {
      if (inside_[iy * nx_ + ix]) out.push_back(Center({ix, iy}));
    }
  }
  return out;
}

SearchPatterns BuildSearchPatterns(const FloorPlan& plan, const std::optional<Vec2>& entry_n,
                                   const SearchSequenceOptions& options) {
  const SearchGrid grid(plan, options.grid);
  SearchPatterns out;
  out.grid_axis_rad = grid.axis_rad();
  out.grid_spacing_m = grid.spacing();
  out.entry_is_corner = !entry_n;
  if (entry_n) {
    out.entry_n = *entry_n;
  } else {
    const auto nearest = grid.Nearest(plan.Bounds().min);
    out.entry_n = nearest ? grid.Center(*nearest) : plan.Bounds().min;
  }
  out.inside_n = grid.InsideCenters();
  out.sequences = ExtractSearchSequences(plan, out.entry_n, options);
  out.doors_not_traversed = DoorsNotTraversed(grid, out.sequences);
  return out;
}

std::vector<std::size_t> DoorsNotTraversed(const SearchGrid& grid,
                                           const std::vector<NodeSequence>& sequences) {
  const FloorPlan& plan = grid.plan();
  const SegmentIndex doors(plan.doors());
  std::vector<char> passed(plan.doors().size(), 0);
  for (const NodeSequence& seq : sequences) {
    const std::size_t n = seq.nodes.size();
    for (std::size_t k = 0; n > 1 && k < n; ++k) {
      const Segment2 move{seq.nodes[k], seq.nodes[(k + 1) % n]};
      doors.ForEachCandidate(BoxAround(move.a, move.b, 0.0), [&](std::size_t d) {
        if (!passed[d] && SegmentsIntersect(move, doors.segments()[d])) passed[d] = 1;
      });
    }
  }
  std::vector<std::size_t> out;
  for (std::size_t d = 0; d < passed.size(); ++d) {
    if (passed[d]) continue;
    // Inside on both sides, 0.3 m from the door's middle along its normal.
    const Segment2& door = plan.doors()[d];
    const Vec2 along = door.b - door.a;
    if (!(along.norm() > 0)) continue;
    const Vec2 normal = Vec2(-along.y(), along.x()) / along.norm();
    const Vec2 mid = 0.5 * (door.a + door.b);
    if (grid.Contains(mid + 0.3 * normal) && grid.Contains(mid - 0.3 * normal)) out.push_back(d);
  }
  return out;
}

std::vector<Vec2> RightHandWalk(const SearchGrid& grid, SearchGrid::Cell c, int dir) {
  std::vector<Vec2> nodes{grid.Center(c)};
  std::map<std::tuple<int, int, int>, std::size_t> seen{{{c.ix, c.iy, dir}, 0}};
  const std::size_t limit = 4 * grid.inside_count() + 8;
  for (std::size_t k = 0; k < limit; ++k) {
    bool moved = false;
    for (int turn : {3, 0, 1, 2}) {  // right, straight, left, back
      const int nd = (dir + turn) % 4;
      if (grid.CanMove(c, nd)) {
        c = SearchGrid::Step(c, nd);
        dir = nd;
        moved = true;
        break;
      }
    }
    if (!moved) return nodes;  // an isolated node
    const auto key = std::make_tuple(c.ix, c.iy, dir);
    const auto it = seen.find(key);
    if (it != seen.end()) {
      return std::vector<Vec2>(nodes.begin() + static_cast<long>(it->second), nodes.end());
    }
    seen[key] = nodes.size();
    nodes.push_back(grid.Center(c));
  }
  return nodes;
}

namespace {

// A heading at `c` with a wall (or the outside) on the right and the way ahead open.
std::optional<int> HeadingAlongWall(const SearchGrid& grid, const SearchGrid::Cell& c) {
  for (int d = 0; d < 4; ++d) {
    if (!grid.CanMove(c, (d + 3) % 4) && grid.CanMove(c, d)) return d;
  }
  return std::nullopt;
}

// Components of the solid walls that pass within reach of any node of the sequences.
std::vector<char> Touched(const SearchGrid& grid, const WallGraph& g,
                          const std::vector<Segment2>& walls,
                          const std::vector<NodeSequence>& sequences) {
  std::vector<char> touched(g.components, 0);
  const double reach = 0.75 * grid.spacing();
  const SegmentIndex index(walls);
  for (const auto& s : sequences) {
    for (const Vec2& p : s.nodes) {
      index.ForEachCandidate(BoxAround(p, p, reach), [&](std::size_t e) {
        if (!touched[g.component[e]] && DistanceToSegment(p, walls[e]) <= reach)
          touched[g.component[e]] = 1;
      });
    }
  }
  return touched;
}

}  // namespace

std::vector<NodeSequence> ExtractSearchSequences(const FloorPlan& plan, const Vec2& entry_n,
                                                 const SearchSequenceOptions& options) {
  const SearchGrid grid(plan, options.grid);
  if (grid.inside_count() == 0) {
    // Name what leaves it open: the plan's checks (wall ends that touch nothing, doors with no
    // wall) carry the features and their coordinates.
    std::string why;
    for (const auto& p : CheckFloorPlan(plan, options.wall_snap_m)) why += "; " + p.message;
    throw std::invalid_argument(
        "the floor plan encloses no area: with the doors closed, the walls must close the "
        "building" +
        (why.empty() ? std::string(" (gaps in the outer walls?)") : why));
  }
  const double reach_m = 3.0 * options.grid.spacing_m + 2.0;
  auto start = grid.Nearest(entry_n);
  Vec2 entry = entry_n;
  if ((grid.Center(*start) - entry).norm() > reach_m) {
    // A responder who starts outside (issue 21: up to 10 m in front of the building) enters
    // through a door: the search begins at the door nearest to the start.
    const Segment2* door = nullptr;
    double best = std::numeric_limits<double>::infinity();
    for (const Segment2& d : plan.doors()) {
      const double dist = DistanceToSegment(entry_n, d);
      if (dist < best) best = dist, door = &d;
    }
    if (door != nullptr && best <= options.entry_door_reach_m) {
      entry = 0.5 * (door->a + door->b);
      start = grid.Nearest(entry);
    }
    if ((grid.Center(*start) - entry).norm() > reach_m) {
      throw std::invalid_argument(fmt::format(
          "the entry ({:.2f}, {:.2f}) is {:.1f} m from the nearest enclosed grid node and no door "
          "within {:g} m leads in: no enclosed area at the entry",
          entry_n.x(), entry_n.y(), (grid.Center(*grid.Nearest(entry_n)) - entry_n).norm(),
          options.entry_door_reach_m));
    }
  }
  std::vector<NodeSequence> sequences;
  {
    const int dir = HeadingAlongWall(grid, *start).value_or(0);
    std::vector<Vec2> nodes = RightHandWalk(grid, *start, dir);
    // The node closest to the entry first (sec. IV-C).
    const auto first =
        std::min_element(nodes.begin(), nodes.end(), [&](const Vec2& a, const Vec2& b) {
          return (a - entry).squaredNorm() < (b - entry).squaredNorm();
        });
    std::rotate(nodes.begin(), first, nodes.end());
    sequences.push_back({std::move(nodes), false});
  }
  // Inner walls not connected to the outer ones (Fig. 3, grey): a sequence around each.
  std::vector<Segment2> walls;
  for (const auto& w : plan.solid_walls()) {
    if (w.Length() > options.wall_snap_m) walls.push_back(w);
  }
  const WallGraph g = WallGraph::Build(walls, options.wall_snap_m);
  // Each component's wall length, summed once (in the walls' order: the same sums as before).
  std::vector<double> component_length(static_cast<std::size_t>(g.components), 0.0);
  for (std::size_t e = 0; e < walls.size(); ++e) component_length[g.component[e]] += walls[e].Length();
  for (int extra = 0; extra < options.max_extra_sequences; ++extra) {
    const std::vector<char> touched = Touched(grid, g, walls, sequences);
    int component = -1;
    double longest = 0;
    for (int k = 0; k < g.components; ++k) {
      if (touched[k]) continue;
      const double len = component_length[k];
      if (len > longest) longest = len, component = k;
    }
    if (component < 0 || longest < options.grid.spacing_m) break;
    // Start next to the component's longest wall, with it on the right.
    std::size_t wall = 0;
    for (std::size_t e = 0; e < walls.size(); ++e) {
      if (g.component[e] == component &&
          walls[e].Length() >= walls[wall].Length() * (g.component[wall] == component)) {
        wall = e;
      }
    }
    const auto c = grid.Nearest(0.5 * (walls[wall].a + walls[wall].b));
    const auto dir = c ? HeadingAlongWall(grid, *c) : std::nullopt;
    if (!dir) break;
    std::vector<Vec2> nodes = RightHandWalk(grid, *c, *dir);
    NodeSequence s{std::move(nodes), true};
    sequences.push_back(std::move(s));
    if (!Touched(grid, g, walls, sequences)[component]) break;  // could not get round it
  }
  // Enclosed parts the searches never enter (rooms closed off, sec. V-A): a sequence each.
  // The cells whose centre lies within 1.5 spacings of a node of a sequence, marked once per
  // sequence (such a centre is at most two cells from the node's cell).
  const double near_m2 = 2.25 * options.grid.spacing_m * options.grid.spacing_m;
  std::unordered_set<std::int64_t> near_cells;
  auto key = [](const SearchGrid::Cell& c) {
    return (static_cast<std::int64_t>(c.ix) << 32) ^ static_cast<std::uint32_t>(c.iy);
  };
  std::size_t marked = 0;
  auto mark_new_sequences = [&] {
    for (; marked < sequences.size(); ++marked) {
      for (const Vec2& p : sequences[marked].nodes) {
        const SearchGrid::Cell at = grid.CellOf(p);
        for (int dy = -2; dy <= 2; ++dy) {
          for (int dx = -2; dx <= 2; ++dx) {
            const SearchGrid::Cell c{at.ix + dx, at.iy + dy};
            if ((p - grid.Center(c)).squaredNorm() <= near_m2) near_cells.insert(key(c));
          }
        }
      }
    }
  };
  const std::vector<Vec2> inside_centers = grid.InsideCenters();
  for (int extra = 0; extra < options.max_extra_sequences; ++extra) {
    std::optional<SearchGrid::Cell> unreached;
    mark_new_sequences();
    for (const Vec2& c : inside_centers) {
      if (near_cells.count(key(grid.CellOf(c))) != 0) continue;
      // Start where a wall is on the right.
      const SearchGrid::Cell cell = grid.CellOf(c);
      if (HeadingAlongWall(grid, cell)) {
        unreached = cell;
        break;
      }
    }
    if (!unreached) break;
    sequences.push_back(
        {RightHandWalk(grid, *unreached, *HeadingAlongWall(grid, *unreached)), true});
  }
  for (auto& seq : sequences) seq.grid_axis_rad = grid.axis_rad();
  return sequences;
}

}  // namespace trailmark::mapmatch

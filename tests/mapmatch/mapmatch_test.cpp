// SPDX-License-Identifier: MIT
// Map-aided search (mapmatch/): pattern extraction on hand-made floor plans (exact node
// sequences), floor-plan checks, eq. (1), ICP on known transforms, pattern comparison of an
// exact pattern, and the particle filter's wall constraint.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <numbers>

#include "trailmark/core/random.h"
#include "trailmark/geometry/rigid_fit.h"
#include "trailmark/ins/dead_reckoning.h"
#include "trailmark/mapmatch/particle_filter.h"
#include "trailmark/sim/house_search.h"

namespace trailmark::mapmatch {
namespace {

Mat2 Rot(double a) { return Eigen::Rotation2Dd(a).toRotationMatrix(); }

// A w x h room with a 1 m door on the west wall at y in [1, 2].
FloorPlan Room(double w, double h, std::vector<Segment2> extra = {}) {
  std::vector<Segment2> walls = {
      {{0, 0}, {w, 0}}, {{w, 0}, {w, h}}, {{w, h}, {0, h}}, {{0, h}, {0, 0}}};
  for (const auto& e : extra) walls.push_back(e);
  return FloorPlan(walls, {{{0, 1}, {0, 2}}}, {});
}

TEST(SearchSequences, RightHandSearchOfARoomIsItsPerimeterFromTheEntry) {
  const FloorPlan plan = Room(4, 3);
  const auto seqs = ExtractSearchSequences(plan, Vec2(0, 1.5));
  ASSERT_EQ(seqs.size(), 1u);
  // From the node by the door, keeping the wall on the right: south along the west wall, east,
  // north, west (the right-hand search of Fig. 1).
  const std::vector<Vec2> expected = {{0.5, 1.5}, {0.5, 0.5}, {1.5, 0.5}, {2.5, 0.5}, {3.5, 0.5},
                                      {3.5, 1.5}, {3.5, 2.5}, {2.5, 2.5}, {1.5, 2.5}, {0.5, 2.5}};
  ASSERT_EQ(seqs[0].nodes.size(), expected.size());
  for (std::size_t k = 0; k < expected.size(); ++k)
    EXPECT_LT((seqs[0].nodes[k] - expected[k]).norm(), 1e-12) << k;
  EXPECT_FALSE(seqs[0].around_inner_walls);
}

TEST(SearchSequences, InnerWallsNotOnTheOuterWallsGetTheirOwnSequence) {
  const FloorPlan plan = Room(8, 6, {{{3, 3}, {5, 3}}});  // a free-standing wall in the middle
  const auto seqs = ExtractSearchSequences(plan, Vec2(0, 1.5));
  ASSERT_EQ(seqs.size(), 2u);
  EXPECT_EQ(seqs[0].nodes.size(), 24u);  // the perimeter ring of 8 x 6 cells
  EXPECT_TRUE(seqs[1].around_inner_walls);
  const std::vector<Vec2> around = {{3.5, 2.5}, {2.5, 2.5}, {2.5, 3.5}, {3.5, 3.5},
                                    {4.5, 3.5}, {5.5, 3.5}, {5.5, 2.5}, {4.5, 2.5}};
  ASSERT_EQ(seqs[1].nodes.size(), around.size());
  for (std::size_t k = 0; k < around.size(); ++k)
    EXPECT_LT((seqs[1].nodes[k] - around[k]).norm(), 1e-12) << k;
  const WallGraph g = WallGraph::Build(plan.solid_walls());
  EXPECT_EQ(g.components, 2);
}

TEST(SearchSequences, ClosedOffRoomsAndTJunctions) {
  // A wall from the south wall to y = 4 (a T-junction: same component), and a room closed by a
  // full-height wall at x = 6 (never entered from the door: its own sequence).
  const FloorPlan plan = Room(9, 5, {{{3, 0}, {3, 4}}, {{6, 0}, {6, 5}}});
  const auto seqs = ExtractSearchSequences(plan, Vec2(0, 1.5));
  ASSERT_EQ(seqs.size(), 2u);
  EXPECT_TRUE(seqs[1].around_inner_walls);
  for (const Vec2& p : seqs[1].nodes) EXPECT_GT(p.x(), 6.0);
  EXPECT_EQ(WallGraph::Build(plan.solid_walls()).components, 1);
}

TEST(SearchSequences, APlanDrawnRotatedAndShiftedGetsTheSameGridAndSequences) {
  // Issue 23: the grid lies along the walls' dominant direction, turned by the quarter turn the
  // plan defines (GridAxis), its offsets counted from the plan's corner: the same room with an
  // inner wall drawn rotated by any angle and moved gives the same inside and the same
  // sequences, node for node, rotated and moved. Along the map's axes (the paper) a room at 33
  // degrees gives other ones.
  const FloorPlan plan = Room(6, 4, {{{3, 0}, {3, 2.5}}});
  const auto seqs = ExtractSearchSequences(plan, Vec2(0, 1.5));
  const SearchGrid grid(plan);
  for (const double deg : {0.0, 33.0, 90.0, 137.0, 251.0}) {
    const Mat2 R = Rot(deg * std::numbers::pi / 180.0);
    const Vec2 shift(1234.5, -987.6);
    auto move = [&](const Vec2& p) { return Vec2(R * p + shift); };
    std::vector<Segment2> walls, doors;
    for (const auto& w : plan.walls()) walls.push_back({move(w.a), move(w.b)});
    for (const auto& d : plan.doors()) doors.push_back({move(d.a), move(d.b)});
    const FloorPlan moved(walls, doors, {});
    const SearchGrid moved_grid(moved);
    EXPECT_EQ(moved_grid.inside_count(), grid.inside_count()) << deg;
    const auto moved_seqs = ExtractSearchSequences(moved, move(Vec2(0, 1.5)));
    ASSERT_EQ(moved_seqs.size(), seqs.size()) << deg;
    for (std::size_t m = 0; m < seqs.size(); ++m) {
      ASSERT_EQ(moved_seqs[m].nodes.size(), seqs[m].nodes.size()) << deg;
      for (std::size_t n = 0; n < seqs[m].nodes.size(); ++n)
        EXPECT_LT((moved_seqs[m].nodes[n] - move(seqs[m].nodes[n])).norm(), 1e-9) << deg;
    }
    if (deg == 33.0) {
      SearchSequenceOptions map_axes;
      map_axes.grid.align_to_walls = false;
      const auto other = ExtractSearchSequences(moved, move(Vec2(0, 1.5)), map_axes);
      bool same = other.size() == seqs.size() && other[0].nodes.size() == seqs[0].nodes.size();
      for (std::size_t n = 0; same && n < seqs[0].nodes.size(); ++n)
        same = (other[0].nodes[n] - move(seqs[0].nodes[n])).norm() < 1e-6;
      EXPECT_FALSE(same);
    }
  }
  // The dominant direction modulo a quarter turn, whatever the walls' lengths and order.
  EXPECT_NEAR(
      DominantWallAxis({{{0, 0}, {Rot(0.3) * Vec2(5, 0)}}, {{0, 0}, {Rot(0.3) * Vec2(0, 2)}}}), 0.3,
      1e-12);
  EXPECT_NEAR(DominantWallAxis({{{0, 0}, {Rot(1.2) * Vec2(5, 0)}}}), 1.2 - std::numbers::pi / 2,
              1e-12);
}

TEST(SearchGrid, ContainsIsThePointInPolygonTestNotTheCellsRounding) {
  // Issue 23: a room with a 45-degree corner cut (no grid fits every wall) and a door on its
  // west wall. Contains (a point reaches an inside node near it without crossing a wall or the
  // closed door) agrees with the exact point-in-polygon test at every point more than 5 cm from
  // a wall; the 1 m cells (the paper's test, Inside(CellOf(p))) misjudge a share of them.
  const std::vector<Vec2> ring = {{0, 0}, {9, 0}, {9, 4}, {6, 7}, {0, 7}};
  std::vector<Segment2> walls;
  for (std::size_t k = 0; k < ring.size(); ++k)
    walls.push_back({ring[k], ring[(k + 1) % ring.size()]});
  const FloorPlan plan(walls, {{{0, 1}, {0, 2}}}, {});
  const SearchGrid grid(plan);
  auto in_polygon = [&](const Vec2& p) {  // crossing number
    bool in = false;
    for (std::size_t k = 0, j = ring.size() - 1; k < ring.size(); j = k++) {
      if ((ring[k].y() > p.y()) != (ring[j].y() > p.y()) &&
          p.x() <
              (ring[j].x() - ring[k].x()) * (p.y() - ring[k].y()) / (ring[j].y() - ring[k].y()) +
                  ring[k].x())
        in = !in;
    }
    return in;
  };
  Random rng(5);
  int tested = 0, wrong = 0, cells_wrong = 0;
  for (int k = 0; k < 20000; ++k) {
    const Vec2 p(rng.Uniform(-2, 11), rng.Uniform(-2, 9));
    double to_wall = 1e9;
    for (const auto& w : walls) to_wall = std::min(to_wall, DistanceToSegment(p, w));
    if (to_wall < 0.05) continue;
    ++tested;
    wrong += grid.Contains(p) != in_polygon(p);
    cells_wrong += grid.Inside(grid.CellOf(p)) != in_polygon(p);
  }
  EXPECT_GT(tested, 15000);
  EXPECT_EQ(wrong, 0);
  EXPECT_GT(cells_wrong, tested / 200);  // measured: 177 (0.9 %)
  EXPECT_FALSE(grid.Contains({std::nan(""), 1}));
}

TEST(SearchSequences, AnInnerDoorNoSequencePassesIsNamed) {
  // Issue 23, item 2: an 8 x 4 m building split by a wall at x = 4 with a door in it, and the
  // entry door on the west wall (exterior: closed for the searches, never counted). A 2 m door
  // is passed by the right-hand search; a 0.4 m one between two rows of the 1 m grid is not
  // (its room gets a sequence of its own, but no pattern goes through the door).
  auto plan_with_door = [](double y0, double y1) {
    return FloorPlan(
        {{{0, 0}, {8, 0}}, {{8, 0}, {8, 4}}, {{8, 4}, {0, 4}}, {{0, 4}, {0, 0}}, {{4, 0}, {4, 4}}},
        {{{0, 1}, {0, 2}}, {{4, y0}, {4, y1}}}, {});
  };
  const FloorPlan wide = plan_with_door(1.0, 3.0), narrow = plan_with_door(0.9, 1.3);
  EXPECT_TRUE(
      DoorsNotTraversed(SearchGrid(wide), ExtractSearchSequences(wide, {0.5, 1.5})).empty());
  EXPECT_EQ(DoorsNotTraversed(SearchGrid(narrow), ExtractSearchSequences(narrow, {0.5, 1.5})),
            std::vector<std::size_t>{1});
}

TEST(FloorPlanChecks, BadPlansAreReportedClearly) {
  EXPECT_TRUE(CheckFloorPlan(FloorPlan({}, {}, {})).front().fatal);
  const FloorPlan odd({{{0, 0}, {4, 0}},
                       {{4, 0}, {4, 3}},
                       {{4, 3}, {0, 3}},
                       {{0, 3}, {0, 0}},
                       {{1, 1}, {1, 1}},   // zero length
                       {{1, 0}, {3, 0}},   // drawn twice
                       {{2, 1}, {2, 2}}},  // free-standing
                      {}, {});
  std::string all;
  for (const auto& p : CheckFloorPlan(odd)) {
    EXPECT_FALSE(p.fatal);
    all += p.message + "\n";
  }
  EXPECT_NE(all.find("zero length"), std::string::npos) << all;
  EXPECT_NE(all.find("overlap"), std::string::npos) << all;
  EXPECT_NE(all.find("touch no other wall"), std::string::npos) << all;
  // A gap in the outer wall: nothing is enclosed.
  const FloorPlan gap({{{0, 0}, {4, 0}}, {{4, 0}, {4, 3}}, {{4, 3}, {0, 3}}, {{0, 3}, {0, 1.5}}},
                      {}, {});
  try {
    ExtractSearchSequences(gap, Vec2(1, 1));
    ADD_FAILURE() << "no error";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("encloses no area"), std::string::npos) << e.what();
    // ... and says where: the two wall ends of the gap (issue 23).
    EXPECT_NE(std::string(e.what()).find("first at (0.00, 0.00)"), std::string::npos) << e.what();
  }
  // A door with no wall: named with its coordinates; a door along a wall or across a gap is not.
  const FloorPlan stray({{{0, 0}, {4, 0}}, {{4, 0}, {4, 3}}, {{4, 3}, {0, 3}}, {{0, 3}, {0, 0}}},
                        {{{0, 1}, {0, 2}}, {{2, 1}, {2.8, 1}}}, {});
  std::string messages;
  for (const auto& p : CheckFloorPlan(stray)) messages += p.message + "\n";
  EXPECT_NE(messages.find("door 1 from (2.00, 1.00) to (2.80, 1.00)"), std::string::npos)
      << messages;
  EXPECT_EQ(messages.find("door 0"), std::string::npos) << messages;
  const FloorPlan across(
      {{{0, 0}, {4, 0}}, {{4, 0}, {4, 3}}, {{4, 3}, {0, 3}}, {{0, 3}, {0, 2}}, {{0, 1}, {0, 0}}},
      {{{0, 1}, {0, 2}}}, {});
  // ... and its jambs are not gaps (they touch the door).
  for (const auto& p : CheckFloorPlan(across)) ADD_FAILURE() << p.message;
  // An entry far from anything enclosed and from every door.
  EXPECT_THROW(ExtractSearchSequences(Room(4, 3), Vec2(50, 50)), std::invalid_argument);
}

TEST(SearchSequences, AStartOutsideEntersByTheNearestDoor) {
  // The room's door is on the west wall at y 1-2; a responder 8 m in front of it (and one 8 m
  // north-west of it) is searched from the door, as if the entry were there.
  const auto from_door = ExtractSearchSequences(Room(4, 3), Vec2(0, 1.5));
  for (const Vec2& outside : {Vec2(-8, 1.5), Vec2(-5.6, 7.1)}) {
    const auto seqs = ExtractSearchSequences(Room(4, 3), outside);
    ASSERT_EQ(seqs.size(), from_door.size());
    ASSERT_EQ(seqs[0].nodes.size(), from_door[0].nodes.size());
    for (std::size_t i = 0; i < seqs[0].nodes.size(); ++i) EXPECT_EQ(seqs[0].nodes[i], from_door[0].nodes[i]);
  }
  // Beyond the reach (15 m) it is no entry.
  EXPECT_THROW(ExtractSearchSequences(Room(4, 3), Vec2(-20, 1.5)), std::invalid_argument);
}

TEST(PatternComparison, PrincipalRotationOfEquationOne) {
  // An L-shaped walk whose legs point 10 deg off the axes: eq. (1) rotates them back.
  std::vector<Vec2> x;
  const Mat2 R = Rot(0.1745);
  for (int k = 0; k <= 10; ++k) x.push_back(R * Vec2(k, 0));
  for (int k = 1; k <= 10; ++k) x.push_back(R * Vec2(10, k));
  EXPECT_NEAR(PrincipalRotation(x), -0.1745, 1e-9);
  EXPECT_EQ(PrincipalRotation({}), 0.0);
}

TEST(PatternComparison, IcpRecoversAKnownTransform) {
  const std::vector<Vec2> target = {{0, 0}, {4, 0}, {4, 3}, {1, 3}, {1, 5}};
  const std::vector<Vec2> dense = ResampleByDistance(target, 0.25);
  const Mat2 R = Rot(0.3);
  const Vec2 t(1.0, -2.0);
  std::vector<Vec2> source;
  for (const auto& p : dense) source.push_back(R.transpose() * (p - t));  // target = R s + t
  IcpOptions exact;
  exact.tolerance_m = 1e-14;
  exact.max_iterations = 500;
  const IcpResult r = Icp(source, target, Rot(0.2), Vec2(0.8, -1.7), exact);
  EXPECT_LT(r.rmse_m, 1e-6);
  EXPECT_LT((r.rotation - R).norm(), 1e-6);
  EXPECT_LT((r.translation - t).norm(), 1e-6);
}

// The reference: plain point-to-point ICP, every segment of the target scanned for every point.
IcpResult PlainScanIcp(const std::vector<Vec2>& source, const std::vector<Vec2>& target,
                       const Mat2& R0, const Vec2& t0, int iterations) {
  IcpResult r;
  r.rotation = R0;
  r.translation = t0;
  for (int it = 0; it < iterations; ++it) {
    std::vector<Vec2> closest;
    double sq = 0;
    for (const Vec2& s : source) {
      const Vec2 p = r.Apply(s);
      Vec2 best = target[0];
      double best_d = 1e300;
      for (std::size_t k = 1; k < target.size(); ++k) {
        const Vec2 d = target[k] - target[k - 1];
        const Vec2 c =
            target[k - 1] + std::clamp((p - target[k - 1]).dot(d) / d.squaredNorm(), 0.0, 1.0) * d;
        if ((c - p).squaredNorm() < best_d) best_d = (c - p).squaredNorm(), best = c;
      }
      closest.push_back(best);
      sq += best_d;
    }
    r.rmse_m = std::sqrt(sq / source.size());
    const RigidFit2 fit = FitRigid(source, closest, false);
    r.rotation = fit.rotation;
    r.translation = fit.translation;
  }
  return r;
}

// The closest-point search skips runs of segments by their bounding boxes; on a long winding
// pattern (40 segments) and a noisy, offset walk every iterate equals the plain scan's exactly.
TEST(PatternComparison, IcpEqualsThePlainScanExactly) {
  Random rng(11);
  std::vector<Vec2> target = {{0, 0}};
  for (int k = 0; k < 40; ++k) {
    const Vec2 step = k % 3 == 2 ? Vec2(0, k % 2 ? 1.0 : -1.0) : Vec2(1.0, 0.0);
    target.push_back(target.back() + step);
  }
  std::vector<Vec2> source;
  for (const Vec2& p : ResampleByDistance(target, 0.5))
    source.push_back(Rot(0.4) * p + Vec2(2.0 + rng.Normal(0, 0.2), -1.0 + rng.Normal(0, 0.2)));
  IcpOptions o;
  o.abandon_rmse_m = 1e9;  // never stop early: compare whole runs
  o.tolerance_m = -1;      // and run every iteration
  for (int iterations : {1, 2, 5, 12}) {
    o.max_iterations = iterations;
    const IcpResult ours = Icp(source, target, Rot(-0.3), Vec2(0.5, 0.5), o);
    // Both report the RMSE of the last correspondences and the fit made from them.
    const IcpResult ref = PlainScanIcp(source, target, Rot(-0.3), Vec2(0.5, 0.5), iterations);
    EXPECT_EQ(ours.rmse_m, ref.rmse_m) << iterations;
    EXPECT_EQ(ours.rotation, ref.rotation) << iterations;
    EXPECT_EQ(ours.translation, ref.translation) << iterations;
    EXPECT_EQ(ours.iterations, iterations);
  }
}

TEST(PatternComparison, AnExactPatternMatchesAtItsNodeAndEnd) {
  // A partition stub from the north wall makes the room asymmetric (a unique best match).
  const FloorPlan plan = Room(10, 8, {{{3, 8}, {3, 6}}});
  const auto seqs = ExtractSearchSequences(plan, Vec2(0, 1.5));
  ASSERT_EQ(seqs.size(), 1u);
  const auto& nodes = seqs[0].nodes;
  // Walk nodes 5 .. 25 forward (a right-hand search), seen from a rotated, shifted odometry.
  std::vector<Vec2> walk;
  for (int n = 5; n <= 25; ++n) walk.push_back(Rot(2.0) * nodes[n] + Vec2(30, -7));
  PatternComparisonOptions co;
  co.icp.tolerance_m = 1e-14;
  co.icp.max_iterations = 500;
  const PatternComparison pc = ComparePatterns(walk, seqs, co);
  double best = 1e9;
  int best_eta = -1, best_end = -1;
  for (int eta = 0; eta < static_cast<int>(nodes.size()); ++eta) {
    for (int end = 0; end < 2; ++end) {
      if (pc.sequences[0].rmse_m[eta][end] < best)
        best = pc.sequences[0].rmse_m[eta][end], best_eta = eta, best_end = end;
    }
  }
  EXPECT_LT(best, 1e-6);
  EXPECT_EQ(best_eta, 5);
  EXPECT_EQ(best_end, 1);  // the last node: a right-hand search observation
  EXPECT_LT((pc.sequences[0].position_n[5][1] - nodes[25]).norm(), 1e-12);
  const Vec2 d = nodes[26] - nodes[25];
  EXPECT_NEAR(pc.sequences[0].heading_rad[5][1], std::atan2(d.y(), d.x()), 1e-12);
}

// A house-1 search of `duration_s` with its map's search sequences and grid.
struct HouseOneSearch {
  SimulatedMission sim;
  std::vector<NodeSequence> seqs;
  SearchGrid grid;
  HouseOneSearch(double duration_s, std::uint64_t seed)
      : sim(Simulate(duration_s, seed)),
        seqs(ExtractSearchSequences(sim.plan, HouseEntry(1))),
        grid(sim.plan) {}
  static SimulatedMission Simulate(double duration_s, std::uint64_t seed) {
    HouseSearchOptions o;
    o.duration_s = duration_s;
    return SimulateHouseSearch(o, seed);
  }
};

TEST(MapParticleFilter, NoParticleEverEndsAStepThroughAWall) {
  const HouseOneSearch house(120, 3);
  const auto& [sim, seqs, grid] = house;
  for (bool uniform : {false, true}) {
    MapParticleFilter pf(grid, seqs);
    if (uniform)
      pf.InitializeUniform();
    else
      pf.InitializeKnown(HouseEntry(1), 0.0, 0.2, 0.05);
    for (const auto& st : sim.data.steps) {
      pf.Predict(st.delta_n.head<2>());
      for (const auto& q : pf.particles()) {
        ASSERT_TRUE(q.position_n.allFinite());
        ASSERT_FALSE(sim.plan.Crosses(q.step_from_n, q.position_n)) << st.t1;
      }
      const Mat2 c = pf.Covariance();
      ASSERT_GT(c.determinant(), 0);
    }
    EXPECT_GT(pf.summary().wall_eliminations, 0u);
  }
}

TEST(MapParticleFilter, BlockedMassIsTheShareOfTheBeliefAStepDrivesIntoWalls) {
  // A 6 x 4 m room (door on the west wall); the particles 0.5 m from the east wall.
  const FloorPlan plan = Room(6, 4);
  const SearchGrid grid(plan);
  const auto seqs = ExtractSearchSequences(plan, Vec2(0, 1.5));
  MapParticleFilterOptions o;
  o.position_noise_m = 0.01;
  o.heading_noise_rad_per_m = 0;
  MapParticleFilter pf(grid, seqs, o);
  pf.InitializeKnown(Vec2(5.5, 2), 0.0, 0.02, 0.0);
  pf.Predict(Vec2(0, 0.4));  // along the wall: nothing blocked
  EXPECT_EQ(pf.LastBlockedMass(), 0.0);
  pf.Predict(Vec2(1.0, 0));  // through the east wall: every particle blocked
  EXPECT_EQ(pf.LastBlockedMass(), 1.0);
  pf.InitializeKnown(Vec2(5.5, 2), 0.0, 0.3, 0.0);
  pf.Predict(Vec2(0.5, 0));  // half the spread crosses the wall at x = 6
  EXPECT_GT(pf.LastBlockedMass(), 0.3);
  EXPECT_LT(pf.LastBlockedMass(), 0.7);
  MapParticleFilterOptions bad;
  bad.relocalize_above_variance_m2 = -1;
  std::string why;
  EXPECT_FALSE(bad.IsValid(&why));
}

TEST(MapParticleFilter, AWalkIntoAWallRaisesTheWallAlarmAndRecovers) {
  const FloorPlan plan = Room(6, 4);
  const SearchGrid grid(plan);
  const auto seqs = ExtractSearchSequences(plan, Vec2(0, 1.5));
  for (bool pseudo : {true, false}) {
    MapParticleFilterOptions o;
    o.pseudo_observations = pseudo;
    MapParticleFilter pf(grid, seqs, o);
    pf.InitializeKnown(Vec2(5.4, 2), 0.0, 0.05, 0.0);
    pf.Predict(Vec2(0, 0.1));
    EXPECT_FALSE(pf.WantsPatterns());  // converged: variance far below 2 m^2
    // Blocked share 1 per step: the CUSUM (k 0.2) passes h = 1.75 at the third step.
    int alarm_at = -1;
    for (int k = 1; k <= 3; ++k) {
      pf.Predict(Vec2(1.0, 0));
      if (pf.LastStepRaisedWallAlarm() && alarm_at < 0) alarm_at = k;
    }
    EXPECT_EQ(alarm_at, 3);
    EXPECT_EQ(pf.summary().wall_alarms, 1u);
    // With pseudo observations the filter spreads and asks for patterns; without, alarm only.
    EXPECT_EQ(pf.summary().recoveries, pseudo ? 1u : 0u);
    EXPECT_EQ(pf.WantsPatterns(), pseudo);
    for (const auto& q : pf.particles()) ASSERT_TRUE(q.position_n.allFinite());
  }
}

// A 6 x 4 room with its search sequence walked twice (an exact search pattern) and that
// walk's comparison; and filter options under which one step east (from a 1 m spread round
// the room's middle) raises a wall alarm whose recovery (no spread) forces the next
// comparisons while the filter stays settled (pattern level 5 m^2).
struct RoomWithExactPattern {
  FloorPlan plan = Room(6, 4);
  SearchGrid grid{plan};
  std::vector<NodeSequence> seqs = ExtractSearchSequences(plan, Vec2(0, 1.5));
  std::vector<Vec2> walk = Twice(seqs[0].nodes);
  PatternComparison pc = ComparePatterns(walk, seqs);
  static std::vector<Vec2> Twice(const std::vector<Vec2>& nodes) {
    std::vector<Vec2> w = nodes;
    w.insert(w.end(), nodes.begin(), nodes.end());
    return w;
  }
  static MapParticleFilterOptions ForcedComparisons() {
    MapParticleFilterOptions o;
    o.wall_follow = false;
    o.use_patterns_above_variance_m2 = 5;
    o.wall_alarm_k = 0;
    o.wall_alarm_h = 0.01;
    o.recover_position_sigma_m = 0;
    o.recover_heading_sigma_rad = 0;
    return o;
  }
};

TEST(MapParticleFilter, AfterARecoveryASettledFilterOnlyDrawsNewParticlesFromPatterns) {
  // A 6 x 4 room; the belief spread 1 m round its middle (trace ~2 m^2, under the pattern level
  // of 5 m^2 set here: settled); a step east blocks part of it and (k 0, h 0.01) raises a wall
  // alarm; the recovery (no spread) forces the next comparisons. With the default, a forced
  // comparison of a settled filter leaves the weights of the particles it does not redraw as
  // they were; recover_reweight_converged weights them by eq. (2) as well (and replaces those
  // under the weight floor).
  const RoomWithExactPattern room;
  const auto& [plan, grid, seqs, walk, pc] = room;
  for (bool reweight : {false, true}) {
    MapParticleFilterOptions o = RoomWithExactPattern::ForcedComparisons();
    o.recover_reweight_converged = reweight;
    // The paper's sigma throughout: this tests the rule, not the tracking sigma (whose exact
    // scaling of the same weights is the next test).
    o.tracking_likelihood_sigma = 0;
    MapParticleFilter pf(grid, seqs, o);
    pf.InitializeKnown(Vec2(3.5, 2), 0.0, 1.0, 0.0);
    pf.Predict(Vec2(1.0, 0));
    ASSERT_EQ(pf.summary().recoveries, 1u);
    ASSERT_LT(pf.Covariance().trace(), 5.0);
    ASSERT_TRUE(pf.WantsPatterns());  // forced although settled
    const auto before = pf.particles();
    const std::size_t resamples = pf.summary().systematic_resamples;
    const Vec2 d = walk.back() - walk[walk.size() - 2];
    pf.UpdatePatterns(pc, std::atan2(d.y(), d.x()));
    EXPECT_GT(pf.summary().pattern_resamples, 0u);  // new particles drawn either way
    // The weights of the particles not redrawn, relative to one another.
    double lo = 1e300, hi = 0;
    for (std::size_t i = 0; i < before.size(); ++i) {
      if (pf.particles()[i].position_n != before[i].position_n) continue;  // redrawn
      const double r = pf.particles()[i].weight / before[i].weight;
      lo = std::min(lo, r), hi = std::max(hi, r);
    }
    if (!reweight) {
      EXPECT_NEAR(hi / lo, 1.0, 1e-9);
      EXPECT_EQ(pf.summary().systematic_resamples, resamples);
      EXPECT_EQ(pf.summary().floor_replacements, 0u);
    } else {
      // Eq. (2): the weights change, and particles pushed under the floor are replaced.
      EXPECT_GT(hi / lo, 1.01);
      EXPECT_GT(pf.summary().floor_replacements, 0u);
    }
  }
}

TEST(MapParticleFilter, OnceTheTrackIsFoundComparisonsWeighWithTheTrackingSigma) {
  // Eq. (2) weights a particle by exp(-(E - E_min) / sigma^2). Before the track is found
  // (unknown start, unconfirmed) sigma is likelihood_sigma (0.1); once found (a known start
  // that converged, here re-weighted by a forced comparison after a wall alarm), the tracking
  // sigma (default 0.5). Same seeds, so the same particles and E: the log-weight differences
  // between particles must scale by exactly (0.5 / 0.1)^2 = 25 once tracking, and not at all
  // before.
  const RoomWithExactPattern room;
  const auto& [plan, grid, seqs, walk, pc] = room;
  const Vec2 d = walk.back() - walk[walk.size() - 2];
  // log(w_after / w_before) of every particle, relative to particle 0's.
  auto log_weight_changes = [&](double tracking_sigma, bool known) {
    MapParticleFilterOptions o = RoomWithExactPattern::ForcedComparisons();
    o.recover_reweight_converged = true;
    o.weight_floor = 0;                // nothing replaced,
    o.resample_from_patterns = false;  // nothing drawn,
    o.ess_resample_fraction = 0;       // nothing resampled: only eq. (2) changes the weights
    o.tracking_likelihood_sigma = tracking_sigma;
    MapParticleFilter pf(grid, seqs, o);
    if (known) {
      pf.InitializeKnown(Vec2(3.5, 2), 0.0, 1.0, 0.0);
      pf.Predict(Vec2(1.0, 0));  // converged: the track is found; the wall alarm forces patterns
      EXPECT_EQ(pf.summary().recoveries, 1u);
    } else {
      pf.InitializeUniform();
    }
    EXPECT_TRUE(pf.WantsPatterns());
    const auto before = pf.particles();
    pf.UpdatePatterns(pc, std::atan2(d.y(), d.x()));
    std::vector<double> change;
    for (std::size_t i = 0; i < before.size(); ++i)
      change.push_back(std::log(pf.particles()[i].weight / before[i].weight));
    const double reference = change[0];
    for (auto& c : change) c -= reference;
    return change;
  };
  for (bool known : {true, false}) {
    const auto sharp = log_weight_changes(0.0, known);  // likelihood_sigma (0.1) throughout
    const double tracking_sigma = MapParticleFilterOptions{}.tracking_likelihood_sigma;
    ASSERT_GT(tracking_sigma, 0.1);  // the default is the softer one
    const auto tracking = log_weight_changes(tracking_sigma, known);
    ASSERT_EQ(sharp.size(), tracking.size());
    ASSERT_TRUE(std::isfinite(sharp[0]));
    const double scale = known ? std::pow(tracking_sigma / 0.1, 2) : 1.0;
    int compared = 0, informative = 0;
    for (std::size_t i = 0; i < sharp.size(); ++i) {
      if (!std::isfinite(sharp[i]) || std::abs(sharp[i]) > 500) continue;  // underflowed
      ++compared;
      informative += std::abs(sharp[i]) > 1.0;
      EXPECT_NEAR(tracking[i] * scale, sharp[i], 1e-6 * (1 + std::abs(sharp[i]))) << i;
    }
    EXPECT_GT(compared, 100) << known;
    EXPECT_GT(informative, 10) << known;  // the comparison does tell the particles apart
  }
  MapParticleFilterOptions bad;
  bad.tracking_likelihood_sigma = -0.1;
  EXPECT_FALSE(bad.IsValid(nullptr));
}

TEST(MapParticleFilter, OnlyADistinctiveComparisonConfirmsAndUntilThenTheEllipseCoversTheBuilding) {
  // Issue 23: a 30 x 10 m hall, unknown start. Five comparisons whose best matches lie at two
  // places 26 m apart (a corridor that repeats) do not confirm a place, and the reported
  // covariance includes the hall's spread; five whose best matches lie at one place (two
  // neighbouring nodes) do, and then the reported covariance is the particles' own. With
  // confirm_distinct_m = 0 the ambiguous ones confirm too (the rule before issue 23).
  const FloorPlan plan = Room(30, 10);
  const SearchGrid grid(plan);
  const auto seqs = ExtractSearchSequences(plan, Vec2(0, 1.5));
  ASSERT_EQ(seqs.size(), 1u);
  const auto& nodes = seqs[0].nodes;
  auto nearest = [&](const Vec2& p) {
    return static_cast<std::size_t>(std::min_element(nodes.begin(), nodes.end(),
                                                     [&](const Vec2& a, const Vec2& b) {
                                                       return (a - p).squaredNorm() <
                                                              (b - p).squaredNorm();
                                                     }) -
                                    nodes.begin());
  };
  const std::size_t west = nearest({2, 2}), east = nearest({28, 8});
  ASSERT_GT((nodes[west] - nodes[east]).norm(), 25);
  auto comparison = [&](std::vector<std::pair<std::size_t, double>> good) {
    PatternComparison pc;
    SequenceComparison sc;
    const double inf = std::numeric_limits<double>::infinity();
    sc.rmse_m.assign(nodes.size(), {inf, inf});
    sc.heading_rad.assign(nodes.size(), {0.0, 0.0});
    sc.last_node.assign(nodes.size(), 0);
    for (std::size_t n = 0; n < nodes.size(); ++n) sc.position_n.push_back({nodes[n], nodes[n]});
    for (const auto& [n, e] : good) sc.rmse_m[n] = {e, inf};
    pc.sequences.push_back(sc);
    return pc;
  };
  const PatternComparison twice = comparison({{west, 0.10}, {east, 0.10}});
  const PatternComparison once = comparison({{west, 0.10}, {(west + 1) % nodes.size(), 0.11}});
  // The hall's spread: the variance of a uniform 30 x 10 m rectangle, about 83 m^2.
  const double hall = (30.0 * 30.0 + 10.0 * 10.0) / 12.0;
  for (const double distinct_m : {3.0, 0.0}) {
    for (const bool ambiguous : {true, false}) {
      MapParticleFilterOptions o;
      o.wall_follow = false;
      o.confirm_distinct_m = distinct_m;
      MapParticleFilter pf(grid, seqs, o);
      pf.InitializeUniform();
      ASSERT_TRUE(pf.Unconfirmed());
      EXPECT_GT(pf.ReportedCovariance().trace(), pf.Covariance().trace() + 0.8 * hall);
      for (int k = 0; k < o.confirm_pattern_updates; ++k)
        pf.UpdatePatterns(ambiguous ? twice : once, 0.0);
      const bool confirmed = !ambiguous || distinct_m == 0;
      EXPECT_EQ(pf.Unconfirmed(), !confirmed) << distinct_m << " " << ambiguous;
      EXPECT_EQ(pf.summary().ambiguous_updates,
                confirmed ? 0u : static_cast<std::size_t>(o.confirm_pattern_updates));
      if (confirmed) {
        EXPECT_EQ(pf.ReportedCovariance(), pf.Covariance());
      } else {
        EXPECT_GT(pf.ReportedCovariance().trace(), pf.Covariance().trace() + 0.8 * hall);
      }
    }
  }
  MapParticleFilterOptions bad;
  bad.confirm_distinct_m = -1;
  EXPECT_FALSE(bad.IsValid(nullptr));
}

TEST(MapParticleFilter, AKnownStartComparesAgainOnlyWhenClearlyLost) {
  // A 30 x 30 m hall; a known start (converged at once); wide odometry noise spreads the belief
  // to a variance between the pattern level (2 m^2) and the known start's (8 m^2): a known
  // start does not ask for comparisons there (option 0: it does, as a uniform start would);
  // spread further, above 8 m^2, it does.
  const FloorPlan plan = Room(30, 30);
  const SearchGrid grid(plan);
  const auto seqs = ExtractSearchSequences(plan, Vec2(0, 1.5));
  for (double known_level : {8.0, 0.0}) {
    MapParticleFilterOptions o;
    o.wall_follow = false;
    o.position_noise_m = 1.0;
    o.heading_noise_rad_per_m = 0;
    o.known_start_relocalize_above_variance_m2 = known_level;
    MapParticleFilter pf(grid, seqs, o);
    pf.InitializeKnown(Vec2(15, 15), 0.0, 0.05, 0.0);
    pf.Predict(Vec2(0.1, 0));  // converged
    pf.Predict(Vec2(0.1, 0));
    pf.Predict(Vec2(0.1, 0));
    const double variance = pf.Covariance().trace();
    ASSERT_GT(variance, 2.0);
    ASSERT_LT(variance, 8.0);
    EXPECT_EQ(pf.WantsPatterns(), known_level == 0.0) << variance;
    while (pf.Covariance().trace() <= 8.0) pf.Predict(Vec2(0.1, 0));
    EXPECT_TRUE(pf.WantsPatterns());
  }
}

TEST(WallFollowing, StepLikelihoodIsTheForwardRecursionOfTheOnOffChain) {
  // Walls along y = 0.05 and y = 3.05, and a short one 10 m south (beyond the 2 m clamp): the
  // field's cells count from the walls' box grown by 2 m, (-2, -12), so their centres lie at
  // (k + 1/2) 0.1 m and the field is exact at the side points used below.
  DistanceField::Options fo;
  fo.cell_m = 0.1;
  const DistanceField walls(
      {{{0, 0.05}, {10, 0.05}}, {{0, 3.05}, {10, 3.05}}, {{0, -10}, {0.1, -10}}}, fo);
  MapParticleFilterOptions o;  // leave 0.05, return 0.15, off-wall likelihood 0.6, s 0.25 m
  const double c = o.wall_follow_off_likelihood;
  const Vec2 on_left(5.05, -0.5);  // heading east: the side point (5.05, 0.05) is on the wall
  const Vec2 in_room(5.05, 0.8);   // side point (5.05, 1.35): 1.3 m from the nearest wall
  const double l_room = std::exp(-1.3 * 1.3 / (2 * 0.25 * 0.25));
  float p_off = 0;
  // Following the wall (p_off 0): prior_off = leave; l = (1 - leave) * 1 + leave * c.
  double l = WallFollowingLikelihood(walls, on_left, 0.0, true, o, p_off);
  EXPECT_NEAR(l, 0.95 + 0.05 * c, 1e-12);
  EXPECT_NEAR(p_off, 0.05 * c / (0.95 + 0.05 * c), 1e-7);
  // Leaving it: the first step off costs about the leave probability ...
  const double prior2 = p_off * (1 - 0.15) + (1 - p_off) * 0.05;
  l = WallFollowingLikelihood(walls, in_room, 0.0, true, o, p_off);
  EXPECT_NEAR(l, (1 - prior2) * l_room + prior2 * c, 1e-7);
  EXPECT_LT(l, 0.05);
  EXPECT_GT(p_off, 0.999);
  // ... staying off costs little (the walker is following furniture): about (1 - return) * c.
  l = WallFollowingLikelihood(walls, in_room, 0.0, true, o, p_off);
  EXPECT_NEAR(l, 0.85 * c, 1e-3);
  // The wrong hand: at (5.05, 0.6) heading east the wall is on the right; a left-hand
  // hypothesis looks for it 1.1 m from any wall; a right-hand one finds it.
  float p_left = 0, p_right = 0;
  const Vec2 by_wall(5.05, 0.6);
  const double l_left = WallFollowingLikelihood(walls, by_wall, 0.0, true, o, p_left);
  const double l_right = WallFollowingLikelihood(walls, by_wall, 0.0, false, o, p_right);
  EXPECT_NEAR(l_right, 0.95 + 0.05 * c, 1e-12);
  EXPECT_LT(l_left, 0.05);
  // Heading west flips the sides: the left-hand hypothesis there finds the wall.
  float p_west = 0;
  EXPECT_NEAR(WallFollowingLikelihood(walls, by_wall, std::numbers::pi, true, o, p_west),
              0.95 + 0.05 * c, 1e-12);
}

TEST(MapParticleFilter, ParticlesStayInsideTheBuildingThroughAnOpenEntry) {
  // The house-1 map shows the entry door open (the search is inside with it shut behind).
  const HouseOneSearch house(90, 5);
  const auto& [sim, seqs, grid] = house;
  for (bool stay : {true, false}) {
    MapParticleFilterOptions o;
    o.stay_inside = stay;
    o.wall_follow = false;  // the odometry alone moves the particles
    MapParticleFilter pf(grid, seqs, o);
    pf.InitializeUniform();
    std::size_t outside = 0;
    for (const auto& st : sim.data.steps) {
      pf.Predict(st.delta_n.head<2>());
      for (const auto& q : pf.particles()) outside += !grid.Inside(grid.CellOf(q.position_n));
    }
    if (stay) {
      EXPECT_EQ(outside, 0u);
      EXPECT_GT(pf.summary().outside_eliminations, 0u);
    } else {
      EXPECT_GT(outside, 0u);  // without the rule, some walk out through the entry
    }
  }
}

TEST(KldSampling, TheSampleSizeIsTheChiSquareQuantileOverTwiceEpsilon) {
  // chi^2 quantiles at 0.99 (tables): 1 dof 6.635, 9 dof 21.666, 49 dof 74.919.
  EXPECT_NEAR(KldSampleSize(2, 0.05, 0.99), 6.635 / 0.1, 0.01);
  EXPECT_NEAR(KldSampleSize(10, 0.05, 0.99), 21.666 / 0.1, 0.01);
  EXPECT_NEAR(KldSampleSize(50, 0.1, 0.99), 74.919 / 0.2, 0.01);
  EXPECT_EQ(KldSampleSize(1, 0.05, 0.99), 1.0);
  EXPECT_EQ(KldSampleSize(0, 0.05, 0.99), 1.0);
  // Fox (2003), eq. (13): the Wilson-Hilferty form, within 0.5 % from 20 bins on.
  const double z = 2.326348;  // the standard normal's 0.99 quantile
  for (int k : {20, 50, 200, 1000}) {
    const double a = 2.0 / (9 * (k - 1));
    const double wilson_hilferty = (k - 1) / (2 * 0.05) * std::pow(1 - a + std::sqrt(a) * z, 3);
    EXPECT_NEAR(KldSampleSize(k, 0.05, 0.99) / wilson_hilferty, 1.0, 0.005) << k;
  }
}

TEST(MapParticleFilter, KldSamplingShrinksAGatheredBeliefAndTakesEveryParticleForARecovery) {
  // A 6 x 4 room, a known start 0.6 m from the east wall with a 5 cm spread: a step north
  // along the wall weighs the particles (wall following) and resamples them (at any loss of
  // effective size here); with KLD-sampling it keeps the particles the histogram asks for —
  // few bins, so the fewest — within [kld_min_particles, particles]. A step east to the wall
  // then drives part of the belief through it and raises a wall alarm; the recovery spreads a
  // belief of every particle again. Without KLD-sampling the number never changes.
  const RoomWithExactPattern room;
  const auto& [plan, grid, seqs, walk, pc] = room;
  for (const double epsilon : {0.0, 0.05}) {
    MapParticleFilterOptions o = RoomWithExactPattern::ForcedComparisons();
    o.wall_follow = true;
    o.ess_resample_fraction = 1.0;
    o.particles = 2000;
    o.kld_epsilon = epsilon;
    o.kld_min_particles = 50;
    MapParticleFilter pf(grid, seqs, o);
    pf.InitializeKnown(Vec2(5.4, 2), 0.0, 0.05, 0.0);
    ASSERT_EQ(pf.particles().size(), 2000u);
    pf.Predict(Vec2(0, 0.3));
    ASSERT_GT(pf.summary().systematic_resamples, 0u) << epsilon;
    ASSERT_EQ(pf.summary().recoveries, 0u);
    const std::size_t gathered = pf.particles().size();
    double sum = 0;
    for (const auto& q : pf.particles()) sum += q.weight;
    EXPECT_NEAR(sum, 1.0, 1e-9);
    // At most 3 x 3 position bins (0.5 m; the spread is 0.14 m after the step's noise) x 2
    // of heading (the offset 0 lies on a bin's edge) x 2 hands = 36 bins:
    // chi^2_35(0.99) / 0.1 = 573.4.
    if (epsilon > 0) {
      EXPECT_LE(gathered, 574u);
      EXPECT_GE(gathered, 50u);
      EXPECT_EQ(pf.summary().particles_min, gathered);
    } else {
      EXPECT_EQ(gathered, 2000u);
    }
    // East, to the wall from the belief's mean: about half of it crosses.
    const Vec2 m = pf.Mean();
    pf.Predict(Vec2(6.0 - m.x(), 0));
    ASSERT_EQ(pf.summary().recoveries, 1u) << epsilon;
    EXPECT_EQ(pf.summary().restarts, 0u);
    EXPECT_EQ(pf.particles().size(), 2000u);
    EXPECT_EQ(pf.summary().particles_max, 2000u);
    if (epsilon == 0) EXPECT_EQ(pf.summary().particles_min, 2000u);
    for (const auto& q : pf.particles()) ASSERT_TRUE(q.position_n.allFinite());
  }
  MapParticleFilterOptions bad;
  bad.kld_epsilon = 0.05;
  bad.kld_min_particles = bad.particles + 1;
  EXPECT_FALSE(bad.IsValid(nullptr));
  bad.kld_min_particles = 100;
  bad.kld_quantile = 1.0;
  EXPECT_FALSE(bad.IsValid(nullptr));
}

TEST(MapParticleFilter, KldSamplingOffIsTheFixedFilterBitForBit) {
  // The default (kld_epsilon 0) and the explicit "off" of every KLD option give the same
  // particles at every step of a house search: the options change nothing unless KLD is on.
  const HouseOneSearch house(60, 5);
  const auto& [sim, seqs, grid] = house;
  MapParticleFilterOptions other;
  other.kld_quantile = 0.9;
  other.kld_bin_m = 0.2;
  other.kld_min_particles = 20;
  MapParticleFilter a(grid, seqs), b(grid, seqs, other);
  a.InitializeUniform();
  b.InitializeUniform();
  for (const auto& st : sim.data.steps) {
    a.Predict(st.delta_n.head<2>());
    b.Predict(st.delta_n.head<2>());
    ASSERT_EQ(a.particles().size(), b.particles().size());
    for (std::size_t i = 0; i < a.particles().size(); ++i)
      ASSERT_EQ(a.particles()[i].position_n, b.particles()[i].position_n);
  }
  EXPECT_EQ(a.particles().size(), static_cast<std::size_t>(MapParticleFilterOptions{}.particles));
}

// The foot INS's motion model (stated steps, issue 23): a loop of 0.5 m steps with four quarter
// turns and a rest, in a room large enough that no particle meets a wall.
struct StatedWalk {
  std::vector<Vec2> steps_n;
  std::vector<double> t1_s;
  std::vector<StatedStep> stated;  ///< each step's turn and time since the last, no noise
};
StatedWalk LoopWithARest() {
  StatedWalk w;
  double t = 0, heading = 0.3;
  for (int leg = 0; leg < 5; ++leg) {
    for (int i = 0; i < 16; ++i) {
      t += leg == 2 && i == 0 ? 40.0 : 0.6;  // standing 40 s before the third leg
      w.steps_n.push_back(0.5 * Vec2(std::cos(heading), std::sin(heading)));
      w.t1_s.push_back(t);
    }
    heading += leg % 2 == 0 ? std::numbers::pi / 2 : -std::numbers::pi / 3;
  }
  w.stated.resize(w.steps_n.size());
  for (std::size_t i = 1; i < w.steps_n.size(); ++i) {
    const Vec2& a = w.steps_n[i - 1];
    const Vec2& b = w.steps_n[i];
    w.stated[i].turn_rad = std::atan2(a.x() * b.y() - a.y() * b.x(), a.dot(b));
    w.stated[i].dt_s = w.t1_s[i] - w.t1_s[i - 1];
  }
  return w;
}

/// An 80 x 80 m room (no particle meets a wall on the walk above), its grid and sequences, and
/// a filter of `particles` without the wall-following model (nothing weighs the particles).
struct OpenRoom {
  explicit OpenRoom(int particles)
      : grid(plan), seqs(ExtractSearchSequences(plan, Vec2(0, 1.5))), pf(grid, seqs, [&] {
          MapParticleFilterOptions o;
          o.particles = particles;
          o.wall_follow = false;
          return o;
        }()) {}
  const FloorPlan plan = Room(80, 80);
  const SearchGrid grid;
  const std::vector<NodeSequence> seqs;
  MapParticleFilter pf;
};

TEST(MapParticleFilter, EachParticleMovesAsADeadReckoningWithItsOwnSharedErrors) {
  // Without white noise each particle's walk is exactly its own dead reckoning: the steps
  // stretched by its scale, each turned by its heading error, which grows by its gyro scale x
  // the turns and its drift rate x the time (standing included).
  OpenRoom room(200);
  MapParticleFilter& pf = room.pf;
  pf.UseSharedErrors({0.05, 0.05, 0.002});  // wide, so that a wrong sign or factor shows
  const Vec2 start(40, 40);
  pf.InitializeKnown(start, 0.0, 0.0, 0.0);
  const StatedWalk walk = LoopWithARest();
  for (std::size_t i = 0; i < walk.steps_n.size(); ++i)
    pf.Predict(walk.steps_n[i], &walk.stated[i]);
  EXPECT_EQ(pf.summary().wall_eliminations, 0u);
  double spread = 0;
  for (const auto& q : pf.particles()) {
    Vec2 p = start;
    double heading_error = 0;
    for (std::size_t i = 0; i < walk.steps_n.size(); ++i) {
      heading_error +=
          q.turn_scale * walk.stated[i].turn_rad + q.drift_rad_per_s * walk.stated[i].dt_s;
      p += (1.0 + q.step_scale) * (Rot(heading_error) * walk.steps_n[i]);
    }
    ASSERT_LT((q.position_n - p).norm(), 1e-9);
    EXPECT_NEAR(WrapAngle(q.heading_offset_rad - heading_error), 0.0, 1e-12);
    spread += (q.position_n - pf.Mean()).squaredNorm();
  }
  EXPECT_GT(spread / pf.particles().size(), 0.5);  // the errors moved them: 1.6 m^2 drawn
}

TEST(MapParticleFilter, StatedStepsSpreadTheParticlesAsTheDeadReckoningsCovariance) {
  // The same walk with the foot INS's shared errors (PdrOptions::foot_ins) and each step's own
  // noise: the cloud's covariance is the dead reckoning's (first order; 4,000 particles).
  OpenRoom room(4000);
  MapParticleFilter& pf = room.pf;
  PdrOptions pdr = PdrOptions{}.ForFootIns();
  pdr.track_heading_offset_sigma_rad = 0;
  pf.UseSharedErrors(
      {pdr.step_scale_sigma, pdr.turn_scale_sigma, pdr.heading_drift_sigma_rad_per_s});
  const Vec2 start(40, 40);
  const double start_sigma_m = 0.1, start_heading_sigma_rad = 0.05;
  pf.InitializeKnown(start, 0.0, start_sigma_m, start_heading_sigma_rad);
  DeadReckoning dr(Vec3(start.x(), start.y(), 0), start_sigma_m, pdr, start_heading_sigma_rad);
  const StatedWalk walk = LoopWithARest();
  for (std::size_t i = 0; i < walk.steps_n.size(); ++i) {
    Step step;
    step.t0 = i == 0 ? 0.0 : walk.t1_s[i - 1];
    step.t1 = walk.t1_s[i];
    step.agent = "ff1";
    step.delta_n = Vec3(walk.steps_n[i].x(), walk.steps_n[i].y(), 0);
    step.variance_m2 = Vec3(4e-4, 4e-4, 0);
    step.heading_var_rad2 = 2e-6;
    dr.AddStep(step);
    StatedStep stated = walk.stated[i];  // the turn and time the dead reckoning sees too
    stated.position_sigma_m = 0.02;
    stated.heading_sigma_rad = std::sqrt(2e-6);
    pf.Predict(walk.steps_n[i], &stated);
  }
  const Mat2 particles = pf.Covariance();
  const Mat2 expected = dr.covariance();
  // The mean within a tenth of the spread (the cloud's mean is the exact rotations', shrunk
  // toward the start by the heading's second order; the dead reckoning's is the steps' sum).
  EXPECT_LT((pf.Mean() - dr.position_n().head<2>()).norm(), 0.1 * std::sqrt(expected.trace()));
  EXPECT_NEAR(particles.trace() / expected.trace(), 1.0, 0.1);
  // The shape too: the largest axis along the same direction, of the same length.
  const Eigen::SelfAdjointEigenSolver<Mat2> a(particles), b(expected);
  EXPECT_NEAR(std::sqrt(a.eigenvalues()(1) / b.eigenvalues()(1)), 1.0, 0.05);
  EXPECT_GT(std::abs(a.eigenvectors().col(1).dot(b.eigenvectors().col(1))), 0.99);
}

}  // namespace
}  // namespace trailmark::mapmatch

namespace trailmark::mapmatch {
namespace {

struct CorridorWalk {
  double in95 = 0;                ///< share of steps with the truth inside the 95 % ellipse
  double mean_error_m = 0;        ///< mean distance of the estimate from the truth
  double least_free_share = 1.0;  ///< the free walkers' smallest share of the belief
  double last_free_share = 0.0;
};

// An L-shaped corridor 2.4 m wide (30 m east, then 20 m north; its entry door on the west)
// walked down its middle, 0.5 m steps, from a known start: no directional search.
CorridorWalk WalkACorridorsMiddle(double free_walk_share) {
  const double w = 2.4, h = w / 2, L = 30, H = 20;
  const std::vector<Vec2> outline = {{0, 0}, {L, 0}, {L, H}, {L - w, H}, {L - w, w}, {0, w}};
  std::vector<Segment2> walls;
  for (std::size_t i = 0; i < outline.size(); ++i)
    walls.push_back({outline[i], outline[(i + 1) % outline.size()]});
  const FloorPlan plan(walls, {{{0, h - 0.6}, {0, h + 0.6}}}, {});
  const SearchGrid grid(plan);
  const auto seqs = ExtractSearchSequences(plan, Vec2(0, h));
  MapParticleFilterOptions o;
  o.free_walk_share = free_walk_share;
  MapParticleFilter pf(grid, seqs, o);
  pf.InitializeKnown(Vec2(1, h), 0.0, 0.2, 0.02);
  CorridorWalk r;
  int steps = 0, inside = 0;
  std::vector<Vec2> route;
  for (double x = 1.5; x <= L - h + 1e-9; x += 0.5) route.emplace_back(x, h);
  for (double y = h + 0.5; y <= H - 1.0 + 1e-9; y += 0.5) route.emplace_back(L - h, y);
  Vec2 last(1, h);
  for (const Vec2& truth : route) {
    pf.Predict(truth - last);
    last = truth;
    ++steps;
    const Vec2 e = pf.Mean() - truth;
    const Mat2 c = pf.ReportedCovariance();
    inside += e.dot(c.ldlt().solve(e)) <= 5.991;  // chi-square 2 dof, 95 %
    r.mean_error_m += e.norm();
    double free = 0;
    for (const auto& q : pf.particles()) free += q.hand == 2 ? q.weight : 0.0;
    if (steps >= 5) r.least_free_share = std::min(r.least_free_share, free);
    r.last_free_share = free;
  }
  r.in95 = static_cast<double>(inside) / steps;
  r.mean_error_m /= steps;
  return r;
}

TEST(MapParticleFilter, WallsDoNotWeighTheFreeWalkersAgainstTheSearchers) {
  // Down a corridor's middle the walls cannot tell a free walker from a searcher at arm's
  // length; a free walker's particles diffuse into the walls that the searchers' prior keeps
  // its particles away from. Weighed across the two models by those eliminations, the free
  // walkers' share fell to 0.32 here (0.15 on the neighbour trail); within each model, it
  // stays at its prior (measured: never below 0.44).
  const CorridorWalk mixed = WalkACorridorsMiddle(0.5);
  EXPECT_GT(mixed.least_free_share, 0.4);
  EXPECT_LT(mixed.last_free_share, 0.6);
  EXPECT_GT(mixed.in95, 0.9);
  const CorridorWalk searchers = WalkACorridorsMiddle(0.0);
  EXPECT_EQ(searchers.last_free_share, 0.0);
}

TEST(MapParticleFilter, FreeWalkersNeedTheWallFollowingModelAndAShareBelowOne) {
  MapParticleFilterOptions o;
  std::string why;
  for (double bad : {-0.1, 1.0, std::nan("")}) {
    o.free_walk_share = bad;
    EXPECT_FALSE(o.IsValid(&why)) << bad;
    EXPECT_NE(why.find("free_walk_share"), std::string::npos);
  }
  o.free_walk_share = 0.5;
  o.free_walk_switch = 1.5;
  EXPECT_FALSE(o.IsValid(&why));
  // Without the wall-following model there are no free walkers to draw (the paper's filter).
  o.free_walk_switch = 0.1;
  o.wall_follow = false;
  const FloorPlan plan = Room(10, 8);
  const SearchGrid grid(plan);
  const auto seqs = ExtractSearchSequences(plan, Vec2(0, 1.5));
  MapParticleFilter pf(grid, seqs, o);
  pf.InitializeUniform();
  for (int k = 0; k < 20; ++k) pf.Predict(Vec2(0.3, 0.1));
  for (const auto& q : pf.particles()) EXPECT_EQ(q.hand, 0);
}

}  // namespace
}  // namespace trailmark::mapmatch

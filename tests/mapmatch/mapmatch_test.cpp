// Map-aided search (mapmatch/): pattern extraction on hand-made floor plans (exact node
// sequences), floor-plan checks, eq. (1), ICP on known transforms, pattern comparison of an
// exact pattern, and the particle filter's wall constraint.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <numbers>

#include "trailmark/core/random.h"
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
  }
  // An entry far from anything enclosed.
  EXPECT_THROW(ExtractSearchSequences(Room(4, 3), Vec2(50, 50)), std::invalid_argument);
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

TEST(MapParticleFilter, NoParticleEverEndsAStepThroughAWall) {
  HouseSearchOptions o;
  o.duration_s = 120;
  const SimulatedMission sim = SimulateHouseSearch(o, 3);
  const auto seqs = ExtractSearchSequences(sim.plan, HouseEntry(1));
  const SearchGrid grid(sim.plan);
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

}  // namespace
}  // namespace trailmark::mapmatch

// SPDX-License-Identifier: MIT
// Map matching in a multi-level building (issue 26, item 4): a belief moves to another level's
// plan only through a stairwell; a level change elsewhere keeps every particle and is noted,
// or is refused while the belief is confident when asked to; the estimates carry the level.
#include <gtest/gtest.h>

#include <set>

#include "trailmark/mapmatch/map_match_estimator.h"
#include "set_levels.h"
#include "trailmark/sim/multi_floor.h"

namespace trailmark::mapmatch {
namespace {

using testing::SetLevels;

MissionInfo TwoStoreys() {
  MissionInfo info;
  info.name = "two storeys";
  info.floors = {{0, 0.0}, {1, 3.5}};
  // In the ground floor's corridor, facing the stairwell (east).
  info.nodes.push_back(NodeInfo::Agent("ff1", Vec3(17.0, 6.0, 0.0), 0.2, 0.0, 0.02));
  return info;
}

/// Walks `to` in 0.5 m steps along a straight line from `from`; returns the last estimate.
Estimate Walk(MapMatchEstimator& e, Vec2 from, Vec2 to, TimeS& t) {
  VectorSink sink;
  const Vec2 d = to - from;
  const int n = static_cast<int>(std::ceil(d.norm() / 0.5));
  for (int i = 0; i < n; ++i) {
    const Vec2 step = d / n;
    e.Add(Step{t, t + 0.5, "ff1", Vec3(step.x(), step.y(), 0), Vec3(0.01, 0.01, 0.01)}, sink);
    t += 0.5;
  }
  return sink.rows.back();
}

LevelPlans Plans() { return {{0, BuildMultiFloorLevel(0)}, {1, BuildMultiFloorLevel(2)}}; }

TEST(MapMatchLevels, TheBeliefChangesLevelInTheStairwellAndTheEstimatesCarryIt) {
  MapMatchEstimatorOptions o;
  o.filter.particles = 500;
  MapMatchEstimator e(TwoStoreys(), Plans(), "plan", o);
  SetLevels levels;
  levels.storey_m = 3.5;
  levels.level["ff1"] = 0;
  e.UseLevels(&levels);
  TimeS t = 0;
  Estimate last = Walk(e, {17.0, 6.0}, {21.0, 6.0}, t);  // into the stairwell
  EXPECT_EQ(last.floor, 0);
  levels.level["ff1"] = 1;
  last = Walk(e, {21.0, 6.0}, {21.0, 4.0}, t);  // up the first flight's first steps
  EXPECT_EQ(last.floor, 1);
  EXPECT_NEAR(last.position_n.x(), 21.0, 0.6);
  last = Walk(e, {21.0, 4.0}, {21.0, 6.0}, t);
  last = Walk(e, {21.0, 6.0}, {15.0, 6.0}, t);  // along level 1's corridor
  EXPECT_EQ(last.floor, 1);
  EXPECT_NEAR(last.position_n.x(), 15.0, 1.0);
  EXPECT_NEAR(last.position_n.y(), 6.0, 1.0);
  const EstimatorSummary s = e.Summary();
  EXPECT_EQ(s.numbers.at("ff1.level_changes"), 1.0);
  EXPECT_EQ(s.numbers.at("ff1.level_changes_outside_stairwell"), 0.0);
  EXPECT_EQ(s.numbers.at("ff1.final_level"), 1.0);
  EXPECT_EQ(s.numbers.at("levels"), 2.0);
  EXPECT_EQ(s.numbers.at("stairwells"), 2.0);
  ASSERT_TRUE(e.Current("ff1").has_value());
  EXPECT_EQ(e.Current("ff1")->floor, 1);
}

TEST(MapMatchLevels, AChangeOutsideAStairwellIsNotedOrRefused) {
  for (const double veto : {0.0, 4.0}) {
    MapMatchEstimatorOptions o;
    o.filter.particles = 500;
    o.stairwell_veto_variance_m2 = veto;
    MapMatchEstimator e(TwoStoreys(), Plans(), "plan", o);
    SetLevels levels;
    levels.storey_m = 3.5;
    levels.level["ff1"] = 0;
    e.UseLevels(&levels);
    TimeS t = 0;
    Walk(e, {17.0, 6.0}, {15.0, 6.0}, t);  // west along the corridor, far from the stairs
    levels.level["ff1"] = 1;                // a barometer that drifted across a boundary
    const Estimate last = Walk(e, {15.0, 6.0}, {13.0, 6.0}, t);
    const EstimatorSummary s = e.Summary();
    if (veto == 0) {
      EXPECT_EQ(last.floor, 1);
      EXPECT_EQ(s.numbers.at("ff1.level_changes_outside_stairwell"), 1.0);
      EXPECT_EQ(s.numbers.at("ff1.level_changes_refused"), 0.0);
    } else {
      EXPECT_EQ(last.floor, 0);  // the map's level stands
      EXPECT_EQ(s.numbers.at("ff1.level_changes"), 0.0);
      // One refusal, however many steps it lasts.
      EXPECT_EQ(s.numbers.at("ff1.level_changes_refused"), 1.0);
    }
    bool noted = false;
    for (const auto& n : s.notes) noted = noted || n.find("level 0 -> 1") != std::string::npos;
    EXPECT_TRUE(noted) << veto;
  }
}

TEST(MapMatchLevels, ASinglePlanNeverChangesLevelNorSetsTheFloor) {
  MapMatchEstimatorOptions o;
  o.filter.particles = 300;
  MapMatchEstimator e(TwoStoreys(), BuildMultiFloorLevel(0), "plan", o);
  SetLevels levels;
  levels.storey_m = 3.5;
  levels.level["ff1"] = 1;
  e.UseLevels(&levels);
  TimeS t = 0;
  const Estimate last = Walk(e, {17.0, 6.0}, {15.0, 6.0}, t);
  EXPECT_FALSE(last.floor.has_value());  // the height channel sets it
  EXPECT_EQ(e.Summary().numbers.count("ff1.level_changes"), 0u);
}

TEST(MapParticleFilter, ContinueFromKeepsOnlyTheMarkedParticles) {
  const FloorPlan a = BuildMultiFloorLevel(0), b = BuildMultiFloorLevel(2);
  SearchSequenceOptions so;
  const SearchGrid grid_a(a, so.grid), grid_b(b, so.grid);
  const auto seq_a = ExtractSearchSequences(a, {21.0, 6.0}, so);
  const auto seq_b = ExtractSearchSequences(b, {21.0, 6.0}, so);
  MapParticleFilterOptions fo;
  fo.particles = 400;
  MapParticleFilter from(grid_a, seq_a, fo), to(grid_b, seq_b, fo);
  from.InitializeKnown({20.0, 6.0}, 0.0, 1.0, 0.05);
  std::vector<char> keep;
  std::set<std::pair<double, double>> kept;
  for (const auto& p : from.particles()) {
    keep.push_back(p.position_n.x() > 20.0 ? 1 : 0);
    if (keep.back()) kept.insert({p.position_n.x(), p.position_n.y()});
  }
  ASSERT_GT(kept.size(), 50u);
  to.ContinueFrom(from, keep);
  ASSERT_EQ(to.particles().size(), from.particles().size());
  double sum = 0;
  for (const auto& p : to.particles()) {
    EXPECT_TRUE(kept.count({p.position_n.x(), p.position_n.y()})) << p.position_n.transpose();
    sum += p.weight;
  }
  EXPECT_NEAR(sum, 1.0, 1e-9);
  // None kept: every particle goes on, as it was.
  to.ContinueFrom(from, std::vector<char>(keep.size(), 0));
  for (std::size_t i = 0; i < keep.size(); ++i) {
    EXPECT_EQ(to.particles()[i].position_n, from.particles()[i].position_n);
  }
  EXPECT_THROW(to.ContinueFrom(from, std::vector<char>(3, 1)), std::invalid_argument);
}

}  // namespace
}  // namespace trailmark::mapmatch

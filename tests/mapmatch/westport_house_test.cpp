// SPDX-License-Identifier: MIT
// The map-aided search on a real building's floor plan: Westport House (Dundee), floor 1, from
// the WRLD indoor-map example in ../shared/data/floorplan-westport-house (CC BY 4.0, WRLD; read
// in place, not copied). The walls there are polygons with thickness, the outer wall has
// windows, the stairs and lifts are blocks: the wall graph, the search sequences and the
// particle filter have to cope with a plan nobody drew for them. Skipped without the data.
#include <gtest/gtest.h>

#include <Eigen/LU>
#include <cmath>
#include <numbers>

#include "pipelines/run_named.h"
#include "test_util.h"
#include "trailmark/core/random.h"
#include "trailmark/eval/metrics.h"
#include "trailmark/io/convert_wrld.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/mapmatch/particle_filter.h"
#include "trailmark/sim/house_search.h"
#include "trailmark/sim/pdr_error_model.h"
#include "trailmark/sim/walker.h"

namespace trailmark::mapmatch {
namespace {

using testing::CanRunNamed;
using testing::RunNamed;

TEST(WestportHouse, SearchSequencesAndTheFilterOnARealFloorPlan) {
  const auto dir = testing::SharedData("floorplan-westport-house");
  if (dir.empty()) GTEST_SKIP() << "../shared/data/floorplan-westport-house not found";
  // The level's walls, windows, outline, stairs and lifts as wall segments (polygon edges), in
  // metres east/north of the building's location; the door polygons as doors across the gaps.
  const WrldBuilding building = ReadWrldBuilding(dir);
  ASSERT_NE(building.Level("westport-house-floor-1"), nullptr);
  const FloorPlan plan = building.Level("westport-house-floor-1")->Plan();
  // 826 wall pieces; the outline drawn over the outer walls gives overlaps (reported, not fatal).
  for (const auto& p : CheckFloorPlan(plan)) EXPECT_FALSE(p.fatal) << p.message;
  const SearchGrid grid(plan);
  EXPECT_GT(grid.inside_count(), 1000u);  // m^2 at 1 m (measured: 2,493 with the doors)
  // The walk starts at the middle node of a grid along the map's axes (the start these figures
  // were first measured from; the search grid itself lies along the walls, issue 23).
  SearchGridOptions map_axes;
  map_axes.align_to_walls = false;
  const auto centers = SearchGrid(plan, map_axes).InsideCenters();
  ASSERT_FALSE(centers.empty());
  const Vec2 start = centers[centers.size() / 2];
  // The building stands 11.5 degrees off east in the converter's frame: the grid follows it.
  EXPECT_NEAR(std::remainder(grid.axis_rad(), std::numbers::pi / 2), 0.2016, 0.01);
  const auto seqs = ExtractSearchSequences(plan, start);
  ASSERT_GT(seqs.size(), 1u);  // measured: 23 sequences, 676 nodes
  // A 120 m left-hand search from there at a search pace, odometry from a drifting foot INS.
  WallFollowOptions wf;
  wf.wall_offset_m = 0.55;
  wf.max_length_m = 120;
  const Route route = FollowWall(plan, start, 0.0, Hand::kLeft, wf);
  Random rng(11);
  WalkerOptions wo;
  wo.speed_mps = 0.45;
  wo.step_length_m = 0.5;
  const Walk walk = WalkRoute(route, wo, 0.0, rng);
  PdrErrorOptions po;
  po.heading_drift_sigma_rad_per_s = 0.0015;
  MapParticleFilterOptions fo;
  fo.particles = 2000;
  {
    // Known start: no particle ever crosses a wall; within 1.5 m on average (measured: mean
    // 0.92 m, worst 1.76 m; 0.91 / 1.59 m before the converter kept the doors).
    PdrErrorModel pdr(po, Random(21));
    MapParticleFilter pf(grid, seqs, fo);
    pf.InitializeKnown(walk.steps.front().from, 0.0, 0.2, 0.05);
    double worst = 0, sum = 0;
    for (const auto& st : walk.steps) {
      pf.Predict(pdr.Apply(st.to - st.from, st.t1 - st.t0));
      for (const auto& q : pf.particles()) {
        ASSERT_TRUE(q.position_n.allFinite());
        ASSERT_FALSE(plan.Crosses(q.step_from_n, q.position_n));
      }
      ASSERT_GT(pf.Covariance().determinant(), 0);
      const double e = (pf.Mean() - st.to).norm();
      worst = std::max(worst, e), sum += e;
    }
    EXPECT_LT(sum / walk.steps.size(), 1.5);
    EXPECT_LT(worst, 3.0);
  }
  {
    // Unknown start on a 2,500 m^2 office floor: 120 m of search does not localize the walker
    // (the corridors repeat), but the filter must not claim it has: from 90 s on, whenever the
    // estimate is more than 5 m off, its reported variance stays above the 2 m^2 convergence
    // level. With the search grid along the building's walls (issue 23) the comparisons match
    // well — a straight corridor in a hundred places up to 54 m apart — and the walls gathered
    // every particle 25 m off with a spread of 0.09 m^2 (the grid along the map's axes matched
    // nothing and kept the spread above 4 m^2). Only a distinctive comparison confirms a place
    // now (confirm_distinct_m), and until one has, the reported covariance includes the
    // building's spread: measured 796-888 m^2 throughout, no comparison distinctive (41 made).
    PdrErrorModel pdr(po, Random(12));
    MapParticleFilter pf(grid, seqs, fo);
    pf.InitializeUniform();
    std::vector<Vec2> odometry{Vec2::Zero()};
    std::vector<double> walked{0};
    double since = 0;
    for (const auto& st : walk.steps) {
      const Vec2 d = pdr.Apply(st.to - st.from, st.t1 - st.t0);
      pf.Predict(d);
      odometry.push_back(odometry.back() + d);
      walked.push_back(walked.back() + d.norm());
      since += d.norm();
      if (walked.back() >= 20 && since >= 2) {  // the pipeline's schedule (every 2 m, 20 m)
        since = 0;
        if (pf.WantsPatterns()) {
          std::vector<Vec2> last;
          for (std::size_t k = 0; k < odometry.size(); ++k) {
            if (walked[k] >= walked.back() - 20) last.push_back(odometry[k]);
          }
          const Vec2 dir = odometry.back() - odometry[odometry.size() - 3];
          pf.UpdatePatterns(ComparePatterns(last, seqs), std::atan2(dir.y(), dir.x()));
        }
      }
      if (st.t1 < 90) continue;
      const double error = (pf.Mean() - st.to).norm();
      if (error > 5) ASSERT_GT(pf.ReportedCovariance().trace(), 2.0) << "t = " << st.t1;
    }
  }
  {
    // The pipeline from a known start (what an integrator who knows the entry gets), on a
    // 5-minute search simulated on this floor (`trailmark simulate search`), pattern
    // comparisons on: walking a corridor spreads the belief past the 2 m^2 pattern level; a
    // known start compares again only above 8 m^2 (or after a wall alarm), else the draws from
    // the repeating corridors lose it. Measured: mean 0.96 m (PDR alone 0.97 m); with the known
    // start's level at 0 (as a uniform start), 5.7 m (2026-11-23; 13.4 m before the simulated
    // gyro ignored shuffling steps and the tracking sigma became 0.5).
    HouseSearchOptions so;
    so.duration_s = 300;
    const SimulatedMission sim = SimulateSearchOnPlan(plan, start, 0.0, so, 1);
    testing::TempDir mission_dir;
    WriteMissionDirectory(mission_dir.path(), sim.data, &sim.plan);
    const MissionDirectory mission(mission_dir.path());
    auto mean_error = [&](const std::map<std::string, std::string>& options) {
      VectorSink sink;
      RunNamed("mapmatch", mission, options, sink);
      return Evaluate(sim.data.info, sim.data.truth, sink.rows).agents.stats.mean_m;
    };
    EXPECT_LT(mean_error({}), 1.5);
    EXPECT_GT(mean_error({{"known_start_relocalize_above_variance_m2", "0"}}), 3.0);
  }
}

}  // namespace
}  // namespace trailmark::mapmatch

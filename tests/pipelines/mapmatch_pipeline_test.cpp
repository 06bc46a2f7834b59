// SPDX-License-Identifier: MIT
// The mapmatch pipeline end to end on the simulated house search, and its input checks.

#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>

#include "pipelines/run_named.h"
#include "test_util.h"
#include "trailmark/core/error.h"
#include "trailmark/eval/metrics.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/sim/beacon_lab.h"
#include "trailmark/sim/house_search.h"

namespace trailmark {
namespace {

using testing::CanRunNamed;
using testing::RunNamed;

/// The mapmatch summary of house 1's search `seed` (its hall door drawn 2 m off when
/// `map_error`) with `options`; the estimates into `sink` when given.
EstimatorSummary RunHouseSearch(int seed, bool map_error, const OptionValues& options,
                                VectorSink* sink = nullptr) {
  HouseSearchOptions o;
  o.map_error = map_error;
  const SimulatedMission sim = SimulateHouseSearch(o, seed);
  testing::TempDir dir;
  WriteMissionDirectory(dir.path(), sim.data, &sim.plan);
  VectorSink own;
  return RunNamed("mapmatch", MissionDirectory(dir.path()), options, sink ? *sink : own);
}

TEST(MapMatchPipeline, KnownStartStaysOnTheMapAndEveryEstimateIsValid) {
  HouseSearchOptions o;
  const SimulatedMission sim = SimulateHouseSearch(o, 1);
  testing::TempDir dir;
  WriteMissionDirectory(dir.path(), sim.data, &sim.plan);
  const MissionDirectory mission(dir.path());
  const PipelineSpec& pipeline = RequirePipeline("mapmatch");
  ASSERT_TRUE(CanRun(pipeline, mission));
  for (const auto& options :
       std::vector<std::map<std::string, std::string>>{{{"pseudo", "false"}},
                                                       {},
                                                       {{"init", "uniform"}},
                                                       {{"patterns_above_variance_m2", "0"}}}) {
    VectorSink sink;
    const EstimatorSummary s = RunBatch(pipeline, {mission, options}, sink);
    // The start and one per step, and the view between rows (view_period_s) at other times.
    std::set<TimeS> own{sim.data.steps.front().t0};
    for (const Step& step : sim.data.steps) own.insert(step.t1);
    ASSERT_EQ(std::count_if(sink.rows.begin(), sink.rows.end(),
                            [&](const Estimate& e) { return own.count(e.t) != 0; }),
              static_cast<std::ptrdiff_t>(sim.data.steps.size() + 1));
    for (const auto& e : sink.rows) {
      ASSERT_TRUE(e.position_n.allFinite());
      ASSERT_GT(e.sxx, 0);
      ASSERT_GT(e.sxx * e.syy - e.sxy * e.sxy, 0);
    }
    const Metrics m = Evaluate(sim.data.info, sim.data.truth, sink.rows);
    if (options.count("pseudo")) {
      // The conventional map-aided filter from a known start: within 1 m on average (seeds 1-6
      // of house 1: 0.4-0.8 m).
      EXPECT_LT(m.agents.stats.mean_m, 1.0);
      EXPECT_EQ(s.numbers.at("ff1.pattern_comparisons"), 0.0);
    } else {
      // A comparison every 2 m after the first 20 m: used, or skipped while converged.
      EXPECT_GT(s.numbers.at("ff1.pattern_comparisons") +
                    s.numbers.at("ff1.comparisons_skipped_converged"),
                20.0);
      if (options.count("patterns_above_variance_m2")) {  // the paper's filter: always used
        EXPECT_EQ(s.numbers.at("ff1.comparisons_skipped_converged"), 0.0);
        EXPECT_GT(s.numbers.at("icp_runs"), 1000.0);
      }
    }
    EXPECT_EQ(s.numbers.at("search_sequences"), 3.0);  // the searched part + two closed bedrooms
  }
}

TEST(MapMatchPipeline, AnUnconfirmedPlaceIsReportedAndItsEllipseCoversTheBuilding) {
  // Issue 23: from an unknown start the house search is confirmed by distinctive comparisons
  // (the summary says so, the last ellipse is the particles' own); without comparisons
  // (pseudo=false) nothing can confirm it: the summary and a note say so, and every ellipse
  // stays at least the house's spread (the searched part alone is 70 m^2: its variance is
  // several m^2).
  for (const bool pseudo : {true, false}) {
    VectorSink sink;
    const EstimatorSummary s = RunHouseSearch(
        3, false, {{"init", "uniform"}, {"pseudo", pseudo ? "true" : "false"}}, &sink);
    EXPECT_EQ(s.numbers.at("ff1.place_unconfirmed"), pseudo ? 0.0 : 1.0);
    bool noted = false;
    for (const auto& n : s.notes) noted = noted || n.find("never confirmed") != std::string::npos;
    EXPECT_EQ(noted, !pseudo);
    if (pseudo) {
      EXPECT_LT(sink.rows.back().sxx + sink.rows.back().syy, 2.0);
    } else {
      for (const auto& e : sink.rows) ASSERT_GT(e.sxx + e.syy, 10.0) << e.t;
    }
  }
}

TEST(MapMatchPipeline, AWalkThroughAWallOfTheMapRaisesTheWallCrossingAlarm) {
  // The map error of sec. V-E (the hall door drawn 2 m from where it is) against the right
  // map, the same left-hand searches (seeds 11-16; the indicator was tuned on seeds 1-10). One
  // seed's verdict moves with the particles' draws (seed 12 is flagged with the 1 m cells'
  // inside test, not with the exact one), so the rate is asserted. Measured 2026-12-03: the
  // verdict on 4 of 6, a wall alarm on 6 of 6, no false alarm — with either inside test.
  int flagged = 0, false_alarms = 0, with_wall_alarms = 0;
  for (int seed = 11; seed <= 16; ++seed) {
    for (bool map_error : {true, false}) {
      const EstimatorSummary s =
          RunHouseSearch(seed, map_error, {{"init", "known"}, {"seed", std::to_string(seed)}});
      const bool verdict = s.numbers.at("ff1.map_error_suspected") == 1.0;
      if (map_error) {
        flagged += verdict;
        with_wall_alarms += s.numbers.at("ff1.wall_alarms") >= 1.0;
      } else {
        false_alarms += verdict;
      }
      bool noted = false;
      for (const auto& n : s.notes)
        noted = noted || n.find("kept crossing walls") != std::string::npos;
      EXPECT_TRUE(noted) << seed;
    }
  }
  EXPECT_GE(flagged, 4);
  EXPECT_GE(with_wall_alarms, 5);
  EXPECT_EQ(false_alarms, 0);
}

TEST(MapMatchPipeline, FromAnUnknownStartTheSearchForThePlaceIsNoMapError) {
  // The variance indicator (sec. V-E) watches a filter that has found its place: from an
  // unknown start the first minute's variance is the search for the place. Before issue 23 it
  // counted, and every search from an unknown start on the right map was "map error
  // suspected" (house 1, seeds 241-270: 30 of 30; now 1 of 30). Seeds 11-16, both maps,
  // measured 2026-12-03: the moved door flagged in 6 of 6, the right map in 1 of 6.
  int flagged = 0, false_alarms = 0;
  for (int seed = 11; seed <= 16; ++seed) {
    for (bool map_error : {true, false}) {
      const EstimatorSummary s =
          RunHouseSearch(seed, map_error, {{"init", "uniform"}, {"seed", std::to_string(seed)}});
      (map_error ? flagged : false_alarms) += s.numbers.at("ff1.map_error_suspected") == 1.0;
    }
  }
  EXPECT_GE(flagged, 5);
  EXPECT_LE(false_alarms, 1);
}

TEST(MapMatchPipeline, BadFloorPlansAndOptionsAreReportedClearly) {
  HouseSearchOptions o;
  o.duration_s = 60;
  SimulatedMission sim = SimulateHouseSearch(o, 2);
  testing::TempDir dir;
  WriteMissionDirectory(dir.path(), sim.data, &sim.plan);
  VectorSink sink;
  {
    const MissionDirectory mission(dir.path());
    EXPECT_THROW(RunNamed("mapmatch", mission, {{"init", "maybe"}}, sink),
                 std::invalid_argument);
    EXPECT_THROW(RunNamed("mapmatch", mission, {{"particles", "3"}}, sink),
                 std::invalid_argument);
    EXPECT_THROW(RunNamed("mapmatch", mission, {{"wall_alarm_k", "1.5"}}, sink),
                 std::invalid_argument);
    EXPECT_THROW(RunNamed("mapmatch", mission, {{"relocalize_above_variance_m2", "-2"}}, sink),
                 std::invalid_argument);
    for (const auto& [key, value] :
         std::vector<std::pair<std::string, std::string>>{{"map_error_wall_alarms", "0"},
                                                          {"wall_follow_sigma_m", "0"},
                                                          {"wall_follow_leave", "1"},
                                                          {"wall_follow_off_likelihood", "1.5"},
                                                          {"wall_follow", "maybe"},
                                                          {"seed", "-1"},
                                                          {"seed", "2.5"},
                                                          {"seed", "1e30"},
                                                          {"particles", "2500.5"},
                                                          {"map_error_wall_alarms", "2.5"}}) {
      EXPECT_THROW(RunNamed("mapmatch", mission, {{key, value}}, sink), std::invalid_argument)
          << key;
    }
  }
  // A floor plan with its outer wall broken: nothing enclosed, named with the file.
  const FloorPlan broken({{{0, 0}, {12.5, 0}}, {{12.5, 0}, {12.5, 10}}, {{12.5, 10}, {0, 10}}}, {},
                         {});
  WriteMissionDirectory(dir.path(), sim.data, &broken);
  try {
    const MissionDirectory mission(dir.path());
    RunNamed("mapmatch", mission, {}, sink);
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("floorplan.geojson"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("encloses no area"), std::string::npos) << e.what();
  }
  // A wall drawn a million kilometres away (a unit or typing error): refused, not allocated.
  const FloorPlan far(
      {{{0, 0}, {12.5, 0}}, {{12.5, 0}, {12.5, 10}}, {{12.5, 10}, {0, 10}}, {{0, 10}, {1e9, 0}}},
      {}, {});
  WriteMissionDirectory(dir.path(), sim.data, &far);
  try {
    const MissionDirectory mission(dir.path());
    RunNamed("mapmatch", mission, {}, sink);
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("too large for a 1 m search grid"), std::string::npos)
        << e.what();
  }
  // No floor plan at all: the pipeline cannot run and says so.
  sim.data.info.floorplan.reset();
  testing::TempDir bare;
  WriteMissionDirectory(bare.path(), sim.data, nullptr);
  const MissionDirectory mission(bare.path());
  EXPECT_FALSE(CanRunNamed("mapmatch", mission));
  try {
    RunNamed("mapmatch", mission, {}, sink);
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("needs a floor plan"), std::string::npos) << e.what();
  }
}

TEST(MapMatchPipeline, AMultiFloorPlanIsMatchedOnOneFloor) {
  // House 1 on level 0 and, on level 1, walls every metre across it (the floor above, cut into
  // offices), walls that enclose nothing: merged into one plan every step would cross a wall.
  // Not told which floor, the filter follows the levels; level 1 cannot be matched on and is
  // left out (noted), and the filter gives exactly the single-floor result.
  HouseSearchOptions o;
  o.duration_s = 60;
  const SimulatedMission sim = SimulateHouseSearch(o, 3);
  testing::TempDir single, multi;
  WriteMissionDirectory(single.path(), sim.data, &sim.plan);
  WriteMissionDirectory(multi.path(), sim.data, &sim.plan);
  {
    auto plan = nlohmann::json::parse(std::ifstream(multi.path() / "floorplan.geojson"));
    for (int x = 1; x < 12; ++x) {
      plan["features"].push_back(
          {{"type", "Feature"},
           {"properties", {{"kind", "wall"}, {"level", 1}}},
           {"geometry",
            {{"type", "LineString"}, {"coordinates", {{x + 0.5, 0.0}, {x + 0.5, 10.0}}}}}});
    }
    std::ofstream(multi.path() / "floorplan.geojson") << plan.dump();
  }
  const std::map<std::string, std::string> options{{"pseudo", "false"}};
  VectorSink a, b;
  RunNamed("mapmatch", MissionDirectory(single.path()), options, a);
  const EstimatorSummary s = RunNamed("mapmatch", MissionDirectory(multi.path()), options, b);
  ASSERT_EQ(a.rows.size(), b.rows.size());
  for (std::size_t k = 0; k < a.rows.size(); ++k) {
    ASSERT_EQ(a.rows[k].position_n, b.rows[k].position_n) << k;
  }
  bool noted = false, left_out = false;
  for (const auto& n : s.notes) {
    noted |= n.find("2 levels (0, 1)") != std::string::npos;
    left_out |= n.find("level 1 left out") != std::string::npos;
  }
  EXPECT_TRUE(noted);
  EXPECT_TRUE(left_out);
  // Asked for a floor the plan does not have, or not a whole number: named.
  const MissionDirectory mission(multi.path());
  try {
    RunNamed("mapmatch", mission, {{"level", "2"}}, b);
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("no level 2 (its levels: 0, 1)"), std::string::npos)
        << e.what();
  }
  EXPECT_THROW(RunNamed("mapmatch", mission, {{"level", "0.5"}}, b), std::invalid_argument);
}

TEST(MapMatchPipeline, TheWallFollowingModelHoldsHouseTwoFromAnUnknownStart) {
  // House 2 (furniture against the walls, left-hand searches of 10 min), seeds 1-6, unknown
  // start, N = 500 (the paper's; quicker): the RMSE over the six searches at each minute from
  // 2 min on, averaged. Measured 2026-11-23: 0.47 m with the wall-following model and
  // stay-inside, 1.19 m without them (runs that lose the track at the furniture for minutes);
  // 0.50 and 1.92 m before the simulated gyro ignored shuffling steps and the tracking sigma
  // became 0.5, 0.51 and 2.81 m before the tracking sigma.
  const std::vector<double> checkpoints = {120, 180, 240, 300, 360, 420, 480, 540, 600};
  auto mean_rmse = [&](const std::map<std::string, std::string>& extra) {
    std::vector<double> sq(checkpoints.size(), 0);
    for (int seed = 1; seed <= 6; ++seed) {
      HouseSearchOptions o;
      o.house = 2;
      o.duration_s = 600;
      const SimulatedMission sim = SimulateHouseSearch(o, seed);
      testing::TempDir dir;
      WriteMissionDirectory(dir.path(), sim.data, &sim.plan);
      const MissionDirectory mission(dir.path());
      std::map<std::string, std::string> options{
          {"init", "uniform"}, {"seed", std::to_string(seed)}, {"particles", "500"}};
      options.insert(extra.begin(), extra.end());
      VectorSink sink;
      RunNamed("mapmatch", mission, options, sink);
      const Metrics m = Evaluate(sim.data.info, sim.data.truth, sink.rows);
      for (std::size_t k = 0; k < checkpoints.size(); ++k) {
        double e = 1e9;
        for (const auto& s : m.agents.series) {
          if (s.t <= checkpoints[k] + 1e-9) e = s.error_m;
        }
        sq[k] += e * e;
      }
    }
    double mean = 0;
    for (double v : sq) mean += std::sqrt(v / 6);
    return mean / checkpoints.size();
  };
  // The searchers' model alone (no free walkers: searches are what it is for).
  const double with_model = mean_rmse({{"free_walk_share", "0"}});
  const double without = mean_rmse({{"wall_follow", "false"}, {"stay_inside", "false"}});
  EXPECT_LT(with_model, 0.75);
  EXPECT_LT(with_model, 0.5 * without);
  // The default holds half the belief as free walkers (honest on walks that are no search):
  // measured 0.62 m here (2026-12-06), the price on house 2 of that honesty.
  EXPECT_LT(mean_rmse({}), 0.75);
}

TEST(MapMatchPipeline, AWalkAlongATrailIsNotTakenForADirectionalSearch) {
  // The beacon neighbour trail (a U or L corridor walked down its middle, out and back),
  // seeds 1-4, known start: the searchers' model alone packs the belief at arm's length from a
  // wall and its ellipse holds the truth less than half the time (measured 47 %, mean error
  // 0.87 m); with free walkers beside the searchers, 84 % and 0.64 m (2026-12-06).
  auto run = [](const std::map<std::string, std::string>& options) {
    double in95 = 0, mean = 0;
    for (int seed = 1; seed <= 4; ++seed) {
      const SimulatedMission sim = SimulateShapedTrail({}, seed);
      testing::TempDir dir;
      WriteMissionDirectory(dir.path(), sim.data, &sim.plan);
      VectorSink sink;
      RunNamed("mapmatch", MissionDirectory(dir.path()), options, sink);
      const Metrics m = Evaluate(sim.data.info, sim.data.truth, sink.rows);
      in95 += m.agents.stats.in95 / 4;
      mean += m.agents.stats.mean_m / 4;
    }
    return std::pair(in95, mean);
  };
  // Without the view between rows, which moves both on (the searchers' in95 then 60 %).
  const auto [searchers_in95, searchers_mean] =
      run({{"free_walk_share", "0"}, {"view_period_s", "0"}});
  const auto [mixed_in95, mixed_mean] = run({{"view_period_s", "0"}});
  EXPECT_LT(searchers_in95, 0.6);
  EXPECT_GT(mixed_in95, 0.75);
  EXPECT_LT(mixed_mean, 0.85 * searchers_mean);
}

}  // namespace
}  // namespace trailmark

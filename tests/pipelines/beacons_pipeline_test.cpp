// SPDX-License-Identifier: MIT
// The ultrasound-beacon pipelines end to end on simulated lab missions.

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <algorithm>
#include <fstream>
#include <numbers>

#include "pipelines/run_named.h"
#include "test_util.h"
#include "trailmark/core/error.h"
#include "trailmark/eval/metrics.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/sim/beacon_lab.h"
#include "trailmark/sim/scenarios.h"
#include "trailmark/sim/variation.h"

namespace trailmark {
namespace {

using testing::CanRunNamed;
using testing::RunNamed;

struct Outcome {
  EstimatorSummary summary;
  Metrics metrics;
  std::vector<double> agent_errors;
};

// A simulated mission written to a temporary directory and opened as the pipelines read it.
struct OnDisk {
  OnDisk(const MissionData& data, const FloorPlan& plan)
      : mission((WriteMissionDirectory(dir.path(), data, &plan), dir.path())) {}
  testing::TempDir dir;
  MissionDirectory mission;
};

Outcome RunOn(const PipelineSpec& pipeline, const MissionDirectory& mission, const MissionData& data,
              std::map<std::string, std::string> options = {}) {
  VectorSink sink;
  Outcome o;
  o.summary = RunBatch(pipeline, {mission, options}, sink);
  for (const auto& e : sink.rows) {
    EXPECT_TRUE(e.position_n.allFinite()) << e.id;
    EXPECT_GT(e.sxx, 0) << e.id;
    EXPECT_GT(e.sxx * e.syy - e.sxy * e.sxy, 0) << e.id;
  }
  sink.rows = sink.TakeSortedByTime();
  o.metrics = Evaluate(data.info, data.truth, sink.rows);
  for (const auto& s : o.metrics.agents.series) o.agent_errors.push_back(s.error_m);
  return o;
}

TEST(BeaconsPipeline, TracksTheLabTraceWithinTheIssueTargets) {
  BeaconLabOptions lab;
  lab.trace = LabTrace::kC;
  const SimulatedMission sim = SimulateBeaconLab(lab, 3);
  const OnDisk disk(sim.data, sim.plan);
  const MissionDirectory& mission = disk.mission;
  const PipelineSpec& ekf = RequirePipeline("beacons-ekf");
  ASSERT_TRUE(CanRun(ekf, mission));
  const Outcome ours = RunOn(ekf, mission, sim.data);
  const Outcome paper = RunOn(ekf, mission, sim.data, {{"update", "position"}});
  const Outcome us_only = RunOn(ekf, mission, sim.data, {{"filter", "us-only"}});
  const Outcome pdr = RunOn(RequirePipeline("pdr"), mission, sim.data);
  // Issue targets (paper Table 1 overall 1.93 / 3.70 m): 50 % <= 1.0 m, 75 % <= 1.8 m.
  EXPECT_LE(Percentile(ours.agent_errors, 50), 1.0);
  EXPECT_LE(Percentile(ours.agent_errors, 75), 1.8);
  // Fusion beats each modality alone (Figs. 6 and 9).
  EXPECT_LT(Percentile(ours.agent_errors, 50), Percentile(us_only.agent_errors, 50));
  EXPECT_LT(Percentile(ours.agent_errors, 50), 0.5 * Percentile(pdr.agent_errors, 50));
  EXPECT_LE(Percentile(paper.agent_errors, 50), 1.0);
  EXPECT_GT(ours.summary.numbers.at("ff1.range_updates"), 500);
  EXPECT_EQ(ours.summary.numbers.at("beacons_surveyed"), ours.summary.numbers.at("beacons"));
}

TEST(BeaconsPipeline, StartsWithoutASurveyedStartFromTheFirstUltrasound) {
  const SimulatedMission sim = SimulateBeaconLab({}, 5);
  const OnDisk disk(sim.data, sim.plan);
  const MissionDirectory& mission = disk.mission;
  const Outcome o = RunOn(RequirePipeline("beacons-ekf"), mission, sim.data, {{"init", "ultrasound"}});
  ASSERT_TRUE(o.summary.numbers.count("ff1.initialized_at_s"));
  EXPECT_LT(o.summary.numbers.at("ff1.initialized_at_s"), 20.0);
  EXPECT_LE(Percentile(o.agent_errors, 50), 1.0);
  // Instants before the initialization are not scored, and are few.
  EXPECT_LT(o.metrics.agents.uncovered, 200u);
}

TEST(BeaconsPipeline, DroppedTrailIsLocalizedByMdsAndLeadsBackOut) {
  const SimulatedMission sim = SimulateScenario("beacon-trail", 2);
  const OnDisk disk(sim.data, sim.plan);
  const MissionDirectory& mission = disk.mission;
  const Outcome mds = RunOn(RequirePipeline("beacons-mds"), mission, sim.data);
  EXPECT_TRUE(mds.agent_errors.empty());  // beacons only
  EXPECT_EQ(mds.summary.numbers.at("beacons_from_mds"), mds.summary.numbers.at("beacons"));
  double final_sum = 0;
  int n = 0;
  for (const auto& node : mds.metrics.nodes) {
    if (node.kind != NodeKind::kCrumb) continue;
    final_sum += node.stats.final_m;
    ++n;
  }
  ASSERT_GE(n, 18);
  EXPECT_LT(final_sum / n, 1.5);  // seeds 1-4: 0.55-1.04 m
  const Outcome ekf = RunOn(RequirePipeline("beacons-ekf"), mission, sim.data);
  const Outcome pdr = RunOn(RequirePipeline("pdr"), mission, sim.data);
  EXPECT_LT(Percentile(ekf.agent_errors, 50), 1.5);
  EXPECT_LT(ekf.metrics.agents.stats.mean_m, pdr.metrics.agents.stats.mean_m);
  // At the end the firefighter is back at the door: the way out is the entry beacon.
  bool noted = false;
  for (const auto& note : ekf.summary.notes) noted |= note == "ff1: way out b01";
  EXPECT_TRUE(noted);
  // Mid-mission (deep in the trace), the way out descends through the ids to b01.
  const beacons::WayOutReport w = ComputeWayOut(mission, "ff1", 120.0);
  ASSERT_FALSE(w.route.empty());
  EXPECT_FALSE(w.broken.has_value());
  EXPECT_EQ(w.route.back(), "b01");
  EXPECT_TRUE(std::is_sorted(w.route.rbegin(), w.route.rend()));
  for (const auto& p : w.route_positions_n) EXPECT_TRUE(p.has_value());
}

TEST(BeaconsPipeline, AMapSolvedOnAWorkerIsPutInPlaceItsLagLaterAndEndsTheSame) {
  // map_lag_s: each solve is put in place that much mission time after its tick (issue 20):
  // the first map is written a lag later, and the map at the end is the same map.
  const SimulatedMission sim = SimulateScenario("beacon-trail", 2);
  const OnDisk disk(sim.data, sim.plan);
  const MissionDirectory& mission = disk.mission;
  const PipelineSpec& mds = RequirePipeline("beacons-mds");
  std::map<std::string, std::pair<TimeS, Estimate>> at_once, lagged;  // first time, last row
  for (const auto& [lag, out] : {std::pair{"0", &at_once}, std::pair{"1", &lagged}}) {
    VectorSink sink;
    RunBatch(mds, {mission, {{"map_lag_s", lag}}}, sink);
    for (const Estimate& e : sink.rows) {
      auto [it, fresh] = out->emplace(e.id, std::pair{e.t, e});
      if (!fresh) it->second.second = e;
    }
  }
  ASSERT_GE(at_once.size(), 18u);
  ASSERT_EQ(lagged.size(), at_once.size());
  TimeS first_at_once = 1e300, first_lagged = 1e300;
  for (const auto& [id, first] : at_once) {
    SCOPED_TRACE(id);
    const auto& later = lagged.at(id);
    first_at_once = std::min(first_at_once, first.first);
    first_lagged = std::min(first_lagged, later.first);
    EXPECT_LT((later.second.position_n - first.second.position_n).norm(), 1e-4);
  }
  EXPECT_GE(first_lagged, first_at_once + 1.0 - 1e-9);
  EXPECT_LT(first_lagged, first_at_once + 1.5);
}

TEST(BeaconsPipeline, TheViewIsNeverOlderThanTheOutputPeriodAndHeldItStaysHonest) {
  // The view between rows (issue 22; the step front end's view_period_s since 2026-12-07, the
  // tracker's own output_period_s before, with the same figures on the randomized families):
  // between the ~3 Hz rows of a steps mission, each agent's estimate extrapolated every 0.1 s.
  // Held until the next (the eval's online semantics), the view then keeps the truth in its
  // ellipse (seed 1: in95 84 -> 91 %, mean 0.60 -> 0.57 m; seed 2, this test's seed until drops
  // were placed within their step (drop_within_step), was 85 -> 93 % then and is 99 -> 97 %
  // since: its map no longer lags the walk).
  const SimulatedMission sim = SimulateScenario("beacon-trail", 1);
  const OnDisk disk(sim.data, sim.plan);
  const MissionDirectory& mission = disk.mission;
  const PipelineSpec& ekf = RequirePipeline("beacons-ekf");
  const Outcome sparse = RunOn(ekf, mission, sim.data, {{"view_period_s", "0"}});
  const Outcome ticked = RunOn(ekf, mission, sim.data);
  EXPECT_GT(ticked.metrics.agents.stats.in95, sparse.metrics.agents.stats.in95 + 0.05);
  EXPECT_LT(ticked.metrics.agents.stats.mean_m, sparse.metrics.agents.stats.mean_m);
  VectorSink sink;
  RunBatch(ekf, {mission, {}}, sink);
  std::vector<TimeS> t;
  for (const Estimate& e : sink.rows)
    if (e.id == "ff1") t.push_back(e.t);
  ASSERT_GT(t.size(), 1000u);
  for (std::size_t i = 1; i < t.size(); ++i) {
    ASSERT_GE(t[i], t[i - 1]) << i;
    if (t[i - 1] > 1.0) ASSERT_LE(t[i] - t[i - 1], 0.1 + 1e-9) << t[i - 1];  // after the first step
  }
  // A period that would flood the sink is refused.
  EXPECT_THROW(RunOn(ekf, mission, sim.data, {{"output_period_s", "0.001"}}), std::invalid_argument);
  EXPECT_THROW(RunOn(ekf, mission, sim.data, {{"view_period_s", "0.001"}}), std::invalid_argument);
}

TEST(BeaconsPipeline, BeaconsWithoutDropEventsAreAnchoredWhereTheyArePassedClosely) {
  // Recorded data may not log the drops: each beacon is then anchored where the responder is
  // the first time a range to it is at most 1.5 m.
  SimulatedMission sim = SimulateScenario("beacon-trail", 2);
  sim.data.events.clear();
  const OnDisk disk(sim.data, sim.plan);
  const MissionDirectory& mission = disk.mission;
  const Outcome ekf = RunOn(RequirePipeline("beacons-ekf"), mission, sim.data);
  const Outcome pdr = RunOn(RequirePipeline("pdr"), mission, sim.data);
  EXPECT_EQ(ekf.summary.numbers.at("beacons_from_mds"), ekf.summary.numbers.at("beacons"));
  EXPECT_EQ(ekf.summary.numbers.at("beacons_anchored_by_close_pass"),
            ekf.summary.numbers.at("beacons"));
  EXPECT_LT(ekf.metrics.agents.stats.mean_m,
            0.5 * pdr.metrics.agents.stats.mean_m);  // 0.57 vs 2.92 m
}

// Those anchors (close_pass_on_track, the default since 2026-12-06) are a drop's: a point of the
// passer's dead-reckoning track in the map, a consider state of its tracker. At the tracker's
// estimate instead, each pass anchored the map where the map had put it and the ellipses held
// the truth less often. Seeds 1-4 without events (2026-12-06: in95 90 % against 52 %).
TEST(BeaconsPipeline, CloseAnchorsOnTheTrackKeepTheEllipseHonest) {
  double in95_on = 0, in95_off = 0, mean_on = 0, mean_pdr = 0;
  const int seeds = 4;
  for (std::uint64_t seed = 1; seed <= seeds; ++seed) {
    SimulatedMission sim = SimulateScenario("beacon-trail", seed);
    sim.data.events.clear();
    const OnDisk disk(sim.data, sim.plan);
    const Outcome on = RunOn(RequirePipeline("beacons-ekf"), disk.mission, sim.data);
    const Outcome off = RunOn(RequirePipeline("beacons-ekf"), disk.mission, sim.data,
                              {{"close_pass_on_track", "false"}});
    const Outcome pdr = RunOn(RequirePipeline("pdr"), disk.mission, sim.data);
    EXPECT_EQ(on.summary.numbers.at("beacons_anchored_by_close_pass"),
              on.summary.numbers.at("beacons"));
    in95_on += on.metrics.agents.stats.in95 / seeds;
    in95_off += off.metrics.agents.stats.in95 / seeds;
    mean_on += on.metrics.agents.stats.mean_m / seeds;
    mean_pdr += pdr.metrics.agents.stats.mean_m / seeds;
  }
  EXPECT_GT(in95_on, 0.8);
  EXPECT_LT(in95_off, 0.7);
  EXPECT_LT(mean_on, 0.5 * mean_pdr);  // 0.48 against 2.78 m
}

TEST(BeaconsPipeline, HoldsOnANeighbourOnlyTrailWithImplausibleLinks) {
  // A trail laid out by someone else (issue 22): neighbour-only links, NLOS long tails, 15 %
  // bearing outliers; seed 2 of the development seeds (the reported ones are 101-124). Two
  // beacon links of 0 m and 5 km are added: counted and reported, never a NaN (1e6 m is
  // refused by the reader, below).
  const SimulatedMission sim = SimulateShapedTrail({}, 2);
  MissionData data = sim.data;
  const std::size_t k = data.ranges.size() / 2;
  const TimeS t = data.ranges[k].t;
  data.ranges.insert(data.ranges.begin() + static_cast<long>(k) + 1,
                     {{t, "b02", "b03", 0.0, 0.1, "ultrasound"},
                      {t, "b02", "b04", 5e3, 0.1, "ultrasound"}});
  const OnDisk disk(data, sim.plan);
  const MissionDirectory& mission = disk.mission;
  const auto& dir = disk.dir;
  const Outcome ours = RunOn(RequirePipeline("beacons-ekf"), mission, sim.data);
  const Outcome pdr = RunOn(RequirePipeline("pdr"), mission, sim.data);
  EXPECT_GE(ours.summary.numbers.at("implausible_beacon_links"), 2.0);
  EXPECT_TRUE(std::any_of(ours.summary.notes.begin(), ours.summary.notes.end(), [](const std::string& n) {
    return n.find("implausible") != std::string::npos;
  }));
  // The issue's targets (median <= 0.6 m, p75 <= 0.9 m; in95 >= 85 % at the estimates' own
  // instants) and better than dead reckoning.
  EXPECT_LE(ours.metrics.agents.stats.median_m, 0.6);
  EXPECT_LE(ours.metrics.agents.stats.p75_m, 0.9);
  EXPECT_LT(ours.metrics.agents.stats.p75_m, pdr.metrics.agents.stats.p75_m);
  EXPECT_GE(ours.metrics.agents.at_estimates.in95, 0.85);
  // A range of 1e6 m is not data: the reader names the file and line.
  {
    std::ofstream f(dir.path() / "ranges.csv", std::ios::app);
    f << "1e4,b02,b04,1e6,0.1,ultrasound\n";
  }
  const MissionDirectory again(dir.path());
  VectorSink sink;
  try {
    RunNamed("beacons-ekf", again, {}, sink);
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("ranges.csv:"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("'range'"), std::string::npos) << e.what();
  }
}

TEST(BeaconsPipeline, ADeadReckoningFarOutsideItsModelLoosensItsDropsToo) {
  // Phone-class steps on the deployed trail (`simulate beacon-trail --seed 105 --vary 5
  // --family phone`, a variant of the development set K 1-20): the dropper's shared errors
  // come out far beyond their sigma. Inflating those alone, the drops held at their stated
  // white sigma bent the map with confidence: worse than dead reckoning, in95 12 %. With the
  // drops' white covariances scaled alike: better than dead reckoning and honest more often.
  const SimulatedMission base = SimulateScenario("beacon-trail", 105);
  const Variation v = DrawVariation(VariationFamily::kPhone, 5);
  SimulatedMission sim = base;
  ApplyVariation(v, sim);
  testing::TempDir dir;
  WriteMissionDirectory(dir.path(), sim.data, &sim.plan, v.write);
  const MissionDirectory mission(dir.path());
  const Outcome pdr = RunOn(RequirePipeline("pdr"), mission, sim.data);
  const Outcome loosened = RunOn(RequirePipeline("beacons-ekf"), mission, sim.data);
  const Outcome shared_only =
      RunOn(RequirePipeline("beacons-ekf"), mission, sim.data, {{"map_inflate_white", "false"}});
  EXPECT_GT(shared_only.metrics.agents.stats.p75_m, pdr.metrics.agents.stats.p75_m);
  EXPECT_LT(loosened.metrics.agents.stats.p75_m, 0.6 * pdr.metrics.agents.stats.p75_m);
  EXPECT_GT(loosened.metrics.agents.stats.in95, shared_only.metrics.agents.stats.in95 + 0.3);
}

TEST(BeaconsPipeline, SightingsAreUsedWhereSurveyedBeaconsHoldTheMapsRotation) {
  // Sightings (`sightings=true`) go into a part of the map with at least
  // `sightings_min_surveyed` surveyed beacons: the neighbour trail has three, the deployed
  // trail none, where they are not even kept unless the gate is 0.
  const SimulatedMission surveyed = SimulateShapedTrail({}, 2);
  const OnDisk surveyed_disk(surveyed.data, surveyed.plan);
  const Outcome on = RunOn(RequirePipeline("beacons-mds"), surveyed_disk.mission, surveyed.data,
                           {{"sightings", "true"}});
  EXPECT_GT(on.summary.numbers.at("map_sightings_used"), 0.0);
  const SimulatedMission deployed = SimulateScenario("beacon-trail", 2);
  const OnDisk deployed_disk(deployed.data, deployed.plan);
  const Outcome gated = RunOn(RequirePipeline("beacons-mds"), deployed_disk.mission, deployed.data,
                              {{"sightings", "true"}});
  EXPECT_EQ(gated.summary.numbers.at("map_sightings"), 0.0);
  const Outcome everywhere =
      RunOn(RequirePipeline("beacons-mds"), deployed_disk.mission, deployed.data,
            {{"sightings", "true"}, {"sightings_min_surveyed", "0"}});
  EXPECT_GT(everywhere.summary.numbers.at("map_sightings_used"), 0.0);
  // Gated, the map is the one without sightings.
  const Outcome off = RunOn(RequirePipeline("beacons-mds"), deployed_disk.mission, deployed.data);
  EXPECT_EQ(gated.metrics.static_nodes.stats.mean_m, off.metrics.static_nodes.stats.mean_m);
  EXPECT_NE(everywhere.metrics.static_nodes.stats.mean_m, off.metrics.static_nodes.stats.mean_m);
}

TEST(BeaconsPipeline, AMapThatDisagreesWithItsNoiseIsNotUsedAndSaysSo) {
  // One of the trail's surveyed beacons written 4 m from where it is: the least-squares map
  // fails its chi-square test, the beacons fall back to their surveys and drop priors, and an
  // integrity note (a live alert) says so; the responder stays better than dead reckoning.
  const SimulatedMission sim = SimulateShapedTrail({}, 3);
  MissionData data = sim.data;
  int moved = 0;
  for (NodeInfo& n : data.info.nodes) {
    if (n.kind == NodeKind::kLandmark && n.position && moved == 0) {
      n.position->x() += 4.0;
      ++moved;
    }
  }
  ASSERT_EQ(moved, 1);
  const OnDisk disk(data, sim.plan);
  const MissionDirectory& mission = disk.mission;
  const Outcome ours = RunOn(RequirePipeline("beacons-ekf"), mission, sim.data);
  const Outcome pdr = RunOn(RequirePipeline("pdr"), mission, sim.data);
  const auto fallback = std::find_if(ours.summary.integrity.begin(), ours.summary.integrity.end(),
                                     [](const IntegrityNote& n) {
                                       return n.source == "beacon map" && n.action == "fallback";
                                     });
  ASSERT_NE(fallback, ours.summary.integrity.end());
  EXPECT_NE(fallback->message.find("chi-square"), std::string::npos) << fallback->message;
  EXPECT_LT(ours.metrics.agents.stats.p75_m, pdr.metrics.agents.stats.p75_m);
}

// The neighbour trail of seed `seed` without its start heading, its PDR steps rotated by
// `angle_rad` (a foot unit whose yaw starts anywhere).
MissionData RotatedPdrWithoutHeading(const SimulatedMission& sim, double angle_rad) {
  MissionData data = sim.data;
  for (NodeInfo& n : data.info.nodes) {
    n.start_heading_rad.reset();
    n.start_heading_sigma_rad.reset();
  }
  const Eigen::Rotation2Dd r(angle_rad);
  for (Step& st : data.steps) st.delta_n.head<2>() = r * Vec2(st.delta_n.head<2>());
  return data;
}

TEST(BeaconsPipeline, EstimatesTheEntryHeadingWhenNoneIsGiven) {
  // Without start_heading the PDR's rotation into the navigation frame is estimated from the
  // first ultrasound measurements (issue 22): the same walk with its PDR frame turned by 40 or
  // by 130 degrees gives the same estimates, headings 90 degrees apart, within the targets.
  const SimulatedMission sim = SimulateShapedTrail({}, 2);
  std::vector<std::vector<Estimate>> runs;
  std::vector<double> headings;
  for (const double deg : {40.0, 130.0}) {
    testing::TempDir dir;
    WriteMissionDirectory(dir.path(), RotatedPdrWithoutHeading(sim, deg * std::numbers::pi / 180),
                          &sim.plan);
    const MissionDirectory mission(dir.path());
    VectorSink sink;
    const EstimatorSummary summary = RunBatch(RequirePipeline("beacons-ekf"), {mission, {}}, sink);
    ASSERT_TRUE(summary.numbers.count("ff1.estimated_heading_rad")) << summary.BriefReport();
    headings.push_back(summary.numbers.at("ff1.estimated_heading_rad"));
    runs.push_back(sink.TakeSortedByTime());
    const Metrics m = Evaluate(sim.data.info, sim.data.truth, runs.back());
    EXPECT_LE(m.agents.stats.median_m, 0.6) << deg;
    EXPECT_LE(m.agents.stats.p75_m, 0.9) << deg;
    EXPECT_GE(m.agents.at_estimates.in95, 0.85) << deg;
  }
  EXPECT_NEAR(WrapAngle(headings[0] - headings[1]), std::numbers::pi / 2, 1e-6);
  // No estimate within the fallback distance (1 m here): the PDR's frame is taken after all,
  // and the summary says so.
  {
    testing::TempDir dir;
    WriteMissionDirectory(dir.path(), RotatedPdrWithoutHeading(sim, 0.0), &sim.plan);
    const MissionDirectory mission(dir.path());
    const Outcome assumed = RunOn(RequirePipeline("beacons-ekf"), mission, sim.data,
                                  {{"entry_heading_fallback_m", "1"}});
    const Outcome pdr = RunOn(RequirePipeline("pdr"), mission, sim.data);
    EXPECT_TRUE(std::any_of(assumed.summary.notes.begin(), assumed.summary.notes.end(),
                            [](const std::string& n) {
                              return n.find("taken as the navigation frame") != std::string::npos;
                            }));
    EXPECT_LT(assumed.metrics.agents.stats.p75_m, pdr.metrics.agents.stats.p75_m);
  }
  ASSERT_EQ(runs[0].size(), runs[1].size());
  for (std::size_t k = 0; k < runs[0].size(); ++k) {
    ASSERT_EQ(runs[0][k].id, runs[1][k].id);
    EXPECT_LT((runs[0][k].position_n - runs[1][k].position_n).norm(), 1e-6) << runs[0][k].id;
  }
}

TEST(BeaconsPipeline, BadInputIsReportedClearly) {
  const SimulatedMission sim = SimulateBeaconLab({}, 1);
  testing::TempDir dir;
  MissionData data = sim.data;
  data.bearings.resize(50);
  WriteMissionDirectory(dir.path(), data, &sim.plan);
  const MissionDirectory mission(dir.path());
  VectorSink sink;
  EXPECT_THROW(RunNamed("beacons-ekf", mission, {{"filter", "kalman"}}, sink),
               std::invalid_argument);
  EXPECT_THROW(RunNamed("beacons-ekf", mission, {{"update", "polar"}}, sink),
               std::invalid_argument);
  EXPECT_THROW(RunNamed("beacons-ekf", mission, {{"no_such_option", "1"}}, sink),
               std::invalid_argument);
  // A NaN bearing is named with its file and line.
  {
    std::ofstream f(dir.path() / "bearings.csv", std::ios::app);
    f << "1000,b01,ff1,nan,0.5\n";
  }
  try {
    RunNamed("beacons-ekf", mission, {}, sink);
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("bearings.csv:52"), std::string::npos) << e.what();
  }
  // Without ranges.csv the pipeline cannot run, and says why.
  std::filesystem::remove(dir.path() / "ranges.csv");
  const MissionDirectory no_ranges(dir.path());
  EXPECT_FALSE(CanRunNamed("beacons-ekf", no_ranges));
  try {
    RunNamed("beacons-mds", no_ranges, {}, sink);
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("ranges.csv"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace trailmark

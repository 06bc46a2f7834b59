// SPDX-License-Identifier: MIT
// The breadcrumb localizer: exact on a PDR-only chain, end to end on the simulated office loop
// (the targets), two firefighters sharing a network, kicked crumbs, and never a NaN or
// a non-PSD covariance under fuzzed measurement streams.
#include "trailmark/breadcrumb/localizer.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <cstdio>
#include <map>

#include "pipelines/run_named.h"
#include "test_util.h"
#include "trailmark/core/random.h"
#include "trailmark/eval/metrics.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/sim/multi_floor.h"
#include "trailmark/sim/scenarios.h"
#include "trailmark/sim/variation.h"

namespace trailmark::breadcrumb {
namespace {

using testing::RunNamed;

using testing::TempDir;

// A fixed pseudo-random number in [-0.5, 0.5) (a linear congruential generator: the walks'
// noise, the same on every platform).
double NextUniform(std::uint32_t* state) {
  *state = *state * 1664525u + 1013904223u;
  return *state / 4294967296.0 - 0.5;
}

void ExpectValidCovariance(const Mat2& c) {
  ASSERT_TRUE(c.allFinite());
  ASSERT_NEAR(c(0, 1), c(1, 0), 1e-9 * (1 + c.norm()));
  ASSERT_GT(c(0, 0), 0);
  ASSERT_GT(c.determinant(), 0);
}

// With no radio and no heading/scale node, the GEN chain of mobile states is dead reckoning:
// the estimate is the sum of the steps and the covariance the sum of their variances.
// With the steps' own heading offset (a consider parameter, track_heading_offset_sigma_rad), the
// covariance adds sigma^2 s s^T with s the walk turned by 90 degrees (each step turns with it).
TEST(BreadcrumbLocalizer, PdrOnlyChainEqualsDeadReckoning) {
  LocalizerOptions o;
  o.estimate_heading_scale = false;
  o.step_sigma_floor_m = 0;
  o.step_sigma_floor_relative = 0;
  o.state_period_s = 0;  // a new state for every step
  o.gen.regularization_sigma_m = 1e9;
  LocalizerOptions with_offset = o;
  ASSERT_GT(with_offset.track_heading_offset_sigma_rad, 0.0);
  o.track_heading_offset_sigma_rad = 0;
  BreadcrumbLocalizer loc(o), turned(with_offset);
  loc.AddAgent("ff1", Vec2(1, 2), 0.1);
  turned.AddAgent("ff1", Vec2(1, 2), 0.1);
  Random rng(1);
  Vec2 sum(1, 2);
  Vec2 var(0.01, 0.01);
  for (int k = 0; k < 200; ++k) {
    Step s{k * 0.6, (k + 1) * 0.6, "ff1", Vec3(rng.Normal(0.5, 0.2), rng.Normal(0, 0.3), 0),
           Vec3(0.01 + 0.001 * k, 0.02, 1e-4)};
    loc.AddStep(s);
    turned.AddStep(s);
    // Radio-free steps create no state; an encounter-free range-free run still must agree.
    sum += s.delta_n.head<2>();
    var += s.variance_m2->head<2>();
    const auto e = loc.Estimate("ff1");
    ASSERT_TRUE(e);
    EXPECT_LT((e->position_n - sum).norm(), 1e-9);
    EXPECT_NEAR(e->covariance(0, 0), var.x(), 1e-9);
    EXPECT_NEAR(e->covariance(1, 1), var.y(), 1e-9);
    EXPECT_NEAR(e->covariance(0, 1), 0.0, 1e-12);
    const auto et = turned.Estimate("ff1");
    ASSERT_TRUE(et);
    EXPECT_EQ(et->position_n, e->position_n);
    const Vec2 walk = sum - Vec2(1, 2), sens(-walk.y(), walk.x());
    const double sigma = with_offset.track_heading_offset_sigma_rad;
    const Mat2 share = sigma * sigma * sens * sens.transpose();
    EXPECT_LT((et->covariance - e->covariance - share).norm(), 1e-9 * (1 + share.norm()));
  }
  EXPECT_EQ(loc.summary().steps, 200u);
}

// IV-F: a displacement no firefighter can make is dropped.
TEST(BreadcrumbLocalizer, RejectsStepsBeyondTheSpeedLimit) {
  BreadcrumbLocalizer loc;
  loc.AddAgent("ff1", Vec2::Zero(), 0.1);
  loc.AddStep({0.0, 0.6, "ff1", Vec3(0.7, 0, 0), std::nullopt});
  loc.AddStep({0.6, 1.2, "ff1", Vec3(40.0, 0, 0), std::nullopt});  // 67 m/s
  loc.AddStep({1.2, 1.8, "ff1", Vec3(0.7, 0, 0), std::nullopt});
  EXPECT_EQ(loc.summary().steps_rejected, 1u);
  EXPECT_NEAR(loc.Estimate("ff1")->position_n.x(), 1.4, 1e-6);
  EXPECT_THROW(loc.AddStep({2, 3, "nobody", Vec3::Zero(), std::nullopt}), std::invalid_argument);
}

Metrics RunOnSim(const PipelineSpec& p, const SimulatedMission& sim, const TempDir& dir,
                    std::vector<Estimate>* rows = nullptr,
                    std::map<std::string, std::string> options = {}) {
  struct Sink : EstimateSink {
    void Add(const Estimate& e) override { rows.push_back(e); }
    std::vector<Estimate> rows;
  } sink;
  const MissionDirectory mission(dir.path());
  RunBatch(p, {mission, options}, sink);
  if (rows) *rows = sink.rows;
  return Evaluate(sim.data.info, sim.data.truth, sink.rows);
}

// Many firefighters (issue 27's load): the network is re-solved and its marginals refreshed at
// most every solve_period_s / covariance_period_s of mission time (0.25 s by default) instead of
// at every agent's estimate; between solves an estimate is the last solution plus the PDR since.
// Far fewer factorizations, about the same errors (the scenario's tables: docs/breadcrumb.md).
TEST(BreadcrumbPipeline, ThrottledSolvesCostLessAndStayCloseToTheExactOnes) {
  MultiFloorOptions o;
  o.foot_imu = false;
  o.firefighters = 6;
  o.duration_s = 300.0;
  const SimulatedMission sim = SimulateMultiFloor(o, 2);
  TempDir dir;
  WriteMissionDirectory(dir.path(), sim.data, sim.levels);
  struct Sink : EstimateSink {
    void Add(const Estimate& e) override { rows.push_back(e); }
    std::vector<Estimate> rows;
  };
  const MissionDirectory mission(dir.path());
  Sink throttled, exact;
  const EstimatorSummary st = RunBatch(RequirePipeline("breadcrumb"), {mission, {}}, throttled);
  const EstimatorSummary se =
      RunBatch(RequirePipeline("breadcrumb"),
               {mission, {{"solve_period_s", "0"}, {"covariance_period_s", "0"}}}, exact);
  const double f_throttled = st.numbers.at("factorizations");
  const double f_exact = se.numbers.at("factorizations");
  // A solve factorizes once per Gauss-Newton pass over the persistent links (at most 3).
  EXPECT_LE(f_throttled, 3 * (o.duration_s / 0.25 + 20)) << f_exact;
  EXPECT_LT(f_throttled, 0.6 * f_exact);
  const Metrics mt = Evaluate(sim.data.info, sim.data.truth, throttled.rows);
  const Metrics me = Evaluate(sim.data.info, sim.data.truth, exact.rows);
  EXPECT_LT(mt.agents.stats.mean_m, 1.1 * me.agents.stats.mean_m + 0.05);
  EXPECT_LT(mt.agents.stats.p95_m, 1.1 * me.agents.stats.p95_m + 0.1);
  // Honest: the ellipses cover as often (the cached covariance grows with the PDR since).
  EXPECT_GE(mt.agents.stats.in95, me.agents.stats.in95 - 0.02);
}

// The targets on the breadcrumb paper's 400 m office experiment (sec. V-A), one seed
// (the 8-seed table is `trailmark reproduce breadcrumb`).
TEST(BreadcrumbPipeline, OfficeLoopMeetsTheTargets) {
  const SimulatedMission sim = SimulateScenario("office-loop", 3);
  TempDir dir;
  WriteMissionDirectory(dir.path(), sim.data, &sim.plan);
  std::vector<Estimate> rows;
  const Metrics gen = RunOnSim(RequirePipeline("breadcrumb"), sim, dir, &rows);
  const Metrics pdr = RunOnSim(RequirePipeline("pdr"), sim, dir);
  const double dist = gen.agents.distance_m;
  ASSERT_GT(dist, 390);
  EXPECT_LT(gen.agents.stats.mean_m, 0.01 * dist);  // mean <= 1 % of distance
  EXPECT_LT(gen.agents.stats.max_m, 0.02 * dist);   // max <= 2 %
  EXPECT_LT(gen.agents.stats.final_m * 5, pdr.agents.stats.final_m);  // >= 5x lower end error
  EXPECT_EQ(gen.agents.uncovered, 0u);
  for (const auto& e : rows) {
    ASSERT_TRUE(e.position_n.allFinite());
    Mat2 c;
    c << e.sxx, e.sxy, e.sxy, e.syy;
    ExpectValidCovariance(c);
  }
  // Every dropped crumb is estimated, within a few metres.
  for (const auto& n : gen.nodes) {
    if (n.kind == NodeKind::kCrumb) {
      EXPECT_GT(n.stats.samples, 0u) << n.id;
      EXPECT_LT(n.stats.final_m, 5.0) << n.id;
    }
  }
}

// Sec. V-B: two firefighters share one breadcrumb network in a training building with a fire.
// Over ten seeds (2026-12-01): breadcrumb 3.85 m mean agent error against PDR's 5.17 m, better
// on 9 of 10; seed 1 is the exception (7.07 vs 6.38 m) since simultaneous packets go in by node
// (the live server's order): with the simulator's file order it was 3.83 m — a tie order
// swinging the result by 3 m is the estimator's fragility that docs/breadcrumb.md records.
TEST(BreadcrumbPipeline, TwoFirefightersShareTheNetwork) {
  double sum_gen = 0, sum_pdr = 0;
  int better = 0;
  for (std::uint64_t seed = 1; seed <= 10; ++seed) {
    const SimulatedMission s = SimulateScenario("training-building", seed);
    TempDir d;
    WriteMissionDirectory(d.path(), s.data, &s.plan);
    const Metrics g = RunOnSim(RequirePipeline("breadcrumb"), s, d);
    const Metrics p = RunOnSim(RequirePipeline("pdr"), s, d);
    sum_gen += g.agents.stats.mean_m;
    sum_pdr += p.agents.stats.mean_m;
    better += g.agents.stats.mean_m < p.agents.stats.mean_m;
    for (const auto& n : g.nodes) {
      if (n.kind == NodeKind::kAgent) EXPECT_EQ(n.uncovered, 0u) << n.id << " seed " << seed;
    }
  }
  EXPECT_LT(sum_gen, 0.8 * sum_pdr);
  EXPECT_GE(better, 9);
  const SimulatedMission sim = SimulateScenario("training-building", 1);
  TempDir dir;
  WriteMissionDirectory(dir.path(), sim.data, &sim.plan);
  std::vector<Estimate> rows;
  const Metrics gen = RunOnSim(RequirePipeline("breadcrumb"), sim, dir, &rows);
  // Crumbs dropped by either firefighter are estimated.
  std::size_t crumbs = 0;
  for (const auto& n : gen.nodes) crumbs += n.kind == NodeKind::kCrumb && n.stats.samples > 0;
  EXPECT_GE(crumbs, 4u);
  // Spec: static nodes get a final row at the end of the mission, agents their last estimate.
  ASSERT_FALSE(rows.empty());
  const double t_end = rows.back().t;
  std::map<std::string, double> last;
  for (const auto& e : rows) last[e.id] = std::max(last[e.id], e.t);
  for (const auto& [id, t] : last) {
    if (id.rfind("c", 0) == 0 || id == "base") EXPECT_EQ(t, t_end) << id;
  }
}

// The steps' own heading offset (track_heading_offset_sigma_rad, 5 deg) is a consider
// parameter per agent: the estimates are the ones without it, to the bit (agents and crumbs,
// one walker and two sharing the network), only the reported covariances grow (by a positive
// semi-definite share). On office loops whose steps are all turned by 6 deg (a boot's toe-out;
// the `pdr` robustness family turns them by 2-10 deg) the agent's ellipse holds the truth with
// it and does not without it (2026-12-06, docs/breadcrumb.md).
TEST(BreadcrumbPipeline, TheStepsHeadingOffsetWidensTheEllipsesOnly) {
  const auto compare = [](const SimulatedMission& sim, const TempDir& dir, double* in95_with,
                          double* in95_without) {
    const MissionDirectory mission(dir.path());
    // The dead-reckoning guard's growth depends on the covariance it is given (a wider one
    // needs less): the share is checked with the guard only reporting, the estimates both ways.
    for (const bool guard : {false, true}) {
      std::map<std::string, std::string> options;
      if (!guard) options["integrity.on_disagreement"] = "report";
      auto without_options = options;
      without_options["track_heading_offset_sigma_rad"] = "0";
      VectorSink with, without;
      RunBatch(RequirePipeline("breadcrumb"), {mission, options}, with);
      RunBatch(RequirePipeline("breadcrumb"), {mission, without_options}, without);
      const double grew =
          testing::ExpectSameEstimatesWiderCovariances(with.rows, without.rows, !guard);
      if (!guard) {
        EXPECT_GT(grew, 0.05);
        continue;
      }
      *in95_with = Evaluate(sim.data.info, sim.data.truth, with.rows).agents.stats.in95;
      *in95_without = Evaluate(sim.data.info, sim.data.truth, without.rows).agents.stats.in95;
    }
  };
  double with = 0, without = 0;
  const int seeds = 3;
  for (std::uint64_t seed = 1; seed <= seeds; ++seed) {
    SimulatedMission sim = SimulateScenario("office-loop", seed);
    testing::TurnSteps(sim.data.steps, 6.0);
    TempDir dir;
    WriteMissionDirectory(dir.path(), sim.data, &sim.plan);
    double w = 0, wo = 0;
    compare(sim, dir, &w, &wo);
    with += w / seeds;
    without += wo / seeds;
  }
  EXPECT_GT(with, 0.9);  // 2026-12-06: 98 % against 69 %
  EXPECT_LT(without, 0.8);
  // Two firefighters (agent-to-agent packets move with both offsets).
  const SimulatedMission two = SimulateScenario("training-building", 1);
  TempDir dir;
  WriteMissionDirectory(dir.path(), two.data, &two.plan);
  double w = 0, wo = 0;
  compare(two, dir, &w, &wo);
  EXPECT_GE(w, wo);
}

// Sec. V-C: a kicked crumb is detected from the jump on its links and allowed to move; no
// detection without a kick (seeds checked: office-loop-kicked 4 and 8, office-loop 2).
TEST(BreadcrumbPipeline, KickedCrumbIsDetected) {
  for (std::uint64_t seed : {4u, 8u}) {
    const SimulatedMission sim = SimulateScenario("office-loop-kicked", seed);
    std::map<std::string, double> kicked;  // second truth row of a crumb = its kick
    std::map<std::string, int> seen;
    for (const auto& t : sim.data.truth) {
      if (t.id.rfind("c", 0) == 0 && seen[t.id]++ == 1) kicked[t.id] = t.t;
    }
    ASSERT_FALSE(kicked.empty());
    TempDir dir;
    WriteMissionDirectory(dir.path(), sim.data, &sim.plan);
    const MissionDirectory mission(dir.path());
    struct Null : EstimateSink {
      void Add(const Estimate&) override {}
    } sink;
    const EstimatorSummary s = RunNamed("breadcrumb", mission, {}, sink);
    ASSERT_GE(s.numbers.at("moved_detected"), 1.0) << "seed " << seed;
    for (const auto& note : s.notes) {
      if (note.find("detected as moved") == std::string::npos) continue;
      const double t = std::stod(note.substr(2));
      const auto q1 = note.find('\''), q2 = note.find('\'', q1 + 1);
      const std::string id = note.substr(q1 + 1, q2 - q1 - 1);
      ASSERT_TRUE(kicked.count(id)) << note;
      EXPECT_GE(t, kicked[id]) << note;
      EXPECT_LE(t, kicked[id] + 40.0) << note;
    }
  }
  const SimulatedMission calm = SimulateScenario("office-loop", 2);
  TempDir dir;
  WriteMissionDirectory(dir.path(), calm.data, &calm.plan);
  const MissionDirectory mission(dir.path());
  struct Null : EstimateSink {
    void Add(const Estimate&) override {}
  } sink;
  const EstimatorSummary summary = RunNamed("breadcrumb", mission, {}, sink);
  EXPECT_EQ(summary.numbers.at("moved_detected"), 0.0);
  // Each crumb's RSSI offset is reported (rssi_offsets=innovations by default), within its
  // prior's reach; none with rssi_offsets=off.
  int offsets = 0;
  for (const auto& [key, value] : summary.numbers) {
    if (key.ends_with(".rssi_offset_db")) {
      ++offsets;
      EXPECT_TRUE(std::isfinite(value)) << key;
      EXPECT_LT(std::abs(value), 12.0) << key;
    }
  }
  EXPECT_GE(offsets, 4);
  for (const auto& [key, value] :
       RunNamed("breadcrumb", mission, {{"rssi_offsets", "off"}}, sink).numbers)
    EXPECT_FALSE(key.ends_with(".rssi_offset_db")) << key;
}

// Fuzzed streams: random steps (some impossible), RSSI anywhere from -100 to -10 dBm between any
// nodes, ranges with gross outliers, drops, unknown landmarks. Estimates stay finite and every
// covariance symmetric positive definite.
TEST(BreadcrumbLocalizer, FuzzedStreamsNeverGiveNaNOrNonPsdCovariance) {
  for (std::uint64_t seed = 1; seed <= 12; ++seed) {
    Random rng(seed);
    BreadcrumbLocalizer loc;
    loc.AddKnownNode("base", Vec2::Zero(), 0.0);
    loc.AddUnknownNode("lm1");
    loc.AddAgent("a", Vec2::Zero(), 0.1);
    loc.AddAgent("b", std::nullopt, 0.0);
    std::vector<std::string> nodes{"base", "lm1", "a", "b"};
    double t = 0;
    int crumbs = 0;
    for (int k = 0; k < 1500; ++k) {
      t += rng.Uniform(0, 0.3);
      const double u = rng.Uniform(0, 1);
      const std::string agent = rng.Uniform(0, 1) < 0.5 ? "a" : "b";
      if (u < 0.4) {
        const double scale = rng.Uniform(0, 1) < 0.02 ? 100.0 : 0.8;
        loc.AddStep({t - 0.5, t, agent, Vec3(rng.Normal(0, scale), rng.Normal(0, scale), 0),
                     rng.Uniform(0, 1) < 0.5 ? std::optional<Vec3>() : Vec3(1e-4, 1e-2, 1e-4)});
      } else if (u < 0.75) {
        const auto& rx = nodes[static_cast<std::size_t>(rng.Uniform(0, nodes.size() - 1e-9))];
        const auto& tx = nodes[static_cast<std::size_t>(rng.Uniform(0, nodes.size() - 1e-9))];
        if (rx != tx) loc.AddRssi({t, rx, tx, rng.Uniform(-100, -10)});
      } else if (u < 0.9) {
        const auto& other = nodes[static_cast<std::size_t>(rng.Uniform(0, nodes.size() - 1e-9))];
        const double range = rng.Uniform(0, 1) < 0.1 ? rng.Uniform(0, 1e4) : rng.Uniform(0, 30);
        if (other != agent) {
          loc.AddRange({t, agent, other, range,
                        rng.Uniform(0, 1) < 0.5 ? std::optional<double>() : 0.3, "uwb"});
        }
      } else if (u < 0.95 && crumbs < 30) {
        const std::string id = "c" + std::to_string(++crumbs);
        loc.AddEvent({t, agent, "drop", id});
        nodes.push_back(id);
      } else {
        loc.AdvanceTo(t);
      }
      if (k % 50 == 0) {
        for (const auto& id : nodes) {
          if (auto e = loc.Estimate(id)) {
            ASSERT_TRUE(e->position_n.allFinite()) << id << " seed " << seed;
            ExpectValidCovariance(e->covariance);
          }
        }
      }
    }
    loc.Finish();
    for (const auto& id : nodes) {
      if (auto e = loc.Estimate(id)) {
        ASSERT_TRUE(e->position_n.allFinite());
        ExpectValidCovariance(e->covariance);
      }
    }
  }
}

// Issue 25, item 3: packets >= min_rssi_dbm only are a truncated sample. The truncated model
// predicts the mean of the kept packets; its slope is the derivative of its prediction, and
// without a truncation it is the plain log-distance model.
TEST(ScalarModel, TheTruncatedRssiModelsSlopeIsTheDerivativeOfItsPrediction) {
  ScalarModel plain;
  plain.kind = ScalarModel::Kind::kRssiDb;
  plain.alpha_dbm = -40.0;
  plain.path_loss_exponent = 2.5;
  ScalarModel truncated = plain;
  truncated.truncation_dbm = -65.0;
  truncated.sigma_db = 5.0;
  for (const double d : {0.5, 2.0, 8.0, 10.0, 15.0, 40.0}) {
    const double h = 1e-5 * d;
    EXPECT_NEAR(truncated.Slope(d), (truncated.Predict(d + h) - truncated.Predict(d - h)) / (2 * h),
                1e-6);
    EXPECT_GE(truncated.Predict(d), -65.0);
    EXPECT_GE(truncated.Predict(d), plain.Predict(d));  // the weak packets are missing
    const ScalarModel::Linear lin = truncated.Linearize(d);
    EXPECT_EQ(lin.predicted, truncated.Predict(d));
    EXPECT_EQ(lin.slope, truncated.Slope(d));
  }
  ScalarModel sigma_only = plain;
  sigma_only.sigma_db = 5.0;  // no truncation: the plain model exactly
  EXPECT_EQ(sigma_only.Predict(12.0), plain.Predict(12.0));
  EXPECT_EQ(sigma_only.Slope(12.0), plain.Slope(12.0));
}

// The calibrated exponent with truncated_rssi depends less on where min_rssi_dbm cuts than the
// least-squares fit of the kept packets (measured over 24 seeds: 1.77 at -65 dBm and 2.27 at
// -75 for least squares, 2.55 and 2.62 for the truncated fit; docs/breadcrumb.md).
TEST(BreadcrumbPipeline, TheTruncatedCalibrationDependsLessOnTheRssiFloor) {
  double moved_ls = 0, moved_truncated = 0;
  for (const int seed : {11, 12, 13, 14}) {
    const SimulatedMission sim = SimulateScenario("office-loop", seed);
    TempDir dir;
    WriteMissionDirectory(dir.path(), sim.data, &sim.plan);
    const MissionDirectory mission(dir.path());
    struct Null : EstimateSink {
      void Add(const Estimate& e) override { ASSERT_TRUE(e.position_n.allFinite()); }
    } sink;
    auto exponent = [&](const char* truncated, const char* floor) {
      const auto s = RunNamed("breadcrumb", mission,
                              {{"truncated_rssi", truncated}, {"min_rssi_dbm", floor}}, sink);
      return s.numbers.at("calibrated_path_loss_exponent");
    };
    moved_ls += std::abs(exponent("0", "-65") - exponent("0", "-75"));
    moved_truncated += std::abs(exponent("1", "-65") - exponent("1", "-75"));
  }
  EXPECT_LT(moved_truncated, 0.5 * moved_ls) << moved_truncated << " vs " << moved_ls;
}

// start_heading_sigma_floor raises a stated start-heading sigma: after a 20 m straight walk
// the sideways variance holds the heading's (sigma x 20 m)^2 on top of the steps' own (40
// steps, each at most (0.03 + 0.15 x 0.5 m)^2 per axis, plus the heading random walk) — with
// an agent state at every step end (a range of 1 km sigma to a far anchor: no information) and
// with none after the start (no radio at all: the walk since the state turns with the heading).
/// An agent state of ff1 at `t` without information: a range of `sigma_m` to the anchor "far"
/// 5 km away (AddKnownNode("far", (10, 5000))).
void AddUninformativeRange(BreadcrumbLocalizer& loc, TimeS t, double sigma_m = 1000) {
  RangeMeasurement r;
  r.t = t;
  r.a = "ff1";
  r.b = "far";
  r.range_m = 5000;
  r.sigma_m = sigma_m;
  loc.AddRange(r);
}

TEST(BreadcrumbLocalizer, AStartHeadingSigmaBelowTheFloorIsRaisedToIt) {
  auto sideways_variance = [](double floor_rad, bool states) {
    LocalizerOptions o;
    o.start_heading_sigma_floor_rad = floor_rad;
    o.estimate_range_bias = false;
    o.track_heading_offset_sigma_rad = 0;  // the heading node's prior alone
    BreadcrumbLocalizer loc(o);
    loc.AddKnownNode("far", Vec2(10, 5000), 1e-3);
    loc.AddAgent("ff1", Vec2::Zero(), 0.01, 0.01);  // mission.json: 0.01 rad
    for (int k = 0; k < 40; ++k) {
      const TimeS t1 = 0.5 * k + 0.5;
      loc.AddStep({t1 - 0.5, t1, "ff1", Vec3(0.5, 0, 0), std::nullopt});
      if (states) AddUninformativeRange(loc, t1);
    }
    loc.Finish();
    return loc.Estimate("ff1")->covariance(1, 1);
  };
  const double steps_at_most = 40 * std::pow(0.03 + 0.15 * 0.5, 2) + 0.5;
  for (const bool states : {true, false}) {
    const double stated = sideways_variance(0.0, states),
                 floored = sideways_variance(0.087, states);
    EXPECT_GT(stated, std::pow(0.01 * 20, 2)) << states;
    EXPECT_LT(stated, std::pow(0.01 * 20, 2) + steps_at_most) << states;
    EXPECT_GT(floored, std::pow(0.087 * 20, 2)) << states;
    EXPECT_LT(floored, std::pow(0.087 * 20, 2) + steps_at_most) << states;
  }
}

TEST(BreadcrumbLocalizer, AFootInsAgentMovesWithTheInsOwnErrors) {
  // 40 steps of 0.5 m along x from a known start, states kept by a far, uninformative range.
  // Along the walk the error is the start's, the steps' noise (the floor: the INS's own variance
  // is below it) and the scale error times the 20 m walked — linear, so its variance is their
  // sum: with the foot INS's errors 1 % of scale (the PDR's prior tightened by a second one) and
  // its step floor; with the PDR's, 5 % and its floor. Across, each step's own yaw variance
  // (heading_var_rad2) is the heading's walk: larger ones widen it.
  auto walk = [](bool foot_ins, bool own_errors, double heading_var) {
    LocalizerOptions o;
    o.estimate_range_bias = false;
    o.track_heading_offset_sigma_rad = 0;
    o.foot_ins.own_errors = own_errors;
    BreadcrumbLocalizer loc(o);
    loc.AddKnownNode("far", Vec2(10, 5000), 1e-3);
    loc.AddAgent("ff1", Vec2::Zero(), 0.01, 0.01);
    if (foot_ins) loc.UseFootInsMotion("ff1");
    for (int k = 0; k < 40; ++k) {
      const TimeS t1 = 0.5 * k + 0.5;
      Step s{t1 - 0.5, t1, "ff1", Vec3(0.5, 0, 0), Vec3(1e-6, 1e-6, 1e-6), heading_var};
      loc.AddStep(s);
      AddUninformativeRange(loc, t1);
    }
    loc.Finish();
    return Mat2(loc.Estimate("ff1")->covariance);
  };
  const LocalizerOptions o;
  const double foot_floor =
      o.foot_ins.step_sigma_floor_m + o.foot_ins.step_sigma_floor_relative * 0.5;
  const double pdr_floor = o.step_sigma_floor_m + o.step_sigma_floor_relative * 0.5;
  const double foot_along =
      1e-4 + 40 * foot_floor * foot_floor + std::pow(o.foot_ins.scale_sigma0 * 20, 2);
  const double pdr_along = 1e-4 + 40 * pdr_floor * pdr_floor + std::pow(o.scale_sigma0 * 20, 2);
  const Mat2 foot = walk(true, true, 1e-6), pdr = walk(false, true, 1e-6);
  EXPECT_NEAR(foot(0, 0), foot_along, 0.02 * foot_along);
  EXPECT_NEAR(pdr(0, 0), pdr_along, 0.02 * pdr_along);
  EXPECT_LT(foot(1, 1), 0.5 * pdr(1, 1));
  // Off: the foot INS's steps with the PDR's errors, to the digit.
  const Mat2 off = walk(true, false, 1e-6);
  EXPECT_EQ(off, pdr);
  // The INS's own heading walk: a larger yaw variance per step widens the walk across.
  EXPECT_GT(walk(true, true, 1e-4)(1, 1), 1.5 * foot(1, 1));
}

// Crumbs heard but never dropped (events.csv absent) are placed from their packets once those
// pin them down; each packet counts with the edges' per-packet sigma (a link's packets are
// correlated) rather than the channel's whole sigma_db, which made the placed crumbs claim far
// more than they had and pulled the agent with them. The agent stays well within its dead
// reckoning's error and its ellipse holds the truth (seeds 41-43, not used for any setting).
TEST(BreadcrumbPipeline, CrumbsHeardWithoutADropKeepTheAgentHonest) {
  double in95 = 0, samples = 0, agent_m = 0, pdr_m = 0;
  for (const std::uint64_t seed : {41u, 42u, 43u}) {
    SimulatedMission sim = SimulateScenario("office-loop", seed);
    Variation v;
    v.events = EventsKept::kNone;  // the crumbs declared in mission.json, never dropped
    ApplyVariation(v, sim);
    ASSERT_TRUE(sim.data.events.empty());
    TempDir dir;
    WriteMissionDirectory(dir.path(), sim.data, &sim.plan);
    const Metrics m = RunOnSim(RequirePipeline("breadcrumb"), sim, dir);
    in95 += m.agents.at_estimates.in95 * static_cast<double>(m.agents.at_estimates.samples);
    samples += static_cast<double>(m.agents.at_estimates.samples);
    agent_m += m.agents.stats.mean_m;
    pdr_m += RunOnSim(RequirePipeline("pdr"), sim, dir).agents.stats.mean_m;
  }
  ASSERT_GT(samples, 0.0);
  EXPECT_GE(in95 / samples, 0.85);
  EXPECT_LT(agent_m, 0.5 * pdr_m);
}

// A poor BLE channel (6 dB shadowing and 3 dB more spatially correlated over 5 m, every node
// offset by up to 6 dB, no radio model stated): a walker's approach to a crumb and its departure
// from one just dropped have RSSI peaks above the encounter threshold metres away, and a node
// far hotter than the others passes it 10-20 m out before any offset is known. The strongest
// peak within +-3 s of a link, no encounter of a dropper with the crumb it is leaving, a node's
// estimated offset taken off its packets, encounters down-weighted beyond Huber's constant,
// against the encounters before (the first local maximum of +-1.5 s, own crumbs included, each
// at 1 m whatever its innovation). Every arm without the step front end's view between rows
// (view_period_s=0): the encounters are measured, not the view (with it, on both sides, 2 of
// the 6 seeds end worse than dead reckoning: 53 by 2.23 against 2.10 m).
TEST(BreadcrumbPipeline, EncountersUnderAPoorChannelAreTheClosestApproach) {
  struct Arm {
    double in95 = 0, samples = 0, encounters = 0, own = 0;
    std::vector<double> mean_m;
  };
  Arm now, before;
  std::vector<double> pdr_m;
  for (const std::uint64_t seed : {51u, 52u, 53u, 54u, 55u, 56u}) {
    SimulatedMission sim = SimulateScenario("office-loop", seed);
    Variation v;
    v.radio = true;
    v.band = RadioBand::kBle2G4;
    v.alpha_dbm = -60.0;
    v.path_loss_exponent = 2.2;
    v.shadowing_sigma_db = 6.0;
    v.correlated_shadowing_db = 3.0;
    v.shadowing_length_m = 5.0;
    v.node_offset_max_db = 6.0;
    v.stated_radio = StatedRadio::kAbsent;
    ApplyVariation(v, sim);
    TempDir dir;
    WriteMissionDirectory(dir.path(), sim.data, &sim.plan);
    const MissionDirectory mission(dir.path());
    auto run = [&](const std::map<std::string, std::string>& options, Arm* arm) {
      struct Rows : EstimateSink {
        void Add(const Estimate& e) override { rows.push_back(e); }
        std::vector<Estimate> rows;
      } sink;
      const EstimatorSummary summary = RunNamed("breadcrumb", mission, options, sink);
      const Metrics m = Evaluate(sim.data.info, sim.data.truth, sink.rows);
      arm->mean_m.push_back(m.agents.stats.mean_m);
      arm->in95 += m.agents.at_estimates.in95 * static_cast<double>(m.agents.at_estimates.samples);
      arm->samples += static_cast<double>(m.agents.at_estimates.samples);
      arm->encounters += summary.numbers.at("encounters");
      arm->own += summary.numbers.at("encounters_after_own_drop");
    };
    run({{"view_period_s", "0"}}, &now);
    run({{"encounter_window_s", "1.5"},
         {"own_drop_encounter_after_s", "0"},
         {"robust_encounters", "0"},
         {"view_period_s", "0"}},
        &before);
    pdr_m.push_back(RunOnSim(RequirePipeline("pdr"), sim, dir, nullptr, {{"view_period_s", "0"}})
                        .agents.stats.mean_m);
  }
  ASSERT_GT(now.samples, 0.0);
  ASSERT_GT(before.samples, 0.0);
  int better = 0, now_worse_than_dr = 0, before_worse_than_dr = 0;
  for (std::size_t k = 0; k < pdr_m.size(); ++k) {
    better += now.mean_m[k] < before.mean_m[k];
    now_worse_than_dr += now.mean_m[k] > pdr_m[k];
    before_worse_than_dr += before.mean_m[k] > pdr_m[k];
    std::printf(
        "poor channel, seed %zu: agents %.2f m against %.2f m before, dead reckoning %.2f m\n",
        51 + k, now.mean_m[k], before.mean_m[k], pdr_m[k]);
  }
  EXPECT_GT(now.own, 0.0);  // the departures' peaks were there, and refused
  EXPECT_EQ(before.own, 0.0);
  EXPECT_LT(now.encounters, before.encounters);
  EXPECT_GE(better, 5);
  EXPECT_LE(now_worse_than_dr, 1);
  EXPECT_LT(now_worse_than_dr, before_worse_than_dr);
  EXPECT_GE(now.in95 / now.samples, before.in95 / before.samples + 0.10);
  std::printf(
      "poor channel, 6 seeds: in95 %.0f %% against %.0f %%, %g encounters (%g refused as "
      "departures) against %g; worse than dead reckoning on %d against %d\n",
      100 * now.in95 / now.samples, 100 * before.in95 / before.samples, now.encounters, now.own,
      before.encounters, now_worse_than_dr, before_worse_than_dr);
}

// own_drop_encounter_after_s: a walker drops c1 at x = 10 m and walks on east at 1 m/s; c1's
// packets follow the model but one, 3 m past it, reads 25 dB hot (a shadowing peak): the
// strongest of its link within +-3 s, so a peak, 3 s after the drop. It drops c2 at x = 30 m
// and stands on it for 5 s (a peak at the crumb). Within 10 s of their drops neither is an
// encounter (the drop already says where the crumb is); with 0, both are.
TEST(BreadcrumbLocalizer, ADroppersPeakSoonAfterTheDropIsNotAnEncounter) {
  auto walk = [](double after_s) {
    LocalizerOptions o;
    o.radio_given = true;  // alpha -40 dBm, n 2.3
    o.calibrate_online = false;
    o.own_drop_encounter_after_s = after_s;
    BreadcrumbLocalizer loc(o);
    loc.AddAgent("ff1", Vec2::Zero(), 0.05, 0.02);
    double x = 0;
    TimeS t = 0;
    auto packets = [&](const std::string& crumb, double at_x, double hot_x) {
      const double d = std::max(std::abs(x - at_x), 0.5);
      const double hot = std::abs(x - hot_x) < 0.25 ? 25.0 : 0.0;
      loc.AddRssi({t, "ff1", crumb, -40.0 - 23.0 * std::log10(d) + hot});
    };
    for (int k = 0; k < 100; ++k) {  // 50 s: steps of 0.5 m every 0.5 s, standing 30.5-35.5 s
      const bool standing = t >= 30.0 && t < 35.0;
      loc.AddStep({t, t + 0.5, "ff1", Vec3(standing ? 0.0 : 0.5, 0, 0), std::nullopt});
      t += 0.5;
      x += standing ? 0.0 : 0.5;
      if (t == 10.0) loc.AddEvent({t, "ff1", "drop", "c1"});
      if (t == 30.0) loc.AddEvent({t, "ff1", "drop", "c2"});
      if (t > 10.0 && t < 25.0) packets("c1", 10.0, 13.0);
      if (t > 30.0) packets("c2", 25.0 + 5.0, -100.0);
      loc.AdvanceTo(t);
    }
    loc.Finish();
    return loc.summary();
  };
  const LocalizerSummary checked = walk(10.0);
  EXPECT_EQ(checked.encounters_after_own_drop, 2u);
  EXPECT_EQ(checked.encounters, 0u);
  const LocalizerSummary every = walk(0.0);
  EXPECT_EQ(every.encounters_after_own_drop, 0u);
  EXPECT_EQ(every.encounters, 2u);
}

// robust_encounters against its reference (Chang 2014's inflation at IV-F's Huber constant,
// 2-D radius 2.0): a walker whose start is known to 6 m walks east; a surveyed node 20 m north
// of its track gives one false peak (a shadowing spike) as it passes. The encounter's innovation
// nu (the node minus the agent) moves the agent by P (P + R~)^-1 nu, R~ = kappa R + (kappa - 1) P,
// kappa = d / 2.0, d its Mahalanobis distance; with robust_encounters=false by P (P + R)^-1 nu.
TEST(BreadcrumbLocalizer, AnEncounterFarOutsideItsSigmaMovesTheAgentAsHuberSays) {
  struct Run {
    Vec2 end = Vec2::Zero();
    Mat2 cov_at_peak = Mat2::Identity();
    LocalizerSummary summary;
  };
  auto walk = [](bool spike, bool robust) {
    LocalizerOptions o;
    o.radio_given = true;  // alpha -40 dBm, n 2.3
    o.calibrate_online = false;
    o.estimate_heading_scale = false;  // positions only: the update is the reference's exactly
    o.entry_heading = false;
    o.use_agent_rssi = false;  // the spike an encounter only, not also a range edge
    o.robust_encounters = robust;
    BreadcrumbLocalizer loc(o);
    loc.AddKnownNode("b", Vec2(10, 20), 1e-3);
    loc.AddAgent("ff1", Vec2::Zero(), 6.0, 0.02);
    Run run;
    TimeS t = 0;
    for (int k = 0; k < 60; ++k) {
      loc.AddStep({t, t + 0.5, "ff1", Vec3(0.5, 0, 0), std::nullopt});
      t += 0.5;
      const double x = 0.5 * (k + 1);
      const bool peak = spike && x == 10.0;
      loc.AddRssi({t, "ff1", "b", peak ? -20.0 : -90.0});  // below min_rssi_dbm but the spike
      loc.AdvanceTo(t);
      if (x == 10.0) run.cov_at_peak = loc.Estimate("ff1")->covariance;
    }
    loc.Finish();
    run.end = loc.Estimate("ff1")->position_n;
    run.summary = loc.summary();
    return run;
  };
  const Run none = walk(false, true), robust = walk(true, true), plain = walk(true, false);
  ASSERT_EQ(none.summary.encounters, 0u);
  ASSERT_EQ(robust.summary.encounters, 1u);
  ASSERT_EQ(plain.summary.encounters, 1u);
  EXPECT_EQ(robust.summary.encounters_downweighted, 1u);
  EXPECT_EQ(plain.summary.encounters_downweighted, 0u);
  const Vec2 nu = Vec2(10, 20) - Vec2(10, 0);  // the node minus the agent at the peak
  const Mat2 P = none.cov_at_peak + Mat2::Identity() * 1e-3;
  const Mat2 R = Mat2::Identity();  // encounter_sigma_m 1
  const double d = std::sqrt(nu.dot((P + R).ldlt().solve(nu)));
  const double kappa = d / 2.006;
  ASSERT_GT(kappa, 1.0);
  ASSERT_LT(d, 5.0);  // inside the gate
  const Mat2 R_robust = kappa * R + (kappa - 1.0) * P;
  const Vec2 expected_robust = P * (P + R_robust).ldlt().solve(nu);
  const Vec2 expected_plain = P * (P + R).ldlt().solve(nu);
  EXPECT_NEAR((robust.end - none.end - expected_robust).norm(), 0.0, 0.05 * nu.norm())
      << (robust.end - none.end).transpose() << " vs " << expected_robust.transpose();
  EXPECT_NEAR((plain.end - none.end - expected_plain).norm(), 0.0, 0.05 * nu.norm())
      << (plain.end - none.end).transpose() << " vs " << expected_plain.transpose();
  EXPECT_LT(expected_robust.norm(), 0.8 * expected_plain.norm());
}

// encounter_places_crumbs: a crumb no drop named, passed at 0.3 m, enters the network at its
// encounter (where the agent was at the peak, tied to it like a drop) instead of waiting for
// its packets to pin it down. A walk east at 1 m/s with a surveyed anchor's ranges, the crumb's
// packets noise-free on the stated model but too few to place it alone.
TEST(BreadcrumbLocalizer, AnEncounterPlacesACrumbNoDropNamed) {
  auto walk = [](bool place) {
    LocalizerOptions o;
    o.radio_given = true;  // alpha -40 dBm, n 2.3
    o.calibrate_online = false;
    o.encounter_places_crumbs = place;
    o.init_min_measurements = 1000;  // the packets alone never place it on this walk
    BreadcrumbLocalizer loc(o);
    loc.AddKnownNode("a", Vec2(10, 8), 1e-3);
    loc.AddUnknownNode("c1");
    loc.AddAgent("ff1", Vec2::Zero(), 0.05, 0.02);
    const Vec2 crumb(10, 0.3);
    for (int k = 0; k < 40; ++k) {
      const TimeS t0 = 0.5 * k, t1 = t0 + 0.5;
      loc.AddStep({t0, t1, "ff1", Vec3(0.5, 0, 0), std::nullopt});
      const Vec2 at(0.5 * (k + 1), 0);
      loc.AddRange({t1, "ff1", "a", (at - Vec2(10, 8)).norm(), 0.1, "uwb"});
      loc.AddRssi({t1, "ff1", "c1", -40.0 - 23.0 * std::log10((at - crumb).norm())});
      loc.AdvanceTo(t1);
    }
    loc.Finish();
    return std::make_pair(loc.Estimate("c1"), loc.summary());
  };
  const auto [placed, with] = walk(true);
  EXPECT_EQ(with.crumbs_placed_by_encounters, 1u);
  ASSERT_TRUE(placed.has_value());
  EXPECT_LT((placed->position_n - Vec2(10, 0.3)).norm(), 1.0) << placed->position_n.transpose();
  const auto [waited, without] = walk(false);
  EXPECT_EQ(without.crumbs_placed_by_encounters, 0u);
  EXPECT_FALSE(waited.has_value());
}

// The near-field check of the stated channel level, against its exact reference: an agent walks
// east at 1 m/s and drops a crumb every 10 s; the crumb's packets 0.5-2.5 s after each drop
// follow level - 10 n log10(d) with no noise (d from the PDR, n the model's 2.3). Each becomes
// level + 5 dB at 1 m (half the assumed body-loss bound: the crumb is behind its dropper), and
// the stated -40 dBm is refuted when that differs from it by more than 5 dB plus 3 standard
// errors of the median over the drops (1.25 x 4 dB / sqrt(drops)).
double ThresholdShiftAfterDrops(double level_dbm, int drops, bool relative = true) {
  LocalizerOptions o;
  o.radio_given = true;  // the default model stated: alpha -40 dBm, n 2.3, sigma 4 dB
  o.calibrate_online = false;
  o.relative_rssi_thresholds = relative;
  BreadcrumbLocalizer loc(o);
  loc.AddAgent("ff1", Vec2::Zero(), 0.01, 0.01);
  const double end = 10.0 * drops + 5.0;
  std::vector<TimeS> drop_t;
  for (int k = 1; k <= drops; ++k) drop_t.push_back(10.0 * k);
  for (int k = 0; 0.5 * k < end; ++k) {
    const TimeS t0 = 0.5 * k, t1 = t0 + 0.5;
    loc.AddStep({t0, t1, "ff1", Vec3(0.5, 0, 0), std::nullopt});
    for (std::size_t c = 0; c < drop_t.size(); ++c) {
      const std::string crumb = "c" + std::to_string(c);
      if (t1 == drop_t[c]) loc.AddEvent({t1, "ff1", "drop", crumb});
      const double d = t1 - drop_t[c];  // m behind, at 1 m/s
      if (d >= 0.5 && d <= 2.5) loc.AddRssi({t1, "ff1", crumb, level_dbm - 23.0 * std::log10(d)});
    }
  }
  loc.Finish();
  return loc.summary().rssi_threshold_shift_db;
}

TEST(BreadcrumbLocalizer, ANearFieldLevelRefutesTheStatedChannelBeyondBodyLossAndNoise) {
  // 25 dB below the statement: refuted by the first drop's 5 packets (allowed 5 + 15 dB).
  EXPECT_NEAR(ThresholdShiftAfterDrops(-70.0, 1), -25.0, 1e-9);
  EXPECT_NEAR(ThresholdShiftAfterDrops(-70.0, 6), -25.0, 1e-9);
  // 13 dB below: within 5 + 15 / sqrt(m) for m = 3 drops (13.66), refuted by the 4th (12.5).
  EXPECT_EQ(ThresholdShiftAfterDrops(-58.0, 3), 0.0);
  EXPECT_NEAR(ThresholdShiftAfterDrops(-58.0, 4), -13.0, 1e-9);
  // 7 dB below, as a body in the way reads: never refuted by a few drops.
  EXPECT_EQ(ThresholdShiftAfterDrops(-52.0, 8), 0.0);
  // Stronger than stated by 12 dB: refuted after 3 drops (allowed 13.66 -> no; 4: 12.5 -> no;
  // 5: 11.7 -> yes), the thresholds move up.
  EXPECT_EQ(ThresholdShiftAfterDrops(-33.0, 4), 0.0);
  EXPECT_NEAR(ThresholdShiftAfterDrops(-33.0, 5), 12.0, 1e-9);
  // Off: the paper's thresholds whatever the packets.
  EXPECT_EQ(ThresholdShiftAfterDrops(-70.0, 6, false), 0.0);
}

// The RSSI thresholds are the paper's (encounters above -40 dBm, edges above -65 dBm) for its
// 868 MHz channel. A BLE channel 20 dB weaker with mission.json still stating the paper's model
// (a stale statement): with the fixed thresholds few encounters (a shadowing peak above
// -40 dBm now and then), no calibration and the radio unused; relative to the level the drops'
// near-field packets show, encounters are found, the channel is fitted, and the error falls below
// half of dead reckoning's (seeds 31-33, not used for any setting).
TEST(BreadcrumbPipeline, ItsRssiThresholdsFollowAChannelWeakerThanStated) {
  double fixed_m = 0, relative_m = 0, pdr_m = 0;
  for (const std::uint64_t seed : {31u, 32u, 33u}) {
    SimulatedMission sim = SimulateScenario("office-loop", seed);
    Variation v;
    v.radio = true;
    v.band = RadioBand::kBle2G4;
    v.alpha_dbm = -60.0;
    v.stated_radio = StatedRadio::kNominal;
    ApplyVariation(v, sim);
    ASSERT_TRUE(sim.data.info.radio.has_value());
    EXPECT_EQ(sim.data.info.radio->alpha_dbm, -40.0);  // the stale statement
    TempDir dir;
    WriteMissionDirectory(dir.path(), sim.data, &sim.plan);
    const MissionDirectory mission(dir.path());
    struct Rows : EstimateSink {
      void Add(const Estimate& e) override { rows.push_back(e); }
      std::vector<Estimate> rows;
    };
    auto run = [&](const char* relative, EstimatorSummary* summary) {
      Rows sink;
      *summary = RunNamed("breadcrumb", mission, {{"relative_rssi", relative}}, sink);
      return Evaluate(sim.data.info, sim.data.truth, sink.rows).agents.stats.mean_m;
    };
    EstimatorSummary fixed, relative;
    fixed_m += run("0", &fixed);
    relative_m += run("1", &relative);
    EXPECT_EQ(fixed.numbers.at("calibrations"), 0.0) << seed;
    EXPECT_GE(relative.numbers.at("encounters"), fixed.numbers.at("encounters") + 5.0) << seed;
    EXPECT_GE(relative.numbers.at("calibrations"), 1.0) << seed;
    EXPECT_LT(relative.numbers.at("rssi_threshold_shift_db"), -10.0) << seed;
    pdr_m += RunOnSim(RequirePipeline("pdr"), sim, dir).agents.stats.mean_m;
  }
  EXPECT_LT(relative_m, 0.5 * pdr_m) << relative_m << " vs dead reckoning " << pdr_m;
  EXPECT_LT(relative_m, 0.5 * fixed_m) << relative_m << " vs fixed thresholds " << fixed_m;
}

/// Issue 25, item 1: a PDR whose heading drifts at `rate` rad/s, walking or standing. A zigzag
/// (left and right turns alike: the gyro scale factor cannot take the drift) with UWB ranges to
/// three anchors for 4 minutes, 2 minutes standing, then 30 steps east without any radio. The
/// final position error of the localizer (truth: the last step's end).
struct DriftWalk {
  double final_error_m = 0;
  double heading_rate = 0;  ///< estimated, rad/s
};
DriftWalk WalkWithADriftingHeading(bool estimate_rate, double rate) {
  LocalizerOptions o;
  o.estimate_heading_rate = estimate_rate;
  BreadcrumbLocalizer loc(o);
  const std::vector<Vec2> anchors = {{-5, -5}, {40, -5}, {15, 40}};
  for (std::size_t k = 0; k < anchors.size(); ++k) loc.AddKnownNode("a" + std::to_string(k), anchors[k], 1e-3);
  loc.AddAgent("ff1", Vec2::Zero(), 0.05, 0.02);
  Vec2 truth = Vec2::Zero();
  TimeS t = 0;
  auto step = [&](const Vec2& along, bool ranges) {
    const double pdr_error = rate * t;  // the PDR's heading error so far
    const Vec2 reported = Eigen::Rotation2Dd(pdr_error) * along;
    loc.AddStep({t, t + 0.5, "ff1", Vec3(reported.x(), reported.y(), 0), std::nullopt});
    truth += along;
    t += 0.5;
    if (ranges) {
      for (std::size_t k = 0; k < anchors.size(); ++k) {
        loc.AddRange({t, "ff1", "a" + std::to_string(k), (truth - anchors[k]).norm(), 0.05, "uwb"});
      }
    }
    loc.AdvanceTo(t);
  };
  for (int leg = 0; leg < 16; ++leg) {  // 16 legs of 15 steps: east, north, east, south, ...
    const Vec2 dir = leg % 2 == 0 ? Vec2(0.7, 0) : Vec2(0, leg % 4 == 1 ? 0.7 : -0.7);
    for (int k = 0; k < 15; ++k) step(dir, true);
  }
  t += 120.0;  // standing: no steps, no radio; the PDR heading drifts on
  for (int k = 0; k < 30; ++k) step(Vec2(0.7, 0), false);
  loc.Finish();
  DriftWalk out;
  out.final_error_m = (loc.Estimate("ff1")->position_n - truth).norm();
  if (const auto kb = loc.GyroScaleRate("ff1")) out.heading_rate = kb->y();
  return out;
}

TEST(BreadcrumbLocalizer, AHeadingDriftIsLearntAndCarriedThroughAStandstill) {
  const double rate = 3.0 / 60.0 * 3.14159265358979 / 180.0;  // 3 deg/min
  const DriftWalk with = WalkWithADriftingHeading(true, rate);
  const DriftWalk without = WalkWithADriftingHeading(false, rate);
  // The correction is minus the PDR's drift; the heading random walk takes a share of it over
  // four minutes (the filtered estimate is 68 % of it here), so not the whole.
  EXPECT_LT(with.heading_rate, -0.5 * rate);
  EXPECT_GT(with.heading_rate, -1.5 * rate);
  EXPECT_LT(with.final_error_m, 0.5 * without.final_error_m)
      << with.final_error_m << " vs " << without.final_error_m;
  // Without drift the rate stays near zero and costs nothing.
  const DriftWalk still = WalkWithADriftingHeading(true, 0.0);  // (the option is off by default)
  EXPECT_LT(std::abs(still.heading_rate), 0.1 * rate);
  EXPECT_LT(still.final_error_m, 0.5);
}

// A zigzag walk with UWB ranges (0.3 m) to three anchors every 1.5 s; the PDR's steps state
// 5 cm per axis, but when `lying` their heading is off by a carrying mode that jumps between
// -30 and +30 degrees every 20 steps (a hand-held phone's). Returns the agent's motion-noise
// factor, its mean error and the share of its estimates whose 95 % ellipse holds the truth.
struct LyingPdrWalk {
  double motion_noise_scale = 0;
  double mean_error_m = 0;
  double in95 = 0;
  std::size_t refused = 0, blamed_on_motion = 0;  ///< by the node check; overruled
};
LyingPdrWalk WalkWithALyingPdr(bool lying, bool adapt, double anchor_a1_offset_m = 0) {
  LocalizerOptions o;
  o.adapt_motion_noise = adapt;
  BreadcrumbLocalizer loc(o);
  const std::vector<Vec2> anchors = {{-5, -5}, {40, -5}, {15, 40}};
  for (std::size_t k = 0; k < anchors.size(); ++k)
    loc.AddKnownNode("a" + std::to_string(k), anchors[k], 1e-3);
  loc.AddAgent("ff1", Vec2::Zero(), 0.05, 0.02);
  Vec2 truth = Vec2::Zero();
  TimeS t = 0;
  double sum_error = 0;
  int n = 0, inside = 0;
  std::uint32_t noise = 4242;  // a fixed pseudo-random +-0.52 m (sigma 0.3 m) per range
  for (int leg = 0; leg < 24; ++leg) {
    const Vec2 dir = leg % 2 == 0 ? Vec2(0.7, 0) : Vec2(0, leg % 4 == 1 ? 0.7 : -0.7);
    for (int k = 0; k < 15; ++k) {
      const int step = leg * 15 + k;
      const double mode = lying ? ((step / 20) % 2 == 0 ? 0.52 : -0.52) : 0.0;
      const Vec2 reported = Eigen::Rotation2Dd(mode) * dir;
      loc.AddStep(
          {t, t + 0.5, "ff1", Vec3(reported.x(), reported.y(), 0), Vec3(0.0025, 0.0025, 0.01)});
      truth += dir;
      t += 0.5;
      if (k % 3 == 0) {
        for (std::size_t a = 0; a < anchors.size(); ++a) {
          const double e = 1.04 * NextUniform(&noise);
          const double offset = a == 1 ? anchor_a1_offset_m : 0.0;
          loc.AddRange({t, "ff1", "a" + std::to_string(a), (truth - anchors[a]).norm() + e + offset,
                        0.3, "uwb"});
        }
      }
      loc.AdvanceTo(t);
      const auto est = loc.Estimate("ff1");
      const Vec2 err = est->position_n - truth;
      sum_error += err.norm();
      inside += err.dot(est->covariance.ldlt().solve(err)) <= 5.991;  // chi2(2), 95 %
      ++n;
    }
  }
  loc.Finish();
  return {*loc.MotionNoiseScale("ff1"), sum_error / n, static_cast<double>(inside) / n,
          loc.summary().refused, loc.summary().refusals_blamed_on_motion};
}

// The PDR checked against its stated noise (adapt_motion_noise): steps whose heading jumps by
// 60 degrees while they claim 5 cm make the ranges' innovations far larger than stated, and the
// agent's step and heading noise grow until its ellipses hold the truth again; honest steps
// leave them as stated, and so does one anchor that lies.
TEST(BreadcrumbLocalizer, APdrThatLiesAboutItsNoiseIsScaledUp) {
  const LyingPdrWalk adapted = WalkWithALyingPdr(true, true);
  const LyingPdrWalk fixed = WalkWithALyingPdr(true, false);
  // Without it the node check blames the anchors (all three at once) and refuses 293 of their
  // 360 ranges: 5.3 m mean error, ellipses holding the truth 17 % of the time. With it, 0.8 m
  // and 63 % (the factor grows over the first minute); the verdicts on anchors like their peers
  // are blamed on the motion (BlameMotion; without that, 1.8 m).
  EXPECT_GT(adapted.motion_noise_scale, 4.0);
  EXPECT_EQ(fixed.motion_noise_scale, 1.0);
  EXPECT_GT(adapted.in95, fixed.in95 + 0.3) << adapted.in95 << " vs " << fixed.in95;
  EXPECT_LT(adapted.mean_error_m, 0.25 * fixed.mean_error_m)
      << adapted.mean_error_m << " vs " << fixed.mean_error_m;
  EXPECT_GT(adapted.blamed_on_motion, 0u);
  EXPECT_GT(fixed.refused, 200u);
  EXPECT_EQ(fixed.blamed_on_motion, 0u);
  const LyingPdrWalk honest = WalkWithALyingPdr(false, true);
  EXPECT_LT(honest.motion_noise_scale, 2.0) << honest.motion_noise_scale;
  EXPECT_GT(honest.in95, 0.9) << honest.in95;
  EXPECT_LT(honest.mean_error_m, 0.5) << honest.mean_error_m;
  // One anchor that lies (4 m long) is its own: the median over the nodes is not moved.
  const LyingPdrWalk liar = WalkWithALyingPdr(false, true, 4.0);
  EXPECT_LT(liar.motion_noise_scale, 2.0) << liar.motion_noise_scale;
  EXPECT_GT(liar.refused, 0u);  // the node check still names it
  EXPECT_EQ(liar.blamed_on_motion, 0u);
}

// The zigzag walk above, PDR exact, UWB ranges to three anchors holding the position; three
// crumbs at known places send RSSI by the stated model, crumb k2 `offset_db` louder.
struct OffsetWalk {
  std::optional<double> k1, k2, k3;
  double mean_error_m = 0;
};
OffsetWalk WalkPastALoudCrumb(LocalizerOptions::RssiOffsets mode, double offset_db) {
  LocalizerOptions o;
  o.rssi_offsets = mode;
  o.radio = {-40.0, 2.3, 4.0};
  o.radio_given = true;
  o.calibrate_online = false;
  BreadcrumbLocalizer loc(o);
  const std::vector<Vec2> anchors = {{-5, -5}, {40, -5}, {15, 40}};
  for (std::size_t k = 0; k < anchors.size(); ++k)
    loc.AddKnownNode("a" + std::to_string(k), anchors[k], 1e-3);
  const std::vector<Vec2> crumbs = {{3, 2}, {12, 4}, {22, 1}};
  for (std::size_t k = 0; k < crumbs.size(); ++k)
    loc.AddKnownNode("k" + std::to_string(k + 1), crumbs[k], 1e-3);
  loc.AddAgent("ff1", Vec2::Zero(), 0.05, 0.02);
  Vec2 truth = Vec2::Zero();
  TimeS t = 0;
  double sum_error = 0;
  int n = 0;
  std::uint32_t noise = 12345;  // a fixed pseudo-random +-2 dB per packet
  for (int leg = 0; leg < 16; ++leg) {
    const Vec2 dir = leg % 2 == 0 ? Vec2(0.7, 0) : Vec2(0, leg % 4 == 1 ? 0.7 : -0.7);
    for (int k = 0; k < 15; ++k) {
      loc.AddStep({t, t + 0.5, "ff1", Vec3(dir.x(), dir.y(), 0), std::nullopt});
      truth += dir;
      t += 0.5;
      if (k % 3 == 0) {
        for (std::size_t a = 0; a < anchors.size(); ++a)
          loc.AddRange(
              {t, "ff1", "a" + std::to_string(a), (truth - anchors[a]).norm(), 0.3, "uwb"});
      }
      for (std::size_t c = 0; c < crumbs.size(); ++c) {
        const double e = 4.0 * NextUniform(&noise);
        const double d = std::max((truth - crumbs[c]).norm(), 0.5);
        const double rssi = -40.0 - 23.0 * std::log10(d) + (c == 1 ? offset_db : 0.0) + e;
        loc.AddRssi({t, "ff1", "k" + std::to_string(c + 1), rssi});
      }
      loc.AdvanceTo(t);
      sum_error += (loc.Estimate("ff1")->position_n - truth).norm();
      ++n;
    }
  }
  loc.Finish();
  return {loc.RssiOffsetDb("k1"), loc.RssiOffsetDb("k2"), loc.RssiOffsetDb("k3"), sum_error / n};
}

TEST(BreadcrumbLocalizer, ACrumbsRssiOffsetIsLearnt) {
  using Mode = LocalizerOptions::RssiOffsets;
  const OffsetWalk without = WalkPastALoudCrumb(Mode::kOff, 8.0);
  EXPECT_FALSE(without.k2.has_value());
  for (const Mode mode : {Mode::kInnovations, Mode::kNetwork}) {
    SCOPED_TRACE(static_cast<int>(mode));
    const OffsetWalk with = WalkPastALoudCrumb(mode, 8.0);
    ASSERT_TRUE(with.k1 && with.k2 && with.k3);
    EXPECT_NEAR(*with.k2, 8.0, 1.5);  // the loud crumb
    EXPECT_NEAR(*with.k1, 0.0, 1.5);  // the others stay near their prior's zero
    EXPECT_NEAR(*with.k3, 0.0, 1.5);
    // Without an offset the loudness is read as distance: the walk's error grows.
    EXPECT_LT(with.mean_error_m, without.mean_error_m);
    // No offset: none is invented.
    const OffsetWalk honest = WalkPastALoudCrumb(mode, 0.0);
    EXPECT_LT(std::abs(*honest.k2), 1.5);
  }
}

}  // namespace
}  // namespace trailmark::breadcrumb

namespace trailmark::breadcrumb {
namespace {

// A walker whose stated start is 8 m off (sigma 8 m) ranges to three anchors every 1.5 s (UWB,
// 0.3 m): its first range edges are linearized far from the truth. Returns the mean error over
// the first 30 s, the largest number of nodes in the network and the persistent edges left.
struct LagWalk {
  double early_error_m = 0;
  int max_nodes = 0;
  std::size_t persistent_left = 0;
};
LagWalk WalkFromAPoorStart(double lag_s) {
  LocalizerOptions o;
  o.fixed_lag_s = lag_s;
  o.second_order = false;  // the re-linearization alone
  o.estimate_heading_scale = false;
  o.track_heading_offset_sigma_rad = 0;
  BreadcrumbLocalizer loc(o);
  const std::vector<Vec2> anchors = {{-5, -5}, {40, -5}, {15, 40}};
  for (std::size_t k = 0; k < anchors.size(); ++k)
    loc.AddKnownNode("a" + std::to_string(k), anchors[k], 1e-3);
  loc.AddAgent("ff1", Vec2::Zero(), 8.0);
  Vec2 truth(6, -5);
  TimeS t = 0;
  LagWalk out;
  double sum = 0;
  int n = 0;
  std::uint32_t noise = 777;
  for (int step = 0; step < 240; ++step) {
    const Vec2 dir = Eigen::Rotation2Dd(0.02 * step) * Vec2(0.6, 0);
    loc.AddStep({t, t + 0.5, "ff1", Vec3(dir.x(), dir.y(), 0), Vec3(0.0025, 0.0025, 0.01)});
    truth += dir;
    t += 0.5;
    if (step % 3 == 0) {
      for (std::size_t a = 0; a < anchors.size(); ++a) {
        const double e = 0.6 * NextUniform(&noise);
        loc.AddRange(
            {t, "ff1", "a" + std::to_string(a), (truth - anchors[a]).norm() + e, 0.3, "uwb"});
      }
    }
    loc.AdvanceTo(t);
    const auto est = loc.Estimate("ff1");
    if (t <= 30.0) {
      sum += (est->position_n - truth).norm();
      ++n;
    }
    out.max_nodes = std::max(out.max_nodes, loc.network().active_nodes());
  }
  loc.Finish();
  out.early_error_m = sum / n;
  out.persistent_left = loc.network().active_persistent();
  return out;
}

// The fixed-lag window (issue 25, item 2): the range edges added at the poor start are taken
// again at the better estimates the next ones give, before they are committed; the window keeps
// only its span of states, and every edge of a state that left it is folded.
TEST(BreadcrumbLocalizer, AFixedLagWindowTakesRangesAgainBeforeCommittingThem) {
  const LagWalk once = WalkFromAPoorStart(0.0);
  const LagWalk window = WalkFromAPoorStart(10.0);
  // (1.92 m against 0.11 m when written; the default second-order edges, which widen an edge by
  // its nodes' uncertainty, take linearize-once to 0.15 m: docs/breadcrumb.md.)
  EXPECT_LT(window.early_error_m, 0.2 * once.early_error_m)
      << window.early_error_m << " vs " << once.early_error_m;
  EXPECT_EQ(once.persistent_left, 0u);
  // 3 anchors, the range bias node, the state, and one earlier state per range time (every
  // 1.5 s) of the last 10 s.
  EXPECT_LE(window.max_nodes, 3 + 1 + 1 + 7);
  EXPECT_GT(window.max_nodes, once.max_nodes);
  // Ranges come every 1.5 s, three at a time: the states of the last 10 s hold at most 21.
  EXPECT_LE(window.persistent_left, 21u);
}

// A responder enters along the stated start heading (sigma 3 deg) and walks a 12 x 8 m loop
// three times, dropping a crumb every 3 m and ranging the crumbs within 10 m every second (UWB,
// 0.1 m); its steps are turned by `turn_rad` (a PDR aligned worse than stated), and its first
// metre goes `entry_rad` from the start heading. Ranges to crumbs it dropped cannot see a
// rotation about the start: only the start heading can. Returns the crumbs' mean error at the
// end and the localizer's summary.
struct EntryWalk {
  double crumb_error_m = 0;
  LocalizerSummary summary;
};
EntryWalk WalkInTurned(bool entry, double turn_rad, double entry_rad = 0) {
  LocalizerOptions o;
  o.entry_heading = entry;
  BreadcrumbLocalizer loc(o);
  loc.AddAgent("ff1", Vec2::Zero(), 0.05, 0.05, 0.0);
  std::vector<Vec2> path = {Vec2::Zero(), Vec2(std::cos(entry_rad), std::sin(entry_rad))};
  const std::vector<Vec2> corners = {{12, 0}, {12, 8}, {0, 8}, {0, 0}};
  for (int lap = 0; lap < 3; ++lap)
    for (const Vec2& c : corners) path.push_back(c);
  std::vector<Vec2> crumbs;
  Vec2 truth = Vec2::Zero();
  TimeS t = 0;
  double since_drop = 0;
  std::uint32_t noise = 99;
  const Eigen::Rotation2Dd turned(turn_rad);
  for (std::size_t leg = 1; leg < path.size(); ++leg) {
    const Vec2 to = path[leg];
    while ((to - truth).norm() > 1e-9) {
      const Vec2 step =
          (to - truth).norm() > 0.5 ? Vec2(0.5 * (to - truth).normalized()) : Vec2(to - truth);
      const Vec2 reported = turned * step;
      loc.AddStep(
          {t, t + 0.5, "ff1", Vec3(reported.x(), reported.y(), 0), Vec3(0.0025, 0.0025, 0.01)});
      truth += step;
      t += 0.5;
      since_drop += step.norm();
      if (since_drop >= 3.0) {
        since_drop = 0;
        const std::string id = "c" + std::to_string(crumbs.size());
        loc.AddEvent({t, "ff1", "drop", id});
        crumbs.push_back(truth);
      }
      if (std::fmod(t, 1.0) < 1e-9) {
        for (std::size_t c = 0; c < crumbs.size(); ++c) {
          const double d = (truth - crumbs[c]).norm();
          if (d > 10.0 || d < 0.5) continue;
          loc.AddRange(
              {t, "ff1", "c" + std::to_string(c), d + 0.2 * NextUniform(&noise), 0.1, "uwb"});
        }
      }
      loc.AdvanceTo(t);
    }
  }
  loc.Finish();
  EntryWalk out;
  for (std::size_t c = 0; c < crumbs.size(); ++c)
    out.crumb_error_m += (loc.Estimate("c" + std::to_string(c))->position_n - crumbs[c]).norm();
  out.crumb_error_m /= static_cast<double>(crumbs.size());
  out.summary = loc.summary();
  return out;
}

// The entry heading (issue 25, item 1): the stated start heading minus the first metre of
// steps measures the steps' rotation. Turned by 17 deg where 3 deg are stated, the claim is
// refuted and the rotation taken from the entry; turned by 3 deg, the claim holds and the
// measurement is added to it; an entry walked 60 deg off the stated heading is not used.
TEST(BreadcrumbLocalizer, TheEntryHeadingMeasuresTheStepsRotation) {
  const EntryWalk off = WalkInTurned(false, 0.3);
  const EntryWalk on = WalkInTurned(true, 0.3);
  EXPECT_EQ(on.summary.entry_headings_refuted, 1u);
  EXPECT_EQ(on.summary.entry_headings + on.summary.entry_headings_refused, 0u);
  EXPECT_EQ(off.summary.entry_headings_refuted, 0u);
  // (0.53 m against 2.60 m when written)
  EXPECT_LT(on.crumb_error_m, 0.3 * off.crumb_error_m)
      << on.crumb_error_m << " vs " << off.crumb_error_m;
  const EntryWalk small_off = WalkInTurned(false, 0.05), small_on = WalkInTurned(true, 0.05);
  EXPECT_EQ(small_on.summary.entry_headings, 1u);
  EXPECT_LT(small_on.crumb_error_m, small_off.crumb_error_m + 0.05);
  const EntryWalk aside = WalkInTurned(true, 0.3, 1.05);
  EXPECT_EQ(aside.summary.entry_headings_refused, 1u);
  bool noted = false;
  for (const std::string& n : aside.summary.notes)
    noted = noted || n.find("not walked along it") != std::string::npos;
  EXPECT_TRUE(noted);
}

/// A dead-reckoning-only walk along +x whose every step makes a network state (an
/// uninformative range, sigma 1e6 m, to a far anchor at each step): the covariance reported at
/// the end, and the heading node's estimate.
struct StatesWalk {
  Mat2 covariance;
  Vec2 walk_n;  ///< the raw steps' sum
};
StatesWalk WalkWithStates(LocalizerOptions o, double start_sigma_m, int steps = 200) {
  o.estimate_range_bias = false;
  BreadcrumbLocalizer loc(o);
  loc.AddKnownNode("far", Vec2(10, 5000), 1e-3);
  loc.AddAgent("ff1", Vec2::Zero(), start_sigma_m);
  StatesWalk w{Mat2::Zero(), Vec2::Zero()};
  for (int k = 0; k < steps; ++k) {
    const TimeS t1 = 0.5 * k + 0.5;
    const Vec3 d(0.5, 0.02 * std::sin(0.3 * k), 0);
    loc.AddStep({t1 - 0.5, t1, "ff1", d, Vec3(1e-3, 1e-3, 1e-4)});
    w.walk_n += d.head<2>();
    AddUninformativeRange(loc, t1, 1e6);
    if (k == 0) loc.Estimate("ff1");  // the cached covariance refreshed here
  }
  w.covariance = loc.Estimate("ff1")->covariance;
  return w;
}

TEST(BreadcrumbLocalizer, AWalkOfManyStatesKeepsTheUncertaintyOfAnUnknownStart) {
  // Each new state of a walk took the network's 1e-8 regularization prior again, and the
  // marginalization carried it on: after N states, N times the "negligible" information (found
  // by a review, 2026-12-06). An agent started at 1,000 m: 400 states later its variance is
  // still about the start's (the first state's one prior takes 1 %; it was a fifth of it).
  LocalizerOptions o;
  o.estimate_heading_scale = false;
  o.track_heading_offset_sigma_rad = 0;
  const StatesWalk w = WalkWithStates(o, 1000.0, 400);
  EXPECT_GT(w.covariance(0, 0), 0.98e6);
  EXPECT_GT(w.covariance(1, 1), 0.98e6);
}

TEST(BreadcrumbLocalizer, ACovarianceRefreshedLessOftenCountsEachStepOnce) {
  // Between two refreshes of an agent's cached covariance, each new state added its edge's
  // variance and the estimate added the same walk's variance again (found by a review,
  // 2026-12-06). The walk's covariance must not depend on how often it is refreshed.
  LocalizerOptions every, seldom;
  every.estimate_heading_scale = seldom.estimate_heading_scale = false;
  every.track_heading_offset_sigma_rad = seldom.track_heading_offset_sigma_rad = 0;
  every.covariance_period_s = every.solve_period_s = 0;
  seldom.covariance_period_s = 1000;
  const StatesWalk a = WalkWithStates(every, 0.1), b = WalkWithStates(seldom, 0.1);
  EXPECT_LT((a.covariance - b.covariance).norm(), 0.02 * a.covariance.norm())
      << a.covariance << "\n vs\n"
      << b.covariance;
}

}  // namespace
}  // namespace trailmark::breadcrumb

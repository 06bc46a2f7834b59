// SPDX-License-Identifier: MIT
// The pdr pipeline against an exact reference: error-free steps must reproduce the truth.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "pipelines/run_named.h"
#include "test_util.h"
#include "trailmark/core/error.h"
#include "trailmark/eval/metrics.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/sim/scenarios.h"

namespace trailmark {
namespace {

using testing::CanRunNamed;
using testing::RunNamed;

using testing::TempDir;


TEST(PdrPipeline, ErrorFreeStepsReproduceTruthExactly) {
  OfficeLoopOptions o;
  o.laps = 1;
  o.sim.pdr = {.heading_random_walk_rad = 0, .heading_drift_sigma_rad_per_s = 0,
               .turn_scale_error_sigma = 0, .scale_error_sigma = 0, .step_noise_m = 0};
  const SimulatedMission sim = SimulateOfficeLoop(o, 11);
  TempDir dir;
  WriteMissionDirectory(dir.path(), sim.data, &sim.plan);
  const MissionDirectory mission(dir.path());
  VectorSink sink;
  RunNamed("pdr", mission, {{"view_period_s", "0"}}, sink);  // the estimator's own rows
  ASSERT_EQ(sink.rows.size(), sim.data.steps.size() + 1);
  // Each estimate equals the true foot position at the end of its step (<1e-9 m).
  // Truth samples are at 10 Hz, so compare against the step endpoints via the metrics instead:
  // the final estimate is the start, as the loop closes.
  EXPECT_NEAR((sink.rows.back().position_n - Vec3::Zero()).norm(), 0.0, 1e-9);
  // Covariance stays positive definite. (It need not grow monotonically: the heading and scale
  // errors are shared by all steps, and a loop walked back towards the start undoes their
  // lever; only the drift rate and the white parts remain when it closes.)
  for (std::size_t i = 1; i < sink.rows.size(); ++i) {
    EXPECT_GT(sink.rows[i].sxx, 0.0);
    EXPECT_GT(sink.rows[i].sxx * sink.rows[i].syy - sink.rows[i].sxy * sink.rows[i].sxy, 0.0);
  }
  // Against truth at 10 Hz, the online error is at most one step length.
  const Metrics m = Evaluate(sim.data.info, sim.data.truth, sink.rows);
  EXPECT_LT(m.agents.stats.max_m, 0.9);
  // With the view between rows (the default): the same rows at the steps' ends, and between
  // them the walk moved on, so the held error halves (measured: p75 0.41 -> 0.17 m).
  VectorSink viewed;
  RunNamed("pdr", mission, {}, viewed);
  std::size_t same = 0;
  for (const Estimate& e : viewed.rows) {
    for (const Estimate& s : sink.rows) same += s.t == e.t && s.position_n == e.position_n;
  }
  EXPECT_EQ(same, sink.rows.size());
  EXPECT_GT(viewed.rows.size(), 4 * sink.rows.size());
  const Metrics v = Evaluate(sim.data.info, sim.data.truth, viewed.rows);
  EXPECT_LT(v.agents.stats.p75_m, 0.6 * m.agents.stats.p75_m);
  EXPECT_LE(v.agents.stats.max_m, m.agents.stats.max_m);
}

TEST(PdrPipeline, NeedsAStartAndAnAgent) {
  TempDir dir;
  dir.File("mission.json", R"({"nodes":[{"id":"ff1","kind":"agent"},{"id":"lm","kind":"landmark"}]})");
  dir.File("steps.csv", "t0,t1,agent,dx,dy\n0,1,ff1,1,0\n");
  const MissionDirectory mission(dir.path());
  VectorSink sink;
  try {
    RunNamed("pdr", mission, {}, sink);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_THAT(e.what(), ::testing::HasSubstr("no 'start'"));
  }
  dir.File("steps.csv", "t0,t1,agent,dx,dy\n0,1,lm,1,0\n");
  const MissionDirectory mission2(dir.path());
  EXPECT_THROW(RunNamed("pdr", mission2, {}, sink), InputError);
}

TEST(PdrPipeline, SaysWhenImuCsvIsNotUsed) {
  TempDir dir;
  dir.File("mission.json", R"({"nodes":[{"id":"ff1","kind":"agent","start":[0,0,0]}]})");
  dir.File("steps.csv", "t0,t1,agent,dx,dy\n0,1,ff1,1,0\n");
  dir.File("imu.csv", "t,agent,ax,ay,az,gx,gy,gz\n0,ff1,0,0,9.8,0,0,0\n");
  VectorSink sink;
  const EstimatorSummary s = RunNamed("pdr", MissionDirectory(dir.path()), {}, sink);
  bool said = false;
  for (const auto& n : s.notes) said = said || n.find("imu.csv not used") != std::string::npos;
  EXPECT_TRUE(said);
  EXPECT_EQ(sink.rows.size(), 2u);  // the start and the one step of steps.csv
}

TEST(Pipelines, RegistryListsPdrAndRunnableChecksFiles) {
  ASSERT_NE(FindPipeline("pdr"), nullptr);
  EXPECT_EQ(FindPipeline("nope"), nullptr);
  TempDir dir;
  dir.File("mission.json", "{}");
  EXPECT_TRUE(RunnablePipelines(MissionDirectory(dir.path())).empty());
}

}  // namespace
}  // namespace trailmark

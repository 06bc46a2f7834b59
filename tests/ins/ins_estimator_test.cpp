// SPDX-License-Identifier: MIT
// The `ins` estimator's output rule: at most output_hz per agent and every step end besides
// (the foot at rest), or the step ends only, or every sample; each agent's last state at the
// end of data; the estimates are the INS's own states at those samples.
#include "trailmark/ins/ins_estimator.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <map>

#include "trailmark/core/random.h"
#include "trailmark/sim/imu_sim.h"
#include "trailmark/sim/scenarios.h"

namespace trailmark::ins {
namespace {

struct Walked {
  MissionInfo info;
  std::vector<ImuSample> imu;
};

Walked SimulatedFoot() {
  const SimulatedMission sim = SimulateScenario("office-loop-1lap", 7);
  ImuSimOptions o;
  o.rate_hz = 820;  // an OpenShoe-rate IMU
  const auto& [id, walk] = sim.walks.front();
  Walked w;
  w.info = sim.data.info;
  w.imu = SimulateFootImu(walk, id, o, Random(8)).samples;
  return w;
}

struct Output {
  std::vector<Estimate> estimates;
  std::vector<InsState> states;  ///< every state of the agent's INS
  std::vector<Step> steps;
};

Output RunEstimator(const Walked& w, InsEstimatorOptions options) {
  Output out;
  // The same INS alone: its states and steps, to check the estimates against.
  MultiAgentIns ins(w.info, options.ins);
  ins.on_state = [&](const std::string&, const InsState& s) { out.states.push_back(s); };
  ins.on_step = [&](const Step& s) { out.steps.push_back(s); };
  InsEstimator estimator(w.info, options);
  VectorSink sink;
  for (const auto& s : w.imu) {
    estimator.Add(MissionRow(s), sink);
    ins.Add(s);
  }
  estimator.Finish(sink);
  ins.Finish();
  out.estimates = sink.rows;
  return out;
}

std::map<double, const InsState*> ByTime(const Output& out) {
  std::map<double, const InsState*> m;
  for (const auto& s : out.states) m[s.t] = &s;
  return m;
}

TEST(InsEstimator, RateOutputKeepsEveryStepEndAndTheLastState) {
  const Walked w = SimulatedFoot();
  InsEstimatorOptions o;  // defaults: rate, 50 Hz
  ASSERT_EQ(o.output, InsOutput::kRate);
  const Output out = RunEstimator(w, o);
  ASSERT_GT(out.steps.size(), 50u);
  const auto states = ByTime(out);
  std::vector<double> times;
  for (const auto& e : out.estimates) {
    const auto it = states.find(e.t);
    ASSERT_NE(it, states.end()) << "an estimate at t=" << e.t << " that is no INS state";
    EXPECT_EQ(e.position_n.head<2>(), it->second->position_n.head<2>());
    // z comes from the height channel: a level walk's INS vertical noise (mm) never persists
    // as a height change, so the agent stays at its start's height, on level 0.
    EXPECT_EQ(e.position_n.z(), 0.0);
    ASSERT_TRUE(e.szz && e.floor);
    EXPECT_EQ(*e.floor, 0);
    EXPECT_EQ(e.sxx, it->second->position_cov(0, 0));
    times.push_back(e.t);
  }
  ASSERT_TRUE(std::is_sorted(times.begin(), times.end()));
  for (const auto& step : out.steps) {
    EXPECT_TRUE(std::binary_search(times.begin(), times.end(), step.t1)) << "step end " << step.t1;
  }
  EXPECT_EQ(times.back(), out.states.back().t);
  // Besides the step ends, no two estimates closer than 1/50 s; and no gap much longer.
  std::vector<double> step_ends;
  for (const auto& s : out.steps) step_ends.push_back(s.t1);
  double last_rate = -1e9;
  std::size_t rate_rows = 0;
  for (const double t : times) {
    if (std::binary_search(step_ends.begin(), step_ends.end(), t)) continue;
    if (t == times.back()) continue;
    EXPECT_GE(t - last_rate, 0.02 - 1e-6);
    last_rate = t;
    ++rate_rows;
  }
  const double duration = out.states.back().t - out.states.front().t;
  EXPECT_GT(rate_rows, 0.9 * 50 * duration - 1);
  EXPECT_LT(out.estimates.size(), out.states.size() / 8);  // 820 Hz -> ~50 Hz + steps
}

TEST(InsEstimator, StepsOutputIsTheStepEndsAndZeroHzIsEverySample) {
  const Walked w = SimulatedFoot();
  InsEstimatorOptions o;
  o.output = InsOutput::kSteps;
  const Output steps = RunEstimator(w, o);
  // + the last state, unless the data ended in a stance (then it is the last step's end)
  const bool ends_in_step = steps.steps.back().t1 == steps.states.back().t;
  ASSERT_EQ(steps.estimates.size(), steps.steps.size() + (ends_in_step ? 0 : 1));
  for (std::size_t k = 0; k < steps.steps.size(); ++k) {
    EXPECT_EQ(steps.estimates[k].t, steps.steps[k].t1);
  }
  o.output = InsOutput::kRate;
  o.output_hz = 0;
  const Output all = RunEstimator(w, o);
  EXPECT_EQ(all.estimates.size(), all.states.size());
}

TEST(InsEstimator, RefusesABadRate) {
  InsEstimatorOptions o;
  o.output_hz = -1;
  std::string why;
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_NE(why.find("output_hz"), std::string::npos);
}

}  // namespace
}  // namespace trailmark::ins

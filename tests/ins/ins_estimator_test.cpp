// SPDX-License-Identifier: MIT
// The `ins` estimator's output rule: at most output_hz per agent and every step end besides
// (the foot at rest), or the step ends only, or every sample; each agent's last state at the
// end of data; the estimates are the INS's own states at those samples.
#include "trailmark/ins/ins_estimator.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <stdexcept>

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

/// What mission.json says of the start that the filter leaves out (ins_estimator.h), written
/// out: the start position's variance, and the start heading's (with the foot's own offset)
/// beyond the filter's initial yaw variance, turning the walk about the start.
const NodeInfo& FirstAgent(const MissionInfo& info) {
  for (const NodeInfo& n : info.nodes) {
    if (n.kind == NodeKind::kAgent) return n;
  }
  throw std::logic_error("no agent");
}

/// (And the foot's distance from the walker, isotropic: InsEstimatorOptions::foot_offset_sigma_m.)
Mat2 StartVariance(const MissionInfo& info, const InsState& st, double offset_rad,
                   double foot_m = InsEstimatorOptions{}.foot_offset_sigma_m) {
  const NodeInfo& n = FirstAgent(info);
  const double sp = n.start_sigma_m.value_or(0.0);
  const double own = InsOptions{}.initial_yaw_sigma_rad;
  const double sh = n.start_heading_sigma_rad.value_or(own);
  const double yaw_var = n.start_heading_rad ? sh * sh + offset_rad * offset_rad - own * own : 0.0;
  const Vec2 from = st.position_n.head<2>() - info.AgentStart(n).value_or(Vec3::Zero()).head<2>();
  const Vec2 u(-from.y(), from.x());
  return (sp * sp + foot_m * foot_m) * Mat2::Identity() +
         std::max(0.0, yaw_var) * u * u.transpose();
}

TEST(InsEstimator, TheCovarianceCarriesTheStatedStartItsFilterLeavesOut) {
  Walked w = SimulatedFoot();
  const auto agent_it = std::find_if(w.info.nodes.begin(), w.info.nodes.end(),
                                     [](const NodeInfo& n) { return n.kind == NodeKind::kAgent; });
  ASSERT_NE(agent_it, w.info.nodes.end());
  NodeInfo& agent = *agent_it;
  ASSERT_TRUE(agent.start_heading_rad);
  // Stated exactly (the filter's own yaw sigma) and the foot taken to point as stated: the
  // filter's covariance as it is.
  agent.start_sigma_m = 0.0;
  agent.start_heading_sigma_rad = InsOptions{}.initial_yaw_sigma_rad;
  InsEstimatorOptions as_stated;
  as_stated.track_heading_offset_sigma_rad = 0.0;
  as_stated.foot_offset_sigma_m = 0.0;  // the foot is what is tracked
  const Output exact = RunEstimator(w, as_stated);
  // Stated as a door a firefighter walks in by: 0.2 m, 0.05 rad; the foot's own offset (toe-out)
  // at its default.
  agent.start_sigma_m = 0.2;
  agent.start_heading_sigma_rad = 0.05;
  const double offset = InsEstimatorOptions{}.track_heading_offset_sigma_rad;
  ASSERT_GT(offset, 0.0);
  const Output door = RunEstimator(w, {});
  ASSERT_EQ(exact.estimates.size(), door.estimates.size());
  ASSERT_GT(door.estimates.size(), 100u);
  const auto states = ByTime(door);
  double far = 0;
  for (std::size_t i = 0; i < door.estimates.size(); ++i) {
    const Estimate& a = exact.estimates[i];
    const Estimate& b = door.estimates[i];
    ASSERT_EQ(a.position_n, b.position_n) << i;  // the filter is the same
    const InsState& st = *states.at(b.t);
    EXPECT_EQ(a.sxx, st.position_cov(0, 0));
    const Mat2 extra = StartVariance(w.info, st, offset);
    EXPECT_NEAR(b.sxx, st.position_cov(0, 0) + extra(0, 0), 1e-12);
    EXPECT_NEAR(b.sxy, st.position_cov(0, 1) + extra(0, 1), 1e-12);
    EXPECT_NEAR(b.syy, st.position_cov(1, 1) + extra(1, 1), 1e-12);
    far = std::max(far, (b.position_n - *w.info.AgentStart(agent)).head<2>().norm());
  }
  // 20 m from the door the heading's share alone is (0.05^2 - 0.01^2) x 400 m^2 = 0.96 m^2.
  ASSERT_GT(far, 20.0);
  // The steps are differences: the same either way.
  ASSERT_EQ(exact.steps.size(), door.steps.size());
  for (std::size_t i = 0; i < door.steps.size(); ++i) {
    EXPECT_EQ(exact.steps[i].delta_n, door.steps[i].delta_n);
    EXPECT_EQ(exact.steps[i].variance_m2, door.steps[i].variance_m2);
  }
}

// An INS outside its noise model (a gyro bias at rest of 1.7 deg/s against the stated 0.11:
// ZuptIns::OwnErrorsHold) has a covariance that is not this device's; its estimates carry the
// dead reckoning of its own steps with a PDR's errors (the `pdr` estimator's covariance on the
// same steps) on top of the filter's, written out here at every step end; a note says so.
TEST(InsEstimator, AnInsOutsideItsModelCarriesItsStepsDeadReckoningWithAPdrsErrors) {
  Walked w = SimulatedFoot();
  for (auto& s : w.imu) s.gyro_b.z() += 0.03;
  const Output out = RunEstimator(w, {});
  const NodeInfo& agent = FirstAgent(w.info);
  DeadReckoningEstimator pdr(w.info);
  pdr.StepsFromFootIns(agent.id, true);
  NullSink none;
  std::map<double, Mat2> dr_at;
  ASSERT_GT(out.steps.size(), 50u);
  for (const Step& step : out.steps) {
    EXPECT_FALSE(step.heading_var_rad2.has_value());  // (the INS says so on its steps)
    pdr.Add(MissionRow(step), none);
    const Estimate e = *pdr.Current(agent.id);
    dr_at[step.t1] = Mat2{{e.sxx, e.sxy}, {e.sxy, e.syy}};
  }
  const auto states = ByTime(out);
  std::size_t checked = 0;
  for (const Estimate& e : out.estimates) {
    const auto dr = dr_at.find(e.t);
    if (dr == dr_at.end()) continue;
    const Mat3& filter = states.at(e.t)->position_cov;
    const double foot = std::pow(InsEstimatorOptions{}.foot_offset_sigma_m, 2);
    EXPECT_NEAR(e.sxx, filter(0, 0) + dr->second(0, 0) + foot, 1e-12);
    EXPECT_NEAR(e.sxy, filter(0, 1) + dr->second(0, 1), 1e-12);
    EXPECT_NEAR(e.syy, filter(1, 1) + dr->second(1, 1) + foot, 1e-12);
    ++checked;
  }
  EXPECT_EQ(checked, out.steps.size());
  // Wider than the filter's own with the start's (what the estimator writes for an INS that
  // holds its model) by the end of the walk.
  const Estimate& last = out.estimates.back();
  const InsState& st = *states.at(last.t);
  const Mat2 own = st.position_cov.topLeftCorner<2, 2>() +
                   StartVariance(w.info, st, InsEstimatorOptions{}.track_heading_offset_sigma_rad);
  EXPECT_GT(last.sxx + last.syy, own.trace());
  InsEstimator estimator(w.info, {});
  VectorSink sink;
  for (const auto& s : w.imu) estimator.Add(MissionRow(s), sink);
  estimator.Finish(sink);
  const auto notes = estimator.Summary().notes;
  EXPECT_TRUE(std::any_of(notes.begin(), notes.end(), [](const std::string& n) {
    return n.find("dead reckoning with a PDR's errors") != std::string::npos;
  }));
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
    EXPECT_NEAR(e.sxx,
                it->second->position_cov(0, 0) +
                    StartVariance(w.info, *it->second, o.track_heading_offset_sigma_rad)(0, 0),
                1e-12);
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

// SPDX-License-Identifier: MIT
// A separate project using the installed package: estimators of the library driven row by row
// from memory, with no files at all — dead reckoning, and the breadcrumb paper's GEN estimator
// behind the StepFrontEnd (INS steps from a foot IMU, rows in time order).
#include <cstdio>

#include "trailmark/breadcrumb/breadcrumb_estimator.h"
#include "trailmark/ins/dead_reckoning.h"
#include "trailmark/ins/step_front_end.h"
#include "trailmark/sim/imu_sim.h"
#include "trailmark/sim/scenarios.h"

int main() {
  using namespace trailmark;
  SimulatedMission sim = SimulateScenario("office-loop-1lap", 1);

  DeadReckoningEstimator pdr(sim.data.info);
  VectorSink pdr_out;
  for (const auto& step : sim.data.steps) pdr.Add(step, pdr_out);
  const auto end = pdr.Current("ff1");

  ImuSimOptions imu;
  imu.rate_hz = 100;
  AddFootImu(sim, imu, 2);
  StepFrontEnd gen(sim.data.info, {}, RowOrder::kGlobal, Feed::kTimeOrdered,
                   std::make_unique<breadcrumb::BreadcrumbEstimator>(
                       sim.data.info, breadcrumb::BreadcrumbEstimatorOptions{}));
  VectorSink gen_out;
  std::size_t r = 0;  // IMU and RSSI merged by time
  for (const auto& s : sim.data.imu) {
    for (; r < sim.data.rssi.size() && sim.data.rssi[r].t <= s.t; ++r) gen.Add(sim.data.rssi[r], gen_out);
    gen.Add(s, gen_out);
  }
  gen.Finish(gen_out);
  const auto summary = gen.Summary();
  std::printf("pdr: %zu steps, end %.3f %.3f; breadcrumb from the foot IMU: %zu estimates, %g steps\n",
              sim.data.steps.size(), end ? end->position_n.x() : 0.0,
              end ? end->position_n.y() : 0.0, gen_out.rows.size(), summary.numbers.at("steps"));
  return end && !gen_out.rows.empty() && summary.numbers.at("steps") > 50 ? 0 : 1;
}

// A separate project using the installed package: an estimator used with no files at all.
#include <cstdio>

#include "trailmark/pipelines/pdr_pipeline.h"
#include "trailmark/sim/scenarios.h"

int main() {
  const trailmark::SimulatedMission sim = trailmark::SimulateScenario("office-loop-1lap", 1);
  trailmark::DeadReckoning dr(trailmark::Vec3::Zero(), 0.1);
  for (const auto& step : sim.data.steps) dr.AddStep(step);
  std::printf("steps %zu, end %.3f %.3f\n", sim.data.steps.size(), dr.position_n().x(),
              dr.position_n().y());
  return sim.data.steps.empty() ? 1 : 0;
}

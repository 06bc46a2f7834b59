// SPDX-License-Identifier: MIT
#pragma once
// Runs a pipeline of the registry by name on a mission directory (the batch run), for tests.

#include <string>

#include "trailmark/pipelines/batch_run.h"
#include "trailmark/sim/imu_sim.h"
#include "trailmark/sim/scenarios.h"

namespace trailmark::testing {

inline EstimatorSummary RunNamed(const std::string& name, const MissionDirectory& mission,
                                 const OptionValues& options, EstimateSink& sink) {
  return RunBatch(RequirePipeline(name), {mission, options}, sink);
}

inline bool CanRunNamed(const std::string& name, const MissionDirectory& mission) {
  return CanRun(RequirePipeline(name), mission);
}

/// The mission with a simulated 100 Hz foot IMU instead of its steps (the pipelines then run
/// the INS).
inline SimulatedMission WithFootImuOnly(SimulatedMission sim, std::uint64_t seed) {
  ImuSimOptions imu;
  imu.rate_hz = 100;
  AddFootImu(sim, imu, seed);
  sim.data.steps.clear();
  return sim;
}

}  // namespace trailmark::testing

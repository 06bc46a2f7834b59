// SPDX-License-Identifier: MIT
#pragma once
// Runs a pipeline of the registry by name on a mission directory (the batch run), for tests.

#include <string>

#include "trailmark/pipelines/batch_run.h"

namespace trailmark::testing {

inline EstimatorSummary RunNamed(const std::string& name, const MissionDirectory& mission,
                                 const OptionValues& options, EstimateSink& sink) {
  return RunBatch(RequirePipeline(name), {mission, options}, sink);
}

inline bool CanRunNamed(const std::string& name, const MissionDirectory& mission) {
  return CanRun(RequirePipeline(name), mission);
}

}  // namespace trailmark::testing

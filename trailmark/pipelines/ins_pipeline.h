#pragma once
/// `ins`: the zero-velocity-aided INS (ins/zupt_ins.h) on imu.csv. Output: each agent's position
/// at every IMU sample (or at `output_hz`), with its horizontal covariance; diagnostics with
/// steps, stance fraction, biases, gaps and unit warnings. `InsStepsFromImu` turns imu.csv into
/// steps.csv rows so that every steps-based pipeline can start from raw IMU data.

#include <map>
#include <string>

#include "trailmark/ins/zupt_ins.h"
#include "trailmark/pipelines/pipeline.h"

namespace trailmark {

class InsPipeline : public Pipeline {
 public:
  std::string name() const override { return "ins"; }
  std::string description() const override {
    return "zero-velocity-aided INS of raw foot IMU samples (ZUPT/ZARU error-state KF; "
           "detectors shoe, are, mv, mag, adaptive)";
  }
  std::vector<std::string> required_files() const override { return {"imu.csv"}; }
  PipelineSummary Run(const PipelineContext& context, EstimateSink& sink) const override;
};

/// INS options from `--option key=value` (keys in docs/ins.md). Also returns the output rate.
ins::InsOptions InsOptionsFrom(const std::map<std::string, std::string>& values,
                               double* output_hz = nullptr);

/// Runs the INS over every agent of the mission's imu.csv and returns the steps (ordered by t1).
/// `ins_options` as InsOptionsFrom; agents' start and heading from mission.json.
std::vector<Step> InsStepsFromImu(const MissionDirectory& mission,
                                  const std::map<std::string, std::string>& ins_options,
                                  PipelineSummary* summary = nullptr);

}  // namespace trailmark

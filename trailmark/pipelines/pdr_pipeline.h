#pragma once
/// Pedestrian dead reckoning from steps.csv: every agent starts at its `start` (or the single
/// base, spec) and adds its steps. The baseline every other pipeline is compared with.

#include "trailmark/pipelines/pipeline.h"

namespace trailmark {

struct PdrOptions {
  /// Per-axis variance used for a step that has none in steps.csv: (5 cm)^2 + (3 % of length)^2.
  double default_step_noise_m = 0.05;
  double default_step_relative_sigma = 0.03;
};

/// Dead reckoning of one agent, usable without files.
class DeadReckoning {
 public:
  DeadReckoning(const Vec3& start_n, double start_sigma_m, const PdrOptions& options = {});
  /// Adds one step; returns the new estimate (position and horizontal covariance).
  void AddStep(const Step& step);
  const Vec3& position_n() const { return position_n_; }
  const Mat2& covariance() const { return covariance_; }

 private:
  PdrOptions options_;
  Vec3 position_n_;
  Mat2 covariance_;
};

class PdrPipeline : public Pipeline {
 public:
  std::string name() const override { return "pdr"; }
  std::string description() const override {
    return "dead reckoning of PDR steps from each agent's start (baseline)";
  }
  std::vector<std::string> required_files() const override { return {"steps.csv or imu.csv"}; }
  bool CanRun(const MissionDirectory& mission) const override;
  PipelineSummary Run(const PipelineContext& context, EstimateSink& sink) const override;
};

}  // namespace trailmark

#pragma once
/// One zero-velocity INS per agent (ins/zupt_ins.h), created at the agent's first IMU sample
/// with its start and heading from mission.json. Shared by the batch `ins` pipeline, the INS
/// steps of the steps-based pipelines, and their live forms.

#include <functional>
#include <map>
#include <memory>
#include <string>

#include "trailmark/core/mission.h"
#include "trailmark/ins/zupt_ins.h"
#include "trailmark/pipelines/pipeline.h"

namespace trailmark {

class LiveIns {
 public:
  /// `options`: the ins pipeline's `--option` keys (docs/ins.md); throws std::invalid_argument.
  LiveIns(const MissionInfo& info, const std::map<std::string, std::string>& options);
  ~LiveIns();
  /// Adds a sample of its agent (samples of one agent in time order). Positions go to `sink`
  /// (every sample, or at the option output_hz) when it is not null; steps to `on_step`.
  /// Throws std::invalid_argument for a sample the INS refuses or a node that is not an agent.
  void Add(const ImuSample& sample, EstimateSink* sink);
  /// End of data: every agent's INS processes what it still holds.
  void Finish(EstimateSink* sink);
  /// Per agent: samples, steps, stance fraction, distance, gaps, saturation, gyro bias, warnings.
  PipelineSummary Summary() const;
  const ins::InsOptions& options() const { return options_; }

  std::function<void(const Step&)> on_step;

 private:
  struct Agent;
  const MissionInfo& info_;
  ins::InsOptions options_;
  double output_hz_ = 0;
  EstimateSink* sink_ = nullptr;
  std::map<std::string, std::unique_ptr<Agent>> agents_;
};

}  // namespace trailmark

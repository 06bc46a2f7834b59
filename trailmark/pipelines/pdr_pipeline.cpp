#include "trailmark/pipelines/pdr_pipeline.h"

#include <fmt/format.h>

#include <map>

#include "trailmark/core/error.h"
#include "trailmark/pipelines/pipeline_options.h"
#include "trailmark/pipelines/step_source.h"

namespace trailmark {

DeadReckoning::DeadReckoning(const Vec3& start_n, double start_sigma_m, const PdrOptions& options)
    : options_(options), position_n_(start_n) {
  covariance_ = Mat2::Identity() * start_sigma_m * start_sigma_m;
}

void DeadReckoning::AddStep(const Step& step) {
  position_n_ += step.delta_n;
  if (step.variance_m2) {
    covariance_(0, 0) += step.variance_m2->x();
    covariance_(1, 1) += step.variance_m2->y();
  } else {
    const double s = options_.default_step_noise_m +
                     options_.default_step_relative_sigma * step.delta_n.head<2>().norm();
    covariance_ += Mat2::Identity() * s * s;
  }
}

bool PdrPipeline::CanRun(const MissionDirectory& mission) const { return HasSteps(mission); }

PipelineSummary PdrPipeline::Run(const PipelineContext& context, EstimateSink& sink) const {
  const MissionDirectory& mission = context.mission;
  PipelineSummary summary;
  const auto [ins_options, rest] = SplitInsOptions(context.options);
  PipelineOptions(rest, "pdr").RejectUnknown();
  StepSource reader(mission, ins_options, "the pdr pipeline", &summary);
  std::map<std::string, DeadReckoning> agents;
  std::map<std::string, std::size_t> step_counts;
  Step step;
  std::size_t rows = 0;
  while (reader.Next(step)) {
    auto it = agents.find(step.agent);
    if (it == agents.end()) {
      const NodeInfo* node = mission.info().Find(step.agent);
      if (node == nullptr || node->kind != NodeKind::kAgent) {
        reader.Fail(fmt::format("'{}' has steps but is not an agent in mission.json", step.agent));
      }
      const auto start = mission.info().AgentStart(*node);
      if (!start) {
        reader.Fail(fmt::format(
            "agent '{}' has no 'start' in mission.json and the mission has no single base: "
            "pdr needs a known start",
            step.agent));
      }
      it = agents.emplace(step.agent, DeadReckoning(*start, node->start_sigma_m.value_or(0.0)))
               .first;
      const Mat2& c = it->second.covariance();
      sink.Add({step.t0, step.agent, *start, c(0, 0), c(0, 1), c(1, 1)});
    }
    it->second.AddStep(step);
    ++step_counts[step.agent];
    const Mat2& c = it->second.covariance();
    sink.Add({step.t1, step.agent, it->second.position_n(), c(0, 0), c(0, 1), c(1, 1)});
    if ((++rows & 0x3fff) == 0) context.progress(reader.Progress());
  }
  context.progress(1.0);
  summary.numbers["steps"] = static_cast<double>(rows);
  summary.numbers["agents"] = static_cast<double>(agents.size());
  for (const auto& [id, n] : step_counts) summary.notes.push_back(fmt::format("{}: {} steps", id, n));
  return summary;
}

}  // namespace trailmark

#include "trailmark/pipelines/live_ins.h"

#include <fmt/format.h>

#include <cmath>
#include <stdexcept>

#include "trailmark/pipelines/ins_pipeline.h"

namespace trailmark {

struct LiveIns::Agent {
  std::unique_ptr<ins::ZuptIns> ins;
  double next_output = -1e300;
};

LiveIns::LiveIns(const MissionInfo& info, const std::map<std::string, std::string>& options)
    : info_(info), options_(InsOptionsFrom(options, &output_hz_)) {}

LiveIns::~LiveIns() = default;

void LiveIns::Add(const ImuSample& sample, EstimateSink* sink) {
  sink_ = sink;
  auto it = agents_.find(sample.agent);
  if (it == agents_.end()) {
    const NodeInfo* node = info_.Find(sample.agent);
    if (node == nullptr || node->kind != NodeKind::kAgent) {
      throw std::invalid_argument(
          fmt::format("'{}' has IMU samples but is not an agent in mission.json", sample.agent));
    }
    ins::InsOptions o = options_;
    if (auto start = info_.AgentStart(*node)) o.initial_position_n = *start;
    if (node->start_heading_rad) o.initial_yaw_rad = *node->start_heading_rad;
    it = agents_.emplace(sample.agent, std::make_unique<Agent>()).first;
    Agent* a = it->second.get();
    a->ins = std::make_unique<ins::ZuptIns>(o);
    const std::string id = sample.agent;
    a->ins->on_state = [this, id, a](const ins::InsState& st) {
      if (sink_ == nullptr) return;
      if (output_hz_ > 0 && st.t < a->next_output) return;
      a->next_output = st.t + (output_hz_ > 0 ? 1.0 / output_hz_ : 0.0);
      const auto& c = st.position_cov;
      sink_->Add({st.t, id, st.position_n, c(0, 0), c(0, 1), c(1, 1)});
    };
    a->ins->on_step = [this](const Step& step) {
      if (on_step) on_step(step);
    };
  }
  it->second->ins->Add(sample);
}

void LiveIns::Finish(EstimateSink* sink) {
  sink_ = sink;
  for (auto& [id, a] : agents_) {
    try {
      a->ins->Finish();
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(id + ": " + e.what());
    }
  }
}

PipelineSummary LiveIns::Summary() const {
  PipelineSummary summary;
  for (const auto& [id, a] : agents_) {
    const auto& s = a->ins->summary();
    summary.numbers[id + ".samples"] = static_cast<double>(s.samples);
    summary.numbers[id + ".steps"] = static_cast<double>(s.steps);
    summary.numbers[id + ".stance_fraction"] =
        s.samples ? static_cast<double>(s.stance_samples) / s.samples : 0.0;
    summary.numbers[id + ".distance_m"] = s.distance_m;
    summary.numbers[id + ".gaps"] = static_cast<double>(s.gaps);
    summary.numbers[id + ".saturated_samples"] = static_cast<double>(s.saturated);
    summary.numbers[id + ".gyro_bias_z_deg_per_h"] = s.gyro_bias.z() * 180 / M_PI * 3600;
    for (const auto& w : s.warnings) summary.notes.push_back(id + ": " + w);
  }
  summary.notes.push_back("detector: " + ins::ToString(options_.detector.kind));
  return summary;
}

}  // namespace trailmark

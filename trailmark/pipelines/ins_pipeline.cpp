#include "trailmark/pipelines/ins_pipeline.h"

#include <fmt/format.h>

#include <algorithm>
#include <map>
#include <memory>

#include "trailmark/core/error.h"
#include "trailmark/pipelines/pipeline_options.h"

namespace trailmark {

ins::InsOptions InsOptionsFrom(const std::map<std::string, std::string>& values, double* output_hz) {
  PipelineOptions o(values, "ins");
  ins::InsOptions x;
  x.detector.kind = ins::ParseDetectorKind(o.String("detector", ins::ToString(x.detector.kind)));
  if (values.count("window")) x.detector.window_s = 0;  // an explicit sample count wins
  x.detector.window = static_cast<int>(o.Double("window", x.detector.window));
  x.detector.window_s = o.Double("window_s", x.detector.window_s);
  if (values.count("gamma")) x.detector.gamma = o.Double("gamma", 0);
  else o.Double("gamma", 0);
  x.detector.sigma_a_mps2 = o.Double("detector_sigma_a", x.detector.sigma_a_mps2);
  x.detector.sigma_g_radps = o.Double("detector_sigma_g", x.detector.sigma_g_radps);
  x.detector.adaptive_reference = o.Double("adaptive_reference", x.detector.adaptive_reference);
  x.detector.adaptive_power = o.Double("adaptive_power", x.detector.adaptive_power);
  x.detector.adaptive_min_scale = o.Double("adaptive_min_scale", x.detector.adaptive_min_scale);
  x.detector.adaptive_max_scale = o.Double("adaptive_max_scale", x.detector.adaptive_max_scale);
  x.detector.adaptive_tau_s = o.Double("adaptive_tau_s", x.detector.adaptive_tau_s);
  x.accel_noise_mps2 = o.Double("accel_noise", x.accel_noise_mps2);
  x.gyro_noise_radps = o.Double("gyro_noise", x.gyro_noise_radps);
  x.estimate_biases = o.Bool("biases", x.estimate_biases);
  x.zaru = o.Bool("zaru", x.zaru);
  x.zaru_sigma_radps = o.Double("zaru_sigma", x.zaru_sigma_radps);
  x.zupt_sigma_mps = o.Double("zupt_sigma", x.zupt_sigma_mps);
  x.zaru_gate_chi2 = o.Double("zaru_gate", x.zaru_gate_chi2);
  x.alignment_s = o.Double("alignment_s", x.alignment_s);
  x.gravity_mps2 = o.Double("gravity", x.gravity_mps2);
  const double hz = o.Double("output_hz", 0.0);
  if (output_hz) *output_hz = hz;
  o.RejectUnknown();
  if (x.detector.window < 1 || !(x.zupt_sigma_mps > 0) || !(x.accel_noise_mps2 > 0) ||
      !(x.gyro_noise_radps > 0) || !(x.alignment_s >= 0) || !(hz >= 0)) {
    throw std::invalid_argument("pipeline ins: window >= 1; sigmas, noises, periods > 0");
  }
  return x;
}

namespace {

/// One INS per agent, created at the agent's first sample.
struct AgentIns {
  std::unique_ptr<ins::ZuptIns> ins;
  double next_output = -1e300;
};

ins::InsOptions ForAgent(const MissionDirectory& mission, const std::string& id,
                         ins::InsOptions o) {
  if (const NodeInfo* n = mission.info().Find(id)) {
    if (auto start = mission.info().AgentStart(*n)) o.initial_position_n = *start;
    if (n->start_heading_rad) o.initial_yaw_rad = *n->start_heading_rad;
  }
  return o;
}

}  // namespace

PipelineSummary InsPipeline::Run(const PipelineContext& context, EstimateSink& sink) const {
  const MissionDirectory& mission = context.mission;
  mission.Require("imu.csv", "the ins pipeline");
  double output_hz = 0;
  const ins::InsOptions options = InsOptionsFrom(context.options, &output_hz);
  std::map<std::string, AgentIns> agents;
  auto reader = mission.OpenStream<ImuSample>();
  const double size = std::max<double>(1.0, static_cast<double>(reader.csv().file_size()));
  ImuSample s;
  std::size_t rows = 0;
  while (reader.Next(s)) {
    auto it = agents.find(s.agent);
    if (it == agents.end()) {
      const NodeInfo* node = mission.info().Find(s.agent);
      if (node == nullptr || node->kind != NodeKind::kAgent) {
        reader.csv().Fail(fmt::format("'{}' has IMU samples but is not an agent in mission.json",
                                      s.agent));
      }
      it = agents.emplace(s.agent, AgentIns{}).first;
      it->second.ins = std::make_unique<ins::ZuptIns>(ForAgent(mission, s.agent, options));
      const std::string id = s.agent;
      AgentIns* a = &it->second;
      a->ins->on_state = [&sink, id, a, output_hz](const ins::InsState& st) {
        if (output_hz > 0 && st.t < a->next_output) return;
        a->next_output = st.t + (output_hz > 0 ? 1.0 / output_hz : 0.0);
        const auto& c = st.position_cov;
        sink.Add({st.t, id, st.position_n, c(0, 0), c(0, 1), c(1, 1)});
      };
    }
    try {
      it->second.ins->Add(s);
    } catch (const std::invalid_argument& e) {
      reader.csv().Fail(e.what());
    }
    if ((++rows & 0xffff) == 0) context.progress(reader.csv().bytes_read() / size);
  }
  PipelineSummary summary;
  for (auto& [id, a] : agents) {
    try {
      a.ins->Finish();
    } catch (const std::invalid_argument& e) {
      throw InputError(mission.Path("imu.csv").string(), 0, id + ": " + e.what());
    }
    const auto& s = a.ins->summary();
    summary.numbers[id + ".samples"] = static_cast<double>(s.samples);
    summary.numbers[id + ".steps"] = static_cast<double>(s.steps);
    summary.numbers[id + ".stance_fraction"] =
        s.samples ? static_cast<double>(s.stance_samples) / s.samples : 0.0;
    summary.numbers[id + ".distance_m"] = s.distance_m;
    summary.numbers[id + ".gaps"] = static_cast<double>(s.gaps);
    summary.numbers[id + ".saturated_samples"] = static_cast<double>(s.saturated);
    summary.numbers[id + ".gyro_bias_z_deg_per_h"] = s.gyro_bias.z() * 180 / 3.14159265358979 * 3600;
    for (const auto& w : s.warnings) summary.notes.push_back(id + ": " + w);
  }
  summary.notes.push_back("detector: " + ins::ToString(options.detector.kind));
  context.progress(1.0);
  return summary;
}

std::vector<Step> InsStepsFromImu(const MissionDirectory& mission, const ins::InsOptions& options,
                                  PipelineSummary* summary) {
  std::map<std::string, std::unique_ptr<ins::ZuptIns>> agents;
  std::vector<Step> steps;
  auto reader = mission.OpenStream<ImuSample>();
  ImuSample s;
  while (reader.Next(s)) {
    auto& ins = agents[s.agent];
    if (!ins) {
      const NodeInfo* node = mission.info().Find(s.agent);
      if (node == nullptr || node->kind != NodeKind::kAgent) {
        reader.csv().Fail(fmt::format("'{}' has IMU samples but is not an agent in mission.json",
                                      s.agent));
      }
      ins = std::make_unique<ins::ZuptIns>(ForAgent(mission, s.agent, options));
      ins->on_step = [&steps](const Step& st) { steps.push_back(st); };
    }
    try {
      ins->Add(s);
    } catch (const std::invalid_argument& e) {
      reader.csv().Fail(e.what());
    }
  }
  for (auto& [id, ins] : agents) {
    ins->Finish();
    if (summary) {
      summary->numbers["ins." + id + ".steps"] = static_cast<double>(ins->summary().steps);
      for (const auto& w : ins->summary().warnings) summary->notes.push_back("ins " + id + ": " + w);
    }
  }
  std::stable_sort(steps.begin(), steps.end(), [](const Step& a, const Step& b) { return a.t1 < b.t1; });
  return steps;
}

}  // namespace trailmark

#include "trailmark/pipelines/ins_pipeline.h"

#include <fmt/format.h>

#include <algorithm>
#include <map>
#include <memory>

#include "trailmark/core/error.h"
#include "trailmark/pipelines/live_ins.h"
#include "trailmark/pipelines/pipeline_options.h"

namespace trailmark {

ins::InsOptions InsOptionsFrom(const std::map<std::string, std::string>& values, double* output_hz) {
  PipelineOptions o(values, "ins");
  ins::InsOptions x;
  x.detector.kind = ins::ParseDetectorKind(o.String("detector", ins::ToString(x.detector.kind)));
  if (values.count("window")) x.detector.window_s = 0;  // an explicit sample count wins
  x.detector.window = static_cast<int>(o.Whole("window", x.detector.window, 1, 100000));
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

PipelineSummary InsPipeline::Run(const PipelineContext& context, EstimateSink& sink) const {
  const MissionDirectory& mission = context.mission;
  mission.Require("imu.csv", "the ins pipeline");
  LiveIns ins(mission.info(), context.options);
  auto reader = mission.OpenStream<ImuSample>();
  const double size = std::max<double>(1.0, static_cast<double>(reader.csv().file_size()));
  ImuSample s;
  std::size_t rows = 0;
  while (reader.Next(s)) {
    try {
      ins.Add(s, &sink);
    } catch (const std::invalid_argument& e) {
      reader.csv().Fail(e.what());
    }
    if ((++rows & 0xffff) == 0) context.progress(reader.csv().bytes_read() / size);
  }
  try {
    ins.Finish(&sink);
  } catch (const std::invalid_argument& e) {
    throw InputError(mission.Path("imu.csv").string(), 0, e.what());
  }
  context.progress(1.0);
  return ins.Summary();
}

std::vector<Step> InsStepsFromImu(const MissionDirectory& mission,
                                  const std::map<std::string, std::string>& ins_options,
                                  PipelineSummary* summary) {
  LiveIns ins(mission.info(), ins_options);
  std::vector<Step> steps;
  ins.on_step = [&steps](const Step& st) { steps.push_back(st); };
  auto reader = mission.OpenStream<ImuSample>();
  ImuSample s;
  while (reader.Next(s)) {
    try {
      ins.Add(s, nullptr);
    } catch (const std::invalid_argument& e) {
      reader.csv().Fail(e.what());
    }
  }
  try {
    ins.Finish(nullptr);
  } catch (const std::invalid_argument& e) {
    throw InputError(mission.Path("imu.csv").string(), 0, e.what());
  }
  if (summary) {
    const PipelineSummary s = ins.Summary();
    for (const auto& [key, value] : s.numbers) {
      if (key.size() > 6 && key.compare(key.size() - 6, 6, ".steps") == 0) {
        summary->numbers["ins." + key] = value;
      }
    }
    for (const auto& note : s.notes) {
      if (note.rfind("detector: ", 0) != 0) summary->notes.push_back("ins " + note);
    }
  }
  std::stable_sort(steps.begin(), steps.end(), [](const Step& a, const Step& b) { return a.t1 < b.t1; });
  return steps;
}

}  // namespace trailmark

// SPDX-License-Identifier: MIT
// `trailmark bench ins --mission DIR`: the foot INS on a mission's imu.csv, two ways, best of
// several runs (issue 31):
//  - core: the samples already in memory, through the INS of every agent (detector + filter +
//    steps), nothing written — what another implementation's filter loop compares with;
//  - end to end: `trailmark run --pipeline ins` in process (read imu.csv, estimate, write
//    estimates.csv and diagnostics.json), at the default output rate and at every sample.

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <unistd.h>

#include "commands.h"
#include "trailmark/core/error.h"
#include "trailmark/ins/ins_estimator.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/pipelines/batch_run.h"
#include "trailmark/pipelines/registry.h"

namespace trailmark::cli {

namespace fs = std::filesystem;

int BenchIns(const fs::path& mission_dir, int runs, const OptionValues& options,
             const fs::path& json_out) {
  if (runs < 1) throw std::invalid_argument("bench ins: --runs must be >= 1");
  ins::InsEstimatorOptions parsed;
  std::string why;
  if (!ins::InsEstimatorOptionTable().Apply(options, &parsed, &why) || !parsed.IsValid(&why)) {
    throw std::invalid_argument("bench ins: " + why);
  }
  const MissionDirectory mission(mission_dir);
  mission.Require("imu.csv", "bench ins");
  const std::vector<ImuSample> imu =
      ReadAll<ImuSample>(mission.Path("imu.csv").string(), &mission.registry());
  if (imu.empty()) throw InputError(mission.Path("imu.csv").string(), 0, "no IMU samples");
  using Clock = std::chrono::steady_clock;
  auto seconds = [](Clock::time_point a) {
    return std::chrono::duration<double>(Clock::now() - a).count();
  };

  double core_s = 1e300;
  std::size_t steps = 0;
  for (int r = 0; r < runs; ++r) {
    const auto t0 = Clock::now();
    ins::MultiAgentIns ins(mission.info(), parsed.ins);
    std::size_t n = 0;
    ins.on_step = [&](const Step&) { ++n; };
    for (const auto& s : imu) ins.Add(s);
    ins.Finish();
    core_s = std::min(core_s, seconds(t0));
    steps = n;
  }

  const fs::path out = fs::temp_directory_path() / fmt::format("trailmark-bench-ins-{}", ::getpid());
  const PipelineSpec& pipeline = RequirePipeline("ins");
  auto end_to_end = [&](const OptionValues& options, std::size_t* estimates) {
    double best = 1e300;
    for (int r = 0; r < runs; ++r) {
      const auto t0 = Clock::now();
      const MissionDirectory m(mission_dir);  // reading mission.json is part of a run
      PipelineContext context{m, options};
      const RunResult result = RunPipeline(pipeline, context, out);
      best = std::min(best, seconds(t0));
      *estimates = result.estimates;
    }
    return best;
  };
  std::size_t rows_default = 0, rows_every = 0;
  const double default_s = end_to_end(options, &rows_default);
  OptionValues every = options;
  every["output"] = "rate";
  every["output_hz"] = "0";
  const double every_s = end_to_end(every, &rows_every);
  std::error_code ignored;
  fs::remove_all(out, ignored);

  const double n = static_cast<double>(imu.size());
  const double duration_s = imu.back().t - imu.front().t;
  const ins::InsEstimatorOptions& defaults = parsed;
  fmt::print("{}: {} IMU samples ({:.0f} s), {} steps; best of {} runs\n", mission_dir.string(),
             imu.size(), duration_s, steps, runs);
  fmt::print("  core (in memory: detector + filter + steps)  {:>10.0f} samples/s  {:>8.2f} ms\n",
             n / core_s, core_s * 1e3);
  const std::string output =
      defaults.output == ins::InsOutput::kSteps ? std::string("step ends")
      : defaults.output_hz > 0                  ? fmt::format("{:g} Hz + step ends", defaults.output_hz)
                                                : std::string("every sample");
  fmt::print("  end to end, output {} ({} rows)  {:>10.0f} samples/s  {:>8.2f} ms\n", output,
             rows_default, n / default_s, default_s * 1e3);
  fmt::print("  end to end, every sample ({} rows)  {:>10.0f} samples/s  {:>8.2f} ms\n",
             rows_every, n / every_s, every_s * 1e3);
  if (!json_out.empty()) {
    nlohmann::json j;
    j["mission"] = mission_dir.string();
    j["samples"] = imu.size();
    j["steps"] = steps;
    j["runs"] = runs;
    j["options"] = options;
    j["core_samples_per_s"] = n / core_s;
    j["end_to_end_samples_per_s"] = n / default_s;
    j["end_to_end_rows"] = rows_default;
    j["end_to_end_output"] = output;
    j["end_to_end_every_sample_samples_per_s"] = n / every_s;
    j["end_to_end_every_sample_rows"] = rows_every;
    std::ofstream(json_out) << j.dump(2) << "\n";
  }
  return 0;
}

}  // namespace trailmark::cli

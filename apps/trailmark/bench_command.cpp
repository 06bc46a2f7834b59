// SPDX-License-Identifier: MIT
// `trailmark bench`: rows/s reading and writing each stream kind, and the pdr pipeline on the
// default mission, as a table and JSON. Google Benchmark (bench/) measures the same kernels.

#include <fmt/format.h>

#include <chrono>
#include <fstream>
#include <nlohmann/json.hpp>

#include "commands.h"
#include "progress.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/pipelines/batch_run.h"
#include "trailmark/sim/scenarios.h"
#include "trailmark/sim/synthetic_streams.h"

namespace trailmark::cli {

namespace fs = std::filesystem;

namespace {

double Seconds(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

template <class Row>
nlohmann::json BenchStream(const std::string& kind, const std::vector<Row>& rows,
                           const fs::path& dir) {
  const fs::path path = dir / StreamFileName<Row>();
  auto t0 = std::chrono::steady_clock::now();
  WriteAll<Row>(path.string(), rows);
  const double write_s = Seconds(t0);
  t0 = std::chrono::steady_clock::now();
  RowReader<Row> reader(path.string());
  Row row;
  std::size_t n = 0;
  while (reader.Next(row)) ++n;
  const double read_s = Seconds(t0);
  const auto bytes = fs::file_size(path);
  return {{"kind", kind},
          {"rows", n},
          {"bytes", bytes},
          {"write_rows_per_s", rows.size() / write_s},
          {"read_rows_per_s", n / read_s},
          {"read_mb_per_s", bytes / read_s / 1e6}};
}

}  // namespace

int Bench(std::size_t rows, const fs::path& json_out) {
  const fs::path dir = fs::temp_directory_path() / fmt::format("trailmark-bench-{}", ::getpid());
  fs::create_directories(dir);
  nlohmann::json results = nlohmann::json::array();
  ProgressBar bar("bench");
  results.push_back(BenchStream("imu", SyntheticImu(rows, 1), dir));
  bar.Update(0.3);
  results.push_back(BenchStream("steps", SyntheticSteps(rows, 2), dir));
  bar.Update(0.45);
  results.push_back(BenchStream("rssi", SyntheticRssi(rows, 3), dir));
  bar.Update(0.6);
  results.push_back(BenchStream("truth", SyntheticTruth(rows, 4), dir));
  bar.Update(0.75);
  results.push_back(BenchStream("estimates", SyntheticEstimates(rows, 5), dir));
  bar.Update(0.85);

  // pdr on the default mission.
  const fs::path mission_dir = dir / "mission";
  const SimulatedMission sim = SimulateScenario("office-loop", 1);
  WriteMissionDirectory(mission_dir, sim.data, &sim.plan);
  const double duration = sim.data.truth.back().t - sim.data.truth.front().t;
  const MissionDirectory mission(mission_dir);
  const PipelineSpec* pdr = nullptr;  // the baseline (dead reckoning)
  for (const auto& p : Pipelines()) {
    if (p.baseline && !pdr) pdr = &p;
  }
  double best = 1e30;
  for (int rep = 0; rep < 5; ++rep) {
    PipelineContext ctx{mission, {}, [](double) {}};
    best = std::min(best, RunPipeline(*pdr, ctx, dir / "run").wall_time_s);
  }
  bar.Finish();
  fs::remove_all(dir);

  fmt::print("{:<10} {:>10} {:>12} {:>16} {:>16} {:>10}\n", "stream", "rows", "bytes",
             "write rows/s", "read rows/s", "read MB/s");
  for (const auto& r : results) {
    fmt::print("{:<10} {:>10} {:>12} {:>16.3g} {:>16.3g} {:>10.1f}\n", r["kind"].get<std::string>(),
               r["rows"].get<std::size_t>(), r["bytes"].get<std::size_t>(),
               r["write_rows_per_s"].get<double>(), r["read_rows_per_s"].get<double>(),
               r["read_mb_per_s"].get<double>());
  }
  fmt::print("\npdr pipeline on office-loop ({} steps, {:.0f} s mission): {:.4f} s "
             "(best of 5) = {:.0f}x real time\n",
             sim.data.steps.size(), duration, best, duration / best);
  nlohmann::json out = {{"io", results},
                        {pdr->name, {{"mission_s", duration},
                                 {"steps", sim.data.steps.size()},
                                 {"wall_s", best},
                                 {"x_real_time", duration / best}}}};
  if (!json_out.empty()) {
    std::ofstream(json_out) << out.dump(2) << "\n";
    fmt::print("written to {}\n", json_out.string());
  }
  return 0;
}

}  // namespace trailmark::cli

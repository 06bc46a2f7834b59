// SPDX-License-Identifier: MIT
// `trailmark reproduce landmark-tracking` (issue 24): landmarks-ukf's default tracker (the
// error-state filter of landmarks/landmark_tracker.h), the paper's UKF (`filter=paper`) and dead
// reckoning (`pdr`) on the scenarios the issue names — the office with 16 ceiling BLE landmarks,
// no radio model and no stop/go events (`landmark-office`), the multi-floor building with
// surveyed landmarks on every level (`multi-floor-landmarks`) — and on the paper's corridor; per
// arm over the seeds: the agents' p75 (median and worst run), in95, runs worse than dead
// reckoning by more than 10 % at p75, and the unknown landmarks placed with their final error.

#include <fmt/format.h>

#include <algorithm>

#include "experiments/experiments.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/sim/scenarios.h"

namespace trailmark::experiments {

namespace fs = std::filesystem;

namespace {

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

}  // namespace

int ReproduceLandmarkTracking(int seeds, const fs::path& out, int first_seed,
                              const OptionValues& options) {
  struct Arm {
    std::string label, pipeline;
    OptionValues options;
  };
  std::string ours = "landmarks-ukf (error-state, default)";
  for (const auto& [k, v] : options) ours += fmt::format(" {}={}", k, v);
  const std::vector<Arm> arms = {{ours, "landmarks-ukf", options},
                                 {"landmarks-ukf filter=paper", "landmarks-ukf", {{"filter", "paper"}}},
                                 {"pdr (dead reckoning)", "pdr", {}}};
  std::string text = fmt::format(
      "Seeds {}..{} (`--seeds N --first-seed K`). p75: the agents' pooled p75 per run, the median "
      "run and the worst; in95: share of the agents' truth inside their own 95 % ellipse (mean "
      "over runs; honest: 85-99 %); worse: runs whose p75 is more than 10 % above dead "
      "reckoning's; unknown landmarks: placed of declared, the median of their final errors and "
      "their in95.\n\n"
      "| scenario | arm | p75 m (median) | p75 m (worst) | in95 % | worse than DR | unknown landmarks | final m (median) | in95 % |\n"
      "|---|---|---|---|---|---|---|---|---|\n",
      first_seed, first_seed + seeds - 1);
  for (const std::string scenario : {"landmark-office", "multi-floor-landmarks", "landmark-corridor"}) {
    std::vector<std::vector<double>> p75(arms.size()), in95(arms.size()), final_m(arms.size()),
        lm_in95(arms.size());
    std::vector<int> worse(arms.size(), 0), declared(arms.size(), 0);
    for (int k = 0; k < seeds; ++k) {
      const std::uint64_t seed = static_cast<std::uint64_t>(first_seed + k);
      const fs::path dir = out / "runs" / fmt::format("{}-{}", scenario, seed);
      const SimulatedMission sim = SimulateScenario(scenario, seed);
      WriteMissionDirectory(dir / "mission", sim.data, &sim.plan);
      std::vector<Metrics> m;
      for (std::size_t a = 0; a < arms.size(); ++a) {
        m.push_back(RunAndEvaluate(arms[a].pipeline, dir / "mission", dir / fmt::format("arm{}", a),
                                   nullptr, arms[a].options));
      }
      const double dr_p75 = m.back().agents.stats.p75_m;
      for (std::size_t a = 0; a < arms.size(); ++a) {
        p75[a].push_back(m[a].agents.stats.p75_m);
        in95[a].push_back(m[a].agents.stats.in95);
        worse[a] += m[a].agents.stats.p75_m > 1.1 * dr_p75;
        for (const NodeMetrics& n : m[a].nodes) {
          const NodeInfo* info = sim.data.info.Find(n.id);
          if (n.kind != NodeKind::kLandmark || info == nullptr || info->position) continue;
          ++declared[a];
          if (n.stats.samples == 0) continue;
          final_m[a].push_back(n.stats.final_m);
          lm_in95[a].push_back(n.stats.in95);
        }
      }
    }
    for (std::size_t a = 0; a < arms.size(); ++a) {
      const bool landmarks = arms[a].pipeline != "pdr" && declared[a] > 0;
      text += fmt::format(
          "| {} | {} | {:.2f} | {:.2f} | {:.0f} | {} | {} | {} | {} |\n", scenario, arms[a].label,
          Median(p75[a]), p75[a].empty() ? 0.0 : *std::max_element(p75[a].begin(), p75[a].end()),
          100 * Mean(in95[a]), a + 1 == arms.size() ? "-" : fmt::format("{}/{}", worse[a], seeds),
          landmarks ? fmt::format("{}/{}", final_m[a].size(), declared[a]) : "-",
          landmarks && !final_m[a].empty() ? fmt::format("{:.2f}", Median(final_m[a])) : "-",
          landmarks && !lm_in95[a].empty() ? fmt::format("{:.0f}", 100 * Mean(lm_in95[a])) : "-");
    }
    fmt::print(stderr, "landmark-tracking: {} done\n", scenario);
  }
  return WriteReproduction(out, "Radio-landmark tracking with the motion's real error (issue 24)",
                           text);
}

}  // namespace trailmark::experiments

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
#include <stdexcept>
#include <string>

#include "experiments/ble_flat.h"
#include "experiments/experiments.h"
#include "trailmark/core/random.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/sim/pdr_error_model.h"
#include "trailmark/sim/scenarios.h"

namespace trailmark::experiments {

namespace fs = std::filesystem;

namespace {

/// The recorded BLE flat (../shared/data/ble-rss-flat, Kolakowski 2021, CC BY 4.0) as missions:
/// each robot run with positions (the four calibration sessions, split at gaps over 60 s, and
/// the test path) with its recorded RSSI from the 6 anchors (surveyed, 3-D), the robot's
/// LiDAR-SLAM positions as truth, and odometry steps made from those positions by the
/// simulator's PDR error model (heading drift, turn and step scale, noise) drawn from `seed`:
/// recorded radio, simulated motion errors. The tag is 1.3 m up: the agent's z is 0.1 m under
/// the trackers' 1.2 m handheld height. No radio calibration is given.
std::vector<MissionData> BleFlatRuns(const fs::path& dir, std::uint64_t seed) {
  std::vector<MissionData> runs;
  if (!fs::exists(dir / "anchors.csv")) return runs;
  const std::vector<Vec3> anchors = ReadBleFlatAnchors(dir);
  using Row = BleFlatRow;
  std::vector<std::vector<Row>> sessions;
  for (const char* file : {"calibration_df.csv", "test_robot_df.csv"}) {
    std::vector<Row> rows;
    for (Row& row : ReadBleFlatRows(dir / file, anchors.size())) {
      if (!row.xy) throw std::invalid_argument(std::string(file) + ": no x/y columns");
      if (!rows.empty() && row.t_s - rows.back().t_s > 60.0) {
        sessions.push_back(std::move(rows));
        rows.clear();
      }
      rows.push_back(std::move(row));
    }
    if (!rows.empty()) sessions.push_back(std::move(rows));
  }
  Random rng(seed);
  for (std::size_t k = 0; k < sessions.size(); ++k) {
    const std::vector<Row>& rows = sessions[k];
    if (rows.size() < 20) continue;
    MissionData m;
    m.info.name = fmt::format("ble-rss-flat-run{}", k + 1);
    const double t0 = rows.front().t_s;
    const Vec2 start = *rows.front().xy;
    const Vec2 first_move = *rows[std::min<std::size_t>(5, rows.size() - 1)].xy - start;
    m.info.nodes.push_back(NodeInfo::Agent("robot", Vec3(start.x(), start.y(), 0.1), 0.1,
                                           std::atan2(first_move.y(), first_move.x()), 0.05));
    for (std::size_t a = 0; a < anchors.size(); ++a) {
      NodeInfo n;
      n.id = fmt::format("a{}", a + 1);
      n.kind = NodeKind::kLandmark;
      n.position = anchors[a];
      n.position_sigma_m = 0.05;
      m.info.nodes.push_back(n);
      m.truth.push_back({0.0, n.id, anchors[a]});
    }
    PdrErrorModel pdr(PdrErrorOptions{}, rng.Fork());
    for (std::size_t i = 0; i < rows.size(); ++i) {
      const double t = rows[i].t_s - t0;
      m.truth.push_back({t, "robot", Vec3(rows[i].xy->x(), rows[i].xy->y(), 0.1)});
      for (std::size_t a = 0; a < anchors.size(); ++a) {
        if (rows[i].rssi_dbm[a]) m.rssi.push_back({t, fmt::format("a{}", a + 1), "robot", *rows[i].rssi_dbm[a]});
      }
      if (i == 0) continue;
      const Vec2 d_true = *rows[i].xy - *rows[i - 1].xy;
      const Vec2 d = pdr.Apply(d_true, t - (rows[i - 1].t_s - t0));
      const double var = pdr.ReportedVariance(d_true.norm());
      m.steps.push_back({rows[i - 1].t_s - t0, t, "robot", Vec3(d.x(), d.y(), 0.0), Vec3(var, var, 1e-4)});
    }
    std::stable_sort(m.truth.begin(), m.truth.end(), [](const auto& x, const auto& y) { return x.t < y.t; });
    runs.push_back(std::move(m));
  }
  return runs;
}

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

}  // namespace

int ReproduceLandmarkTracking(int seeds, const fs::path& out, int first_seed,
                              const OptionValues& options, const fs::path& data_dir) {
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
  // Recorded RSSI: the BLE flat's robot runs, odometry errors drawn per seed.
  std::vector<std::vector<double>> p75(arms.size()), in95(arms.size());
  std::vector<int> worse(arms.size(), 0);
  int runs = 0;
  for (int k = 0; k < seeds; ++k) {
    const std::uint64_t seed = static_cast<std::uint64_t>(first_seed + k);
    std::vector<MissionData> missions = BleFlatRuns(data_dir / "ble-rss-flat", seed);
    for (std::size_t r = 0; r < missions.size(); ++r) {
      const fs::path dir = out / "runs" / fmt::format("ble-rss-flat-{}-run{}", seed, r + 1);
      WriteMissionDirectory(dir / "mission", missions[r], nullptr);
      std::vector<Metrics> m;
      for (std::size_t a = 0; a < arms.size(); ++a) {
        m.push_back(RunAndEvaluate(arms[a].pipeline, dir / "mission", dir / fmt::format("arm{}", a),
                                   nullptr, arms[a].options));
      }
      for (std::size_t a = 0; a < arms.size(); ++a) {
        p75[a].push_back(m[a].agents.stats.p75_m);
        in95[a].push_back(m[a].agents.stats.in95);
        worse[a] += m[a].agents.stats.p75_m > 1.1 * m.back().agents.stats.p75_m;
      }
      ++runs;
    }
  }
  if (runs > 0) {
    text += fmt::format(
        "\nRecorded RSSI (`{}`: the BLE flat's {} robot runs with positions, their recorded RSSI "
        "from 6 surveyed anchors, the LiDAR-SLAM positions as truth; odometry made from them by "
        "the simulator's PDR error model, one draw per seed: {} runs; no radio model given):\n\n"
        "| arm | p75 m (median run) | p75 m (worst) | in95 % | worse than DR |\n|---|---|---|---|---|\n",
        (data_dir / "ble-rss-flat").string(), runs / seeds, runs);
    for (std::size_t a = 0; a < arms.size(); ++a) {
      text += fmt::format("| {} | {:.2f} | {:.2f} | {:.0f} | {} |\n", arms[a].label, Median(p75[a]),
                          *std::max_element(p75[a].begin(), p75[a].end()), 100 * Mean(in95[a]),
                          a + 1 == arms.size() ? "-" : fmt::format("{}/{}", worse[a], runs));
    }
  } else {
    text += fmt::format("\n({} not present: no recorded runs)\n", (data_dir / "ble-rss-flat").string());
  }
  return WriteReproduction(out, "Radio-landmark tracking with the motion's real error (issue 24)",
                           text);
}

}  // namespace trailmark::experiments

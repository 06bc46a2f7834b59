// SPDX-License-Identifier: MIT
// `trailmark reproduce floors` (issue 26): the multi-floor building, `ins` (foot IMU) and `pdr`
// (phone steps without height) with and without the barometer, and `mapmatch` on every level's
// plan (without and with its stairwell veto) and on the ground floor's plan only, and
// `breadcrumb` with its radio gated by floor and without, and `landmarks-ukf` on the same
// building with surveyed radio landmarks on every level (`multi-floor-landmarks`), gated and
// not; the right
// floor, vertical and horizontal error and the IPIN score per seed, against the must-hold
// (right floor >= 95 %).

#include <fmt/format.h>

#include <algorithm>
#include <map>

#include "experiments/experiments.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/sim/scenarios.h"

namespace trailmark::experiments {

namespace fs = std::filesystem;

int ReproduceFloors(int seeds, const fs::path& out, int first_seed) {
  struct Arm {
    std::string label, pipeline;
    OptionValues options;
    std::string scenario = "multi-floor";
  };
  const std::vector<Arm> arms{
      {"ins (foot IMU) + baro", "ins", {}},
      {"ins, no baro", "ins", {{"height.use_baro", "false"}}},
      {"pdr (phone steps) + baro", "pdr", {}},
      {"pdr, no baro", "pdr", {{"height.use_baro", "false"}}},
      {"mapmatch, every level + baro", "mapmatch", {}},
      {"mapmatch, stairwell veto at 4 m^2", "mapmatch", {{"stairwell_veto_variance_m2", "4"}}},
      {"mapmatch, level 0's plan only", "mapmatch", {{"level", "0"}}},
      {"breadcrumb, radio gated by floor", "breadcrumb", {}},
      {"breadcrumb, radio across floors", "breadcrumb", {{"gate_other_floors", "false"}}},
      {"landmarks-ukf, radio gated by floor", "landmarks-ukf", {}, "multi-floor-landmarks"},
      {"landmarks-ukf, radio across floors", "landmarks-ukf", {{"gate_other_floors", "false"}},
       "multi-floor-landmarks"},
      {"landmarks-ukf filter=paper (the paper's UKF), gated", "landmarks-ukf",
       {{"filter", "paper"}}, "multi-floor-landmarks"},
  };
  struct Figures {
    std::vector<double> hit, ve95, ipin, ce95, worst_agent, mean_h, in95, vertical_in95, crumbs;
  };
  std::vector<Figures> figures(arms.size());
  std::string text = fmt::format(
      "Multi-floor building (simulate multi-floor): basement, ground floor, two upper floors, a "
      "stairwell; storey heights, searches, weather, device offsets and the fan drawn per seed; "
      "the landmark arms on the same building with 3 surveyed radio landmarks per level "
      "(simulate multi-floor-landmarks); seeds {}..{}.\n\n",
      first_seed, first_seed + seeds - 1);
  text += "| seed | arm | right floor % (worst agent) | VE95 m | vertical mean m | CE95 m | IPIN score m |\n";
  text += "|---|---|---|---|---|---|---|\n";
  for (int k = 0; k < seeds; ++k) {
    const int seed = first_seed + k;
    const fs::path dir = out / fmt::format("seed-{}", seed);
    std::map<std::string, fs::path> missions;  // scenario -> its mission directory
    for (const Arm& arm : arms) {
      if (missions.count(arm.scenario)) continue;
      const SimulatedMission sim = SimulateScenario(arm.scenario, static_cast<std::uint64_t>(seed));
      const fs::path mission = dir / (arm.scenario == "multi-floor" ? "mission" : arm.scenario);
      WriteMissionDirectory(mission, sim.data, sim.levels);
      missions[arm.scenario] = mission;
    }
    for (std::size_t a = 0; a < arms.size(); ++a) {
      double wall = 0;
      const Metrics m = RunAndEvaluate(arms[a].pipeline, missions.at(arms[a].scenario),
                                       dir / fmt::format("run-{}", a), &wall, arms[a].options);
      if (!m.floors) throw std::runtime_error("multi-floor mission without floor metrics");
      const FloorMetrics& f = *m.floors;
      double worst = 1.0;
      for (const auto& [id, rate] : f.hit_rate_by_agent) worst = std::min(worst, rate);
      Figures& g = figures[a];
      g.hit.push_back(f.floor_hit_rate);
      g.ve95.push_back(f.ve95_m);
      g.ipin.push_back(f.ipin_score_m);
      g.ce95.push_back(f.ce95_m);
      g.worst_agent.push_back(worst);
      g.mean_h.push_back(m.agents.stats.mean_m);
      g.in95.push_back(m.agents.stats.in95);
      if (f.vertical_checked > 0) g.vertical_in95.push_back(f.vertical_in95);
      if (m.static_nodes.stats.samples > 0) g.crumbs.push_back(m.static_nodes.stats.mean_m);
      text += fmt::format("| {} | {} | {:.1f} ({:.1f}) | {:.2f} | {:.2f} | {:.2f} | {:.2f} |\n", seed,
                          arms[a].label, 100 * f.floor_hit_rate, 100 * worst, f.ve95_m,
                          f.vertical_mean_m, f.ce95_m, f.ipin_score_m);
    }
  }
  text += "\nSummary over the seeds (must hold: right floor >= 95 % for ins and for pdr with the "
          "barometer):\n\n";
  text += "| arm | right floor % mean | min | worst agent min | VE95 m mean | IPIN score m mean "
          "| horizontal mean m | CE95 m mean | in95 % | vertical in95 % | static nodes mean m |\n";
  text += "|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (std::size_t a = 0; a < arms.size(); ++a) {
    const Figures& g = figures[a];
    text += fmt::format(
        "| {} | {:.1f} | {:.1f} | {:.1f} | {:.2f} | {:.2f} | {:.2f} | {:.2f} | {:.0f} | {} | {} |\n",
        arms[a].label, 100 * Mean(g.hit), 100 * *std::min_element(g.hit.begin(), g.hit.end()),
        100 * *std::min_element(g.worst_agent.begin(), g.worst_agent.end()), Mean(g.ve95),
        Mean(g.ipin), Mean(g.mean_h), Mean(g.ce95), 100 * Mean(g.in95),
        g.vertical_in95.empty() ? std::string("–")
                                : fmt::format("{:.1f}", 100 * Mean(g.vertical_in95)),
        g.crumbs.empty() ? std::string("–") : fmt::format("{:.2f}", Mean(g.crumbs)));
  }
  return WriteReproduction(out, "Floors (issue 26)", text);
}

}  // namespace trailmark::experiments

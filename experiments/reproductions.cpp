// SPDX-License-Identifier: MIT
// `trailmark reproduce NAME`: the papers' experiments on simulated equivalents, side by side
// with the published figures.

#include <fmt/format.h>

#include <algorithm>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include "experiments/experiments.h"
#include "trailmark/eval/metrics.h"
#include "trailmark/ins/ins_estimator.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/pipelines/batch_run.h"
#include "trailmark/sim/scenarios.h"

namespace trailmark::experiments {

namespace fs = std::filesystem;

namespace {

struct SeedResult {
  std::uint64_t seed = 0;
  double distance_m = 0;
  double pdr_mean = 0, pdr_max = 0, pdr_end = 0;
  double gen_mean = 0, gen_max = 0, gen_end = 0;
  double crumb_mean = 0;
  std::size_t crumbs = 0;
  double wall_s = 0;
};

/// Breadcrumb error vs number of measurements (paper Fig. 11): measurements = PDR steps + RSSI
/// packets + ranges received up to the time of each static estimate row.
std::vector<std::pair<std::size_t, double>> ErrorVsMeasurements(const fs::path& mission_dir,
                                                                const fs::path& run_dir) {
  const MissionDirectory mission(mission_dir);
  const MissionData data = ReadMissionData(mission);
  std::vector<double> times;
  for (const auto& s : data.steps) times.push_back(s.t1);
  for (const auto& p : data.rssi) times.push_back(p.t);
  for (const auto& r : data.ranges) times.push_back(r.t);
  std::sort(times.begin(), times.end());
  std::map<std::string, Vec3> truth;  // crumbs: their (first) true position
  for (const auto& t : data.truth) {
    if (!truth.count(t.id)) truth[t.id] = t.position_n;
  }
  const auto est = ReadAll<Estimate>((run_dir / "estimates.csv").string(), &mission.registry());
  std::map<std::size_t, std::pair<double, int>> bins;  // bin of 250 -> (sum, n)
  for (const auto& e : est) {
    const NodeInfo* info = mission.info().Find(e.id);
    if ((info && info->kind != NodeKind::kCrumb) || !truth.count(e.id)) continue;
    if (e.id == "base") continue;
    const std::size_t n = std::upper_bound(times.begin(), times.end(), e.t) - times.begin();
    auto& b = bins[n / 250];
    b.first += (e.position_n - truth[e.id]).head<2>().norm();
    ++b.second;
  }
  std::vector<std::pair<std::size_t, double>> out;
  for (const auto& [bin, v] : bins) out.emplace_back((bin + 1) * 250, v.first / v.second);
  return out;
}

}  // namespace

int ReproduceBreadcrumb(int seeds, const fs::path& out,
                        const std::map<std::string, std::string>& options) {
  fmt::print(
      "Breadcrumb paper, sec. V-A: office floor, 100 m loop walked 4 times (400 m), "
      "dispenser-dropped crumbs, {} seeds\n\n",
      seeds);
  fmt::print("{:>5} {:>7} {:>7} | {:>9} {:>9} {:>9} | {:>9} {:>9} {:>9} | {:>8} {:>7}\n", "seed",
             "crumbs", "dist m", "pdr mean", "pdr max", "pdr end", "gen mean", "gen max", "gen end",
             "crumb m", "time s");
  std::vector<SeedResult> results;
  for (int k = 1; k <= seeds; ++k) {
    SeedResult r;
    r.seed = static_cast<std::uint64_t>(k);
    const fs::path dir = out / fmt::format("seed-{}", k);
    const SimulatedMission sim = SimulateScenario("office-loop", r.seed);
    WriteMissionDirectory(dir / "mission", sim.data, &sim.plan);
    for (const auto& e : sim.data.events) r.crumbs += e.event == "drop";
    const Metrics pdr = RunAndEvaluate("pdr", dir / "mission", dir / "pdr", nullptr);
    const Metrics gen =
        RunAndEvaluate("breadcrumb", dir / "mission", dir / "breadcrumb", &r.wall_s, options);
    r.distance_m = gen.agents.distance_m;
    r.pdr_mean = pdr.agents.stats.mean_m;
    r.pdr_max = pdr.agents.stats.max_m;
    r.pdr_end = pdr.agents.stats.final_m;
    r.gen_mean = gen.agents.stats.mean_m;
    r.gen_max = gen.agents.stats.max_m;
    r.gen_end = gen.agents.stats.final_m;
    r.crumb_mean = gen.static_nodes.stats.mean_m;
    fmt::print(
        "{:>5} {:>7} {:>7.1f} | {:>9.2f} {:>9.2f} {:>9.2f} | {:>9.2f} {:>9.2f} {:>9.2f} | "
        "{:>8.2f} {:>7.3f}\n",
        r.seed, r.crumbs, r.distance_m, r.pdr_mean, r.pdr_max, r.pdr_end, r.gen_mean, r.gen_max,
        r.gen_end, r.crumb_mean, r.wall_s);
    results.push_back(r);
  }
  auto avg = [&](double SeedResult::*f) {
    double s = 0;
    for (const auto& r : results) s += r.*f;
    return s / results.size();
  };
  const double dist = avg(&SeedResult::distance_m);
  const double mean = avg(&SeedResult::gen_mean), max = avg(&SeedResult::gen_max);
  const double end = avg(&SeedResult::gen_end), pdr_end = avg(&SeedResult::pdr_end);
  std::string table;
  table += fmt::format(
      "| figure (average over {} seeds) | paper | trailmark `breadcrumb` | target |\n", seeds);
  table += "|---|---|---|---|\n";
  table += fmt::format("| mean error | 5.6 m (1.4 %) | {:.2f} m ({:.2f} %) | <= 1.0 % |\n", mean,
                       100 * mean / dist);
  table += fmt::format("| max error | 10.9 m (2.7 %) | {:.2f} m ({:.2f} %) | <= 2.0 % |\n", max,
                       100 * max / dist);
  table += fmt::format("| end error, PDR only | > 35 m | {:.2f} m | |\n", pdr_end);
  table +=
      fmt::format("| end error, breadcrumb | - | {:.2f} m ({:.1f}x lower than PDR) | >= 5x |\n",
                  end, pdr_end / std::max(end, 1e-9));
  table += fmt::format("| mean error, PDR only | - | {:.2f} m | |\n", avg(&SeedResult::pdr_mean));
  table += fmt::format("| breadcrumb (crumb) mean error | - | {:.2f} m | |\n",
                       avg(&SeedResult::crumb_mean));
  fmt::print("\n{}", table);

  const auto fig11 = ErrorVsMeasurements(out / "seed-1" / "mission", out / "seed-1" / "breadcrumb");
  std::string fig =
      "\nBreadcrumb error vs number of measurements (paper Fig. 11; seed 1, mean over "
      "crumbs):\n| measurements | crumb error m |\n|---|---|\n";
  for (const auto& [n, e] : fig11) fig += fmt::format("| {} | {:.2f} |\n", n, e);
  fmt::print("{}", fig);
  std::ofstream(out / "results.md") << "# trailmark reproduce breadcrumb\n\n" << table << fig;
  fmt::print("\nwritten: {}\n", (out / "results.md").string());
  return 0;
}


Metrics RunAndEvaluate(const std::string& pipeline, const fs::path& mission_dir,
                       const fs::path& out, double* wall_s, const OptionValues& options,
                       EstimatorSummary* summary) {
  const MissionDirectory mission(mission_dir);
  PipelineContext context{mission, options, [](double) {}};
  const RunResult r = RunPipeline(RequirePipeline(pipeline), context, out);
  if (wall_s) *wall_s = r.wall_time_s;
  if (summary) *summary = r.summary;
  const auto truth = ReadAll<TruthSample>(mission.Path("truth.csv").string(), &mission.registry());
  const auto est = ReadAll<Estimate>((out / "estimates.csv").string(), &mission.registry());
  return Evaluate(mission.info(), truth, est);
}

void WriteVariationJson(const fs::path& file, const std::string& scenario, std::uint64_t seed,
                        const Variation& variation, const std::vector<std::string>& notes) {
  nlohmann::json drawn = nlohmann::json::object();
  for (const auto& [key, value] : variation.Describe()) drawn[key] = value;
  std::ofstream j(file);
  j << nlohmann::json{{"scenario", scenario},
                      {"seed", seed},
                      {"variation", drawn},
                      {"notes", notes}}
           .dump(2)
    << "\n";
  if (!j) throw std::runtime_error(file.string() + ": write failed");
}

void WriteSimulatedMission(const fs::path& dir, const SimulatedMission& sim,
                           const MissionWriteStyle& style) {
  if (!sim.levels.empty()) {
    WriteMissionDirectory(dir, sim.data, sim.levels, style);  // every level, drawn alike
  } else {
    const bool has_plan = !sim.plan.walls().empty();
    WriteMissionDirectory(dir, sim.data, has_plan ? &sim.plan : nullptr, style);
  }
}

RunOutcome RunIfRunnable(const std::string& pipeline, const fs::path& mission_dir,
                         const fs::path& out, const OptionValues& options) {
  RunOutcome o;
  try {
    const MissionDirectory mission(mission_dir);
    if (!CanRun(RequirePipeline(pipeline), mission)) {
      o.refusal = "cannot run (streams or nodes missing)";
      return o;
    }
    const Metrics m = RunAndEvaluate(pipeline, mission_dir, out, &o.wall_s, options, &o.summary);
    o.ran = true;
    o.agents = m.agents.stats;
    o.statics = m.static_nodes.stats;
  } catch (const std::exception& e) {
    o.refusal = e.what();
  }
  return o;
}

void CountProgress(const char* what, const char* unit, int* done, int total) {
  if (++*done % std::max(1, total / 10) == 0 || *done == total)
    fmt::print(stderr, "{}: {}/{} {}\n", what, *done, total, unit);
}

double Mean(const std::vector<double>& v) {
  double sum = 0;
  for (double x : v) sum += x;
  return v.empty() ? 0.0 : sum / static_cast<double>(v.size());
}

int WriteReproduction(const fs::path& out, const std::string& title, const std::string& text) {
  fmt::print("{}", text);
  fs::create_directories(out);
  std::ofstream(out / "results.md") << "# " << title << "\n\n" << text;
  fmt::print("\nwritten: {}\n", (out / "results.md").string());
  return 0;
}

ins::InsOptions ParseInsOptions(const OptionValues& values) {
  ins::InsEstimatorOptions o;
  std::string why;
  if (!ins::InsEstimatorOptionTable().Apply(values, &o, &why))
    throw std::invalid_argument("pipeline ins: " + why);
  if (!o.IsValid(&why)) throw std::invalid_argument("pipeline ins: " + why);
  return o.ins;
}

const std::vector<Reproduction>& Reproductions() {
  static const std::vector<Reproduction> table = {
      {"breadcrumb", "the breadcrumb paper's 400 m office experiment (sec. V-A, Fig. 11)", false,
       true,
       [](const ReproductionArgs& a) {
         return ReproduceBreadcrumb(a.seeds, a.out / "breadcrumb", a.options);
       }},
      {"ins", "the ZUPT INS on the recorded foot-IMU sets (PyShoe VICON, OpenShoe, ...)", false,
       true,
       [](const ReproductionArgs& a) {
         return ReproduceIns(a.data_dir, a.out / "ins", a.options);
       }},
      {"landmarks", "the radio-landmarks paper: stop-and-go, UKF, energy (sec. 5-6)", false, false,
       [](const ReproductionArgs& a) {
         return ReproduceLandmarks(std::max(a.seeds, 20), a.out / "landmarks", a.data_dir);
       }},
      {"beacons", "the ultrasound-beacons paper: MDS (Figs. 4-5) and tracking (Table 1)", false,
       false,
       [](const ReproductionArgs& a) {
         return ReproduceBeacons(std::max(a.seeds, 100), a.seeds, a.out / "beacons");
       }},
      {"mapmatch", "the map-aided search paper on the two simulated houses (Figs. 7-9)", true, true,
       [](const ReproductionArgs& a) {
         return ReproduceMapMatch(a.seeds, a.out / "mapmatch", a.options, a.first_seed);
       }},
      {"robustness",
       "every pipeline x every variation family (simulate --vary) against dead reckoning", true,
       true,
       [](const ReproductionArgs& a) {
         return ReproduceRobustness(a.seeds, a.out / "robustness", a.first_seed, a.pipelines,
                                    a.options, a.families);
       },
       /*takes_pipelines=*/true},
      {"integrity",
       "the kinds of lie the integrity mechanism must catch x magnitudes: named, excluded, p75",
       true, false,
       [](const ReproductionArgs& a) {
         return ReproduceIntegrity(a.seeds, a.out / "integrity", a.first_seed);
       }},
      {"landmark-tracking",
       "landmarks-ukf's error-state tracker against the paper's UKF and dead reckoning: the "
       "office without radio model or events, the multi-floor building, the corridor (issue 24)",
       true, true,
       [](const ReproductionArgs& a) {
         return ReproduceLandmarkTracking(a.seeds, a.out / "landmark-tracking", a.first_seed,
                                          a.options, a.data_dir);
       }},
      {"fusion",
       "the fusion next to every single pipeline on the same missions: the papers' scenarios, "
       "the office loop, the training building and the multi-floor buildings (issue 27)",
       true, true,
       [](const ReproductionArgs& a) {
         return ReproduceFusion(a.seeds, a.out / "fusion", a.first_seed, a.options);
       }},
      {"floors",
       "the multi-floor building: ins and pdr with and without the barometer, the right floor; "
       "mapmatch on every level; breadcrumb and landmarks-ukf radio gated by floor and not",
       true, false,
       [](const ReproductionArgs& a) {
         return ReproduceFloors(a.seeds, a.out / "floors", a.first_seed);
       }},
  };
  return table;
}

int Reproduce(const std::string& name, const ReproductionArgs& args) {
  std::string known;
  for (const Reproduction& r : Reproductions()) {
    known += (known.empty() ? "" : ", ") + r.name;
    if (r.name != name) continue;
    if (args.first_seed != 1 && !r.takes_first_seed)
      throw std::invalid_argument("--first-seed does not apply to the " + name + " reproduction");
    if (!args.options.empty() && !r.takes_options)
      throw std::invalid_argument("the " + name + " reproduction takes no --option");
    if (!args.pipelines.empty() && !r.takes_pipelines)
      throw std::invalid_argument("the " + name + " reproduction takes no --pipeline");
    if (!args.families.empty() && name != "robustness")
      throw std::invalid_argument("the " + name + " reproduction takes no --family");
    return r.run(args);
  }
  throw std::invalid_argument("unknown reproduction '" + name + "' (known: " + known + ")");
}

}  // namespace trailmark::experiments

// SPDX-License-Identifier: MIT
// `trailmark reproduce mapmatch`: the map-aided search paper's experiments (sec. V, Figs. 7-9)
// on simulated equivalents: RMSE over time for known/unknown initial state, with/without
// pseudo observations and resampling, on both houses; the map-error indicator; speed.

#include <fmt/format.h>

#include <chrono>
#include <algorithm>
#include <cmath>
#include <optional>

#include "experiments/experiments.h"
#include "trailmark/eval/metrics.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/pipelines/batch_run.h"
#include "trailmark/sim/house_search.h"
#include "trailmark/sim/scenarios.h"
#include "trailmark/sim/variation.h"

namespace trailmark::experiments {

namespace fs = std::filesystem;

namespace {

struct Config {
  std::string label;
  std::map<std::string, std::string> options;
};

/// Error of the online estimate at each checkpoint (seconds), and the summary of the run.
std::vector<double> ErrorsAt(const fs::path& dir, const MissionData& data,
                             const std::map<std::string, std::string>& options,
                             const std::vector<double>& checkpoints, double* wall_s,
                             EstimatorSummary* summary_out) {
  const MissionDirectory mission(dir);
  VectorSink sink;
  const auto t0 = std::chrono::steady_clock::now();
  const EstimatorSummary summary = RunBatch(RequirePipeline("mapmatch"), {mission, options}, sink);
  *wall_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (summary_out) *summary_out = summary;
  const Metrics m = Evaluate(data.info, data.truth, sink.rows);
  std::vector<double> out;
  for (double c : checkpoints) {
    double e = std::nan("");
    for (const auto& s : m.agents.series) {
      if (s.t <= c + 1e-9) e = s.error_m;
    }
    out.push_back(e);
  }
  return out;
}

}  // namespace

int ReproduceMapMatch(int seeds, const fs::path& out,
                      const std::map<std::string, std::string>& extra, int first_seed) {
  const std::map<std::string, std::string> paper{
      {"particles", "500"},        {"patterns_above_variance_m2", "0"},
      {"max_match_rmse_m", "1e9"}, {"recover", "false"},
      {"wall_follow", "false"},    {"stay_inside", "false"},
      {"tracking_sigma", "0"}};
  auto with = [](std::map<std::string, std::string> a,
                 const std::map<std::string, std::string>& b) {
    a.insert(b.begin(), b.end());
    return a;
  };
  const std::vector<Config> configs = {
      {"known, no pseudo obs.", with({{"init", "known"}, {"pseudo", "false"}}, paper)},
      {"known, pseudo obs. (paper)", with({{"init", "known"}, {"resample", "false"}}, paper)},
      {"known, pseudo obs. + resampling (paper)", with({{"init", "known"}}, paper)},
      {"unknown, no pseudo obs. (conventional)",
       with({{"init", "uniform"}, {"pseudo", "false"}}, paper)},
      {"unknown, pseudo obs. (paper)", with({{"init", "uniform"}, {"resample", "false"}}, paper)},
      {"unknown, pseudo obs. + resampling (paper)", with({{"init", "uniform"}}, paper)},
      {"**unknown, ours (default): patterns while uncertain, wall-following model, stay "
       "inside**",
       {{"init", "uniform"}}},
      {"known, ours (default)", {{"init", "known"}}},
      {"unknown, ours without the wall-following model, stay-inside and the settled-recovery "
       "rule; N = 500",
       {{"init", "uniform"},
        {"wall_follow", "false"},
        {"stay_inside", "false"},
        {"recover_reweight_converged", "true"},
        {"particles", "500"}}},
      {"unknown, ours, wall-following model only while uncertain",
       {{"init", "uniform"}, {"wall_follow_converged_power", "0"}}},
      {"unknown, ours with N = 500", {{"init", "uniform"}, {"particles", "500"}}},
      {"unknown, ours with the paper's sigma (0.1) also once the track is found",
       {{"init", "uniform"}, {"tracking_sigma", "0"}}},
      {"unknown, ours without pattern observations (walls + wall-following model)",
       {{"init", "uniform"}, {"pseudo", "false"}}},
  };
  std::string t = fmt::format(
      "Map-aided search paper (sec. V, Figs. 7-8) on simulated houses: RMSE of the horizontal "
      "error over {} "
      "searches per house (seeds {} to {}) at each time (N = 500 particles in the paper's "
      "configurations, 2,000 in ours); paper: unknown "
      "initial state with pseudo observations "
      "and resampling settles at ~1 m after ~2.5 min, the conventional filter stays around 4 m\n",
      seeds, first_seed, first_seed + seeds - 1);
  double mission_s = 0, wall_s = 0;
  for (int house : {1, 2}) {
    const std::vector<double> checkpoints =
        house == 1 ? std::vector<double>{30, 60, 90, 120, 150, 180, 210, 240, 270}
                   : std::vector<double>{60, 120, 180, 240, 300, 360, 420, 480, 540, 600};
    std::vector<std::vector<std::vector<double>>> err(configs.size());  // [config][run][checkpoint]
    for (int seed = first_seed; seed < first_seed + seeds; ++seed) {
      HouseSearchOptions o;
      o.house = house;
      o.duration_s = house == 1 ? 270 : 600;
      // Data set 1: 16 searches, 9 left-hand; data set 2: left-hand searches.
      o.hand = house == 2 || seed % 16 < 9 ? Hand::kLeft : Hand::kRight;
      if (house == 1 && seed % 2 == 0) o.hand = Hand::kRight;
      const SimulatedMission sim = SimulateHouseSearch(o, static_cast<std::uint64_t>(seed));
      const fs::path dir = out / "missions" / fmt::format("house{}-{}", house, seed);
      WriteMissionDirectory(dir, sim.data, &sim.plan);
      for (std::size_t c = 0; c < configs.size(); ++c) {
        auto options = configs[c].options;
        options["seed"] = std::to_string(seed);
        for (const auto& [k, v] : extra) options[k] = v;
        err[c].push_back(ErrorsAt(dir, sim.data, options, checkpoints, &wall_s, nullptr));
        mission_s += sim.data.truth.back().t - sim.data.truth.front().t;
      }
      fs::remove_all(dir);
    }
    t += fmt::format("\nHouse {} ({}), RMSE (m) at time t:\n\n| configuration |", house,
                     house == 1 ? "data set 1: 125 m^2, searches of 4.5 min in its 70 m^2 west "
                                  "part, left and right hand"
                                : "data set 2: 253 m^2, left-hand searches of 10 min");
    for (double c : checkpoints) t += fmt::format(" {:.1f} min |", c / 60);
    t += " settles <= 1 m at | mean from 2 min | errors > 2 m from 2 min | ten-run sets <= 1 m "
         "from 2 min |\n|---|";
    for (std::size_t k = 0; k <= checkpoints.size() + 3; ++k) t += "---|";
    t += "\n";
    for (std::size_t c = 0; c < configs.size(); ++c) {
      t += "| " + configs[c].label + " |";
      std::vector<double> rmse;
      for (std::size_t k = 0; k < checkpoints.size(); ++k) {
        double sq = 0;
        int n = 0;
        for (const auto& run : err[c]) {
          if (std::isfinite(run[k])) sq += run[k] * run[k], ++n;
        }
        rmse.push_back(n ? std::sqrt(sq / n) : std::nan(""));
        t += fmt::format(" {:.2f} |", rmse.back());
      }
      // First checkpoint after which the RMSE stays at or below 1 m.
      std::string settle = "never";
      for (std::size_t k = 0; k < rmse.size(); ++k) {
        bool stays = true;
        for (std::size_t j = k; j < rmse.size(); ++j) stays = stays && rmse[j] <= 1.0;
        if (stays) {
          settle = fmt::format("{:.1f} min", checkpoints[k] / 60);
          break;
        }
      }
      // One number per configuration (the checkpoint RMSEs move by more than 1 m between seed
      // sets): the mean RMSE from 2 min on, and how many (run, checkpoint) errors exceed 2 m.
      double mean = 0;
      int n_mean = 0, gross = 0, counted = 0;
      for (std::size_t k = 0; k < checkpoints.size(); ++k) {
        if (checkpoints[k] < 120) continue;
        mean += rmse[k], ++n_mean;
        for (const auto& run : err[c]) ++counted, gross += !(run[k] <= 2.0);
      }
      // The target on every consecutive ten of the runs (seed order), each ten taken
      // as one ten-run reproduction: RMSE <= 1 m at every checkpoint from 2 min.
      int sets = 0, sets_met = 0;
      for (std::size_t r0 = 0; r0 + 10 <= err[c].size(); r0 += 10, ++sets) {
        bool met = true;
        for (std::size_t k = 0; k < checkpoints.size(); ++k) {
          if (checkpoints[k] < 120) continue;
          double sq = 0;
          for (std::size_t r = r0; r < r0 + 10; ++r) sq += err[c][r][k] * err[c][r][k];
          met = met && std::sqrt(sq / 10) <= 1.0;  // a NaN error fails the set
        }
        sets_met += met;
      }
      t +=
          fmt::format(" {} | {:.2f} | {} of {} | {} |\n", settle, mean / std::max(n_mean, 1), gross,
                      counted, sets ? fmt::format("{} of {}", sets_met, sets) : std::string("-"));
    }
  }
  // Every drawing of the same house (issue 23): each search as simulated, the same search drawn
  // by the `frame` family (rotated by any angle, moved up to 2 km, doors across gaps in half,
  // connected walls as polylines in half: variant K = the seed) and by the `start` family (a
  // start up to 10 m outside, no start heading), from an unknown start with our defaults: the
  // p75 of the error after 3 minutes per search (the must-hold: <= 1.0 m on every
  // drawing), and the share of truth inside the reported 95 % ellipse over the whole search.
  t += fmt::format(
      "\nEvery drawing of the same house (issue 23): unknown start, ours (default), seeds {} to "
      "{}; per search the p75 of the error after 3 min, and in95 over the whole search:\n\n"
      "| house | drawing | searches with p75 after 3 min <= 1.0 m | p75 after 3 min: median / "
      "largest | in95 % |\n|---|---|---|---|---|\n",
      first_seed, first_seed + seeds - 1);
  for (int house : {1, 2}) {
    for (const auto& [family, name] :
         std::vector<std::pair<std::optional<VariationFamily>, std::string>>{
             {std::nullopt, "as simulated (along the axes, doors along walls)"},
             {VariationFamily::kFrame, "`frame`: rotated, moved, door convention, polylines"},
             {VariationFamily::kStart, "`start`: up to 10 m outside, no start heading"}}) {
      std::vector<double> p75s;
      double inside = 0, scored = 0;
      for (int seed = first_seed; seed < first_seed + seeds; ++seed) {
        SimulatedMission sim = SimulateScenario(house == 1 ? "house1-search" : "house2-search",
                                                static_cast<std::uint64_t>(seed));
        MissionWriteStyle style;
        if (family) {
          const Variation v = DrawVariation(*family, static_cast<std::uint64_t>(seed));
          ApplyVariation(v, sim);
          style = v.write;
        }
        const fs::path dir = out / "missions" / fmt::format("drawn-{}-{}", house, seed);
        WriteMissionDirectory(dir, sim.data, &sim.plan, style);
        std::map<std::string, std::string> options{{"init", "uniform"},
                                                   {"seed", std::to_string(seed)}};
        for (const auto& [k, v] : extra) options[k] = v;
        VectorSink sink;
        RunBatch(RequirePipeline("mapmatch"), {MissionDirectory(dir), options}, sink);
        const Metrics m = Evaluate(sim.data.info, sim.data.truth, sink.rows);
        std::vector<double> late;
        for (const auto& e : m.agents.series) {
          if (e.t >= 180) late.push_back(e.error_m);
        }
        p75s.push_back(late.empty() ? std::nan("") : Percentile(late, 75));
        inside += m.agents.stats.in95 * static_cast<double>(m.agents.series.size());
        scored += static_cast<double>(m.agents.series.size());
        fs::remove_all(dir);
      }
      int met = 0;
      for (double v : p75s) met += v <= 1.0;
      t += fmt::format("| {} | {} | {} of {} | {:.2f} / {:.2f} m | {:.0f} |\n", house, name, met,
                       seeds, Percentile(p75s, 50),
                       *std::max_element(p75s.begin(), p75s.end()), 100 * inside / scored);
    }
  }
  // The map error (sec. V-E): the hall door drawn 2 m from where it is; the same searches with
  // the right map as the control for false alarms. Seeds 11.. : the wall-crossing indicator's
  // k and h were chosen on seeds 1-10, so these are searches it was not tuned on.
  t += "\nMap error (sec. V-E: the hall door of house 1 drawn 2 m from where it is; known start; "
       "searches with seeds " +
       std::to_string(10 + first_seed) + " to " + std::to_string(9 + first_seed + seeds) +
       ", not those the wall-crossing indicator was tuned on), flagged searches:\n\n"
       "| filter | indicator | map error: flagged | right map: flagged (false alarms) | final "
       "error, map error / right map |\n|---|---|---|---|---|\n";
  for (const auto& [label, base] :
       std::vector<std::pair<std::string, std::map<std::string, std::string>>>{
           {"paper (patterns always)", paper}, {"ours (default)", {}}}) {
    int flagged_variance[2] = {0, 0}, flagged_walls[2] = {0, 0}, flagged_verdict[2] = {0, 0};
    double err_sum[2] = {0, 0};
    for (int me = 0; me < 2; ++me) {
      for (int seed = 10 + first_seed; seed < 10 + first_seed + seeds; ++seed) {
        HouseSearchOptions o;
        o.house = 1;
        o.map_error = me == 0;
        o.hand = seed % 2 ? Hand::kLeft : Hand::kRight;
        const SimulatedMission sim = SimulateHouseSearch(o, static_cast<std::uint64_t>(seed));
        const fs::path dir = out / "missions" / fmt::format("map-error-{}", seed);
        WriteMissionDirectory(dir, sim.data, &sim.plan);
        EstimatorSummary s;
        std::map<std::string, std::string> options =
            with({{"init", "known"}, {"seed", std::to_string(seed)}}, base);
        for (const auto& [k, v] : extra) options[k] = v;
        double unused = 0;
        const auto e = ErrorsAt(dir, sim.data, options, {270}, &unused, &s);
        flagged_variance[me] += s.numbers.at("ff1.variance_alarms") > 0;
        flagged_walls[me] += s.numbers.at("ff1.wall_alarms") > 0;
        flagged_verdict[me] += s.numbers.at("ff1.map_error_suspected") > 0;
        err_sum[me] += std::isfinite(e[0]) ? e[0] : 0;
        fs::remove_all(dir);
      }
    }
    const std::string errors =
        fmt::format("{:.2f} / {:.2f} m", err_sum[0] / seeds, err_sum[1] / seeds);
    t += fmt::format("| {} | variance > 3 m^2 for >= 10 s (paper) | {} of {} | {} of {} | {} |\n",
                     label, flagged_variance[0], seeds, flagged_variance[1], seeds, errors);
    t += fmt::format(
        "| {} | walk crossing the map's walls (ours: CUSUM of the blocked share, k 0.2, h 1.75) "
        "| {} of {} | {} of {} | {} |\n",
        label, flagged_walls[0], seeds, flagged_walls[1], seeds, errors);
    t += fmt::format(
        "| {} | **map error suspected** (pipeline verdict: the variance indicator, or 5 or more "
        "wall alarms) | {} of {} | {} of {} | {} |\n",
        label, flagged_verdict[0], seeds, flagged_verdict[1], seeds, errors);
  }
  // Speed: data set 1 is 73 minutes (16 searches of ~4.5 min): the paper's configuration
  // (the target) and the pipeline's default.
  for (const auto& [label, base] :
       std::vector<std::pair<std::string, std::map<std::string, std::string>>>{
           {"the paper's filter, N = 500", paper}, {"ours (default), N = 2,000", {}}}) {
    double wall = 0, mission = 0;
    for (int k = 1; k <= 16; ++k) {
      HouseSearchOptions o;
      o.hand = k <= 9 ? Hand::kLeft : Hand::kRight;  // nine left-hand searches (sec. V-A)
      const SimulatedMission sim = SimulateHouseSearch(o, static_cast<std::uint64_t>(100 + k));
      const fs::path dir = out / "missions" / fmt::format("speed-{}", k);
      WriteMissionDirectory(dir, sim.data, &sim.plan);
      ErrorsAt(dir, sim.data, with({{"init", "uniform"}}, base), {0}, &wall, nullptr);
      mission += sim.data.truth.back().t - sim.data.truth.front().t;
      fs::remove_all(dir);
    }
    t += fmt::format(
        "\nSpeed, {} (data set 1 equivalent: 16 searches, {:.1f} min, unknown start, pseudo "
        "observations and resampling, one core): {:.2f} s, {:.0f}x real time.\n",
        label, mission / 60, wall, mission / wall);
  }
  fs::remove_all(out / "missions");
  return WriteReproduction(out, "trailmark reproduce mapmatch", t);
}

}  // namespace trailmark::experiments

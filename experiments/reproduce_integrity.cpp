// SPDX-License-Identifier: MIT
// `trailmark reproduce integrity` (issue 21, item 3): each kind of lie of sim/lies.h at several
// magnitudes, on simulated missions where the lying source can be told apart: the stop-and-go
// corridor with every landmark surveyed (landmarks-ukf) and the ultrasound lab with surveyed
// beacons (beacons-ekf). For each: the share of seeds where an integrity note names the lying
// source, the honest sources excluded with it (mean per run), and the agents' p75 without the
// lie, with the lie and the check on, and with the lie trusted (integrity.exclude=false and
// integrity.streams=false). The
// dead-reckoning guard only reports here, so that what is measured is the source check.

#include <fmt/format.h>

#include <functional>

#include "experiments/experiments.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/pipelines/registry.h"
#include "trailmark/sim/beacon_lab.h"
#include "trailmark/sim/lies.h"
#include "trailmark/sim/scenarios.h"

namespace trailmark::experiments {

namespace fs = std::filesystem;

namespace {

struct Case {
  std::string pipeline;
  std::function<SimulatedMission(std::uint64_t)> mission;
  Lie lie;
  std::string source;  ///< the integrity note's source that names the lie
  OptionValues options = {};  ///< the pipeline's options beyond the defaults (its row names them)
  std::string where = {};     ///< the mission when not the pipeline's usual one (its row names it)
};

SimulatedMission SurveyedCorridor(std::uint64_t seed) {
  SimulatedMission sim = SimulateScenario("landmark-corridor", seed);
  SurveyAtTruth(sim.data, NodeKind::kLandmark, 0.2);
  return sim;
}

SimulatedMission SurveyedLab(std::uint64_t seed) { return SimulateBeaconLab({}, seed); }

/// The breadcrumb paper's 400 m office experiment (sec. V-A): crumbs dropped by the walker.
SimulatedMission OfficeLoop(std::uint64_t seed) { return SimulateScenario("office-loop", seed); }

/// Beacons dropped by the rules, three of them surveyed away from the entry (issue 22).
SimulatedMission NeighbourTrail(std::uint64_t seed) {
  return SimulateScenario("beacon-neighbour-trail", seed);
}

// An integrity note that says a source is not what it claims (a verdict, not its retraction).
bool Flags(const IntegrityNote& n) {
  return n.action == "excluded" || n.action == "repeats" || n.action == "scale";
}

bool Names(const EstimatorSummary& s, const std::string& source) {
  for (const IntegrityNote& n : s.integrity) {
    if (Flags(n) && n.source.find(source) != std::string::npos) return true;
  }
  return false;
}

double OthersExcluded(const EstimatorSummary& s, const std::string& source) {
  double n = 0;
  for (const IntegrityNote& note : s.integrity) {
    n += Flags(note) && note.source.find(source) == std::string::npos;
  }
  return n;
}

}  // namespace

int ReproduceIntegrity(int seeds, const fs::path& out, int first_seed) {
  std::vector<Case> cases;
  // landmarks-ukf: its default tracker (landmark_tracker.h) and the paper's UKF.
  for (const OptionValues& filter : {OptionValues{}, OptionValues{{"filter", "paper"}}}) {
    for (double m : {3.0, 6.0, 12.0})
      cases.push_back({"landmarks-ukf", SurveyedCorridor, {LieKind::kMovedNode, "lm3", m},
                       "landmark lm3", filter});
    for (double m : {6.0, 10.0, 20.0})
      cases.push_back({"landmarks-ukf", SurveyedCorridor, {LieKind::kRssiOffset, "lm2", m},
                       "landmark lm2", filter});
    cases.push_back({"landmarks-ukf", SurveyedCorridor, {LieKind::kFrozenLink, "lm4", 0, 30}, "lm4",
                     filter});
  }
  for (double m : {1.0, 2.0, 4.0})
    cases.push_back({"beacons-ekf", SurveyedLab, {LieKind::kMovedNode, "b03", m}, "beacon b03 range"});
  // A wrong speed of sound: x 0.93 a room at 60 deg C, x 1.03-1.12 cold air or a device set
  // for another temperature.
  for (const auto& mission : {SurveyedLab, NeighbourTrail}) {
    for (double m : {0.93, 1.03, 1.06, 1.12})
      cases.push_back({"beacons-ekf",
                       mission,
                       {LieKind::kRangeScale, "", m},
                       "ultrasound ranges",
                       {},
                       mission == NeighbourTrail ? "neighbour trail" : ""});
  }

  // A crumb louder than its make (another transmit power, an antenna that broke off): the RSSI
  // network's per-node offset against its stated spread between nodes (4 dB).
  for (double m : {6.0, 10.0, 20.0})
    cases.push_back({"breadcrumb",
                     OfficeLoop,
                     {LieKind::kRssiOffset, "c2", m},
                     "RSSI of c2",
                     {},
                     "office loop"});
  const OptionValues report{{"integrity.on_disagreement", "report"}};
  OptionValues trusted = report;
  trusted["integrity.exclude"] = "false";
  trusted["integrity.streams"] = "false";
  std::string text = fmt::format(
      "Seeds {}..{} (`--seeds N --first-seed K`). `named`: runs where an integrity note names the "
      "lying source (in brackets: on the mission without the lie, a false alarm); `others`: honest "
      "sources excluded per run (with the lie; in brackets without "
      "it); p75 of the agents' error without the lie, with it and the check, with it trusted.\n\n"
      "| pipeline | lie | named | others (honest) | p75 honest m | p75 caught m | p75 trusted m |\n"
      "|---|---|---|---|---|---|---|\n",
      first_seed, first_seed + seeds - 1);
  for (const Case& c : cases) {
    OptionValues report_c = report, trusted_c = trusted;
    std::string label = c.pipeline + (c.where.empty() ? "" : " (" + c.where + ")");
    for (const auto& [k, v] : c.options) {
      report_c[k] = v;
      trusted_c[k] = v;
      label += fmt::format(" {}={}", k, v);
    }
    int named = 0, named_honest = 0;
    std::vector<double> others, others_honest, honest_p75, caught_p75, trusted_p75;
    for (int k = 0; k < seeds; ++k) {
      const std::uint64_t seed = static_cast<std::uint64_t>(first_seed + k);
      const fs::path dir = out / "runs" / fmt::format("seed{}", seed);
      SimulatedMission sim = c.mission(seed);
      WriteMissionDirectory(dir / (c.pipeline + "-honest"), sim.data, &sim.plan);
      EstimatorSummary s;
      honest_p75.push_back(RunAndEvaluate(c.pipeline, dir / (c.pipeline + "-honest"), dir / "honest",
                                          nullptr, report_c, &s)
                               .agents.stats.p75_m);
      others_honest.push_back(OthersExcluded(s, c.source));
      named_honest += Names(s, c.source) ? 1 : 0;
      ApplyLie(sim.data, c.lie);
      WriteMissionDirectory(dir / "lie", sim.data, &sim.plan);
      caught_p75.push_back(
          RunAndEvaluate(c.pipeline, dir / "lie", dir / "caught", nullptr, report_c, &s).agents.stats.p75_m);
      named += Names(s, c.source) ? 1 : 0;
      others.push_back(OthersExcluded(s, c.source));
      trusted_p75.push_back(
          RunAndEvaluate(c.pipeline, dir / "lie", dir / "trusted", nullptr, trusted_c).agents.stats.p75_m);
    }
    text += fmt::format("| {} | {} | {} | {:.1f} ({:.1f}) | {:.2f} | {:.2f} | {:.2f} |\n", label,
                        Describe(c.lie), fmt::format("{}/{} ({})", named, seeds, named_honest),
                        Mean(others), Mean(others_honest), Mean(honest_p75), Mean(caught_p75),
                        Mean(trusted_p75));
    fmt::print(stderr, "integrity: {} {} done\n", label, Describe(c.lie));
  }
  return WriteReproduction(out, "Integrity: the kinds of lie (issue 21, item 3)", text);
}

}  // namespace trailmark::experiments

// SPDX-License-Identifier: MIT
#pragma once
/// The papers' experiments on simulated equivalents (and on recorded data where the paper's
/// data is public), printed side by side with the published figures: `trailmark reproduce
/// NAME`. One table of reproductions; each writes OUT/NAME/results.md. These sit above the
/// library (they read and write mission directories and run pipelines of the registry); the
/// CLI only dispatches to them.

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "trailmark/core/online_estimator.h"
#include "trailmark/core/options.h"
#include "trailmark/eval/metrics.h"
#include "trailmark/ins/zupt_ins.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/sim/mission_sim.h"
#include "trailmark/sim/variation.h"

namespace trailmark::experiments {

struct ReproductionArgs {
  int seeds = 8;                      ///< simulated runs (seeds first_seed .. first_seed + seeds - 1)
  std::filesystem::path out = "out/reproduce";  ///< OUT/NAME/results.md
  OptionValues options;               ///< passed to the reproduced pipeline (ablations)
  std::filesystem::path data_dir = "../shared/data";  ///< recorded data
  int first_seed = 1;
  /// Reproductions over several pipelines: only these (empty: all of them).
  std::vector<std::string> pipelines;
  /// robustness: only these variation families (empty: all of them).
  std::vector<std::string> families;
};

struct Reproduction {
  std::string name;
  std::string description;
  bool takes_first_seed = false;  ///< --first-seed: figures on seeds a setting was not chosen on
  bool takes_options = false;     ///< --option goes to its pipeline
  std::function<int(const ReproductionArgs&)> run;
  bool takes_pipelines = false;   ///< --pipeline chooses which of its pipelines run
};

/// Every reproduction, in a stable order.
const std::vector<Reproduction>& Reproductions();
/// Runs the reproduction `name`; std::invalid_argument for an unknown name or arguments it
/// does not take.
int Reproduce(const std::string& name, const ReproductionArgs& args);

/// Prints `text` and writes it to out/results.md under a "# title" heading; returns 0.
int WriteReproduction(const std::filesystem::path& out, const std::string& title,
                      const std::string& text);
/// Runs the registry's `pipeline` on a mission into `out` and evaluates it against the
/// mission's truth; `wall_s` and `summary` (may be null) get the run's wall time and summary.
Metrics RunAndEvaluate(const std::string& pipeline, const std::filesystem::path& mission_dir,
                       const std::filesystem::path& out, double* wall_s,
                       const OptionValues& options = {}, EstimatorSummary* summary = nullptr);
/// Writes a simulated mission as `trailmark simulate` does: every level's plan in one file for a
/// building of several floors, the one plan otherwise, none for a scenario without a building.
void WriteSimulatedMission(const std::filesystem::path& dir, const SimulatedMission& sim,
                           const MissionWriteStyle& style = {});
/// Writes `file` (variation.json) as `trailmark simulate --vary` does: the scenario, its seed, the
/// drawn variation's values and the notes of what applying it changed. Throws on a failed write.
void WriteVariationJson(const std::filesystem::path& file, const std::string& scenario,
                        std::uint64_t seed, const Variation& variation,
                        const std::vector<std::string>& notes);
/// A pipeline's run on a mission, or why it did not run.
struct RunOutcome {
  bool ran = false;
  std::string refusal;      ///< when it did not: "cannot run (...)" or the error
  ErrorStatistics agents;   ///< agents pooled (empty when the pipeline tracks no agent)
  ErrorStatistics statics;  ///< static nodes pooled
  double wall_s = 0.0;
  EstimatorSummary summary;
};
/// RunAndEvaluate when the mission can feed the pipeline; an error of the run is a refusal.
RunOutcome RunIfRunnable(const std::string& pipeline, const std::filesystem::path& mission_dir,
                         const std::filesystem::path& out, const OptionValues& options = {});
/// Counts one more of `total` and prints "what: done/total unit" to stderr at every tenth.
void CountProgress(const char* what, const char* unit, int* done, int total);
/// Mean of the values; 0 for none.
double Mean(const std::vector<double>& v);

/// The INS options of `values` (the keys of the ins pipeline); std::invalid_argument otherwise.
ins::InsOptions ParseInsOptions(const OptionValues& values);

int ReproduceBreadcrumb(int seeds, const std::filesystem::path& out, const OptionValues& options);
/// The ZUPT INS on the recorded foot-IMU sets under data_dir.
int ReproduceIns(const std::filesystem::path& data_dir, const std::filesystem::path& out,
                 const OptionValues& options = {});
/// The radio-landmarks paper's stop-and-go experiment; recorded BLE figures from data_dir.
int ReproduceLandmarks(int seeds, const std::filesystem::path& out,
                       const std::filesystem::path& data_dir);
/// MDS beacon localization (Figs. 4-5, `runs` simulations per point) and tracking on the six
/// lab traces (Table 1, Figs. 6-9, `seeds` each).
int ReproduceBeacons(int runs, int seeds, const std::filesystem::path& out);
/// The map-aided search paper on the two simulated houses (Figs. 7-9) with seeds first_seed ..
/// first_seed + seeds - 1; `extra` options go to every mapmatch run.
int ReproduceMapMatch(int seeds, const std::filesystem::path& out, const OptionValues& extra = {},
                      int first_seed = 1);

/// Every pipeline x every variation family on its paper's scenario, against dead reckoning on
/// the same variant (issue 21, item 5): variants K = first_seed .. first_seed + variants - 1.
/// `pipelines`: only these (empty: every pipeline but the baseline and ins); `options` go to
/// each of them (not to the dead reckoning they are compared with) and need `pipelines`.
/// `families`: only these variation families (empty: all). Throws std::invalid_argument for a
/// pipeline not in the table, an unknown family or an option one of the pipelines refuses.
int ReproduceRobustness(int variants, const std::filesystem::path& out, int first_seed = 1,
                        const std::vector<std::string>& pipelines = {},
                        const OptionValues& options = {},
                        const std::vector<std::string>& families = {});

/// The kinds of lie of the integrity mechanism (sim/lies.h) x magnitudes, on seeds
/// first_seed .. first_seed + seeds - 1 (issue 21, item 3): how often the lying source is named,
/// how many honest sources are excluded with it, and p75 without the lie, with it caught, and
/// with it trusted (integrity.exclude=false, integrity.streams=false).
/// `trailmark reproduce fusion` (issue 27): the fusion next to every single pipeline on the
/// same missions of each scenario that has a paper or several sources, seeds first_seed.. ;
/// `options` go to the fusion only (an ablation: use.mapmatch=false).
int ReproduceFusion(int seeds, const std::filesystem::path& out, int first_seed = 1,
                    const OptionValues& options = {});
int ReproduceIntegrity(int seeds, const std::filesystem::path& out, int first_seed = 1);

/// The multi-floor building (issue 26): ins and pdr with and without the barometer on seeds
/// first_seed .. first_seed + seeds - 1: the right floor, VE95, the IPIN score.
int ReproduceFloors(int seeds, const std::filesystem::path& out, int first_seed = 1);

/// landmarks-ukf's error-state tracker, the paper's UKF and dead reckoning on the office of
/// issue 24, the multi-floor building's landmarks and the paper's corridor, seeds first_seed ..
/// first_seed + seeds - 1; `options` go to the default tracker's arm; and the recorded BLE
/// flat under data_dir (recorded RSSI, odometry errors drawn per seed).
int ReproduceLandmarkTracking(int seeds, const std::filesystem::path& out, int first_seed = 1,
                              const OptionValues& options = {},
                              const std::filesystem::path& data_dir = "../shared/data");

}  // namespace trailmark::experiments

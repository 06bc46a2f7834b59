// SPDX-License-Identifier: MIT
#pragma once
/// The batch run of a pipeline on a mission directory (`trailmark run`): the streams it uses
/// merged in time order (io/merged_stream.h) into its online estimator, the estimates to a
/// sink or to estimates.csv, the summary to diagnostics.json. The live server runs the very
/// same estimators on its journal rows (server/incident_server.h).

#include <filesystem>
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "trailmark/beacons/trail_estimator.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/pipelines/registry.h"

namespace trailmark {

/// Progress: fraction done in [0, 1].
using ProgressCallback = std::function<void(double fraction)>;

struct PipelineContext {
  const MissionDirectory& mission;
  OptionValues options;  ///< --option key=value from the CLI
  ProgressCallback progress = [](double) {};
};

/// The measurement streams a mission directory has.
StreamSet PresentStreams(const MissionDirectory& mission);
/// Whether the mission has what the pipeline needs (streams, floor plan, landmarks).
bool CanRun(const PipelineSpec& pipeline, const MissionDirectory& mission);
/// Names of the pipelines the mission can feed, in registry order.
std::vector<std::string> RunnablePipelines(const MissionDirectory& mission);
/// Throws InputError naming what the mission lacks for the pipeline (a missing file by its
/// path); returns when it can run.
void RequireCanRun(const PipelineSpec& pipeline, const MissionDirectory& mission);

/// The floor the pipeline works on, loaded from the mission's plan (its `level` option, else
/// the default floor); nullopt when the mission has none. `notes` (optional) gets a line
/// naming the levels of a multi-floor plan.
/// `all_levels` (optional) gets every level's plan when the plan has several and no `level`
/// option is given: a pipeline that follows the floors (mapmatch) then uses them all.
std::optional<FloorPlan> LoadPipelineFloor(const PipelineSpec& pipeline,
                                           const MissionDirectory& mission,
                                           const OptionValues& options,
                                           std::vector<std::string>* notes = nullptr,
                                           LevelPlans* all_levels = nullptr);

/// The floor plan an estimator of the pipeline is built with, loaded from the mission: the
/// floor (or every level), and the name errors give it. Empty when the pipeline needs none.
struct PipelinePlan {
  std::optional<FloorPlan> floor;
  LevelPlans levels;  ///< every level's plan when the pipeline follows the floors
  std::string source = "the floor plan";
  /// The estimator's inputs for the mission's incident (refers to this plan: keep it alive).
  EstimatorInputs InputsFor(const MissionInfo& info) const {
    return EstimatorInputs{info, floor ? &*floor : nullptr, source,
                           levels.empty() ? nullptr : &levels};
  }
};
/// Throws InputError when the pipeline needs a floor plan the mission does not have (no
/// "floorplan" in mission.json, or the file missing); returns otherwise.
void RequireFloorPlan(const PipelineSpec& pipeline, const MissionDirectory& mission);
/// The plan of a pipeline that needs one (RequireFloorPlan, then LoadPipelineFloor).
PipelinePlan LoadPipelinePlan(const PipelineSpec& pipeline, const MissionDirectory& mission,
                              const OptionValues& options,
                              std::vector<std::string>* notes = nullptr);

/// The streams of the mission a batch run of the pipeline feeds it: those it uses that the
/// mission has, except that steps.csv shadows imu.csv for a steps-based pipeline (`notes`, when
/// given, gets a line saying so).
StreamSet BatchFeedStreams(const PipelineSpec& pipeline, const MissionDirectory& mission,
                           const OptionValues& options, std::vector<std::string>* notes = nullptr);

/// Runs the pipeline: estimates to `sink` in the order the estimator emits them. Throws
/// InputError for bad input (file:line of the row an estimator refused) or a mission that
/// lacks what the pipeline needs, std::invalid_argument for bad options.
EstimatorSummary RunBatch(const PipelineSpec& pipeline, const PipelineContext& context,
                          EstimateSink& sink);

/// estimates.csv is in non-decreasing time (spec). An estimate is known when it is emitted: a
/// row stamped earlier than one already passed on (e.g. an agent's start, emitted with its
/// first step, after another agent's rows) is passed on stamped with the latest time instead.
/// What `trailmark run` writes, and what the Python bindings return.
class RestampingSink : public EstimateSink {
 public:
  explicit RestampingSink(EstimateSink& inner) : inner_(inner) {}
  void Add(const Estimate& e) override;
  std::size_t restamped() const { return restamped_; }
  std::size_t count() const { return count_; }

 private:
  EstimateSink& inner_;
  std::size_t count_ = 0;
  std::size_t restamped_ = 0;
  double last_t_ = -std::numeric_limits<double>::infinity();
};

/// Whether the mission's estimates carry the 1.1 columns (szz, floor): it lists floors or has a
/// barometer. A single-floor mission's estimates.csv keeps the 1.0 columns.
bool EstimatesHaveFloorColumns(const MissionDirectory& mission);

struct RunResult {
  std::string pipeline;
  std::size_t estimates = 0;
  double wall_time_s = 0;
  EstimatorSummary summary;
};

/// Runs the pipeline and writes `out_dir`/estimates.csv and diagnostics.json.
RunResult RunPipeline(const PipelineSpec& pipeline, const PipelineContext& context,
                      const std::filesystem::path& out_dir);

/// The way back out along an ultrasound beacon trail (`trailmark wayout`): the beacon map
/// of the mission's rows up to `at_s` (default: the end), and the route of `agent` from the
/// beacons heard in the last `window_s` seconds.
beacons::WayOutReport ComputeWayOut(const MissionDirectory& mission, const std::string& agent,
                                    std::optional<TimeS> at_s, double window_s = 3.0);

}  // namespace trailmark

// SPDX-License-Identifier: MIT
#pragma once
/// The one table of trailmark's pipelines. Each entry names an online estimator of the library
/// (core/online_estimator.h), the streams it needs and uses, what it can do, its options (the
/// schema generated from the estimator's Options struct and OptionTable), and the factory
/// that builds it for an incident. The batch run (batch_run.h), the live server, the CLI
/// (`run`, `pipelines`, `serve`, `reproduce`, `demo`) and the docs' option tables all read it:
/// nothing else compares pipeline names.

#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "trailmark/core/mission.h"
#include "trailmark/core/online_estimator.h"
#include "trailmark/core/options.h"
#include "trailmark/geometry/floor_plan.h"
#include "trailmark/ins/step_front_end.h"
#include "trailmark/mapmatch/search_map.h"

namespace trailmark {

/// What a steps-based pipeline needs: steps.csv, or imu.csv through the foot INS.
inline constexpr StreamSet kStepOrImuStreams{Stream::kSteps, Stream::kImu};

/// What an estimator is built for: the incident's nodes, and the floor it works on.
struct EstimatorInputs {
  const MissionInfo& info;
  const FloorPlan* floor_plan = nullptr;  ///< pipelines that need one: the floor to use
  std::string floor_plan_source = "the floor plan";  ///< names it in errors
  /// Every level's plan of a multi-level building, when the pipeline follows the floors (no
  /// `level` option given); null otherwise.
  const LevelPlans* floor_levels = nullptr;
  /// The streams that will be fed, when known (a batch run knows them; live: nullopt). The
  /// fusion builds only the members these streams can feed.
  std::optional<StreamSet> streams{};
};

struct PipelineSpec {
  std::string name;
  std::string description;
  /// Streams it cannot run without; each entry is a set of alternatives ("steps.csv or
  /// imu.csv").
  std::vector<StreamSet> needs;
  /// Streams it reads when present (those in `needs` included).
  StreamSet uses;
  bool needs_floor_plan = false;
  /// Reads the mission's floor plan when it has one (the fusion's map-matching member).
  bool uses_floor_plan = false;
  int min_landmarks = 0;  ///< landmark nodes mission.json must declare
  /// Its steps come from steps.csv or from imu.csv through the INS (steps.csv wins in a batch
  /// run when a mission has both).
  bool steps_based = false;
  /// Steps-based, and a mission with both imu.csv and steps.csv feeds it the foot IMU's steps
  /// (through the ZUPT INS) instead of steps.csv's (the fusion: a foot INS dead-reckons far
  /// better than a phone's PDR; docs/fusion.md). Live, each agent's first rows decide, as for
  /// every steps-based pipeline (the IMU's come first: it rests before the first step).
  bool prefers_foot_imu = false;
  /// The live server raises map-error alerts from its estimates (a map-aided estimator).
  bool raises_map_alerts = false;
  /// Dead reckoning: the demo runs it on every mission for comparison.
  bool baseline = false;
  /// `trailmark serve` without --pipeline takes the runnable pipeline of lowest rank (nullopt:
  /// never chosen by default).
  std::optional<int> serve_rank;
  /// The simulated experiments of its paper (the demo runs it there).
  std::vector<std::string> paper_scenarios;
  /// Options the demo and reports use (e.g. a lower output rate).
  OptionValues report_options;
  /// Every option with its type, default, unit, range and description.
  std::vector<OptionInfo> options;

  /// Builds the estimator for an incident. `feed`: how rows will arrive (a batch merge in time
  /// order, or live). Throws std::invalid_argument naming the pipeline and the key for an
  /// unknown, malformed or out-of-range option (the message lists the valid keys), or when a
  /// floor plan it needs is missing; InputError for a floor plan it cannot use.
  std::function<std::unique_ptr<OnlineEstimator>(const EstimatorInputs&, const OptionValues&,
                                                 Feed)>
      make;
  /// The floor of a multi-floor plan it works on (its `level` option); nullopt: the plan's
  /// default floor. Throws like `make` for bad options.
  std::function<std::optional<int>(const OptionValues&)> floor_level;
  /// The estimator as a member of the fusion: `make` without its step front end and stream
  /// check (the fusion has its own), with its dead-reckoning guard; rows in global time order.
  /// Null for a pipeline that cannot be a member.
  std::function<std::unique_ptr<OnlineEstimator>(const EstimatorInputs&, const OptionValues&)>
      make_member;
  /// A map-matching pipeline's search-pattern options with these option values (its grid's
  /// spacing and alignment): what the report draws. Empty for a pipeline without patterns.
  std::function<mapmatch::SearchSequenceOptions(const OptionValues&)> search_patterns;

  /// Whether a mission with these streams, landmarks and floor plan can feed it.
  bool CanRun(const MissionInfo& info, StreamSet present, bool has_floor_plan) const;
  /// Its needs in words: "steps.csv or imu.csv", "3+ landmarks in mission.json", ...
  std::vector<std::string> NeedsText() const;
};

/// Every pipeline, in a stable order.
const std::vector<PipelineSpec>& Pipelines();
/// Null when no pipeline has that name.
const PipelineSpec* FindPipeline(std::string_view name);
/// The pipeline of that name; std::invalid_argument naming the known ones otherwise.
const PipelineSpec& RequirePipeline(std::string_view name);
/// The registry as JSON (`trailmark pipelines --json`): every pipeline with name, description,
/// needs, uses, live, capabilities and options [{key, type, default, unit, description, ...}].
std::string RegistryJson();
/// The option tables in Markdown (docs/pipeline-options.md is this text).
std::string RegistryMarkdown();

}  // namespace trailmark

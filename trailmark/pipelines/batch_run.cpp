// SPDX-License-Identifier: MIT
#include "trailmark/pipelines/batch_run.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <chrono>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>

#include "trailmark/core/error.h"
#include "trailmark/io/merged_stream.h"

namespace trailmark {

StreamSet PresentStreams(const MissionDirectory& mission) {
  StreamSet present;
  for (Stream s : kAllStreams) {
    if (mission.Has(std::string(StreamFileName(s)))) present.Add(s);
  }
  return present;
}

namespace {
bool HasFloorPlan(const MissionDirectory& mission) {
  return mission.info().floorplan && mission.Has(*mission.info().floorplan);
}
}  // namespace

bool CanRun(const PipelineSpec& pipeline, const MissionDirectory& mission) {
  return pipeline.CanRun(mission.info(), PresentStreams(mission), HasFloorPlan(mission));
}

std::vector<std::string> RunnablePipelines(const MissionDirectory& mission) {
  std::vector<std::string> names;
  for (const auto& p : Pipelines()) {
    if (CanRun(p, mission)) names.push_back(p.name);
  }
  return names;
}

void RequireCanRun(const PipelineSpec& pipeline, const MissionDirectory& mission) {
  if (CanRun(pipeline, mission)) return;
  const StreamSet present = PresentStreams(mission);
  const std::string who = "pipeline '" + pipeline.name + "'";
  for (const StreamSet& alternatives : pipeline.needs) {
    const auto list = alternatives.List();
    bool any = false;
    for (Stream s : list) any = any || present.Has(s);
    if (any || list.empty()) continue;
    std::vector<std::string> others;
    for (std::size_t k = 1; k < list.size(); ++k) others.emplace_back(StreamFileName(list[k]));
    mission.Require(std::string(StreamFileName(list.front())),
                    others.empty() ? who : fmt::format("{} (or {})", who, fmt::join(others, ", ")));
  }
  RequireFloorPlan(pipeline, mission);
  throw InputError(mission.dir().string(), 0,
                   fmt::format("{} needs {}", who, fmt::join(pipeline.NeedsText(), ", ")));
}

void RequireFloorPlan(const PipelineSpec& pipeline, const MissionDirectory& mission) {
  if (!pipeline.needs_floor_plan) return;
  const std::string who = "pipeline '" + pipeline.name + "'";
  if (!mission.info().floorplan) {
    throw InputError(mission.Path("mission.json").string(), 0,
                     who + " needs a floor plan: mission.json has no \"floorplan\"");
  }
  mission.Require(*mission.info().floorplan, who);
}

PipelinePlan LoadPipelinePlan(const PipelineSpec& pipeline, const MissionDirectory& mission,
                              const OptionValues& options, std::vector<std::string>* notes) {
  PipelinePlan plan;
  const bool optional_plan = pipeline.uses_floor_plan && mission.info().floorplan.has_value();
  if (!pipeline.needs_floor_plan && !optional_plan) return plan;
  RequireFloorPlan(pipeline, mission);
  plan.floor = LoadPipelineFloor(pipeline, mission, options, notes, &plan.levels);
  plan.source = mission.Path(*mission.info().floorplan).string();
  return plan;
}

std::optional<FloorPlan> LoadPipelineFloor(const PipelineSpec& pipeline,
                                           const MissionDirectory& mission,
                                           const OptionValues& options,
                                           std::vector<std::string>* notes,
                                           LevelPlans* all_levels) {
  const std::optional<int> level =
      pipeline.floor_level ? pipeline.floor_level(options) : std::nullopt;
  std::vector<int> levels;
  std::optional<FloorPlan> plan = mission.LoadFloorPlan(level, &levels);
  if (plan && all_levels && !level && levels.size() > 1) {
    all_levels->clear();
    for (const int l : levels) all_levels->emplace_back(l, *mission.LoadFloorPlan(l));
    if (notes) {
      notes->push_back(fmt::format(
          "floor plan: {} levels ({}); each agent's filter uses the plan of the level it is on "
          "(option level=N for one level only)",
          levels.size(), fmt::join(levels, ", ")));
    }
    return plan;
  }
  if (plan && notes && levels.size() > 1) {
    notes->push_back(fmt::format("floor plan: {} levels ({}); the filter uses level {}{}",
                                 levels.size(), fmt::join(levels, ", "),
                                 level.value_or(DefaultFloorPlanLevel(levels)),
                                 level ? "" : " (option level=N for another)"));
  }
  return plan;
}

namespace {

StreamSet Without(StreamSet set, Stream left_out) {
  StreamSet out;
  for (Stream s : set.List()) {
    if (s != left_out) out.Add(s);
  }
  return out;
}

/// The streams of the mission a reader of `uses` gets; steps.csv shadows imu.csv for a
/// steps-based one, imu.csv steps.csv for one that prefers the foot IMU (noted).
StreamSet FeedStreams(StreamSet uses, bool steps_based, bool prefers_foot_imu,
                      const MissionDirectory& mission, const OptionValues& options,
                      std::vector<std::string>* notes) {
  const StreamSet present = PresentStreams(mission);
  StreamSet feed;
  for (Stream s : uses.List()) {
    if (present.Has(s)) feed.Add(s);
  }
  if (steps_based && prefers_foot_imu && feed.Has(Stream::kSteps) && feed.Has(Stream::kImu)) {
    notes->push_back(
        "steps from imu.csv through the foot INS; steps.csv not used (remove imu.csv to use "
        "it)");
    return Without(feed, Stream::kSteps);
  }
  if (steps_based && feed.Has(Stream::kSteps)) {
    bool ins_options = false;
    for (const auto& [key, value] : options) ins_options = ins_options || key.rfind("ins.", 0) == 0;
    if (ins_options) notes->push_back("ins.* options ignored: the mission has steps.csv");
    if (feed.Has(Stream::kImu)) {
      notes->push_back(
          "steps from steps.csv; imu.csv not used (remove steps.csv to run the INS on it, or "
          "run the ins pipeline)");
      feed = Without(feed, Stream::kImu);
    }
  }
  return feed;
}

/// Feeds `stream` into `estimator` until its end (or a row after `until`), then Finish.
void Drive(OnlineEstimator& estimator, MergedStream& stream, const MissionDirectory& mission,
           EstimateSink& sink, const ProgressCallback& progress,
           std::optional<TimeS> until = std::nullopt) {
  MissionRow row;
  std::size_t rows = 0;
  while (stream.Next(row)) {
    if (until && RowTime(row) > *until) break;
    try {
      estimator.Add(row, sink);
    } catch (const std::invalid_argument& e) {
      stream.Fail(e.what());
    }
    if ((++rows & 0xfff) == 0) progress(stream.Progress());
  }
  try {
    estimator.Finish(sink);
  } catch (const std::invalid_argument& e) {
    throw InputError(mission.dir().string(), 0, e.what());
  }
  progress(1.0);
}

}  // namespace

StreamSet BatchFeedStreams(const PipelineSpec& pipeline, const MissionDirectory& mission,
                           const OptionValues& options, std::vector<std::string>* notes) {
  std::vector<std::string> ignored;
  return FeedStreams(pipeline.uses, pipeline.steps_based, pipeline.prefers_foot_imu, mission,
                     options, notes != nullptr ? notes : &ignored);
}

EstimatorSummary RunBatch(const PipelineSpec& pipeline, const PipelineContext& context,
                          EstimateSink& sink) {
  const MissionDirectory& mission = context.mission;
  RequireCanRun(pipeline, mission);
  EstimatorSummary summary;
  const StreamSet feed = BatchFeedStreams(pipeline, mission, context.options, &summary.notes);
  const PipelinePlan plan = LoadPipelinePlan(pipeline, mission, context.options, &summary.notes);
  EstimatorInputs inputs = plan.InputsFor(mission.info());
  inputs.streams = feed;
  const auto estimator = pipeline.make(inputs, context.options, Feed::kTimeOrdered);
  MergedStream stream(mission, feed);
  Drive(*estimator, stream, mission, sink, context.progress);
  summary.Merge(estimator->Summary());
  return summary;
}

void RestampingSink::Add(const Estimate& e) {
  if (e.t < last_t_) {
    Estimate copy = e;
    copy.t = last_t_;
    inner_.Add(copy);
    ++restamped_;
  } else {
    inner_.Add(e);
    last_t_ = e.t;
  }
  ++count_;
}

bool EstimatesHaveFloorColumns(const MissionDirectory& mission) {
  return !mission.info().floors.empty() || PresentStreams(mission).Has(Stream::kBaro);
}

namespace {

class CsvRowSink : public EstimateSink {
 public:
  CsvRowSink(const std::string& path, bool floor_columns) : writer_(path, floor_columns) {}
  void Add(const Estimate& e) override { writer_.Write(e); }
  void Close() { writer_.Close(); }

 private:
  RowWriter<Estimate> writer_;
};

}  // namespace

RunResult RunPipeline(const PipelineSpec& pipeline, const PipelineContext& context,
                      const std::filesystem::path& out_dir) {
  std::filesystem::create_directories(out_dir);
  // Written beside and renamed when the run succeeds: a run refused (a bad option, a bad row)
  // leaves an earlier run's estimates.csv as it was, not truncated beside its diagnostics.json.
  const std::filesystem::path partial = out_dir / "estimates.csv.partial";
  const auto t0 = std::chrono::steady_clock::now();
  RunResult result;
  result.pipeline = pipeline.name;
  std::size_t restamped = 0;
  try {
    CsvRowSink csv(partial.string(), EstimatesHaveFloorColumns(context.mission));
    RestampingSink sink(csv);
    result.summary = RunBatch(pipeline, context, sink);
    csv.Close();
    result.estimates = sink.count();
    restamped = sink.restamped();
  } catch (...) {
    std::error_code ignored;
    std::filesystem::remove(partial, ignored);
    throw;
  }
  std::filesystem::rename(partial, out_dir / "estimates.csv");
  result.wall_time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  nlohmann::json diag;
  diag["pipeline"] = pipeline.name;
  diag["mission"] = context.mission.dir().string();
  diag["estimates"] = result.estimates;
  diag["wall_time_s"] = result.wall_time_s;
  diag["rows_restamped"] = restamped;
  diag["numbers"] = result.summary.numbers;
  diag["notes"] = result.summary.notes;
  // Integrity notes (issue 21): sources excluded and readmitted, fallbacks to dead reckoning.
  diag["integrity"] = nlohmann::json::array();
  for (const IntegrityNote& n : result.summary.integrity) {
    diag["integrity"].push_back({{"t", n.t}, {"source", n.source}, {"node", n.node},
                                 {"action", n.action}, {"message", n.message}});
  }
  diag["options"] = context.options;
  std::ofstream(out_dir / "diagnostics.json") << diag.dump(2) << "\n";
  return result;
}

beacons::WayOutReport ComputeWayOut(const MissionDirectory& mission, const std::string& agent,
                                    std::optional<TimeS> at_s, double window_s) {
  const NodeInfo* node = mission.info().Find(agent);
  if (node == nullptr || node->kind != NodeKind::kAgent) {
    throw InputError(mission.Path("mission.json").string(), 0,
                     "no agent '" + agent + "' in mission.json");
  }
  mission.Require("ranges.csv", "the way out");
  // The beacon map as beacons-mds builds it: steps (when present) place the layout where the
  // beacons were dropped.
  beacons::BeaconTrailOptions options;
  options.tracker = beacons::Tracker::kNone;
  auto map = std::make_unique<beacons::BeaconTrailEstimator>(mission.info(), options);
  const beacons::BeaconTrailEstimator& trail = *map;
  StepFrontEnd estimator(mission.info(), {}, RowOrder::kGlobal, Feed::kTimeOrdered,
                         std::move(map));
  std::vector<std::string> notes;
  const StreamSet uses{Stream::kSteps, Stream::kImu, Stream::kRanges, Stream::kEvents};
  MergedStream stream(mission, FeedStreams(uses, true, false, mission, {}, &notes));
  NullSink sink;
  Drive(estimator, stream, mission, sink, [](double) {}, at_s);
  return trail.WayOut(agent, at_s.value_or(trail.last_t()), window_s);
}

}  // namespace trailmark

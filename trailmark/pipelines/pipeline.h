#pragma once
/// A pipeline turns a mission directory into online estimates (estimates.csv) plus its own
/// diagnostics. Pipelines sit on io/ and on the estimator folders; the CLI, the report and the
/// server run them by name.

#include <chrono>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "trailmark/core/measurements.h"
#include "trailmark/io/mission_io.h"

namespace trailmark {

/// Receives estimates in non-decreasing time.
class EstimateSink {
 public:
  virtual ~EstimateSink() = default;
  virtual void Add(const Estimate& estimate) = 0;
};

/// Keeps every estimate in memory (tests, reproductions, the server's replay).
class VectorSink : public EstimateSink {
 public:
  void Add(const Estimate& estimate) override { rows.push_back(estimate); }
  /// The rows in non-decreasing time (stable: equal times keep their order); empties the sink.
  std::vector<Estimate> TakeSortedByTime();
  std::vector<Estimate> rows;
};

/// Progress: fraction done in [0, 1].
using ProgressCallback = std::function<void(double fraction)>;

struct PipelineContext {
  const MissionDirectory& mission;
  std::map<std::string, std::string> options;  ///< --option key=value from the CLI
  ProgressCallback progress = [](double) {};
};

/// What a run reports besides its estimates (written to diagnostics.json).
struct PipelineSummary {
  std::map<std::string, double> numbers;
  std::vector<std::string> notes;
};

class Pipeline {
 public:
  virtual ~Pipeline() = default;
  virtual std::string name() const = 0;
  virtual std::string description() const = 0;
  /// Files of the mission directory the pipeline cannot run without.
  virtual std::vector<std::string> required_files() const = 0;
  /// Files it uses when present.
  virtual std::vector<std::string> optional_files() const { return {}; }
  /// Whether the mission has what the pipeline needs (default: every required file).
  virtual bool CanRun(const MissionDirectory& mission) const {
    for (const auto& f : required_files()) {
      if (!mission.Has(f)) return false;
    }
    return true;
  }
  /// Throws InputError on bad or missing input.
  virtual PipelineSummary Run(const PipelineContext& context, EstimateSink& sink) const = 0;
};

/// Every pipeline, in a stable order.
const std::vector<std::unique_ptr<Pipeline>>& AllPipelines();
/// Null when no pipeline has that name.
const Pipeline* FindPipeline(const std::string& name);
/// Names of the pipelines whose required files the mission has.
std::vector<std::string> RunnablePipelines(const MissionDirectory& mission);

struct RunResult {
  std::string pipeline;
  std::size_t estimates = 0;
  double wall_time_s = 0;
  PipelineSummary summary;
};

/// Runs a pipeline and writes `out_dir`/estimates.csv and diagnostics.json.
RunResult RunPipeline(const Pipeline& pipeline, const PipelineContext& context,
                      const std::filesystem::path& out_dir);

}  // namespace trailmark

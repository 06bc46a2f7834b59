#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>

#include "trailmark/pipelines/beacons_pipeline.h"
#include "trailmark/pipelines/breadcrumb_pipeline.h"
#include "trailmark/pipelines/ins_pipeline.h"
#include "trailmark/pipelines/landmarks_pipeline.h"
#include "trailmark/pipelines/mapmatch_pipeline.h"
#include "trailmark/pipelines/pdr_pipeline.h"
#include "trailmark/pipelines/pipeline.h"

namespace trailmark {

std::vector<Estimate> VectorSink::TakeSortedByTime() {
  std::vector<Estimate> out = std::move(rows);
  rows.clear();
  std::stable_sort(out.begin(), out.end(),
                   [](const Estimate& a, const Estimate& b) { return a.t < b.t; });
  return out;
}

const std::vector<std::unique_ptr<Pipeline>>& AllPipelines() {
  static const auto* pipelines = [] {
    auto* v = new std::vector<std::unique_ptr<Pipeline>>();
    v->push_back(std::make_unique<PdrPipeline>());
    v->push_back(std::make_unique<BreadcrumbPipeline>());
    v->push_back(std::make_unique<InsPipeline>());
    v->push_back(std::make_unique<LandmarksPipeline>(false));
    v->push_back(std::make_unique<LandmarksPipeline>(true));
    v->push_back(std::make_unique<BeaconsPipeline>(false));
    v->push_back(std::make_unique<BeaconsPipeline>(true));
    v->push_back(std::make_unique<MapMatchPipeline>());
    return v;
  }();
  return *pipelines;
}

const Pipeline* FindPipeline(const std::string& name) {
  for (const auto& p : AllPipelines()) {
    if (p->name() == name) return p.get();
  }
  return nullptr;
}

std::vector<std::string> RunnablePipelines(const MissionDirectory& mission) {
  std::vector<std::string> names;
  for (const auto& p : AllPipelines()) {
    if (p->CanRun(mission)) names.push_back(p->name());
  }
  return names;
}

namespace {

class CsvEstimateSink : public EstimateSink {
 public:
  explicit CsvEstimateSink(const std::string& path) : writer_(path) {}
  // estimates.csv is in non-decreasing time (spec). An estimate is known when it is written:
  // a row stamped earlier than one already written (e.g. an agent's start, emitted with its
  // first step, after another agent's rows) is stamped with the latest time instead.
  void Add(const Estimate& e) override {
    if (e.t < last_t_) {
      Estimate copy = e;
      copy.t = last_t_;
      writer_.Write(copy);
      ++restamped_;
    } else {
      writer_.Write(e);
      last_t_ = e.t;
    }
    ++count_;
  }
  std::size_t restamped() const { return restamped_; }
  void Close() { writer_.Close(); }
  std::size_t count() const { return count_; }

 private:
  RowWriter<Estimate> writer_;
  std::size_t count_ = 0;
  std::size_t restamped_ = 0;
  double last_t_ = -std::numeric_limits<double>::infinity();
};

}  // namespace

RunResult RunPipeline(const Pipeline& pipeline, const PipelineContext& context,
                      const std::filesystem::path& out_dir) {
  std::filesystem::create_directories(out_dir);
  CsvEstimateSink sink((out_dir / "estimates.csv").string());
  const auto t0 = std::chrono::steady_clock::now();
  RunResult result;
  result.pipeline = pipeline.name();
  result.summary = pipeline.Run(context, sink);
  sink.Close();
  result.wall_time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  result.estimates = sink.count();
  nlohmann::json diag;
  diag["pipeline"] = pipeline.name();
  diag["mission"] = context.mission.dir().string();
  diag["estimates"] = result.estimates;
  diag["wall_time_s"] = result.wall_time_s;
  diag["rows_restamped"] = sink.restamped();
  diag["numbers"] = result.summary.numbers;
  diag["notes"] = result.summary.notes;
  diag["options"] = context.options;
  std::ofstream(out_dir / "diagnostics.json") << diag.dump(2) << "\n";
  return result;
}

}  // namespace trailmark

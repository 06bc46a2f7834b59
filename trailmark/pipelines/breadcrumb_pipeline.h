#pragma once
/// `breadcrumb`: the collaborative localization of the breadcrumb paper (GEN estimator,
/// breadcrumb/localizer.h) on a mission directory: PDR steps, RSSI between all nodes, direct
/// ranges, drop events. Online output: each agent at every step; static nodes when their
/// estimate changed (checked every `static_period_s` of mission time) and at the end.

#include "trailmark/breadcrumb/localizer.h"
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "trailmark/pipelines/merged_stream.h"
#include "trailmark/pipelines/pipeline.h"

namespace trailmark {

class BreadcrumbPipeline : public Pipeline {
 public:
  std::string name() const override { return "breadcrumb"; }
  std::string description() const override {
    return "breadcrumb paper: incremental generalized-electrical-network estimator over PDR "
           "steps, RSSI/ranges between agents and dropped crumbs (IV)";
  }
  std::vector<std::string> required_files() const override { return {"steps.csv or imu.csv"}; }
  bool CanRun(const MissionDirectory& mission) const override;
  std::vector<std::string> optional_files() const override {
    return {"rssi.csv", "ranges.csv", "events.csv"};
  }
  PipelineSummary Run(const PipelineContext& context, EstimateSink& sink) const override;
};

/// Options of the pipeline from `--option key=value` (documented in docs/breadcrumb.md).
breadcrumb::LocalizerOptions BreadcrumbOptionsFrom(const std::map<std::string, std::string>& values,
                                                   double* static_period_s);

/// The localizer set up for an incident (nodes, radio model, options) and fed row by row in
/// time order, emitting the pipeline's online estimates: each agent at every step, static nodes
/// when changed (every static_period_s) — the batch pipeline and its live form share it.
class BreadcrumbSession {
 public:
  /// `options`: the pipeline's `--option` keys without the "ins." ones; notes go to `notes`.
  /// Throws std::invalid_argument on bad options.
  BreadcrumbSession(const MissionInfo& info, const std::map<std::string, std::string>& options,
                    PipelineSummary* notes);
  ~BreadcrumbSession();
  /// One row, rows in time order (steps by t1); throws std::invalid_argument for steps of a
  /// node that is not an agent.
  void Add(const MissionRow& row, EstimateSink& sink);
  /// End of data: every agent's and static node's final estimate.
  void Finish(const MissionInfo& info, EstimateSink& sink);
  /// The localizer's counters, calibration, latency percentiles and notes.
  void Summarize(PipelineSummary& summary);

 private:
  void EmitAgent(const std::string& id, EstimateSink& sink);
  void EmitStatic(TimeS t, bool all, EstimateSink& sink);
  double static_period_s_ = 1.0;
  breadcrumb::LocalizerOptions options_;
  std::unique_ptr<breadcrumb::BreadcrumbLocalizer> loc_;
  std::map<std::string, double> agent_z_;
  std::vector<std::string> known_starts_;
  std::map<std::string, Vec2> last_static_;
  std::vector<float> latency_us_;
  TimeS t_last_ = 0, next_static_ = -1e300;
  bool any_ = false;
};

}  // namespace trailmark

#pragma once
/// `breadcrumb`: the collaborative localization of the breadcrumb paper (GEN estimator,
/// breadcrumb/localizer.h) on a mission directory: PDR steps, RSSI between all nodes, direct
/// ranges, drop events. Online output: each agent at every step; static nodes when their
/// estimate changed (checked every `static_period_s` of mission time) and at the end.

#include "trailmark/breadcrumb/localizer.h"
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

}  // namespace trailmark

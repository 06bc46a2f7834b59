// SPDX-License-Identifier: MIT
#pragma once
/// One self-contained HTML report (works offline: Chart.js is embedded, nothing is fetched):
/// floor plan, truth and estimated trajectories per pipeline, crumb/landmark estimates with 95 %
/// ellipses — an SVG map at true scale (a metre as long east as north), zoomable and pannable,
/// in the dashboard's colours — error over time, error CDF and the metrics table.

#include <optional>
#include <string>
#include <vector>

#include "trailmark/core/mission.h"
#include "trailmark/eval/metrics.h"
#include "trailmark/geometry/floor_plan.h"

namespace trailmark {

struct ReportRun {
  std::string pipeline;
  std::vector<Estimate> estimates;
  Metrics metrics;
  double wall_time_s = 0;
};

/// A map layer beside the trajectories (e.g. map matching's search patterns): polylines and
/// points in the navigation frame, listed in the legend, hidden until its box is ticked unless
/// `visible`.
struct ReportLayer {
  std::string label;
  std::string colour = "#6b8e23";
  std::vector<std::vector<Vec2>> lines;
  std::vector<Vec2> points;
  bool dashed = false;
  bool visible = false;
};

struct ReportInput {
  MissionInfo info;
  std::optional<FloorPlan> plan;
  std::vector<ReportLayer> layers;
  std::vector<TruthSample> truth;
  std::vector<ReportRun> runs;
  std::size_t max_points_per_series = 4000;
};

std::string BuildHtmlReport(const ReportInput& input);

/// Points of the 95 % ellipse (chi-square 2 dof, 5.991) of a 2x2 covariance around a centre.
std::vector<Vec2> ConfidenceEllipse(const Vec2& centre, double sxx, double sxy, double syy,
                                    int points = 36);

}  // namespace trailmark

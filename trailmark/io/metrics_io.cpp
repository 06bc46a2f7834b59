// SPDX-License-Identifier: MIT
#include "trailmark/io/metrics_io.h"

#include <fstream>
#include <nlohmann/json.hpp>

namespace trailmark {
namespace {

/// A statistic over `samples` errors: null when there were none (a node never scored has no
/// error, not an error of 0 m).
nlohmann::json Stat(double value, std::size_t samples) {
  return samples > 0 ? nlohmann::json(value) : nlohmann::json(nullptr);
}

nlohmann::json NodeJson(const NodeMetrics& m, std::size_t max_series) {
  nlohmann::json j;
  j["id"] = m.id;
  j["kind"] = std::string(ToString(m.kind));
  const std::size_t n = m.stats.samples;
  j["samples"] = n;
  j["uncovered"] = m.uncovered;
  j["mean_m"] = Stat(m.stats.mean_m, n);
  j["median_m"] = Stat(m.stats.median_m, n);
  j["p75_m"] = Stat(m.stats.p75_m, n);
  j["p95_m"] = Stat(m.stats.p95_m, n);
  j["max_m"] = Stat(m.stats.max_m, n);
  j["rmse_m"] = Stat(m.stats.rmse_m, n);
  j["final_m"] = Stat(m.stats.final_m, n);
  j["in95"] = Stat(m.stats.in95, n);  // share of truth inside the estimate's own 95 % ellipse
  j["mean_nees"] = Stat(m.stats.mean_nees, n);
  if (m.kind == NodeKind::kAgent) {
    // The same check at each estimate's own instant (truth interpolated): no lag of a held row.
    const std::size_t ne = m.at_estimates.samples;
    j["in95_at_estimates"] = Stat(m.at_estimates.in95, ne);
    j["mean_nees_at_estimates"] = Stat(m.at_estimates.mean_nees, ne);
    j["estimates_scored"] = ne;
  }
  j["distance_m"] = m.distance_m;
  j["mean_pct_of_distance"] = m.mean_pct_of_distance ? nlohmann::json(*m.mean_pct_of_distance)
                                                     : nlohmann::json(nullptr);
  j["max_pct_of_distance"] = m.max_pct_of_distance ? nlohmann::json(*m.max_pct_of_distance)
                                                   : nlohmann::json(nullptr);
  nlohmann::json t = nlohmann::json::array(), e = nlohmann::json::array();
  const std::size_t points = m.series.size();
  const std::size_t stride =
      (max_series == 0 || points <= max_series) ? 1 : (points + max_series - 1) / max_series;
  for (std::size_t i = 0; i < points; i += stride) {
    t.push_back(m.series[i].t);
    e.push_back(m.series[i].error_m);
  }
  j["series"] = {{"t", t}, {"error_m", e}};
  return j;
}

}  // namespace

std::string MetricsToJson(const Metrics& metrics, std::size_t max_series) {
  nlohmann::json root;
  root["overall"] = {{"agents", NodeJson(metrics.agents, max_series)},
                     {"static", NodeJson(metrics.static_nodes, max_series)}};
  nlohmann::json nodes = nlohmann::json::array();
  for (const auto& m : metrics.nodes) nodes.push_back(NodeJson(m, max_series));
  root["nodes"] = nodes;
  root["estimates_without_truth"] = metrics.estimates_without_truth;
  if (metrics.floors) {
    const FloorMetrics& f = *metrics.floors;
    root["floors"] = {{"samples", f.samples},
                      {"floor_hit_rate", f.floor_hit_rate},
                      {"ce95_m", f.ce95_m},
                      {"ve95_m", f.ve95_m},
                      {"vertical_mean_m", f.vertical_mean_m},
                      {"se95_m", f.se95_m},
                      {"ipin_score_m", f.ipin_score_m},
                      {"hit_rate_by_agent", f.hit_rate_by_agent},
                      {"vertical_checked", f.vertical_checked}};
    if (f.vertical_checked > 0) {
      root["floors"]["vertical_in95"] = f.vertical_in95;
      root["floors"]["vertical_mean_nees"] = f.vertical_mean_nees;
    }
  }
  return root.dump(1) + "\n";
}

void WriteMetricsJson(const std::filesystem::path& path, const Metrics& metrics) {
  std::ofstream out(path, std::ios::binary);
  out << MetricsToJson(metrics);
  if (!out) throw std::runtime_error(path.string() + ": write failed");
}

}  // namespace trailmark

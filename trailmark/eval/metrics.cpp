// SPDX-License-Identifier: MIT
#include "trailmark/eval/metrics.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>

namespace trailmark {
namespace {

double HorizontalError(const Vec3& a, const Vec3& b) { return (a - b).head<2>().norm(); }

ErrorSample Sample(TimeS t, const Estimate& e, const Vec3& truth_n) {
  const Vec2 d = (e.position_n - truth_n).head<2>();
  // No covariance given (an empty cell in estimates.csv): no NEES, not an ellipse of zero.
  const double nees = e.covariance_known ? HorizontalNees(d, e.sxx, e.sxy, e.syy)
                                         : std::numeric_limits<double>::quiet_NaN();
  return {t, d.norm(), nees};
}

/// The share of the samples with a covariance whose truth is inside it; NaN (written as null,
/// printed as "-") when no sample has one.
double InsideShare(std::size_t inside, std::size_t with_covariance) {
  return with_covariance > 0 ? static_cast<double>(inside) / static_cast<double>(with_covariance)
                             : std::numeric_limits<double>::quiet_NaN();
}

void FinishPercentages(NodeMetrics& m) {
  if (m.distance_m > 0 && m.stats.samples > 0) {
    m.mean_pct_of_distance = 100.0 * m.stats.mean_m / m.distance_m;
    m.max_pct_of_distance = 100.0 * m.stats.max_m / m.distance_m;
  }
}

}  // namespace

double HorizontalNees(const Vec2& error_n, double sxx, double sxy, double syy) {
  const double det = sxx * syy - sxy * sxy;
  if (!(sxx > 0) || !(syy > 0) || !(det > 0) || !std::isfinite(det)) {
    return error_n.norm() <= 1e-3 ? 0.0 : std::numeric_limits<double>::infinity();
  }
  // S^-1 = [syy -sxy; -sxy sxx] / det.
  const double x = error_n.x(), y = error_n.y();
  return (syy * x * x - 2.0 * sxy * x * y + sxx * y * y) / det;
}

double Percentile(std::vector<double> values, double q) {
  if (values.empty()) return 0.0;
  std::sort(values.begin(), values.end());
  const double pos = std::clamp(q, 0.0, 100.0) / 100.0 * static_cast<double>(values.size() - 1);
  const auto lo = static_cast<std::size_t>(std::floor(pos));
  const auto hi = std::min(lo + 1, values.size() - 1);
  return values[lo] + (pos - static_cast<double>(lo)) * (values[hi] - values[lo]);
}

ErrorStatistics ComputeStatistics(const std::vector<ErrorSample>& series) {
  ErrorStatistics s;
  s.samples = series.size();
  if (series.empty()) return s;
  std::vector<double> e;
  e.reserve(series.size());
  double sum = 0, sum2 = 0, nees_sum = 0;
  std::size_t inside = 0, finite = 0, with_covariance = 0;
  for (const auto& x : series) {
    e.push_back(x.error_m);
    sum += x.error_m;
    sum2 += x.error_m * x.error_m;
    with_covariance += !std::isnan(x.nees);
    inside += x.nees <= kChi2Dof2P95;
    if (std::isfinite(x.nees)) nees_sum += x.nees, ++finite;
  }
  const double n = static_cast<double>(series.size());
  s.in95 = InsideShare(inside, with_covariance);
  s.mean_nees = finite > 0 ? nees_sum / static_cast<double>(finite) : 0.0;
  s.mean_m = sum / n;
  s.rmse_m = std::sqrt(sum2 / n);
  s.max_m = *std::max_element(e.begin(), e.end());
  s.median_m = Percentile(e, 50);
  s.p75_m = Percentile(e, 75);
  s.p95_m = Percentile(std::move(e), 95);
  s.final_m = series.back().error_m;
  return s;
}

EllipseCheck ComputeEllipseCheck(const std::vector<ErrorSample>& at_estimates) {
  EllipseCheck c;
  c.samples = at_estimates.size();
  if (at_estimates.empty()) return c;
  std::size_t inside = 0, finite = 0, with_covariance = 0;
  double sum = 0;
  for (const auto& x : at_estimates) {
    with_covariance += !std::isnan(x.nees);
    inside += x.nees <= kChi2Dof2P95;
    if (std::isfinite(x.nees)) sum += x.nees, ++finite;
  }
  c.in95 = InsideShare(inside, with_covariance);
  c.mean_nees = finite > 0 ? sum / static_cast<double>(finite) : 0.0;
  return c;
}

Metrics Evaluate(const MissionInfo& info, const std::vector<TruthSample>& truth,
                 const std::vector<Estimate>& estimates) {
  std::map<std::string, std::vector<const TruthSample*>> truth_by_id;
  std::vector<std::string> order;
  TimeS end_t = -std::numeric_limits<double>::infinity();
  for (const auto& s : truth) {
    auto& v = truth_by_id[s.id];
    if (v.empty()) order.push_back(s.id);
    v.push_back(&s);
    end_t = std::max(end_t, s.t);
  }
  std::map<std::string, std::vector<const Estimate*>> est_by_id;
  Metrics out;
  for (const auto& e : estimates) {
    if (truth_by_id.count(e.id) == 0) {
      ++out.estimates_without_truth;
      continue;
    }
    est_by_id[e.id].push_back(&e);
    end_t = std::max(end_t, e.t);
  }

  out.agents.id = "agents";
  out.agents.kind = NodeKind::kAgent;
  out.static_nodes.id = "static";
  out.static_nodes.kind = NodeKind::kCrumb;
  std::vector<double> agent_mean_pct, agent_max_pct;
  // Floors: horizontal, vertical, level difference at each scored agent instant.
  const bool floors = !info.floors.empty() ||
                      std::any_of(truth.begin(), truth.end(),
                                  [](const TruthSample& s) { return s.floor.has_value(); });
  std::vector<double> h_err, v_err, s_err, ipin;
  std::size_t hits = 0, vertical_in = 0;
  double vertical_nees_sum = 0;
  FloorMetrics floor_metrics;

  for (const auto& id : order) {
    NodeMetrics m;
    m.id = id;
    const NodeInfo* declared = info.Find(id);
    m.kind = declared ? declared->kind : NodeKind::kCrumb;
    const auto& tr = truth_by_id[id];
    const auto& es = est_by_id[id];
    if (m.kind == NodeKind::kAgent) {
      for (std::size_t i = 1; i < tr.size(); ++i) {
        m.distance_m += HorizontalError(tr[i]->position_n, tr[i - 1]->position_n);
      }
      std::size_t k = 0;  // es[k-1] is the latest estimate with t <= truth t
      std::size_t agent_hits = 0, agent_samples = 0;
      for (const TruthSample* s : tr) {
        while (k < es.size() && es[k]->t <= s->t) ++k;
        if (k == 0) {
          ++m.uncovered;
          continue;
        }
        m.series.push_back(Sample(s->t, *es[k - 1], s->position_n));
        if (floors) {
          const Estimate& e = *es[k - 1];
          const int true_level = s->floor.value_or(LevelAt(info.floors, s->position_n.z()));
          const int level = e.floor.value_or(LevelAt(info.floors, e.position_n.z()));
          const double h = m.series.back().error_m;
          const double v = std::abs(e.position_n.z() - s->position_n.z());
          h_err.push_back(h);
          v_err.push_back(v);
          s_err.push_back(std::hypot(h, v));
          ipin.push_back(h + 15.0 * std::abs(level - true_level));
          if (e.szz && *e.szz > 0) {
            const double nees = v * v / *e.szz;
            ++floor_metrics.vertical_checked;
            vertical_nees_sum += nees;
            vertical_in += nees <= kChi2Dof1P95;
          }
          agent_hits += level == true_level;
          ++agent_samples;
        }
      }
      if (floors && agent_samples > 0) {
        hits += agent_hits;
        floor_metrics.hit_rate_by_agent[id] =
            static_cast<double>(agent_hits) / static_cast<double>(agent_samples);
      }
      // Each estimate at its own instant, the truth interpolated between its samples.
      std::size_t j = 0;  // tr[j]->t <= e->t < tr[j + 1]->t
      for (const Estimate* e : es) {
        if (tr.empty() || e->t < tr.front()->t || e->t > tr.back()->t) continue;
        while (j + 1 < tr.size() && tr[j + 1]->t <= e->t) ++j;
        Vec3 truth_n = tr[j]->position_n;
        if (j + 1 < tr.size() && tr[j + 1]->t > tr[j]->t) {
          const double a = (e->t - tr[j]->t) / (tr[j + 1]->t - tr[j]->t);
          truth_n += a * (tr[j + 1]->position_n - tr[j]->position_n);
        }
        m.series_at_estimates.push_back(Sample(e->t, *e, truth_n));
      }
      m.at_estimates = ComputeEllipseCheck(m.series_at_estimates);
    } else {
      std::size_t j = 0;  // tr[j] is the truth in force
      auto truth_at = [&](TimeS t) {
        while (j + 1 < tr.size() && tr[j + 1]->t <= t) ++j;
        return tr[j]->position_n;
      };
      for (const Estimate* e : es) m.series.push_back(Sample(e->t, *e, truth_at(e->t)));
      if (!es.empty() && es.back()->t < end_t) {
        m.series.push_back(Sample(end_t, *es.back(), truth_at(end_t)));
      }
      if (es.empty()) m.uncovered = 1;
    }
    m.stats = ComputeStatistics(m.series);
    FinishPercentages(m);
    if (m.kind == NodeKind::kAgent) {
      out.agents.series.insert(out.agents.series.end(), m.series.begin(), m.series.end());
      out.agents.series_at_estimates.insert(out.agents.series_at_estimates.end(),
                                            m.series_at_estimates.begin(),
                                            m.series_at_estimates.end());
      out.agents.distance_m += m.distance_m;
      out.agents.uncovered += m.uncovered;
      if (m.mean_pct_of_distance) {
        agent_mean_pct.push_back(*m.mean_pct_of_distance);
        agent_max_pct.push_back(*m.max_pct_of_distance);
      }
    } else if (m.kind != NodeKind::kBase) {
      out.static_nodes.series.insert(out.static_nodes.series.end(), m.series.begin(),
                                     m.series.end());
      out.static_nodes.uncovered += m.uncovered;
    }
    out.nodes.push_back(std::move(m));
  }
  for (NodeMetrics* pooled : {&out.agents, &out.static_nodes}) {
    std::stable_sort(pooled->series.begin(), pooled->series.end(),
                     [](const auto& a, const auto& b) { return a.t < b.t; });
    pooled->stats = ComputeStatistics(pooled->series);
  }
  out.agents.at_estimates = ComputeEllipseCheck(out.agents.series_at_estimates);
  if (floors) {
    FloorMetrics& f = floor_metrics;
    f.samples = h_err.size();
    if (f.samples > 0) {
      f.floor_hit_rate = static_cast<double>(hits) / static_cast<double>(f.samples);
      double sum = 0;
      for (const double v : v_err) sum += v;
      f.vertical_mean_m = sum / static_cast<double>(f.samples);
      f.ce95_m = Percentile(h_err, 95);
      f.ve95_m = Percentile(v_err, 95);
      f.se95_m = Percentile(s_err, 95);
      f.ipin_score_m = Percentile(ipin, 75);
    }
    if (f.vertical_checked > 0) {
      const double n = static_cast<double>(f.vertical_checked);
      f.vertical_in95 = static_cast<double>(vertical_in) / n;
      f.vertical_mean_nees = vertical_nees_sum / n;
    }
    out.floors = f;
  }
  // Final error of the pool: mean of the nodes' final errors.
  for (auto [pooled, kind_is_agent] : {std::pair{&out.agents, true},
                                       std::pair{&out.static_nodes, false}}) {
    double sum = 0;
    int n = 0;
    for (const auto& m : out.nodes) {
      const bool is_agent = m.kind == NodeKind::kAgent;
      if (is_agent != kind_is_agent || m.kind == NodeKind::kBase || m.stats.samples == 0) continue;
      sum += m.stats.final_m;
      ++n;
    }
    pooled->stats.final_m = n > 0 ? sum / n : 0.0;
  }
  auto mean = [](const std::vector<double>& v) {
    return std::accumulate(v.begin(), v.end(), 0.0) / static_cast<double>(v.size());
  };
  if (!agent_mean_pct.empty()) {
    out.agents.mean_pct_of_distance = mean(agent_mean_pct);
    out.agents.max_pct_of_distance = mean(agent_max_pct);
  }
  return out;
}

}  // namespace trailmark

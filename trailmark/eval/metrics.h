// SPDX-License-Identifier: MIT
#pragma once
/// Accuracy metrics of estimates against truth (spec: "metrics.json"). Kept apart from every
/// estimator, as OpenVINS keeps ov_eval apart. No I/O (io/metrics_io writes metrics.json).
///
/// Online semantics: at an evaluation instant t the estimate in force is the latest row of that
/// node with time <= t; instants before a node's first estimate are counted as `uncovered` and
/// not scored. Agents are scored at every truth sample. Their ellipses are also checked at each
/// estimate's own instant (`at_estimates`): an estimate row claims where the node is at its time
/// t (spec: "the estimate of node id at time t"), so its 95 % ellipse is tested against the truth
/// at t, linearly interpolated between the truth samples around t; held to a later truth instant
/// it also carries the motion since t, which no ellipse of time t claims to cover. Static nodes (crumbs, landmarks, base)
/// are scored at each of their estimate rows and at the end of the mission, against the truth
/// in force then (a kicked crumb has a second truth row).

#include <map>
#include <optional>
#include <string>
#include <vector>

#include "trailmark/core/measurements.h"
#include "trailmark/core/mission.h"

namespace trailmark {

struct ErrorSample {
  TimeS t = 0;
  double error_m = 0;  ///< horizontal error
  /// Normalized estimation error squared of the horizontal error, e^T S^-1 e with the estimate's
  /// own 2x2 covariance S (chi-square, 2 dof, when the covariance is honest). +inf for an error
  /// larger than 1 mm under a covariance that is not positive definite (a claimed certainty).
  double nees = 0;
};

/// NEES of a horizontal error under the covariance [sxx sxy; sxy syy] (see ErrorSample::nees).
double HorizontalNees(const Vec2& error_n, double sxx, double sxy, double syy);
/// The 95 % point of the chi-square distribution with 2 degrees of freedom: -2 ln(0.05).
inline constexpr double kChi2Dof2P95 = 5.991464547107979;
/// The same with 1 degree of freedom (a height): 1.959964^2.
inline constexpr double kChi2Dof1P95 = 3.841458820694124;

struct ErrorStatistics {
  std::size_t samples = 0;
  double mean_m = 0, median_m = 0, p75_m = 0, p95_m = 0, max_m = 0, rmse_m = 0;
  double final_m = 0;  ///< error at the last scored instant
  /// Share of samples whose truth lies inside the estimate's own 95 % ellipse (NEES <= 5.991);
  /// 0.95 for an honest covariance (issue 21: between 0.85 and 0.99). Over the samples whose
  /// estimate has a covariance; NaN when none has (estimates.csv with empty covariance cells).
  double in95 = 0;
  /// Mean NEES over the samples with a finite NEES (2 for an honest covariance).
  double mean_nees = 0;
};

/// The ellipse check at the estimates' own instants (agents; see the file comment).
struct EllipseCheck {
  std::size_t samples = 0;  ///< estimate rows within the node's truth span
  double in95 = 0;          ///< share with NEES <= 5.991 (0.95 when honest)
  double mean_nees = 0;     ///< over the finite NEES (2 when honest)
};
EllipseCheck ComputeEllipseCheck(const std::vector<ErrorSample>& at_estimates);

struct NodeMetrics {
  std::string id;
  NodeKind kind = NodeKind::kAgent;
  ErrorStatistics stats;
  std::size_t uncovered = 0;         ///< evaluation instants before the first estimate
  double distance_m = 0;             ///< horizontal distance travelled (truth)
  std::optional<double> mean_pct_of_distance;  ///< mean error / distance x 100
  std::optional<double> max_pct_of_distance;   ///< max error / distance x 100
  std::vector<ErrorSample> series;
  /// Agents: every estimate row scored at its own time against interpolated truth.
  std::vector<ErrorSample> series_at_estimates;
  EllipseCheck at_estimates;
};

/// Floors and height (issue 26; spec 1.1), agents at every truth instant with an estimate in
/// force. Levels from the `floor` columns, else from z by the spec's rule (MissionInfo::floors).
/// Figures of ISO/IEC 18305 (CE95, VE95, SE95, floor detection probability) and the IPIN
/// competition's score (the 75th percentile of horizontal error + 15 m per floor wrong).
struct FloorMetrics {
  std::size_t samples = 0;
  double floor_hit_rate = 0;         ///< share of instants on the right level
  double ce95_m = 0;                 ///< horizontal error, 95th percentile
  double ve95_m = 0;                 ///< vertical error |dz|, 95th percentile
  double vertical_mean_m = 0;
  double se95_m = 0;                 ///< spherical (3-D) error, 95th percentile
  double ipin_score_m = 0;           ///< p75 of (horizontal + 15 m x |floor difference|)
  std::map<std::string, double> hit_rate_by_agent;
  /// Honest vertical uncertainty over the instants whose estimate has szz > 0: the share of
  /// true heights inside the estimate's own 95 % interval (dz^2 / szz <= 3.841, chi-square
  /// with 1 dof; 0.95 when honest), and the mean NEES (1 when honest).
  std::size_t vertical_checked = 0;
  double vertical_in95 = 0;
  double vertical_mean_nees = 0;
};

struct Metrics {
  std::vector<NodeMetrics> nodes;  ///< every node with truth, in order of first truth row
  /// All agent instants pooled; distance summed; percentages are the mean over agents.
  NodeMetrics agents;
  /// All static-node instants pooled (crumbs and landmarks; the base is skipped when exact).
  NodeMetrics static_nodes;
  std::size_t estimates_without_truth = 0;  ///< rows for ids that have no truth
  /// Present where the mission is about floors: it lists them or its truth has levels.
  std::optional<FloorMetrics> floors;
};

/// Linear-interpolation percentile (numpy's default) of unsorted values; q in [0, 100].
double Percentile(std::vector<double> values, double q);
ErrorStatistics ComputeStatistics(const std::vector<ErrorSample>& series);

/// Both inputs in non-decreasing time. `info` gives node kinds (undeclared ids are crumbs).
Metrics Evaluate(const MissionInfo& info, const std::vector<TruthSample>& truth,
                 const std::vector<Estimate>& estimates);

}  // namespace trailmark

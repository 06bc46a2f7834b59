// SPDX-License-Identifier: MIT
#pragma once
/// What the incident commander sees, as data: the latest estimate of every node and the alerts
/// derived from them — no data for a while (link lost), motionless (like a PASS alarm),
/// uncertainty too large. Fed with estimates in time order; `Advance` moves the clock (alerts
/// depend on it). No network, no threads: the HTTP server and tests use it alike.

#include <deque>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "trailmark/core/measurements.h"
#include "trailmark/core/mission.h"
#include "trailmark/core/online_estimator.h"

namespace trailmark::server {

struct AlertOptions {
  double no_data_s = 10.0;           ///< an agent without an estimate this long: link lost
  double motionless_s = 30.0;        ///< PASS devices alarm after ~30 s without motion (NFPA 1982)
  double motionless_radius_m = 0.5;  ///< "without motion": within this radius
  double uncertainty_m = 5.0;        ///< 95 % ellipse semi-major axis above this
  /// Map error (map-aided search paper, sec. V-E): a map-aided estimate whose variance
  /// (sxx + syy) stays above map_error_variance_m2 for map_error_min_s means the floor plan
  /// disagrees with the walk (or the filter has not converged yet). Only meaningful for
  /// pipelines that use the floor plan: `serve` enables it for mapmatch.
  bool map_error = false;
  double map_error_variance_m2 = 3.0;
  double map_error_min_s = 10.0;
  /// The trail kept for the timeline: one position per agent every this many seconds.
  double history_period_s = 0.5;
};

struct NodeState {
  std::string id;
  NodeKind kind = NodeKind::kCrumb;
  Estimate estimate;
  std::deque<std::pair<TimeS, Vec2>> recent;  ///< agents: positions over the motionless window
  std::vector<Estimate> history;  ///< agents: every history_period_s, for the timeline
  TimeS variance_high_since = -1e300;  ///< map error: since when the variance is above the level
};

struct Alert {
  std::string id, kind, message;
  TimeS t = 0;
};

class IncidentState {
 public:
  explicit IncidentState(const MissionInfo& info, AlertOptions options = {});
  /// An estimate (non-decreasing time across calls; older ones are ignored and counted).
  void Apply(const Estimate& e);
  /// A measurement from `id` arrived at time t (steps, RSSI, ranges, IMU...): the link is up
  /// even when no estimate changes (a firefighter standing still emits no steps).
  void Heard(const std::string& id, TimeS t);
  /// A device's own status (MQTT last will): "lost" raises a device-lost alert until "online".
  void SetDeviceStatus(const std::string& id, const std::string& status);
  /// The estimator's integrity notes so far (its Summary().integrity, in time order): a source
  /// whose latest note at or before now excluded it (or an agent whose estimate disagrees with
  /// its dead reckoning) is an `integrity` alert until a later note readmits it.
  void SetIntegrity(std::vector<IntegrityNote> notes);
  /// Which sources a node's estimate uses now, with their shares (the estimator's Sources;
  /// the fusion's members): `sources` in /api/state. An empty list removes them.
  void SetSources(const std::string& id, std::vector<SourceShare> sources);
  /// Mission time now; recomputes the alerts.
  void Advance(TimeS now);
  TimeS now() const { return now_; }
  const std::map<std::string, NodeState>& nodes() const { return nodes_; }
  const std::vector<Alert>& alerts() const { return alerts_; }
  std::size_t stale_estimates() const { return stale_; }
  /// The contract of GET /api/state (docs/server.md).
  nlohmann::json ToJson() const;
  /// The same document as JSON text (keys sorted, as nlohmann::json writes them), written
  /// directly: what the event stream sends on every change.
  std::string ToJsonText() const;
  /// Every alert as it was raised (a kind for a node, once until it clears), in time order.
  const std::vector<Alert>& alert_log() const { return alert_log_; }
  /// GET /api/history: the agents' trails and the alert log, for the dashboard's timeline.
  /// `since`: only trail rows and alerts after that mission time (the dashboard's refresh
  /// fetches what it lacks, not the whole incident); "since" in the JSON says so.
  /// `max_rows`: at most this many rows per agent (a long incident): the last
  /// kHistoryFullRateS seconds at the full rate when they fit, the older rows thinned evenly
  /// (each agent's first row kept); "decimated" in the JSON gives each thinned agent's stride.
  /// The cost is that of the rows sent, not of the incident's length.
  nlohmann::json HistoryJson(std::optional<double> since = std::nullopt,
                             std::size_t max_rows = kHistoryMaxRows) const;
  static constexpr std::size_t kHistoryMaxRows = 3000;
  static constexpr double kHistoryFullRateS = 600.0;

 private:
  MissionInfo info_;
  AlertOptions options_;
  std::vector<IntegrityNote> integrity_;
  std::map<std::string, std::vector<SourceShare>> sources_;
  TimeS now_ = -1e300;
  std::map<std::string, NodeState> nodes_;
  std::map<std::string, TimeS> heard_;
  std::map<std::string, std::string> device_status_;
  std::vector<Alert> alerts_;
  std::vector<Alert> alert_log_;
  std::size_t stale_ = 0;
};

/// 95 % confidence ellipse semi-major axis of a horizontal covariance (chi-square 2 dof).
double Ellipse95SemiMajor(double sxx, double sxy, double syy);

}  // namespace trailmark::server

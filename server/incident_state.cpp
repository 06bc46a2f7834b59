#include "server/incident_state.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace trailmark::server {

double Ellipse95SemiMajor(double sxx, double sxy, double syy) {
  const double mean = 0.5 * (sxx + syy);
  const double d = std::sqrt(std::max(0.0, 0.25 * (sxx - syy) * (sxx - syy) + sxy * sxy));
  return std::sqrt(5.991 * std::max(0.0, mean + d));
}

IncidentState::IncidentState(const MissionInfo& info, AlertOptions options)
    : info_(info), options_(options) {}

void IncidentState::Apply(const Estimate& e) {
  auto it = nodes_.find(e.id);
  if (it == nodes_.end()) {
    NodeState n;
    n.id = e.id;
    const NodeInfo* declared = info_.Find(e.id);
    n.kind = declared ? declared->kind : NodeKind::kCrumb;  // undeclared ids are dropped crumbs
    it = nodes_.emplace(e.id, std::move(n)).first;
  } else if (e.t < it->second.estimate.t) {
    ++stale_;
    return;
  }
  NodeState& n = it->second;
  n.estimate = e;
  if (n.kind == NodeKind::kAgent) {
    n.recent.emplace_back(e.t, e.position_n.head<2>());
    while (n.recent.size() > 1 && n.recent.front().first < e.t - options_.motionless_s)
      n.recent.pop_front();
  }
  now_ = std::max(now_, e.t);
}

void IncidentState::Heard(const std::string& id, TimeS t) {
  auto it = heard_.find(id);
  if (it == heard_.end())
    heard_.emplace(id, t);
  else
    it->second = std::max(it->second, t);
}

void IncidentState::SetDeviceStatus(const std::string& id, const std::string& status) {
  device_status_[id] = status;
}

void IncidentState::Advance(TimeS now) {
  now_ = std::max(now_, now);
  alerts_.clear();
  for (const auto& [id, status] : device_status_) {
    if (status == "lost")
      alerts_.push_back({id, "device-lost", id + ": the device was lost (MQTT last will)", now_});
  }
  for (const auto& [id, n] : nodes_) {
    if (n.kind != NodeKind::kAgent) continue;
    const Estimate& e = n.estimate;
    const auto heard = heard_.find(id);
    const TimeS last = heard != heard_.end() ? std::max(heard->second, e.t) : e.t;
    if (now_ - last > options_.no_data_s) {
      alerts_.push_back({id, "no-data",
                         fmt::format("no data from {} for {:.0f} s (link lost?)", id, now_ - last),
                         now_});
    }
    // Motionless: the estimates of the last motionless_s all within the radius (and the window
    // really spans that long).
    if (!n.recent.empty() && e.t - n.recent.front().first >= options_.motionless_s - 1e-9) {
      double spread = 0;
      for (const auto& [t, p] : n.recent)
        spread = std::max(spread, (p - n.recent.back().second).norm());
      if (spread <= options_.motionless_radius_m) {
        alerts_.push_back(
            {id, "motionless",
             fmt::format("{} has not moved for {:.0f} s", id, e.t - n.recent.front().first), now_});
      }
    }
    const double a95 = Ellipse95SemiMajor(e.sxx, e.sxy, e.syy);
    if (a95 > options_.uncertainty_m) {
      alerts_.push_back({id, "uncertainty",
                         fmt::format("{} position uncertain: 95 % within {:.1f} m", id, a95),
                         now_});
    }
  }
}

nlohmann::json IncidentState::ToJson() const {
  nlohmann::json j;
  j["t"] = std::isfinite(now_) && now_ > -1e299 ? nlohmann::json(now_) : nlohmann::json(nullptr);
  j["nodes"] = nlohmann::json::array();
  for (const auto& [id, n] : nodes_) {
    const Estimate& e = n.estimate;
    j["nodes"].push_back({{"id", id},
                          {"kind", std::string(ToString(n.kind))},
                          {"t", e.t},
                          {"x", e.position_n.x()},
                          {"y", e.position_n.y()},
                          {"z", e.position_n.z()},
                          {"sxx", e.sxx},
                          {"sxy", e.sxy},
                          {"syy", e.syy}});
  }
  j["alerts"] = nlohmann::json::array();
  for (const auto& a : alerts_) {
    j["alerts"].push_back({{"id", a.id}, {"kind", a.kind}, {"t", a.t}, {"message", a.message}});
  }
  return j;
}

}  // namespace trailmark::server

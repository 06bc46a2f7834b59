// SPDX-License-Identifier: MIT
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
    // The motionless window at the history's rate (a 100 Hz INS would keep 3,000 per agent).
    if (n.recent.empty() || e.t >= n.recent.back().first + options_.history_period_s)
      n.recent.emplace_back(e.t, e.position_n.head<2>());
    while (n.recent.size() > 1 && n.recent.front().first < e.t - options_.motionless_s)
      n.recent.pop_front();
    if (n.history.empty() || e.t >= n.history.back().t + options_.history_period_s)
      n.history.push_back(e);
    if (e.sxx + e.syy <= options_.map_error_variance_m2)
      n.variance_high_since = -1e300;
    else if (n.variance_high_since < -1e299)
      n.variance_high_since = e.t;
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

void IncidentState::SetIntegrity(std::vector<IntegrityNote> notes) {
  integrity_ = std::move(notes);
}

void IncidentState::SetSources(const std::string& id, std::vector<SourceShare> sources) {
  if (sources.empty()) {
    sources_.erase(id);
  } else {
    sources_[id] = std::move(sources);
  }
}

void IncidentState::Advance(TimeS now) {
  now_ = std::max(now_, now);
  std::vector<Alert> before;
  before.swap(alerts_);
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
        spread = std::max(spread, (p - e.position_n.head<2>()).norm());
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
    if (options_.map_error && n.variance_high_since > -1e299 &&
        e.t - n.variance_high_since >= options_.map_error_min_s) {
      alerts_.push_back(
          {id, "map-error",
           fmt::format("{}: variance {:.1f} m^2 for {:.0f} s on the floor plan near ({:.1f}, "
                       "{:.1f}): map error (or not yet converged)",
                       id, e.sxx + e.syy, e.t - n.variance_high_since, e.position_n.x(),
                       e.position_n.y()),
           now_});
    }
  }
  // Integrity: the latest note of each source up to now decides.
  std::map<std::string, const IntegrityNote*> latest;
  for (const IntegrityNote& n : integrity_) {
    if (n.t <= now_) latest[n.source] = &n;
  }
  for (const auto& [source, n] : latest) {
    if (n->action == "excluded" || n->action == "fallback" || n->action == "disagrees" ||
        n->action == "repeats" || n->action == "scale")
      alerts_.push_back({n->node.empty() ? source : n->node, "integrity", n->message, n->t});
  }
  // The log keeps each alert once, when raised (a (node, kind) not active before).
  for (const Alert& a : alerts_) {
    const bool was_active = std::any_of(before.begin(), before.end(), [&](const Alert& b) {
      return b.id == a.id && b.kind == a.kind;
    });
    if (!was_active) alert_log_.push_back(a);
  }
}

nlohmann::json IncidentState::HistoryJson(std::optional<double> since, std::size_t max_rows) const {
  const auto after = [&](double t) { return !since || t > *since; };
  max_rows = std::max<std::size_t>(max_rows, 2);
  nlohmann::json trails = nlohmann::json::object();
  nlohmann::json decimated = nlohmann::json::object();
  for (const auto& [id, n] : nodes_) {
    if (n.kind != NodeKind::kAgent) continue;
    nlohmann::json rows = nlohmann::json::array();
    // The floor last: null where the estimator gives none (a single-floor mission 1.0).
    auto row = [](const Estimate& e) {
      return nlohmann::json{e.t,   e.position_n.x(), e.position_n.y(), e.sxx, e.sxy, e.syy,
                            e.floor ? nlohmann::json(*e.floor) : nlohmann::json(nullptr)};
    };
    const std::vector<Estimate>& h = n.history;  // in time order
    const auto by_time = [](double t, const Estimate& e) { return t < e.t; };
    const auto first = since ? std::upper_bound(h.begin(), h.end(), *since, by_time) : h.begin();
    const auto count = static_cast<std::size_t>(h.end() - first);
    if (count <= max_rows) {
      for (auto it = first; it != h.end(); ++it) rows.push_back(row(*it));
    } else {
      // The recent rows at the full rate (up to half the budget), the older ones thinned.
      const double recent_from = h.back().t - kHistoryFullRateS;
      auto recent = std::upper_bound(first, h.end(), recent_from, by_time);
      recent = std::max(recent, h.end() - static_cast<std::ptrdiff_t>(max_rows / 2));
      const auto older = static_cast<std::size_t>(recent - first);
      const std::size_t budget = max_rows - static_cast<std::size_t>(h.end() - recent);
      const std::size_t stride = (older + budget - 1) / budget;
      for (std::size_t k = 0; k < older; k += stride) rows.push_back(row(first[static_cast<std::ptrdiff_t>(k)]));
      for (auto it = recent; it != h.end(); ++it) rows.push_back(row(*it));
      decimated[id] = {{"stride", stride}, {"full_rate_from", recent->t}};
    }
    // and the latest, so that the timeline ends where the live view is
    if (!h.empty() && h.back().t < n.estimate.t && after(n.estimate.t)) rows.push_back(row(n.estimate));
    trails[id] = rows;
  }
  nlohmann::json log = nlohmann::json::array();
  for (const auto& a : alert_log_) {
    if (after(a.t))
      log.push_back({{"id", a.id}, {"kind", a.kind}, {"t", a.t}, {"message", a.message}});
  }
  nlohmann::json j;
  j["t"] = std::isfinite(now_) && now_ > -1e299 ? nlohmann::json(now_) : nlohmann::json(nullptr);
  j["columns"] = {"t", "x", "y", "sxx", "sxy", "syy", "floor"};
  j["trails"] = trails;
  j["alerts"] = log;
  if (since) j["since"] = *since;
  if (!decimated.empty()) j["decimated"] = decimated;
  return j;
}

namespace {

/// JSON text of a string (quotes, backslashes and control characters escaped).
void AppendString(std::string& out, const std::string& text) {
  out += '"';
  for (const char c : text) {
    if (c == '"' || c == '\\') {
      out += '\\';
      out += c;
    } else if (static_cast<unsigned char>(c) < 0x20) {
      out += fmt::format("\\u{:04x}", static_cast<unsigned>(c));
    } else {
      out += c;
    }
  }
  out += '"';
}

/// A number as nlohmann::json writes it (shortest round-trip, "2.0" for 2), null when not finite.
void AppendNumber(std::string& out, double v) {
  if (!std::isfinite(v)) {
    out += "null";
    return;
  }
  const std::size_t start = out.size();
  fmt::format_to(std::back_inserter(out), "{}", v);
  if (out.find_first_of(".e", start) == std::string::npos) out += ".0";
}

}  // namespace

std::string IncidentState::ToJsonText() const {
  std::string out;
  out.reserve(64 + 160 * nodes_.size() + 120 * alerts_.size());
  out += "{\"alerts\":[";
  for (std::size_t k = 0; k < alerts_.size(); ++k) {
    const Alert& a = alerts_[k];
    if (k > 0) out += ',';
    out += "{\"id\":";
    AppendString(out, a.id);
    out += ",\"kind\":";
    AppendString(out, a.kind);
    out += ",\"message\":";
    AppendString(out, a.message);
    out += ",\"t\":";
    AppendNumber(out, a.t);
    out += '}';
  }
  out += "],\"nodes\":[";
  bool first = true;
  for (const auto& [id, n] : nodes_) {
    const Estimate& e = n.estimate;
    if (!first) out += ',';
    first = false;
    out += "{\"id\":";
    AppendString(out, id);
    out += ",\"kind\":";
    AppendString(out, std::string(ToString(n.kind)));
    const std::pair<const char*, double> numbers[] = {
        {"sxx", e.sxx}, {"sxy", e.sxy},           {"syy", e.syy},           {"t", e.t},
        {"x", e.position_n.x()}, {"y", e.position_n.y()}, {"z", e.position_n.z()}};
    for (const auto& [key, value] : numbers) {
      out += ",\"";
      out += key;
      out += "\":";
      AppendNumber(out, value);
    }
    // Height (issue 26): the level and the vertical variance where the estimator gives them.
    if (e.floor) out += ",\"floor\":" + std::to_string(*e.floor);
    if (e.szz) {
      out += ",\"szz\":";
      AppendNumber(out, *e.szz);
    }
    // The fusion (issue 27): which members the estimate uses, with their weights.
    if (const auto src = sources_.find(id); src != sources_.end()) {
      out += ",\"sources\":[";
      for (std::size_t i = 0; i < src->second.size(); ++i) {
        out += i == 0 ? "{\"source\":" : ",{\"source\":";
        AppendString(out, src->second[i].source);
        out += ",\"weight\":";
        AppendNumber(out, src->second[i].weight);
        out += '}';
      }
      out += ']';
    }
    out += '}';
  }
  out += "],\"t\":";
  AppendNumber(out, std::isfinite(now_) && now_ > -1e299 ? now_ : NAN);
  out += '}';
  return out;
}

nlohmann::json IncidentState::ToJson() const { return nlohmann::json::parse(ToJsonText()); }

}  // namespace trailmark::server

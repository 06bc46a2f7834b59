// SPDX-License-Identifier: MIT
#include "trailmark/sim/synthetic_incident.h"

#include <algorithm>
#include <cmath>

#include "trailmark/core/random.h"

namespace trailmark {

SyntheticIncident MakeSyntheticIncident(const IncidentOptions& o, std::uint64_t seed) {
  Random rng(seed);
  SyntheticIncident inc;
  inc.info.name = "synthetic-incident";
  inc.info.nodes.push_back(NodeInfo::Base("base", Vec3::Zero()));
  inc.info.radio = RadioCalibration{"log-distance", o.alpha_dbm, o.path_loss_exponent, o.sigma_db};
  const int cols = static_cast<int>(std::ceil(std::sqrt(static_cast<double>(o.agents))));
  const double steps_per_agent = o.duration_s / o.step_period_s;
  const double total_steps = steps_per_agent * o.agents;
  const double packets_wanted = std::max(0.0, static_cast<double>(o.measurements) - total_steps);
  const double packet_period =
      o.duration_s * o.agents * o.heard_per_packet / std::max(1.0, packets_wanted);
  const int crumbs_per_agent = std::max(1, o.crumbs / std::max(1, o.agents));
  struct Crumb {
    std::string id;
    Vec2 p;
  };
  std::vector<std::vector<Crumb>> crumbs(o.agents);
  int crumb_count = 0;
  for (int a = 0; a < o.agents; ++a) {
    Random r = rng.Fork();
    const std::string id = "ff" + std::to_string(a + 1);
    const Vec2 origin((a % cols) * (o.sector_m + 5.0) + 5.0, (a / cols) * (o.sector_m + 5.0) + 5.0);
    Vec2 pos = origin + Vec2(o.sector_m / 2, o.sector_m / 2);
    inc.info.nodes.push_back(NodeInfo::Agent(id, Vec3(pos.x(), pos.y(), 0), 0.1));
    Vec2 target = pos;
    double next_packet = packet_period, next_drop = 5.0;
    for (double t = o.step_period_s; t <= o.duration_s; t += o.step_period_s) {
      if ((target - pos).norm() < o.step_length_m) {
        target = origin + Vec2(r.Uniform(0, o.sector_m), r.Uniform(0, o.sector_m));
      }
      const Vec2 d = (target - pos).normalized() * o.step_length_m;
      pos += d;
      IncidentEvent step;
      step.kind = IncidentEvent::Kind::kStep;
      step.step = {t - o.step_period_s, t, id,
                   Vec3(d.x() + r.Normal(0, 0.02), d.y() + r.Normal(0, 0.02), 0),
                   Vec3(1e-3, 1e-3, 1e-4)};
      inc.events.push_back(step);
      ++inc.steps;
      if (t >= next_drop && static_cast<int>(crumbs[a].size()) < crumbs_per_agent &&
          crumb_count < o.crumbs) {
        next_drop += o.crumb_drop_period_s;
        const std::string cid = "c" + std::to_string(++crumb_count);
        crumbs[a].push_back({cid, pos});
        IncidentEvent drop;
        drop.kind = IncidentEvent::Kind::kDrop;
        drop.drop = {t, id, "drop", cid};
        inc.events.push_back(drop);
        ++inc.drops;
      }
      if (t >= next_packet) {
        next_packet += packet_period;
        std::vector<std::pair<double, const Crumb*>> near;
        for (const auto& c : crumbs[a]) {
          const double dist = (c.p - pos).norm();
          if (dist < o.hearing_range_m) near.emplace_back(dist, &c);
        }
        std::sort(near.begin(), near.end(),
                  [](const auto& x, const auto& y) { return x.first < y.first; });
        for (int k = 0; k < o.heard_per_packet && k < static_cast<int>(near.size()); ++k) {
          const double dist = std::max(near[k].first, 0.3);
          IncidentEvent p;
          p.kind = IncidentEvent::Kind::kRssi;
          p.rssi = {t, id, near[k].second->id,
                    o.alpha_dbm - 10 * o.path_loss_exponent * std::log10(dist) +
                        r.Normal(0, o.sigma_db)};
          inc.events.push_back(p);
          ++inc.packets;
        }
      }
    }
  }
  std::stable_sort(inc.events.begin(), inc.events.end(),
                   [](const IncidentEvent& a, const IncidentEvent& b) { return a.t() < b.t(); });
  return inc;
}

}  // namespace trailmark

// SPDX-License-Identifier: MIT
#include "trailmark/sim/synthetic_incident.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

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

LandmarkIncident MakeLandmarkIncident(const LandmarkIncidentOptions& o, std::uint64_t seed) {
  if (o.agents < 1 || !(o.duration_s > 0) || !(o.sector_m > 0) || !(o.step_period_s > 0) ||
      !(o.step_length_m > 0) || !(o.landmark_spacing_m > 0) || !(o.answer_period_s > 0) ||
      !(o.hearing_range_m > 0) || !(o.unknown_share >= 0 && o.unknown_share <= 1)) {
    throw std::invalid_argument(
        "landmark incident: agents >= 1; duration, sector, step period and length, landmark "
        "spacing, answer period and hearing range > 0; unknown_share within 0 .. 1");
  }
  Random rng(seed);
  LandmarkIncident inc;
  inc.info.name = "synthetic-landmark-incident";
  inc.info.radio = RadioCalibration{"log-distance", o.alpha_dbm, o.path_loss_exponent, o.sigma_db};
  const int cols = static_cast<int>(std::ceil(std::sqrt(static_cast<double>(o.agents))));
  const int rows = (o.agents + cols - 1) / cols;
  const double pitch = o.sector_m + 5.0;
  // The ceiling grid over the site [0, cols pitch + 5] x [0, rows pitch + 5].
  struct Landmark {
    std::string id;
    Vec3 p;
  };
  std::vector<Landmark> landmarks;
  const int nx = static_cast<int>(std::floor((cols * pitch + 5.0) / o.landmark_spacing_m)) + 1;
  const int ny = static_cast<int>(std::floor((rows * pitch + 5.0) / o.landmark_spacing_m)) + 1;
  const int unknown_every =
      o.unknown_share > 0 ? static_cast<int>(std::lround(1 / o.unknown_share)) : 0;
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      const int k = j * nx + i;
      Landmark l{"lm" + std::to_string(k + 1),
                 Vec3(i * o.landmark_spacing_m, j * o.landmark_spacing_m, o.landmark_height_m)};
      NodeInfo n;
      n.id = l.id;
      n.kind = NodeKind::kLandmark;
      if (unknown_every > 0 && k % unknown_every == unknown_every - 1) {
        ++inc.unknown;
      } else {
        n.position = l.p;
        n.position_sigma_m = o.surveyed_sigma_m;
      }
      inc.info.nodes.push_back(n);
      inc.landmark_truth.push_back({0.0, l.id, l.p});
      landmarks.push_back(std::move(l));
    }
  }
  inc.landmarks = landmarks.size();
  // A grid cell index of the landmarks, so that a packet burst looks at the few near ones.
  auto near_landmarks = [&](const Vec2& pos, std::vector<const Landmark*>& out) {
    out.clear();
    const int r = static_cast<int>(std::ceil(o.hearing_range_m / o.landmark_spacing_m));
    const int ci = static_cast<int>(std::lround(pos.x() / o.landmark_spacing_m));
    const int cj = static_cast<int>(std::lround(pos.y() / o.landmark_spacing_m));
    for (int j = std::max(0, cj - r); j <= std::min(ny - 1, cj + r); ++j) {
      for (int i = std::max(0, ci - r); i <= std::min(nx - 1, ci + r); ++i) {
        const Landmark& l = landmarks[static_cast<std::size_t>(j * nx + i)];
        if ((l.p.head<2>() - pos).norm() <= o.hearing_range_m) out.push_back(&l);
      }
    }
  };
  std::vector<const Landmark*> near;
  for (int a = 0; a < o.agents; ++a) {
    Random r = rng.Fork();
    const std::string id = "ff" + std::to_string(a + 1);
    const Vec2 origin((a % cols) * pitch + 5.0, (a / cols) * pitch + 5.0);
    Vec2 pos = origin + Vec2(o.sector_m / 2, o.sector_m / 2);
    inc.info.nodes.push_back(NodeInfo::Agent(id, Vec3(pos.x(), pos.y(), 0), 0.1));
    Vec2 target = pos;
    double next_answer = r.Uniform(0, o.answer_period_s);
    double heading_error = 0;
    for (double t = o.step_period_s; t <= o.duration_s; t += o.step_period_s) {
      if ((target - pos).norm() < o.step_length_m) {
        target = origin + Vec2(r.Uniform(0, o.sector_m), r.Uniform(0, o.sector_m));
      }
      const Vec2 d = (target - pos).normalized() * o.step_length_m;
      // The packets of the step's duration, heard from where the walker is (at the step's start).
      for (; next_answer < t; next_answer += o.answer_period_s) {
        near_landmarks(pos, near);
        for (const Landmark* l : near) {
          const double dist = std::max((l->p - Vec3(pos.x(), pos.y(), 1.2)).norm(), 0.3);
          const double rssi =
              o.alpha_dbm - 10 * o.path_loss_exponent * std::log10(dist) + r.Normal(0, o.sigma_db);
          if (rssi < o.sensitivity_dbm) continue;
          inc.rows.emplace_back(RssiPacket{next_answer, id, l->id, std::round(rssi)});
          ++inc.packets;
        }
      }
      pos += d;
      heading_error += r.Normal(0, o.heading_walk_rad);
      const double error = heading_error + r.Normal(0, o.step_heading_sigma_rad);
      const double c = std::cos(error), s = std::sin(error);
      const Vec2 measured(c * d.x() - s * d.y(), s * d.x() + c * d.y());
      inc.rows.emplace_back(Step{t - o.step_period_s, t, id, Vec3(measured.x(), measured.y(), 0),
                                 Vec3(1e-3, 1e-3, 1e-4)});
      ++inc.steps;
      inc.truth.push_back({t, id, Vec3(pos.x(), pos.y(), 0)});
    }
  }
  std::stable_sort(inc.rows.begin(), inc.rows.end(), [](const MissionRow& x, const MissionRow& y) {
    return RowTime(x) < RowTime(y);
  });
  return inc;
}

}  // namespace trailmark

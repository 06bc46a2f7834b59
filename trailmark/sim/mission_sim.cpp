// SPDX-License-Identifier: MIT
#include "trailmark/sim/mission_sim.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <optional>

namespace trailmark {

namespace {

struct Deployed {
  std::string id;
  Vec2 position;
  TimeS dropped_t = 0;
  bool is_crumb = false;
  double z = 0;
  int level = 0;
};

struct AgentRun {
  const AgentPlan* plan = nullptr;
  Walk walk;
};

/// A walker of the radio network: its walk and its dispenser.
struct Walker {
  const std::string* id = nullptr;
  const Walk* walk = nullptr;
  std::map<std::string, double> ema;
  std::optional<double> weak_since;
  int dropped = 0;
  Vec2 last_drop = Vec2::Constant(1e9);
  double next_packet = 0;
  std::map<std::string, bool> near;  // crumb -> within pass distance at the previous tick
};

}  // namespace

void SimulateCrumbNetwork(SimulatedMission& sim, const Vec3& base3_n,
                          const std::vector<FloorLevel>& floors, const MissionSimOptions& o,
                          bool agent_truth, Random radio_rng, Random& drop_rng, Random& kick_rng) {
  MissionData& m = sim.data;
  const Vec2 base_n = base3_n.head<2>();
  const bool multi = !floors.empty();
  std::vector<Walker> runs(sim.walks.size());
  TimeS t_begin = 1e300, t_end = -1e300;
  for (std::size_t k = 0; k < sim.walks.size(); ++k) {
    runs[k].id = &sim.walks[k].first;
    runs[k].walk = &sim.walks[k].second;
    runs[k].next_packet = runs[k].walk->truth.front().t;
    t_begin = std::min(t_begin, runs[k].walk->truth.front().t);
    t_end = std::max(t_end, runs[k].walk->truth.back().t);
  }
  // The plan of a level (walls on the receiver's level), the level of a height.
  auto plan_of = [&](int level) -> const FloorPlan* {
    for (const auto& [l, plan] : sim.levels) {
      if (l == level) return &plan;
    }
    return &sim.plan;
  };
  auto level_of = [&](double z) { return multi ? LevelAt(floors, z) : 0; };
  auto link = [&](int rx_level, double rx_z, int tx_level, double tx_z) {
    LinkLevels l;
    if (!multi) return l;
    l.floors_crossed = std::abs(rx_level - tx_level);
    l.dz_m = rx_z - tx_z;
    l.plan = plan_of(rx_level);
    return l;
  };
  RssiChannel channel(o.radio, &sim.plan, o.zones, radio_rng);
  std::vector<Deployed> chain{{"base", base_n, t_begin, false, base3_n.z(), level_of(base3_n.z())}};
  m.truth.push_back({t_begin, "base", Vec3(base_n.x(), base_n.y(), base3_n.z())});
  if (multi) m.truth.back().floor = chain.front().level;
  const double dt = 1.0 / o.walker.truth_rate_hz;
  double next_crumb_packet = t_begin;
  int crumbs = 0, kicks = 0;
  const long ticks = std::lround((t_end - t_begin) / dt);
  for (long tick = 0; tick <= ticks; ++tick) {
    const TimeS t = t_begin + tick * dt;
    // Active agents and their true state at this tick.
    struct Here {
      Walker* run;
      Vec2 position;
      double heading;
      double z;
      int level;
    };
    std::vector<Here> active;
    for (auto& r : runs) {
      const auto& tr = r.walk->truth;
      if (t + 1e-9 < tr.front().t || t > tr.back().t + 1e-9) continue;
      const auto idx = static_cast<std::size_t>(std::clamp<long>(
          std::lround((t - tr.front().t) / dt), 0, static_cast<long>(tr.size()) - 1));
      const auto& sample = tr[idx];
      active.push_back({&r, sample.position, sample.heading_rad, sample.z, level_of(sample.z)});
      if (agent_truth) {
        m.truth.push_back({t, *r.id, Vec3(sample.position.x(), sample.position.y(), 0.0)});
      }
    }
    for (auto& h : active) {
      Walker& r = *h.run;
      const std::string& id = *r.id;
      // Kicks: entering the pass zone of a crumb that has lain there a while.
      for (auto& node : chain) {
        if (!node.is_crumb) continue;
        const bool near = (node.position - h.position).norm() < o.kick.pass_distance_m &&
                          node.level == h.level;
        const bool was = r.near[node.id];
        r.near[node.id] = near;
        if (!near || was || t - node.dropped_t < o.kick.min_age_s || kicks >= o.kick.max_kicks ||
            o.kick.probability <= 0 || kick_rng.Uniform(0, 1) >= o.kick.probability) {
          continue;
        }
        for (int attempt = 0; attempt < 20; ++attempt) {
          const double ang = kick_rng.Uniform(-std::numbers::pi, std::numbers::pi);
          const double dist = kick_rng.Uniform(o.kick.min_m, o.kick.max_m);
          const Vec2 to = node.position + dist * Vec2(std::cos(ang), std::sin(ang));
          if (plan_of(node.level)->Crosses(node.position, to)) continue;
          node.position = to;
          channel.SetNodeGain(node.id, kick_rng.Normal(0, o.kick.antenna_gain_sigma_db));
          m.truth.push_back({t, node.id, Vec3(to.x(), to.y(), node.z)});
          if (multi) m.truth.back().floor = node.level;
          ++kicks;
          break;
        }
      }
      if (t + 1e-9 < r.next_packet) continue;
      r.next_packet += o.packet_period_s;
      double best = -1e9;
      for (auto& node : chain) {
        double& ema = r.ema[node.id];
        const bool heard_before = r.ema.count(node.id) && ema != 0;
        if (auto v = channel.Sample(id, h.position, node.id, node.position, h.heading, std::nullopt,
                                    link(h.level, h.z, node.level, node.z))) {
          m.rssi.push_back({t, id, node.id, *v});
          ema = heard_before ? (1 - o.dispenser.smoothing) * ema + o.dispenser.smoothing * *v : *v;
        } else if (heard_before) {
          ema = (1 - o.dispenser.smoothing) * ema + o.dispenser.smoothing * o.radio.sensitivity_dbm;
        }
        if (auto v = channel.Sample(node.id, node.position, id, h.position, std::nullopt, h.heading,
                                    link(node.level, node.z, h.level, h.z))) {
          m.rssi.push_back({t, node.id, id, *v});
        }
        if (ema != 0) best = std::max(best, ema);
      }
      for (const auto& other : active) {  // agent <-> agent
        if (other.run == h.run) continue;
        if (auto v = channel.Sample(id, h.position, *other.run->id, other.position, h.heading,
                                    other.heading, link(h.level, h.z, other.level, other.z))) {
          m.rssi.push_back({t, id, *other.run->id, *v});
        }
      }
      // Dispenser.
      if (best >= o.dispenser.drop_threshold_dbm) {
        r.weak_since.reset();
      } else if (!r.weak_since) {
        r.weak_since = t;
      }
      if (r.weak_since && t - *r.weak_since >= o.dispenser.below_for_s &&
          r.dropped < o.dispenser.capacity &&
          (h.position - r.last_drop).norm() >= o.dispenser.min_spacing_m) {
        r.weak_since.reset();
        ++r.dropped;
        const std::string cid = "c" + std::to_string(++crumbs);
        const Vec2 where = h.position + Vec2(drop_rng.Normal(0, o.dispenser.drop_scatter_m),
                                             drop_rng.Normal(0, o.dispenser.drop_scatter_m));
        chain.push_back({cid, where, t, true, multi ? h.z : 0.0, h.level});
        r.last_drop = h.position;
        m.events.push_back({t, id, "drop", cid});
        m.truth.push_back({t, cid, Vec3(where.x(), where.y(), chain.back().z)});
        if (multi) m.truth.back().floor = h.level;
      }
    }
    if (t + 1e-9 >= next_crumb_packet) {
      next_crumb_packet += o.crumb_packet_period_s;
      for (const auto& rx : chain) {
        for (const auto& tx : chain) {
          if (rx.id == tx.id) continue;
          if (auto v = channel.Sample(rx.id, rx.position, tx.id, tx.position, std::nullopt,
                                      std::nullopt, link(rx.level, rx.z, tx.level, tx.z))) {
            m.rssi.push_back({t, rx.id, tx.id, *v});
          }
        }
      }
    }
  }
}

SimulatedMission SimulateAgents(FloorPlan plan, const Vec2& base_n,
                                const std::vector<AgentPlan>& agents,
                                const MissionSimOptions& o, std::uint64_t seed) {
  Random rng(seed);
  Random walk_rng = rng.Fork();
  Random pdr_rng = rng.Fork();
  Random radio_rng = rng.Fork();
  Random drop_rng = rng.Fork();
  Random kick_rng = rng.Fork();

  SimulatedMission sim;
  sim.plan = std::move(plan);
  MissionData& m = sim.data;
  m.info.nodes.push_back(NodeInfo::Base("base", Vec3(base_n.x(), base_n.y(), 0.0)));
  m.info.radio = RadioCalibration{"log-distance", o.radio.alpha_dbm, o.radio.path_loss_exponent,
                                  o.radio.shadowing_sigma_db};
  m.info.floorplan = "floorplan.geojson";

  std::vector<AgentRun> runs(agents.size());
  for (std::size_t k = 0; k < agents.size(); ++k) {
    const AgentPlan& a = agents[k];
    AgentRun& r = runs[k];
    r.plan = &a;
    r.walk = WalkRoute(a.route, o.walker, a.start_s, walk_rng);
    const Vec2 start = a.route.waypoints.front();
    m.info.nodes.push_back(NodeInfo::Agent(a.id, Vec3(start.x(), start.y(), 0.0), 0.1,
                                           a.start_heading_rad, 0.02));
    PdrErrorModel pdr(o.pdr, pdr_rng.Fork());
    for (const auto& s : r.walk.steps) {
      const Vec2 measured = pdr.Apply(s.to - s.from, s.t1 - s.t0);
      const double var = pdr.ReportedVariance((s.to - s.from).norm());
      m.steps.push_back({s.t0, s.t1, a.id, Vec3(measured.x(), measured.y(), 0.0),
                         Vec3(var, var, 1e-4)});
    }
    m.events.push_back({r.walk.truth.front().t, a.id, "enter", ""});
    m.events.push_back({r.walk.truth.back().t, a.id, "exit", ""});
    for (const auto& st : r.walk.stops) {
      m.events.push_back({st.t_stop, a.id, "stop", ""});
      m.events.push_back({st.t_go, a.id, "go", ""});
    }
  }

  for (const auto& r : runs) sim.walks.emplace_back(r.plan->id, r.walk);
  SimulateCrumbNetwork(sim, Vec3(base_n.x(), base_n.y(), 0.0), {}, o, true, radio_rng, drop_rng,
                       kick_rng);
  auto by_time = [](const auto& a, const auto& b) { return a.t < b.t; };
  std::stable_sort(m.events.begin(), m.events.end(), by_time);
  std::stable_sort(m.truth.begin(), m.truth.end(), by_time);
  std::stable_sort(m.rssi.begin(), m.rssi.end(), by_time);
  std::stable_sort(m.steps.begin(), m.steps.end(),
                   [](const Step& a, const Step& b) { return a.t1 < b.t1; });
  return sim;
}

}  // namespace trailmark

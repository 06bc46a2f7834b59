// SPDX-License-Identifier: MIT
#include "trailmark/sim/landmark_office.h"

#include <fmt/format.h>

#include <algorithm>
#include <numeric>

#include "trailmark/sim/rssi_channel.h"
#include "trailmark/sim/scenarios.h"

namespace trailmark {

SimulatedMission SimulateLandmarkOffice(const LandmarkOfficeOptions& o, std::uint64_t seed) {
  // The walks, steps and plan of the training floor; its crumbs, base and radio are left out.
  const TrainingBuildingOptions floor;
  SimulatedMission sim = SimulateTrainingBuilding(floor, seed);
  MissionData& m = sim.data;
  std::vector<NodeInfo> agents;
  for (const NodeInfo& n : m.info.nodes) {
    if (n.kind == NodeKind::kAgent) agents.push_back(n);
  }
  auto is_agent = [&](const std::string& id) {
    return std::any_of(agents.begin(), agents.end(), [&](const NodeInfo& a) { return a.id == id; });
  };
  m.info.nodes = agents;
  m.info.radio.reset();
  m.rssi.clear();
  std::erase_if(m.events, [](const MissionEvent& e) { return e.event != "enter" && e.event != "exit"; });
  std::erase_if(m.truth, [&](const TruthSample& s) { return !is_agent(s.id); });

  Random rng(seed ^ 0x6c616e646d61726bULL);  // "landmark": streams apart from the floor's
  const double L = floor.rooms_per_side * floor.room_width_m, h = floor.corridor_width_m / 2,
               D = floor.room_depth_m;
  std::vector<Vec2> where;
  for (int k = 0; k < floor.rooms_per_side; ++k) {
    const double xc = (k + 0.5) * floor.room_width_m;
    where.emplace_back(xc + rng.Uniform(-1.5, 1.5), h + D / 2 + rng.Uniform(-1.5, 1.5));
    where.emplace_back(xc + rng.Uniform(-1.5, 1.5), -h - D / 2 + rng.Uniform(-1.5, 1.5));
  }
  for (int k = 0; k < 4; ++k) where.emplace_back(L * (k + 0.5) / 4, 0.0);
  std::vector<int> order(where.size());
  std::iota(order.begin(), order.end(), 0);
  for (std::size_t i = order.size(); i > 1; --i) {  // Fisher-Yates: which are surveyed
    std::swap(order[i - 1], order[static_cast<std::size_t>(rng.Uniform() * i)]);
  }
  std::vector<bool> surveyed(where.size(), false);
  for (int i = 0; i < std::min<int>(o.landmarks_surveyed, static_cast<int>(where.size())); ++i) {
    surveyed[order[i]] = true;
  }
  RssiChannel channel(o.radio, &sim.plan, {}, rng.Fork());
  std::vector<std::string> ids;
  std::vector<Vec3> truth;
  for (std::size_t j = 0; j < where.size(); ++j) {
    ids.push_back(fmt::format("lm{}", j + 1));
    truth.emplace_back(where[j].x(), where[j].y(), o.landmark_height_m);
    NodeInfo n;
    n.id = ids.back();
    n.kind = NodeKind::kLandmark;
    if (surveyed[j]) {
      n.position = truth.back() + Vec3(rng.Normal(0, o.surveyed_sigma_m),
                                       rng.Normal(0, o.surveyed_sigma_m), 0.0);
      n.position_sigma_m = o.surveyed_sigma_m;
    }
    m.info.nodes.push_back(n);
    m.truth.push_back({0.0, n.id, truth.back()});
    channel.SetNodeGain(n.id, rng.Normal(0, o.landmark_offset_sigma_db));
  }
  for (const NodeInfo& a : agents) channel.SetNodeGain(a.id, rng.Normal(0, o.phone_offset_sigma_db));
  for (const auto& [id, walk] : sim.walks) {
    const TimeS t0 = walk.truth.front().t, t1 = walk.truth.back().t;
    std::size_t i = 0;
    for (TimeS t = t0; t <= t1 + 1e-9; t += o.packet_period_s) {
      while (i + 1 < walk.truth.size() && walk.truth[i + 1].t <= t) ++i;
      const Vec2 p = walk.truth[i].position;
      for (std::size_t j = 0; j < ids.size(); ++j) {
        LinkLevels link;
        link.dz_m = o.phone_height_m - o.landmark_height_m;
        const auto rssi =
            channel.Sample(id, p, ids[j], truth[j].head<2>(), std::nullopt, std::nullopt, link);
        if (rssi) m.rssi.push_back({t, id, ids[j], std::round(*rssi)});
      }
    }
  }
  std::stable_sort(m.rssi.begin(), m.rssi.end(), [](const auto& a, const auto& b) { return a.t < b.t; });
  std::stable_sort(m.truth.begin(), m.truth.end(), [](const auto& a, const auto& b) { return a.t < b.t; });
  m.info.name = "landmark-office";
  m.info.description = fmt::format(
      "Office with 16 ceiling BLE landmarks ({} surveyed), two firefighters searching the rooms "
      "with drifting PDR, no radio calibration and no stop/go events (issue 24); simulated, seed {}",
      o.landmarks_surveyed, seed);
  return sim;
}

}  // namespace trailmark

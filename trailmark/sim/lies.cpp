// SPDX-License-Identifier: MIT
#include "trailmark/sim/lies.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <stdexcept>

namespace trailmark {

std::string Describe(const Lie& lie) {
  switch (lie.kind) {
    case LieKind::kMovedNode:
      return fmt::format("{} surveyed {:g} m off", lie.node, lie.magnitude);
    case LieKind::kRssiOffset:
      return fmt::format("{} RSSI {:+g} dB", lie.node, lie.magnitude);
    case LieKind::kRangeScale:
      return fmt::format("{} ranges x {:g}", lie.node.empty() ? "all" : lie.node, lie.magnitude);
    case LieKind::kFrozenLink:
      return fmt::format("{} RSSI frozen from {:g} s", lie.node, lie.from_s);
  }
  return "?";
}

void ApplyLie(MissionData& m, const Lie& lie) {
  NodeInfo* node = nullptr;
  for (NodeInfo& n : m.info.nodes) {
    if (n.id == lie.node) node = &n;
  }
  const auto touches = [&](const RssiPacket& p) { return p.tx == lie.node || p.rx == lie.node; };
  // A moved node must be declared (with a position); an RSSI lie needs the node's packets only
  // (a dropped crumb is not declared).
  const bool radio = lie.kind == LieKind::kRssiOffset || lie.kind == LieKind::kFrozenLink;
  if ((lie.kind == LieKind::kMovedNode && node == nullptr) ||
      (radio && std::none_of(m.rssi.begin(), m.rssi.end(), touches))) {
    throw std::invalid_argument("lie: no node '" + lie.node + "' in the mission");
  }
  switch (lie.kind) {
    case LieKind::kMovedNode: {
      if (!node->position) throw std::invalid_argument("lie: '" + lie.node + "' is not surveyed");
      const double a = 40.0 * M_PI / 180.0;
      node->position->head<2>() += lie.magnitude * Vec2(std::cos(a), std::sin(a));
      break;
    }
    case LieKind::kRssiOffset:
      for (RssiPacket& p : m.rssi) {
        if (touches(p)) p.rssi_dbm += lie.magnitude;
      }
      break;
    case LieKind::kRangeScale:
      for (RangeMeasurement& r : m.ranges) {
        if (lie.node.empty() || r.kind == lie.node) r.range_m *= lie.magnitude;
      }
      break;
    case LieKind::kFrozenLink: {
      std::optional<double> stuck;
      for (RssiPacket& p : m.rssi) {
        if (!touches(p) || p.t < lie.from_s) continue;
        if (!stuck) stuck = p.rssi_dbm;
        p.rssi_dbm = *stuck;
      }
      break;
    }
  }
}

void SurveyAtTruth(MissionData& m, NodeKind kind, double sigma_m) {
  for (NodeInfo& n : m.info.nodes) {
    if (n.kind != kind) continue;
    for (const TruthSample& s : m.truth) {
      if (s.id != n.id) continue;
      n.position = s.position_n;
      n.position_sigma_m = sigma_m;
      break;
    }
  }
}

}  // namespace trailmark

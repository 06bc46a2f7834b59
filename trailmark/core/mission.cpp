// SPDX-License-Identifier: MIT
#include "trailmark/core/mission.h"

namespace trailmark {

const NodeInfo* MissionInfo::Find(const std::string& id) const {
  for (const auto& n : nodes) {
    if (n.id == id) return &n;
  }
  return nullptr;
}

const NodeInfo* MissionInfo::SingleBase() const {
  const NodeInfo* base = nullptr;
  for (const auto& n : nodes) {
    if (n.kind != NodeKind::kBase) continue;
    if (base != nullptr) return nullptr;
    base = &n;
  }
  return base;
}

std::optional<Vec3> MissionInfo::AgentStart(const NodeInfo& agent) const {
  if (agent.start) return agent.start;
  const NodeInfo* base = SingleBase();
  if (base != nullptr && base->position) return base->position;
  return std::nullopt;
}

}  // namespace trailmark

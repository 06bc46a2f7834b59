// SPDX-License-Identifier: MIT
#include "trailmark/core/mission.h"

#include <cmath>
#include <limits>

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

int LevelAt(const std::vector<FloorLevel>& floors, double z_m) {
  if (floors.empty()) {
    return static_cast<int>(std::floor((z_m + kFloorTolerance_m) / kDefaultStoreyM));
  }
  const FloorLevel* best = &floors.front();  // below every level: the lowest
  for (const FloorLevel& f : floors) {
    if (f.elevation_m <= z_m + kFloorTolerance_m) best = &f;
  }
  return best->level;
}

int MountedLevelAt(const std::vector<FloorLevel>& floors, double z_m) {
  return LevelAt(floors, z_m - kFloorTolerance_m + kMountedTolerance_m);
}

std::pair<double, double> LevelHeightInterval(const std::vector<FloorLevel>& floors, int level) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  if (floors.empty()) {
    return {level * kDefaultStoreyM - kFloorTolerance_m,
            (level + 1) * kDefaultStoreyM - kFloorTolerance_m};
  }
  for (std::size_t i = 0; i < floors.size(); ++i) {
    if (floors[i].level != level) continue;
    const double lower = i == 0 ? -kInf : floors[i].elevation_m - kFloorTolerance_m;
    const double upper = i + 1 == floors.size() ? kInf : floors[i + 1].elevation_m - kFloorTolerance_m;
    return {lower, upper};
  }
  return {0.0, 0.0};
}

std::optional<double> LevelElevation(const std::vector<FloorLevel>& floors, int level) {
  if (floors.empty()) return level * kDefaultStoreyM;
  for (const FloorLevel& f : floors) {
    if (f.level == level) return f.elevation_m;
  }
  return std::nullopt;
}

}  // namespace trailmark

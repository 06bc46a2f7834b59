// SPDX-License-Identifier: MIT
#pragma once
// A level source whose levels the test sets (the height channel's role in the pipelines).

#include <map>
#include <optional>
#include <string>

#include "trailmark/core/online_estimator.h"

namespace trailmark::testing {

class SetLevels : public LevelSource {
 public:
  /// A node's level as set (z: storey_m per level, known to 0.1 m); nullopt for others.
  std::optional<LevelBelief> NodeLevel(const std::string& node) const override {
    const auto it = level.find(node);
    if (it == level.end()) return std::nullopt;
    return LevelBelief{it->second, 1.0, storey_m * it->second, 0.01};
  }
  std::map<std::string, int> level;
  double storey_m = 3.0;
};

}  // namespace trailmark::testing

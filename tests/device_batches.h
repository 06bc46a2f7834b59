// SPDX-License-Identifier: MIT
#pragma once
// Rows as live devices deliver them, for the tests of the live path.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <map>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "trailmark/core/online_estimator.h"

namespace trailmark::testing {

/// As devices deliver them: every node sends its rows in batches of `batch_s` seconds; in
/// each period the nodes' batches come in a shuffled order.
inline std::vector<MissionRow> DeviceBatches(const std::vector<MissionRow>& merged, double batch_s,
                                             std::uint32_t seed) {
  std::map<std::pair<long, std::string>, std::vector<MissionRow>> batches;
  for (const MissionRow& r : merged) {
    batches[{static_cast<long>(std::floor(RowTime(r) / batch_s)), RowNode(r)}].push_back(r);
  }
  std::mt19937 rng(seed);
  std::vector<MissionRow> out;
  for (auto it = batches.begin(); it != batches.end();) {
    const long period = it->first.first;
    std::vector<const std::vector<MissionRow>*> now;
    for (; it != batches.end() && it->first.first == period; ++it) now.push_back(&it->second);
    std::shuffle(now.begin(), now.end(), rng);
    for (const auto* b : now) out.insert(out.end(), b->begin(), b->end());
  }
  return out;
}

}  // namespace trailmark::testing

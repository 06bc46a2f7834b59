// SPDX-License-Identifier: MIT
#pragma once
/// Least-squares rigid motion between two 2-D point sets (Kabsch/Umeyama without scale), with
/// or without reflection. Used by trajectory alignment (eval/) and beacon anchoring (beacons/).

#include <vector>

#include "trailmark/core/types.h"

namespace trailmark {

struct RigidFit2 {
  Mat2 rotation = Mat2::Identity();  ///< det -1 when a reflection was allowed and chosen
  Vec2 translation = Vec2::Zero();
  Vec2 Apply(const Vec2& p) const { return rotation * p + translation; }
};

/// Maps `from` onto `to`; throws std::invalid_argument with fewer than 2 pairs.
RigidFit2 FitRigid(const std::vector<Vec2>& from, const std::vector<Vec2>& to, bool allow_reflection);

}  // namespace trailmark

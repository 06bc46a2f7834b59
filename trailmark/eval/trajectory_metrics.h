// SPDX-License-Identifier: MIT
#pragma once
/// Trajectory metrics of the inertial-navigation literature. No I/O.

#include <vector>

#include "trailmark/core/types.h"

namespace trailmark {

/// PyShoe's 2-D ARMSE (Wagstaff et al. 2019): both trajectories are taken relative to their
/// first sample, the estimate is rotated about z so that its position at the first ground-truth
/// sample `align_distance_m` (horizontal) from the start points the same way, and the error is
/// the mean over samples of the horizontal error divided by sqrt(2) (the RMS of its two axes).
/// Sample k of both vectors is the same instant. Throws std::invalid_argument on size mismatch
/// or empty input.
double HeadingAlignedArmse(const std::vector<Vec3>& estimate, const std::vector<Vec3>& truth,
                           double align_distance_m = 0.8);

/// 2-D rigid transform (rotation, translation; Kabsch/Umeyama without scale) that maps
/// `from` onto `to` in the least-squares sense; needs >= 2 distinct points.
struct Rigid2D {
  double rotation_rad = 0;
  Vec2 translation = Vec2::Zero();
  Vec2 Apply(const Vec2& p) const;
};
Rigid2D FitRigid2D(const std::vector<Vec2>& from, const std::vector<Vec2>& to);

/// Precision and recall of a binary labelling (e.g. stance) against a reference.
struct PrecisionRecall {
  double precision = 0, recall = 0;
  std::size_t true_positive = 0, false_positive = 0, false_negative = 0;
};
PrecisionRecall ComparePrecisionRecall(const std::vector<bool>& detected,
                                       const std::vector<bool>& reference);

}  // namespace trailmark

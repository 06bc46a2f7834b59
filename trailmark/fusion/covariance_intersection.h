// SPDX-License-Identifier: MIT
#pragma once
/// Covariance intersection (Julier & Uhlmann 1997): the fusion of estimates of one quantity
/// whose errors are correlated by an unknown amount. Every pipeline of trailmark dead-reckons
/// the same steps, so their errors share the steps' heading and scale errors; adding their
/// information as if independent would claim a precision no one has. Covariance intersection
/// adds it with weights w_i >= 0, sum w_i = 1:
///     P^-1 = sum_i w_i P_i^-1,   x = P sum_i w_i P_i^-1 x_i,
/// which is consistent for every correlation between the inputs. The weights maximize
/// det(P^-1) (the smallest error area), found by the multiplicative algorithm of D-optimal
/// design (Titterington 1976; Silvey, Titterington & Torsney 1978): log det is concave in w,
/// the update keeps w on the simplex and never lowers det. No I/O.

#include <span>
#include <vector>

#include "trailmark/core/types.h"

namespace trailmark::fusion {

/// One input: a horizontal position and its covariance (symmetric positive definite).
struct PositionGaussian {
  Vec2 mean_m = Vec2::Zero();
  Mat2 cov_m2 = Mat2::Identity();
};

struct IntersectionOptions {
  int max_iterations = 200;
  /// Stops when no input's gradient tr(P I_i) exceeds 2 (its value at the optimum) by more
  /// than this fraction (the optimality condition of D-optimal design).
  double tolerance = 1e-6;
};

struct Intersection {
  PositionGaussian fused;
  std::vector<double> weights;  ///< w_i, one per input, sum 1
  int iterations = 0;
};

/// The covariance intersection of `inputs` (at least one). Covariances are made symmetric and
/// floored at `min_variance_m2` per axis (an exact start has P = 0) before they are inverted.
Intersection Intersect(std::span<const PositionGaussian> inputs,
                       const IntersectionOptions& options = {}, double min_variance_m2 = 1e-6);

}  // namespace trailmark::fusion

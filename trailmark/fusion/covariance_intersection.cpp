// SPDX-License-Identifier: MIT
#include "trailmark/fusion/covariance_intersection.h"

#include <Eigen/LU>
#include <algorithm>
#include <stdexcept>

namespace trailmark::fusion {

Intersection Intersect(std::span<const PositionGaussian> inputs, const IntersectionOptions& options,
                       double min_variance_m2) {
  if (inputs.empty()) throw std::invalid_argument("covariance intersection of no estimate");
  const std::size_t n = inputs.size();
  std::vector<Mat2> info(n);       // I_i = P_i^-1
  std::vector<Vec2> info_mean(n);  // I_i x_i
  for (std::size_t i = 0; i < n; ++i) {
    Mat2 p = 0.5 * (inputs[i].cov_m2 + inputs[i].cov_m2.transpose());
    p.diagonal() = p.diagonal().cwiseMax(min_variance_m2);
    // A covariance that is not positive definite after the floor (|sxy| too large) is
    // replaced by its diagonal: an input never makes the fusion singular.
    if (p.determinant() <= 1e-12 * min_variance_m2 * min_variance_m2) p = p.diagonal().asDiagonal();
    info[i] = p.inverse();
    info_mean[i] = info[i] * inputs[i].mean_m;
  }
  Intersection out;
  out.weights.assign(n, 1.0 / static_cast<double>(n));
  Mat2 m = Mat2::Zero();
  auto accumulate = [&] {
    m.setZero();
    for (std::size_t i = 0; i < n; ++i) m += out.weights[i] * info[i];
  };
  accumulate();
  if (n > 1) {
    for (out.iterations = 0; out.iterations < options.max_iterations; ++out.iterations) {
      const Mat2 p = m.inverse();
      // d log det(sum w_i I_i) / d w_i = tr(P I_i); at the optimum every input of positive
      // weight has 2 (the dimension) and none has more (Kiefer-Wolfowitz).
      double worst = 0.0;
      for (std::size_t i = 0; i < n; ++i) {
        const double g = (p * info[i]).trace();
        worst = std::max(worst, g);
        out.weights[i] *= g / 2.0;
      }
      double sum = 0.0;
      for (double w : out.weights) sum += w;
      for (double& w : out.weights) w /= sum;
      accumulate();
      if (worst <= 2.0 * (1.0 + options.tolerance)) break;
    }
  }
  out.fused.cov_m2 = m.inverse();
  out.fused.cov_m2 = 0.5 * (out.fused.cov_m2 + out.fused.cov_m2.transpose()).eval();
  Vec2 b = Vec2::Zero();
  for (std::size_t i = 0; i < n; ++i) b += out.weights[i] * info_mean[i];
  out.fused.mean_m = out.fused.cov_m2 * b;
  return out;
}

}  // namespace trailmark::fusion

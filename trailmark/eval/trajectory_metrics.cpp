// SPDX-License-Identifier: MIT
#include "trailmark/eval/trajectory_metrics.h"

#include "trailmark/geometry/rigid_fit.h"

#include <cmath>
#include <stdexcept>

namespace trailmark {

double HeadingAlignedArmse(const std::vector<Vec3>& estimate, const std::vector<Vec3>& truth,
                           double align_distance_m) {
  if (estimate.size() != truth.size() || estimate.empty()) {
    throw std::invalid_argument("HeadingAlignedArmse: trajectories of different or zero length");
  }
  const Vec2 e0 = estimate.front().head<2>(), g0 = truth.front().head<2>();
  double rotation = 0;
  for (std::size_t k = 0; k < truth.size(); ++k) {
    const Vec2 g = truth[k].head<2>() - g0;
    if (g.norm() >= align_distance_m) {
      const Vec2 e = estimate[k].head<2>() - e0;
      rotation = std::atan2(g.y(), g.x()) - std::atan2(e.y(), e.x());
      break;
    }
  }
  const double c = std::cos(rotation), s = std::sin(rotation);
  double sum = 0;
  for (std::size_t k = 0; k < truth.size(); ++k) {
    const Vec2 e = estimate[k].head<2>() - e0;
    const Vec2 r(c * e.x() - s * e.y(), s * e.x() + c * e.y());
    sum += (r - (truth[k].head<2>() - g0)).norm();
  }
  return sum / static_cast<double>(truth.size()) / std::sqrt(2.0);
}

Vec2 Rigid2D::Apply(const Vec2& p) const {
  const double c = std::cos(rotation_rad), s = std::sin(rotation_rad);
  return Vec2(c * p.x() - s * p.y(), s * p.x() + c * p.y()) + translation;
}

Rigid2D FitRigid2D(const std::vector<Vec2>& from, const std::vector<Vec2>& to) {
  const RigidFit2 fit = FitRigid(from, to, false);
  Rigid2D r;
  r.rotation_rad = std::atan2(fit.rotation(1, 0), fit.rotation(0, 0));
  r.translation = fit.translation;
  return r;
}

PrecisionRecall ComparePrecisionRecall(const std::vector<bool>& detected,
                                       const std::vector<bool>& reference) {
  if (detected.size() != reference.size()) {
    throw std::invalid_argument("ComparePrecisionRecall: labellings of different length");
  }
  PrecisionRecall pr;
  for (std::size_t k = 0; k < detected.size(); ++k) {
    if (detected[k] && reference[k]) ++pr.true_positive;
    if (detected[k] && !reference[k]) ++pr.false_positive;
    if (!detected[k] && reference[k]) ++pr.false_negative;
  }
  const double tp = static_cast<double>(pr.true_positive);
  pr.precision = tp + pr.false_positive > 0 ? tp / (tp + pr.false_positive) : 0.0;
  pr.recall = tp + pr.false_negative > 0 ? tp / (tp + pr.false_negative) : 0.0;
  return pr;
}

}  // namespace trailmark

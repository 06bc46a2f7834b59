// SPDX-License-Identifier: MIT
#include "trailmark/geometry/rigid_fit.h"

#include <Eigen/Dense>
#include <stdexcept>

namespace trailmark {

RigidFit2 FitRigid(const std::vector<Vec2>& from, const std::vector<Vec2>& to, bool allow_reflection) {
  if (from.size() != to.size() || from.size() < 2) {
    throw std::invalid_argument("FitRigid: needs two or more point pairs");
  }
  Vec2 cf = Vec2::Zero(), ct = Vec2::Zero();
  for (std::size_t k = 0; k < from.size(); ++k) {
    cf += from[k];
    ct += to[k];
  }
  cf /= static_cast<double>(from.size());
  ct /= static_cast<double>(to.size());
  Mat2 H = Mat2::Zero();
  for (std::size_t k = 0; k < from.size(); ++k) H += (from[k] - cf) * (to[k] - ct).transpose();
  const Eigen::JacobiSVD<Mat2> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Mat2 R = svd.matrixV() * svd.matrixU().transpose();
  if (!allow_reflection && R.determinant() < 0) {
    Mat2 D = Mat2::Identity();
    D(1, 1) = -1;
    R = svd.matrixV() * D * svd.matrixU().transpose();
  }
  return {R, ct - R * cf};
}

}  // namespace trailmark

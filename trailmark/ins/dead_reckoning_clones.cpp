// SPDX-License-Identifier: MIT
#include "trailmark/ins/dead_reckoning_clones.h"

#include <Eigen/Cholesky>
#include <stdexcept>

namespace trailmark {

DeadReckoningClones::DeadReckoningClones(DeadReckoning dr)
    : dr_(std::move(dr)), cross_(DeadReckoning::kErrors, 0) {}

void DeadReckoningClones::AddStep(const Step& step) {
  dr_.AddStep(step);
  // e' = Phi e + w, w independent of every earlier error: cov(e', clone) = Phi cov(e, clone).
  if (cross_.cols() > 0) cross_ = dr_.last_transition() * cross_;
}

int DeadReckoningClones::Clone(double independent_variance_m2) {
  const int k = clones();
  const Eigen::Index n = 2 * k;
  const auto& P = dr_.error_covariance();
  Eigen::MatrixXd s(n + 2, n + 2);
  s.topLeftCorner(n, n) = clone_cov_;
  // The new clone is the current position error: its covariance with the older clones is the
  // position rows of C, with itself P's position block.
  s.block(n, 0, 2, n) = cross_.topRows<2>();
  s.block(0, n, n, 2) = cross_.topRows<2>().transpose();
  s.block<2, 2>(n, n) = P.topLeftCorner<2, 2>() + Mat2::Identity() * independent_variance_m2;
  clone_cov_ = std::move(s);
  CrossCovariance c(DeadReckoning::kErrors, n + 2);
  c.leftCols(n) = cross_;
  c.rightCols<2>() = P.leftCols<2>();
  cross_ = std::move(c);
  clone_position_n_.push_back(dr_.position_n().head<2>());
  clone_offset_sens_.conservativeResize(n + 2);
  clone_offset_sens_.tail<2>() = dr_.offset_sensitivity().head<2>();
  // The conditioning stays on the earlier clones: the current position does not move.
  return k;
}

void DeadReckoningClones::DropOldest() {
  if (clone_position_n_.empty()) return;
  const Eigen::Index n = cross_.cols() - 2;
  clone_position_n_.erase(clone_position_n_.begin());
  clone_offset_sens_ = Eigen::VectorXd(clone_offset_sens_.tail(n));
  clone_cov_ = Eigen::MatrixXd(clone_cov_.bottomRightCorner(n, n));
  cross_ = CrossCovariance(cross_.rightCols(n));
  if (posterior_n_.size() > 0) {
    const Eigen::Index m = posterior_n_.size() - 2;
    posterior_n_ = Eigen::VectorXd(posterior_n_.tail(m));
    posterior_cov_ = Eigen::MatrixXd(posterior_cov_.bottomRightCorner(m, m));
    posterior_offset_sens_ = Eigen::VectorXd(posterior_offset_sens_.tail(m));
  }
  ConditionOnStored();
}

void DeadReckoningClones::Condition(const Eigen::VectorXd& posterior_n,
                                    const Eigen::MatrixXd& posterior_cov) {
  const Eigen::Index n = 2 * clones();
  if (posterior_n.size() != n || posterior_cov.rows() != n || posterior_cov.cols() != n) {
    throw std::invalid_argument("DeadReckoningClones::Condition: sizes are not the clones'");
  }
  if (!posterior_n.allFinite() || !posterior_cov.allFinite()) {
    throw std::invalid_argument("DeadReckoningClones::Condition: values must be finite");
  }
  const Eigen::LLT<Eigen::MatrixXd> prior(clone_cov_);
  if (n > 0 && prior.info() != Eigen::Success) {
    throw std::invalid_argument(
        "DeadReckoningClones::Condition: the clones' prior is not positive definite");
  }
  posterior_n_ = posterior_n;
  posterior_cov_ = 0.5 * (posterior_cov + posterior_cov.transpose());
  // d posterior / d offset = posterior_cov S^-1 d prior mean / d offset (the solver's normal
  // equations at its solution: the prior is the only information that moves with the offset).
  posterior_offset_sens_ =
      n > 0 ? Eigen::VectorXd(posterior_cov_ * prior.solve(clone_offset_sens_)) : Eigen::VectorXd();
  ConditionOnStored();
}

void DeadReckoningClones::ConditionOnStored() {
  const Eigen::Index m = posterior_n_.size();
  if (m == 0) {
    gain_.resize(0);
    explained_.resize(0, 0);
    offset_gain_.resize(0);
    return;
  }
  // The current error e and the clones' errors c are jointly Gaussian with cov(e, c) = C and
  // cov(c) = S; the measurements behind the posterior saw only c, so
  //   E[e | .] = C S^-1 E[c | .],  cov(e | .) = P - C S^-1 C^T + C S^-1 cov(c | .) S^-1 C^T,
  // with the clones' errors given the posterior: mean DR - posterior, covariance posterior_cov.
  const Eigen::LLT<Eigen::MatrixXd> llt(clone_cov_.topLeftCorner(m, m));
  Eigen::VectorXd dr_n(m);
  for (Eigen::Index i = 0; i < m / 2; ++i) dr_n.segment<2>(2 * i) = clone_position_n_[i];
  gain_ = llt.solve(dr_n - posterior_n_);
  // The offset's sensitivity, alike: the estimate's error is e - C S^-1 (e_c - e_posterior).
  offset_gain_ = llt.solve(clone_offset_sens_.head(m) - posterior_offset_sens_);
  const Eigen::MatrixXd s_inv = llt.solve(Eigen::MatrixXd::Identity(m, m));
  explained_ = s_inv - s_inv * posterior_cov_ * s_inv;
  explained_ = 0.5 * (explained_ + explained_.transpose());
}

Vec2 DeadReckoningClones::position_n() const {
  const Vec2 dr = dr_.position_n().head<2>();
  if (gain_.size() == 0) return dr;
  return dr - cross_.topLeftCorner(2, gain_.size()) * gain_;
}

Vec2 DeadReckoningClones::offset_sensitivity() const {
  const Vec2 s = dr_.offset_sensitivity().head<2>();
  if (offset_gain_.size() == 0) return s;
  return s - cross_.topLeftCorner(2, offset_gain_.size()) * offset_gain_;
}

Mat2 DeadReckoningClones::covariance() const {
  const double sigma = dr_.considered_offset_sigma_rad();
  const Vec2 s = offset_sensitivity();
  Mat2 out = dr_.own_covariance() + sigma * sigma * s * s.transpose();
  if (gain_.size() > 0) {
    const auto c = cross_.topLeftCorner(2, gain_.size());
    out -= c * explained_ * c.transpose();
  }
  return 0.5 * (out + out.transpose());
}

}  // namespace trailmark

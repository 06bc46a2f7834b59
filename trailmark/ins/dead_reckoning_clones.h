// SPDX-License-Identifier: MIT
#pragma once
/// Dead reckoning that remembers its error at chosen instants (e.g. where the walker stood
/// still) jointly with its current error: stochastic cloning (Roumeliotis & Burdick, ICRA
/// 2002). The positions at those instants then have their joint prior — correlated through the
/// heading, drift-rate and scale errors that all steps share (ins/dead_reckoning.h) — so that a
/// solver can place them together with what it measured there, and the current position
/// follows: conditioned on the solver's posterior of the cloned positions, exactly (the walk's
/// errors are jointly Gaussian and the measurements see only the clones). No I/O.
///
/// Errors are dead reckoning minus truth: e = DR - p.

#include <Eigen/Core>

#include "trailmark/ins/dead_reckoning.h"

namespace trailmark {

class DeadReckoningClones {
 public:
  explicit DeadReckoningClones(DeadReckoning dr);
  /// One step of the dead reckoning; the current error's correlation with every clone follows.
  void AddStep(const Step& step);
  /// Remembers the current position error as a new clone (the last one); returns its index.
  /// `independent_variance_m2` (per axis) is added to the clone alone: an error of that instant
  /// that no other shares (it keeps the prior positive definite when two clones are taken with
  /// no step between them).
  int Clone(double independent_variance_m2 = 0.0);
  /// Forgets the oldest clone: its prior is marginalized out and the current position stays
  /// conditioned on the latest posterior of the clones that remain (what was measured only at
  /// the forgotten one no longer moves the current position).
  void DropOldest();
  int clones() const { return static_cast<int>(clone_position_n_.size()); }
  /// The dead reckoning's position at clone i (its prior mean).
  const Vec2& clone_position_n(int i) const { return clone_position_n_[i]; }
  /// The joint prior covariance of the cloned position errors (2K x 2K, clone i at rows 2i).
  const Eigen::MatrixXd& clone_covariance() const { return clone_cov_; }
  /// Conditions on a posterior of the cloned positions (mean 2K, stacked as the clones; its
  /// joint covariance 2K x 2K): from now on position_n() and covariance() are the current
  /// position's given it, and stay so as steps and clones are added. A considered heading
  /// offset (PdrOptions::track_heading_offset_considered) moves the posterior by
  /// posterior_cov S^-1 times the clones' own sensitivity to it (S: clone_covariance()): that of
  /// a solver whose prior on the clones is this one and whose other information (ranges to
  /// surveyed or jointly solved landmarks) does not depend on the walk's heading offset, to
  /// first order at its solution. Throws std::invalid_argument
  /// for sizes that are not the clones', values that are not finite, or a prior that is not
  /// positive definite (nothing changes then).
  void Condition(const Eigen::VectorXd& posterior_n, const Eigen::MatrixXd& posterior_cov);
  /// The raw dead reckoning (its position and covariance without any conditioning).
  const DeadReckoning& dead_reckoning() const { return dr_; }
  /// The current position: the dead reckoning minus the conditioned mean of its error.
  Vec2 position_n() const;
  /// Its covariance: the dead reckoning's minus what the clones' posterior explained, and a
  /// considered offset's share, sigma^2 s s^T with s = offset_sensitivity().
  Mat2 covariance() const;
  /// The current position error's sensitivity to the considered offset (zero if none).
  Vec2 offset_sensitivity() const;

 private:
  using CrossCovariance = Eigen::Matrix<double, DeadReckoning::kErrors, Eigen::Dynamic>;
  DeadReckoning dr_;
  std::vector<Vec2> clone_position_n_;
  Eigen::VectorXd clone_offset_sens_;  ///< each clone's position error's, stacked (2K)
  Eigen::MatrixXd clone_cov_;  ///< S: joint prior of the clones' position errors
  CrossCovariance cross_;      ///< C: current error (6) x clones' position errors (2K)
  /// Conditions on the stored posterior of the first posterior_n_.size() / 2 clones.
  void ConditionOnStored();
  /// The latest posterior, of the first clones (those that existed at Condition).
  Eigen::VectorXd posterior_n_;
  Eigen::MatrixXd posterior_cov_;
  Eigen::VectorXd posterior_offset_sens_;  ///< the posterior's sensitivity to the offset
  /// S_m^-1 (clone sensitivities - posterior's) (empty: none).
  Eigen::VectorXd offset_gain_;
  /// After Condition on the first m clones: the current error's conditioned mean is C_m g, its
  /// covariance P - C_m M C_m^T, with g = S_m^-1 (DR_m - posterior) and
  /// M = S_m^-1 - S_m^-1 posterior_cov S_m^-1 (empty: none).
  Eigen::VectorXd gain_;
  Eigen::MatrixXd explained_;
};

}  // namespace trailmark

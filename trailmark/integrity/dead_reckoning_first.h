// SPDX-License-Identifier: MIT
#pragma once
/// Dead reckoning first (ours, issues 21 and 24: never worse than dead reckoning): the verdict of
/// one agent's estimator on its dead reckoning, for an agent whose dead reckoning is expected to
/// be better than the estimator's absolute source can place it (a foot INS within its noise
/// model against RSSI or ultrasound at its own resolution: docs/landmarks.md, "A good foot INS
/// and the radio"; docs/integrity.md).
///
/// d2 is the dead reckoning's squared Mahalanobis distance from the estimate under the
/// estimator's own covariance (without terms it shares with dead reckoning, such as the steps'
/// heading offset as a consider parameter): if the dead reckoning is right, d2 is the
/// estimator's own error, chi-square with 2 dof when the estimator is honest. Inside the
/// `accept_probability` quantile the dead reckoning is written; beyond `reject_probability`'s
/// the estimate (the dead reckoning is rejected: an integrity note, and another when it is
/// accepted again, back to the dead reckoning); in between a blend linear in d2 with the
/// mixture's mean squared error. The estimator runs all along. No I/O.

#include <optional>
#include <string>

#include "trailmark/core/online_estimator.h"
#include "trailmark/core/options.h"
#include "trailmark/core/types.h"

namespace trailmark::integrity {

struct DeadReckoningFirstOptions {
  double reject_probability = 0.9999;  ///< the estimate beyond this 2-dof quantile (a priori)
  double accept_probability = 0.99;    ///< the dead reckoning inside this one
  bool IsValid(std::string* why) const;
};

/// The `dr_reject_probability` and `dr_accept_probability` keys of the estimators that use it.
const OptionTable<DeadReckoningFirstOptions>& DeadReckoningFirstOptionTable();

class DeadReckoningFirst {
 public:
  /// Throws std::invalid_argument for invalid options.
  explicit DeadReckoningFirst(const DeadReckoningFirstOptions& options);
  /// The verdict after the estimator moved: `estimate` with its own covariance `own_cov`
  /// against the dead reckoning `dr`. Returns the integrity note when the dead reckoning was
  /// rejected or accepted again (`what`: the estimator, e.g. "the tracker"). A covariance that
  /// is not positive definite changes nothing.
  std::optional<IntegrityNote> Test(TimeS t, const std::string& agent, const std::string& what,
                                    const Vec2& estimate, const Mat2& own_cov, const Vec2& dr);
  /// The dead reckoning is no longer within its noise model (its foot INS's steps stopped
  /// claiming the INS's own heading errors: the IMU's mounting not found): the estimate is
  /// written from now on, and Test changes nothing. Returns the integrity note, once.
  std::optional<IntegrityNote> Abandon(TimeS t, const std::string& agent, const std::string& what);
  /// What to write: the dead reckoning, the estimate, or the blend (the mixture's mean squared
  /// error about it: each one's covariance and the spread of the two).
  Vec2 Position(const Vec2& estimate, const Vec2& dr) const;
  Mat2 Covariance(const Vec2& estimate, const Mat2& reported_cov, const Vec2& dr,
                  const Mat2& dr_cov) const;
  /// 0: the dead reckoning is written, 1: the estimate.
  double doubt() const { return doubt_; }
  bool WritesDeadReckoning() const { return doubt_ == 0; }
  /// Estimates written and how many were not the dead reckoning (Count at each write).
  void Count() { ++written_, not_dr_ += doubt_ > 0; }
  double share_not_dead_reckoning() const {
    return written_ ? static_cast<double>(not_dr_) / static_cast<double>(written_) : 0.0;
  }

 private:
  DeadReckoningFirstOptions options_;
  double reject_d2_ = 0, accept_d2_ = 0;
  double doubt_ = 0;
  bool rejected_ = false, abandoned_ = false;
  std::size_t written_ = 0, not_dr_ = 0;
};

}  // namespace trailmark::integrity

// SPDX-License-Identifier: MIT
#include "trailmark/integrity/dead_reckoning_first.h"

#include <fmt/format.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "trailmark/integrity/consistency.h"

namespace trailmark::integrity {

bool DeadReckoningFirstOptions::IsValid(std::string* why) const {
  if (reject_probability > 0 && reject_probability < 1 && accept_probability > 0 &&
      accept_probability < reject_probability)
    return true;
  if (why) *why = "dead reckoning first: need 0 < accept_probability < reject_probability < 1";
  return false;
}

const OptionTable<DeadReckoningFirstOptions>& DeadReckoningFirstOptionTable() {
  static const OptionTable<DeadReckoningFirstOptions> table = [] {
    using O = DeadReckoningFirstOptions;
    OptionTable<O> t;
    t.Real("dr_reject_probability", &O::reject_probability, "",
           OptionBounds::Between(0.5, 0.999999),
           "dr_first: the estimator's estimate where the dead reckoning is outside its own region "
           "of this probability (2-dof chi-square)");
    t.Real("dr_accept_probability", &O::accept_probability, "",
           OptionBounds::Between(0.5, 0.999999),
           "dr_first: the dead reckoning where it is inside this one (a blend in between)");
    return t;
  }();
  return table;
}

DeadReckoningFirst::DeadReckoningFirst(const DeadReckoningFirstOptions& options)
    : options_(options) {
  std::string why;
  if (!options_.IsValid(&why)) throw std::invalid_argument(why);
  reject_d2_ = ChiSquareQuantile(2, options_.reject_probability);
  accept_d2_ = ChiSquareQuantile(2, options_.accept_probability);
}

std::optional<IntegrityNote> DeadReckoningFirst::Test(TimeS t, const std::string& agent,
                                                      const std::string& what, const Vec2& estimate,
                                                      const Mat2& own_cov, const Vec2& dr) {
  if (abandoned_) return std::nullopt;
  const Eigen::LDLT<Mat2> ldlt(own_cov);
  if (ldlt.info() != Eigen::Success || !(own_cov.determinant() > 0)) return std::nullopt;
  const Vec2 d = estimate - dr;
  const double d2 = d.dot(ldlt.solve(d));
  if (!std::isfinite(d2)) return std::nullopt;
  // From the dead reckoning (inside the accept region) to the estimate (outside the reject
  // region), linearly in the squared distance between them.
  doubt_ = std::clamp((d2 - accept_d2_) / (reject_d2_ - accept_d2_), 0.0, 1.0);
  const bool rejected = rejected_ ? doubt_ > 0 : doubt_ >= 1;
  if (rejected == rejected_) return std::nullopt;
  rejected_ = rejected;
  return IntegrityNote{
      t, "agent " + agent, agent, rejected ? "resumed" : "fallback",
      fmt::format("{} at t {:.1f} s: its foot INS's dead reckoning {} {}'s {:g} % region "
                  "(squared Mahalanobis distance {:.1f}, {:.1f} m away): {} written",
                  agent, t, rejected ? "left" : "is back in", what,
                  100 * (rejected ? options_.reject_probability : options_.accept_probability), d2,
                  d.norm(), rejected ? what + "'s estimate" : std::string("dead reckoning"))};
}

std::optional<IntegrityNote> DeadReckoningFirst::Abandon(TimeS t, const std::string& agent,
                                                         const std::string& what) {
  if (abandoned_) return std::nullopt;
  abandoned_ = rejected_ = true;
  doubt_ = 1;
  return IntegrityNote{
      t, "agent " + agent, agent, "resumed",
      fmt::format("{} at t {:.1f} s: its foot INS's steps no longer claim the INS's own errors "
                  "(the IMU's mounting not found): {}'s estimate written from now on",
                  agent, t, what)};
}

Vec2 DeadReckoningFirst::Position(const Vec2& estimate, const Vec2& dr) const {
  if (doubt_ >= 1) return estimate;  // each one exactly as it is at the ends
  if (doubt_ <= 0) return dr;
  return dr + doubt_ * (estimate - dr);
}

Mat2 DeadReckoningFirst::Covariance(const Vec2& estimate, const Mat2& reported_cov, const Vec2& dr,
                                    const Mat2& dr_cov) const {
  if (doubt_ >= 1) return reported_cov;
  if (doubt_ <= 0) return dr_cov;
  const double w = doubt_;
  const Vec2 d = estimate - dr;
  return (1 - w) * dr_cov + w * reported_cov + w * (1 - w) * d * d.transpose();
}

}  // namespace trailmark::integrity

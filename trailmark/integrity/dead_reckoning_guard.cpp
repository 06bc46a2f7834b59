// SPDX-License-Identifier: MIT
#include "trailmark/integrity/dead_reckoning_guard.h"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <utility>

#include "trailmark/integrity/consistency.h"

namespace trailmark::integrity {

bool GuardOptions::IsValid(std::string* why) const {
  if (!(overbound >= 1) || !std::isfinite(overbound)) {
    if (why) *why = "integrity: overbound must be >= 1";
    return false;
  }
  if (!(grow_probability >= 0 && grow_probability < 1)) {
    if (why) *why = "integrity: grow_probability must be in [0, 1)";
    return false;
  }
  if (!(return_probability > 0 && return_probability <= leave_probability &&
        leave_probability < 1)) {
    if (why) *why = "integrity: need 0 < return_probability <= leave_probability < 1";
    return false;
  }
  return true;
}

const OptionTable<GuardOptions>& GuardOptionTable() {
  static const OptionTable<GuardOptions> table = [] {
    OptionTable<GuardOptions> t;
    t.Choice("integrity.on_disagreement", &GuardOptions::on_disagreement,
             std::vector<std::pair<std::string, GuardAction>>{{"grow", GuardAction::kGrow},
                                                              {"fallback", GuardAction::kFallback},
                                                              {"report", GuardAction::kReport}},
             "an agent's estimate outside its dead reckoning's region: grow its covariance to "
             "cover both, fall back to dead reckoning, or only report it");
    t.Real("integrity.leave_probability", &GuardOptions::leave_probability, "",
           OptionBounds::Inside(0, 1),
           "dead reckoning's region an estimate must stay in (2-dof chi-square probability)");
    t.Real("integrity.return_probability", &GuardOptions::return_probability, "",
           OptionBounds::Inside(0, 1),
           "region the estimate must be back in to be emitted again (hysteresis)");
    t.Real("integrity.overbound", &GuardOptions::overbound, "", OptionBounds::AtLeast(1),
           "the shadow's shared PDR error sigmas, x the pdr defaults (an overbound)");
    t.Real("integrity.grow_probability", &GuardOptions::grow_probability, "",
           OptionBounds{0.0, 1.0, false, true},
           "grow: just enough to put dead reckoning on the boundary of the grown covariance's "
           "region of this probability (0: by d d^T, dead reckoning within one sigma)");
    return t;
  }();
  return table;
}

/// Passes the inner estimator's estimates through the guard.
class DeadReckoningGuard::Checked : public EstimateSink {
 public:
  Checked(DeadReckoningGuard& guard, EstimateSink& out) : guard_(guard), out_(out) {}
  void Add(const Estimate& estimate) override { out_.Add(guard_.Check(estimate, true)); }

 private:
  DeadReckoningGuard& guard_;
  EstimateSink& out_;
};

namespace {
/// Records the shadow's estimates per agent.
class HistorySink : public EstimateSink {
 public:
  explicit HistorySink(std::vector<Estimate>& history) : history_(history) {}
  void Add(const Estimate& estimate) override { history_.push_back(estimate); }

 private:
  std::vector<Estimate>& history_;
};

/// The typical device's dead reckoning with its shared-error sigmas x overbound.
PdrOptions Overbounded(PdrOptions o, const GuardOptions& guard) {
  std::string why;
  if (!guard.IsValid(&why)) throw std::invalid_argument(why);
  return o.SharedErrorsScaled(guard.overbound);
}
}  // namespace

DeadReckoningGuard::DeadReckoningGuard(MissionInfo info, GuardOptions options,
                                       std::unique_ptr<OnlineEstimator> inner,
                                       const PdrOptions& typical)
    : options_(options),
      inner_(std::move(inner)),
      shadow_(std::move(info), Overbounded(typical, options)) {
  leave_d2_ = ChiSquareQuantile(2, options_.leave_probability);
  return_d2_ = ChiSquareQuantile(2, options_.return_probability);
  if (options_.grow_probability > 0) grow_d2_ = ChiSquareQuantile(2, options_.grow_probability);
}

void DeadReckoningGuard::Add(const MissionRow& row, EstimateSink& sink) {
  if (const auto* step = std::get_if<Step>(&row)) {
    const std::string& agent = step->agent;
    if (!unguarded_.contains(agent)) {
      Shadow& shadow = agents_[agent];
      HistorySink history(shadow.history);
      try {
        shadow_.Add(row, history);
      } catch (const std::invalid_argument& e) {
        // No dead reckoning for this agent (no known start): its estimates pass unchecked.
        agents_.erase(agent);
        unguarded_.insert(agent);
        notes_.push_back(IntegrityNote{step->t0, "agent " + agent, agent, "unguarded",
                                       fmt::format("agent {}: no dead-reckoning shadow ({}); "
                                                   "its estimates are not checked against it",
                                                   agent, e.what())});
      }
    }
  }
  Checked checked(*this, sink);
  inner_->Add(row, checked);
}

void DeadReckoningGuard::Finish(EstimateSink& sink) {
  Checked checked(*this, sink);
  inner_->Finish(checked);
}

const Estimate* DeadReckoningGuard::ShadowAt(const std::string& agent, TimeS t) const {
  const auto it = agents_.find(agent);
  if (it == agents_.end() || it->second.history.empty()) return nullptr;
  const auto& h = it->second.history;
  // The last dead reckoning at or before t (the first one before the first step: the agent
  // stands at its start).
  auto after = std::upper_bound(h.begin(), h.end(), t,
                                [](TimeS value, const Estimate& e) { return value < e.t; });
  return after == h.begin() ? &h.front() : &*(after - 1);
}

Estimate DeadReckoningGuard::Check(const Estimate& estimate, bool record) {
  const Estimate* dr = ShadowAt(estimate.id, estimate.t);
  if (dr == nullptr) return estimate;
  Shadow& shadow = agents_.at(estimate.id);
  // Squared Mahalanobis distance of the estimate from dead reckoning, under the sum of both
  // covariances (conservative: the two share the steps) and a 1 cm floor.
  Mat2 c;
  c << dr->sxx + estimate.sxx + 1e-4, dr->sxy + estimate.sxy, dr->sxy + estimate.sxy,
      dr->syy + estimate.syy + 1e-4;
  const Vec2 d = (estimate.position_n - dr->position_n).head<2>();
  double d2 = d.dot(c.ldlt().solve(d));
  if (!std::isfinite(d2)) d2 = std::numeric_limits<double>::infinity();
  const bool was = shadow.disagrees;
  const bool now = was ? d2 > return_d2_ : d2 > leave_d2_;
  if (record) {
    ++checked_;
    if (now) ++disagreeing_estimates_;
    if (now != was) {
      shadow.disagrees = now;
      if (now) ++disagreements_;
      const char* what = options_.on_disagreement == GuardAction::kGrow
                             ? ": its ellipse grows to cover both"
                         : options_.on_disagreement == GuardAction::kFallback
                             ? ": dead reckoning is emitted instead"
                             : " (reported only)";
      const bool fallback = options_.on_disagreement == GuardAction::kFallback;
      notes_.push_back(IntegrityNote{
          estimate.t, "agent " + estimate.id, estimate.id,
          now ? (fallback ? "fallback" : "disagrees") : (fallback ? "resumed" : "agrees"),
          now ? fmt::format("agent {} at t {:.1f} s: the estimate is {:.1f} m from dead "
                            "reckoning (Mahalanobis {:.1f} > {:.1f}, outside its {:g} % "
                            "region){}",
                            estimate.id, estimate.t, d.norm(), std::sqrt(d2),
                            std::sqrt(leave_d2_), 100 * options_.leave_probability, what)
              : fmt::format("agent {} at t {:.1f} s: the estimate is back inside dead "
                            "reckoning's {:g} % region ({:.1f} m)",
                            estimate.id, estimate.t, 100 * options_.return_probability,
                            d.norm())});
    }
  }
  return now ? Act(estimate, *dr) : estimate;
}

Estimate DeadReckoningGuard::Act(const Estimate& estimate, const Estimate& dr) const {
  switch (options_.on_disagreement) {
    case GuardAction::kReport:
      return estimate;
    case GuardAction::kFallback: {
      Estimate out = dr;
      out.t = estimate.t;
      return out;
    }
    case GuardAction::kGrow:
      break;
  }
  // P + a d d^T stays SPD for a >= 0. a = 1: dead reckoning lies within one sigma of the
  // estimate under the grown covariance (d^T (P + d d^T)^-1 d = m / (1 + m) < 1,
  // m = d^T P^-1 d).
  const Vec2 d = (dr.position_n - estimate.position_n).head<2>();
  double scale = 1.0;
  if (grow_d2_ > 0) {
    // P + a d d^T puts d at m / (1 + a m) (m = d^T P^-1 d, Sherman-Morrison): a = 1/q - 1/m
    // brings it to q, the p-region's squared radius; none when it is inside already.
    Mat2 P;
    P << estimate.sxx, estimate.sxy, estimate.sxy, estimate.syy;
    const double m = d.dot(P.ldlt().solve(d));
    scale = std::isfinite(m) && m > 0 ? std::clamp(1.0 / grow_d2_ - 1.0 / m, 0.0, 1.0) : 1.0;
  }
  Estimate out = estimate;
  out.sxx += scale * d.x() * d.x();
  out.sxy += scale * d.x() * d.y();
  out.syy += scale * d.y() * d.y();
  return out;
}

std::optional<Estimate> DeadReckoningGuard::Current(const std::string& node) const {
  auto current = inner_->Current(node);
  if (!current || !Disagrees(node)) return current;
  const Estimate* dr = ShadowAt(node, current->t);
  return dr ? Act(*current, *dr) : *current;
}

bool DeadReckoningGuard::Disagrees(const std::string& agent) const {
  const auto it = agents_.find(agent);
  return it != agents_.end() && it->second.disagrees;
}

EstimatorSummary DeadReckoningGuard::Summary() const {
  EstimatorSummary s = inner_->Summary();
  s.numbers["integrity.disagreements"] = static_cast<double>(disagreements_);
  s.numbers["integrity.disagreement_share"] =
      checked_ == 0 ? 0.0 : static_cast<double>(disagreeing_estimates_) / checked_;
  s.integrity.insert(s.integrity.end(), notes_.begin(), notes_.end());
  std::stable_sort(s.integrity.begin(), s.integrity.end(),
                   [](const IntegrityNote& a, const IntegrityNote& b) { return a.t < b.t; });
  if (disagreements_ > 0) {
    const char* what = options_.on_disagreement == GuardAction::kGrow
                           ? "their covariance was grown to cover dead reckoning"
                       : options_.on_disagreement == GuardAction::kFallback
                           ? "dead reckoning was emitted instead"
                           : "reported only";
    s.notes.push_back(fmt::format(
        "integrity: the estimate left dead reckoning's {:g} % region {} time(s); {:.1f} % of the "
        "agents' estimates were outside it ({})",
        100 * options_.leave_probability, disagreements_,
        100 * s.numbers["integrity.disagreement_share"], what));
  }
  return s;
}

std::optional<Mat2> DeadReckoningGuard::StepTransform(const std::string& agent) const {
  if (options_.on_disagreement == GuardAction::kFallback && Disagrees(agent)) return std::nullopt;
  return inner_->StepTransform(agent);
}

std::vector<SourceShare> DeadReckoningGuard::Sources(const std::string& node) const {
  if (options_.on_disagreement == GuardAction::kFallback && Disagrees(node))
    return {{"dead reckoning", 1.0}};
  return inner_->Sources(node);
}

}  // namespace trailmark::integrity

// SPDX-License-Identifier: MIT
#pragma once
/// The dead-reckoning shadow (issue 21, item 3): every steps-based pipeline is checked against
/// the dead reckoning of the same steps. The guard runs each agent's dead reckoning (the `pdr`
/// estimator; its covariance carries the start, heading-drift and scale errors shared by all
/// steps, here overbounded: GuardOptions::overbound) beside the pipeline's estimator. The truth
/// lies inside dead reckoning's region with its stated probability; an estimate of an agent
/// that leaves that region (its squared Mahalanobis distance from dead reckoning under the sum
/// of both covariances beyond the 2-dof chi-square quantile of `leave_probability`) disagrees
/// with it: one of the two is wrong, and the steps alone cannot say which. What the guard does
/// then (`on_disagreement`):
///  - grow (default): the estimate is kept and its covariance grows by a d d^T (d: from the
///    estimate to dead reckoning; a the least that puts dead reckoning inside the grown 95 %
///    ellipse, `grow_probability`), so that its ellipse covers both: the commander sees that
///    the position is in doubt instead of a small ellipse in the wrong place;
///  - fallback: dead reckoning is emitted instead, with its covariance (right when the
///    estimator is the one that is wrong; measured in docs/integrity.md: on our families dead
///    reckoning drifted beyond even its overbound more often, so this is not the default);
///  - report: the estimate is kept unchanged.
/// It lasts until the estimate is back inside the `return_probability` region. Each change is
/// an integrity note naming the agent, the time and the distance. An agent without a known
/// start (no dead reckoning possible) is passed through unchecked, and a note says so. No I/O.

#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "trailmark/core/mission.h"
#include "trailmark/core/online_estimator.h"
#include "trailmark/core/options.h"
#include "trailmark/ins/dead_reckoning.h"

namespace trailmark::integrity {

/// What the guard does while an estimate disagrees with dead reckoning.
enum class GuardAction { kGrow, kFallback, kReport };

struct GuardOptions {
  GuardAction on_disagreement = GuardAction::kGrow;
  /// The region an estimate must stay in: 2-dof chi-square probability (99.9 %: a consistent
  /// estimator's estimate leaves it one time in a thousand).
  double leave_probability = 0.999;
  /// Back to the estimator's own estimate inside this region (hysteresis: no flicker at the
  /// edge).
  double return_probability = 0.99;
  /// The shadow's errors shared by all steps (start heading, heading drift rate, heading walk,
  /// step scale: PdrOptions) are this many times the `pdr` defaults. The defaults describe a
  /// typical device; an integrity check must hold for a poor one too, so its region is an
  /// overbound, as in GNSS integrity monitoring (set a priori: 3, i.e. 15 deg at the start,
  /// 9 deg/min of drift, 9 % of scale).
  double overbound = 3.0;
  /// How far `grow` grows: by the least multiple of d d^T that puts dead reckoning on the
  /// boundary of the grown covariance's region of this probability (0.95: the 95 % ellipse
  /// just reaches it, the ellipse the commander sees and in95 counts); 0: by d d^T itself
  /// (dead reckoning within one sigma; before 2026-12-05). Measured on the robustness
  /// families (docs/integrity.md): the truth is inside the grown ellipses as often either
  /// way, and these are 2.4 times smaller.
  double grow_probability = 0.95;
  bool IsValid(std::string* why) const;
};

/// The `integrity.` keys of every steps-based pipeline.
const OptionTable<GuardOptions>& GuardOptionTable();

class DeadReckoningGuard : public OnlineEstimator {
 public:
  /// `typical`: the dead reckoning whose shared-error sigmas `overbound` multiplies.
  DeadReckoningGuard(MissionInfo info, GuardOptions options, std::unique_ptr<OnlineEstimator> inner,
                     const PdrOptions& typical = {});
  /// Steps also go to the shadow; every row goes to the inner estimator, whose estimates of
  /// agents are checked against the shadow before they reach `sink`.
  void Add(const MissionRow& row, EstimateSink& sink) override;
  void Finish(EstimateSink& sink) override;
  void UseLevels(const LevelSource* levels) override { inner_->UseLevels(levels); }
  /// Also the shadow's: a foot INS's dead reckoning has its own errors (PdrOptions::ForFootIns,
  /// overbounded as the typical device's).
  void StepsFromFootIns(const std::string& agent, bool foot_ins) override {
    shadow_.StepsFromFootIns(agent, foot_ins);
    inner_->StepsFromFootIns(agent, foot_ins);
  }
  /// The estimate the guard would emit for the node now.
  std::optional<Estimate> Current(const std::string& node) const override;
  /// The inner estimator's; dead reckoning alone while it stands in for a disagreeing
  /// estimate (on_disagreement=fallback).
  std::vector<SourceShare> Sources(const std::string& node) const override;
  /// The inner estimator's; none (the steps as they come) while dead reckoning stands in for
  /// a disagreeing estimate (on_disagreement=fallback).
  std::optional<Mat2> StepTransform(const std::string& agent) const override;
  /// The inner summary, and: integrity.disagreements (times an estimate left the region),
  /// integrity.disagreement_share (of the agents' estimates), the notes.
  EstimatorSummary Summary() const override;
  /// Whether the agent's estimate disagrees with its dead reckoning now.
  bool Disagrees(const std::string& agent) const;
  OnlineEstimator& inner() { return *inner_; }

 private:
  class Checked;
  struct Shadow {
    std::vector<Estimate> history;  ///< dead reckoning at its start and after each step
    bool disagrees = false;
  };
  /// What to emit for `estimate`; updates the agent's state when `record`.
  Estimate Check(const Estimate& estimate, bool record);
  /// The estimate as the guard emits it while it disagrees with dead reckoning `dr`.
  Estimate Act(const Estimate& estimate, const Estimate& dr) const;
  const Estimate* ShadowAt(const std::string& agent, TimeS t) const;

  GuardOptions options_;
  std::unique_ptr<OnlineEstimator> inner_;
  DeadReckoningEstimator shadow_;
  std::map<std::string, Shadow> agents_;
  std::set<std::string> unguarded_;
  double leave_d2_ = 0, return_d2_ = 0, grow_d2_ = 0;
  std::size_t disagreements_ = 0, disagreeing_estimates_ = 0, checked_ = 0;
  std::vector<IntegrityNote> notes_;
};

}  // namespace trailmark::integrity

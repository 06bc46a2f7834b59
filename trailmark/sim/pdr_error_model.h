// SPDX-License-Identifier: MIT
#pragma once
/// Errors of a foot-mounted PDR (zero-velocity-aided INS) on each step.
///
/// Heading error grows as a random walk per step plus a constant drift rate (the unobservable
/// yaw gyro bias of a ZUPT-aided INS: Foxlin 2005; Nilsson et al. 2014 "Foot-mounted inertial
/// navigation made easy" report heading as the dominant long-term error). Step length has a
/// per-walk scale error (0.3-3 % in Skog et al. 2010 / Nilsson et al. 2014) and per-step noise.
/// Defaults reproduce the uncorrected PDR of the breadcrumb paper (Fig. 9b: "more than 35 m"
/// after the 400 m walk) in order of magnitude; they are the simulator's, not a fitted model.

#include <optional>
#include <string>

#include "trailmark/core/random.h"
#include "trailmark/core/mission.h"
#include "trailmark/core/types.h"
#include "trailmark/sim/walker.h"

namespace trailmark {

struct PdrErrorOptions {
  double heading_random_walk_rad = 0.006;         ///< per step, 1 sigma (~0.23 deg)
  double heading_drift_sigma_rad_per_s = 0.002;   ///< per-walk drift rate, 1 sigma (~6.9 deg/min)
  std::optional<double> heading_drift_rad_per_s;  ///< fixed drift rate instead of a draw
  /// Per-walk gyro scale-factor error: every true turn adds this fraction of its angle to the
  /// heading error (MEMS gyro scale factor 1-3 %: e.g. ADIS16448 / MPU-9250 datasheets).
  double turn_scale_error_sigma = 0.05;
  double initial_heading_error_rad = 0.0;  ///< heading error at the start
  double scale_error_sigma = 0.02;         ///< per-walk step length scale error, 1 sigma
  double step_noise_m = 0.02;              ///< per-step, per-axis, 1 sigma
  /// Variance reported with each step: the per-step noise plus a heading term; the filter
  /// cannot know the drift, so it is not in the reported variance.
  double reported_heading_sigma_rad = 0.02;
  /// The gyro scale-factor error accrues on the walker's body rotation, which the model takes
  /// from the direction of each step. A step shorter than this moves the foot without saying
  /// where the body faces (edging round furniture, shuffling in a tight spot): its direction
  /// is not a turn, and the next longer step's turn is counted from the last longer step.
  /// Without it, a few 0.15 m steps in scattered directions at a cramped spot add up to
  /// hundreds of degrees of "rotation" the foot never made (wrapped direction changes do not
  /// cancel), and a 3 % scale error turns them into a heading jump of tens of degrees in
  /// seconds (docs/mapmatch.md). 0: every step turns (the other simulations).
  double turn_min_step_m = 0.0;
};

class PdrErrorModel {
 public:
  PdrErrorModel(const PdrErrorOptions& options, Random rng);

  /// The measured displacement for a true one of `delta_true_n` taking `dt_s` seconds.
  Vec2 Apply(const Vec2& delta_true_n, double dt_s);
  /// Per-axis variance (m^2) reported for a step of this length.
  double ReportedVariance(double step_length_m) const;

  double heading_error_rad() const { return heading_error_rad_; }
  double drift_rad_per_s() const { return drift_rad_per_s_; }
  double scale() const { return scale_; }
  double turn_scale() const { return turn_scale_; }

 private:
  PdrErrorOptions options_;
  Random rng_;
  double heading_error_rad_;
  double drift_rad_per_s_;
  double scale_;
  double turn_scale_;
  std::optional<double> last_true_heading_rad_;
};

/// The steps of `walk` as `pdr` measures them (with their reported variance) and its truth,
/// appended to `m` for `agent`.
void AppendPdrWalk(PdrErrorModel& pdr, const Walk& walk, const std::string& agent, MissionData& m);

}  // namespace trailmark

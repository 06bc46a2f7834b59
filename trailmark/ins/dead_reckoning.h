// SPDX-License-Identifier: MIT
#pragma once
/// Pedestrian dead reckoning: every agent starts at its `start` (or the single base, spec) and
/// adds its steps. The baseline every other estimator is compared with, and the `pdr`
/// estimator. No I/O.

#include <map>
#include <optional>
#include <set>
#include <string>

#include "trailmark/core/mission.h"
#include "trailmark/core/online_estimator.h"
#include "trailmark/core/options.h"

namespace trailmark {

struct PdrOptions {
  /// Per-axis sigma of a step that has no variance in steps.csv: a + b * length, i.e.
  /// (5 cm)^2 + (3 % of length)^2 of variance (ours: a consumer PDR's step noise).
  double default_step_noise_m = 0.05;
  double default_step_relative_sigma = 0.03;
  /// The errors of PDR that are not white (issue 21): they are shared by every step and make
  /// the position error grow with the distance walked and with time, also while standing. Each
  /// is a state of the covariance propagation (not of the estimate: nothing observes them).
  /// Set a priori, not fitted on any data here:
  /// heading error at the start when mission.json gives no start_heading_sigma (a heading
  /// aligned by hand or compass at the entrance: 5 degrees).
  double start_heading_sigma_rad = 0.087;
  /// The step stream's own heading offset from the walker's stated start heading, added to
  /// that heading's sigma in quadrature: mission.json states where the responder faced, not how
  /// the device that made the steps is aligned with the walking direction (a boot's toe-out, a
  /// phone's carrying mode). 5 degrees: the spread of the foot progression angle (toe-out) in
  /// gait studies, set before any run. 0: the steps' heading is exactly the stated one.
  double track_heading_offset_sigma_rad = 0.087;
  /// How that offset enters. false: a state of the error (its variance added to the start
  /// heading's). true: a consider parameter (Tapley, Schutz & Born 2004, sec. 6.3): not in the
  /// covariance a fix is weighed with (FusePosition, SetPosition, a clone's prior: the estimate
  /// is that of a dead reckoning without it), but in the reported covariance(), its sensitivity
  /// carried through every step and fix. Without fixes both give the same covariance; with
  /// fixes, a radio that the offset's prior would let rotate the walk cannot, and the ellipse
  /// still says what the offset leaves.
  bool track_heading_offset_considered = false;
  /// heading drift rate (gyro bias left after calibration; it integrates while standing too):
  /// 3 degrees per minute, the order of a consumer MEMS foot INS's yaw drift.
  double heading_drift_sigma_rad_per_s = 0.00087;
  /// heading random walk per step (turn and scale-factor errors): 0.5 degrees.
  double heading_walk_sigma_rad = 0.0087;
  /// step-length scale error shared by all steps of an agent: 3 %.
  double step_scale_sigma = 0.03;
  /// gyro scale-factor error shared by all turns of an agent: every turn of the walking
  /// direction by Delta (rad) adds k Delta to the heading error, so the error grows with the
  /// angle turned, not with the number of steps (four laps of a corridor loop turn 1,440 deg).
  /// 3 %: the sensitivity tolerance of a consumer MEMS gyro (MPU-9250 datasheet: +-3 %).
  double turn_scale_sigma = 0.03;
  /// A step shorter than this says nothing about where the body faces: its direction is not
  /// a turn (shuffling, zero-length steps while standing); the next longer step's turn is
  /// counted from the last longer step.
  double turn_min_step_m = 0.2;
  /// Steps of a foot INS (ins/zupt_ins.h; OnlineEstimator::StepsFromFootIns) err less than a
  /// phone's PDR, and in their own way (issue 24 item 2: the INS's own error, not a consumer
  /// PDR's): its gyro bias is estimated again at every stance (ZARU), its step lengths are
  /// integrated from the accelerometers between zero-velocity updates, and each step carries its
  /// filter's heading variance growth (Step::heading_var_rad2), which replaces the per-step
  /// heading walk. Set a priori, not fitted on any mission here:
  struct FootIns {
    /// The gyro bias left after the stance updates: 1 degree per minute (a third of the PDR's
    /// 3 deg/min; our INS's own filter settles at 0.4 deg/min with its default noises).
    double heading_drift_sigma_rad_per_s = 0.00029;
    /// Step length from the accelerometers' scale factor: 1 % (ZUPT-aided foot INS distance
    /// errors 0.3-1 % in the OpenShoe and PyShoe reports; our INS on the recorded footprint
    /// walks: 1.06 % of distance, heading included, README).
    double step_scale_sigma = 0.01;
    /// The gyro's scale factor over turns: 1 %, a calibrated MEMS unit (a foot-mounted
    /// research IMU; an uncalibrated consumer gyro's +-3 % is PdrOptions' own).
    double turn_scale_sigma = 0.01;
    /// false: a foot INS's steps are taken with the PDR's errors above (before 2026-12-07).
    bool own_errors = true;
  } foot_ins{};
  /// These options for steps of a foot INS: the shared errors' sigmas of `foot_ins` (the start
  /// heading and the track's offset unchanged: the INS aligns its yaw to the stated heading,
  /// the foot may point off it), no heading walk of its own (each step's heading_var_rad2).
  PdrOptions ForFootIns() const;
  /// The heading random walk's variance a step adds (rad^2): heading_walk_sigma_rad squared
  /// for a step that moves, or the step's own heading_var_rad2 where that is larger.
  double HeadingWalkVariance(const Step& step) const;
  /// The heading's sigma at the start: the stated one (else start_heading_sigma_rad) with the
  /// track's own offset, in quadrature.
  double StartHeadingSigma(std::optional<double> stated_rad) const;
  /// A poorer device: the shared errors' sigmas (start heading, drift rate, heading walk, step
  /// and turn scale; a foot INS's too) times `factor` (> 0); the step noise and the track's
  /// offset unchanged.
  PdrOptions SharedErrorsScaled(double factor) const;
  bool IsValid(std::string* why) const;
};

/// What the shared errors of a dead reckoning act on between two steps of an agent: the time
/// since its last step (none at the first; standing included) and the turn of its walking
/// direction since the last step of at least `turn_min_step_m` (shorter ones say nothing of
/// where the body faces). DeadReckoning counts with it, and so does the map matcher's particle
/// model of a foot INS (mapmatch/), so that both see the same turns.
class StepTurnCounter {
 public:
  struct Since {
    double dt_s = 0.0;
    double turn_rad = 0.0;
  };
  /// The step's time and turn since the last one; remembers it.
  Since Next(const Step& step, double turn_min_step_m);

 private:
  std::optional<TimeS> last_t_;
  std::optional<double> last_direction_rad_;  ///< of the last step >= turn_min_step_m
};

/// Dead reckoning of one agent, usable without files. The position is the sum of the steps;
/// its covariance propagates the error state [dx, dy, d_heading, d_heading_rate, d_scale,
/// d_turn_scale]: a step d turns by the heading error (lever (-d_y, d_x)) and stretches by the
/// scale error, the heading error grows by the rate error x time between steps (standing
/// included) and by the turn-scale error x the angle the walking direction turned.
class DeadReckoning {
 public:
  /// `start_heading_sigma_rad`: empty takes the options' default.
  DeadReckoning(const Vec3& start_n, double start_sigma_m, const PdrOptions& options = {},
                std::optional<double> start_heading_sigma_rad = std::nullopt);
  /// Adds one step's displacement and its variance.
  void AddStep(const Step& step);
  /// A position fix (e.g. from landmarks whose map was itself built from this dead reckoning)
  /// of unknown correlation with the estimate: covariance intersection (Julier & Uhlmann 1997),
  /// omega minimizing the trace of the fused position covariance, written as a Kalman
  /// update of the inflated prior P / omega with the inflated fix R / (1 - omega); a Schmidt
  /// update (the heading, drift-rate and scale errors are not estimated, only their
  /// covariance is updated, Joseph form). Consistent whatever the correlation, if both are.
  /// Returns omega (1: the fix was not used). Throws std::invalid_argument for a fix that is not
  /// finite or a covariance that is not symmetric positive definite (nothing changes then).
  double FusePosition(const Vec2& fix_n, const Mat2& fix_cov);
  /// The position and its covariance replaced (a fix taken whole, e.g. the paper's stop-and-go
  /// update): the shared heading, drift-rate and scale errors keep their covariance, their
  /// correlation with the new position error is dropped (the fix's error is not the dead
  /// reckoning's). `cov` excludes the considered offset; `offset_kept` is what the new position
  /// error keeps of the old one's sensitivity to it (zero: the fix is independent of the walk;
  /// I - K for an update with gain K). Throws std::invalid_argument as FusePosition does.
  void SetPosition(const Vec2& position_n, const Mat2& cov, const Mat2& offset_kept = Mat2::Zero());
  /// An extra heading error of this variance (rad^2) from now on, independent of every other
  /// error: e.g. a reversal whose turn's sign the steps do not tell, so that its share of the
  /// turn-scale error is not known either. Not a step: DeadReckoningClones do not see it.
  void AddHeadingVariance(double variance_rad2);
  /// The error covariance [dx, dy, d_heading, d_heading_rate, d_scale, d_turn_scale].
  static constexpr int kErrors = 6;
  using ErrorCovariance = Eigen::Matrix<double, kErrors, kErrors>;
  const ErrorCovariance& error_covariance() const { return error_cov_; }
  /// The shared (not white) errors: heading, rate, step scale and turn scale.
  static constexpr int kSharedErrors = 4;
  const Vec3& position_n() const { return position_n_; }
  /// The position's covariance as reported: own_covariance() and, if the offset is considered,
  /// sigma^2 s s^T with s = offset_sensitivity().
  Mat2 covariance() const;
  /// The position block of error_covariance(): what a fix is weighed with.
  Mat2 own_covariance() const { return error_cov_.topLeftCorner<2, 2>(); }
  /// The considered offset's sigma (rad; 0 when it is a state or none) and the error state's
  /// sensitivity to it (d error / d offset; zero when not considered).
  double considered_offset_sigma_rad() const { return considered_sigma_rad_; }
  const Eigen::Matrix<double, kErrors, 1>& offset_sensitivity() const { return offset_sens_; }
  /// The last step's error transition: the error after it is this times the error before it,
  /// plus the step's own noise (identity before the first step). What a caller needs to carry
  /// the correlation of an earlier error with the current one (DeadReckoningClones).
  const ErrorCovariance& last_transition() const { return last_transition_; }

 private:
  using Mat6 = ErrorCovariance;
  enum : int { kX = 0, kY = 1, kHeading = 2, kRate = 3, kScale = 4, kTurnScale = 5 };
  PdrOptions options_;
  Vec3 position_n_;
  Mat6 error_cov_;
  Mat6 last_transition_ = Mat6::Identity();
  double considered_sigma_rad_ = 0.0;
  Eigen::Matrix<double, kErrors, 1> offset_sens_ = Eigen::Matrix<double, kErrors, 1>::Zero();
  StepTurnCounter turns_;
};

/// The covariance, about the dead reckoning, of a walk turned about its start by an unknown
/// angle (uniform on the circle): a foot INS's walk when mission.json states no start_heading
/// (the INS's yaw starts at 0 in a frame nobody aligned). With d the walk's displacement from
/// the start and R the unknown rotation, the error R d - d has E[R] = 0, so its second moment
/// is |d|^2 / 2 I + d d^T; every point of the circle the truth lies on is inside its 95 %
/// ellipse (Mahalanobis^2 at most 3, against 5.99). A linear heading sigma cannot say this.
Mat2 UnknownHeadingCovariance(const Vec2& displacement_n);

/// `pdr`: each agent's dead reckoning, an estimate at every step (and its start at the first
/// step's t0). A foot INS's agent whose start_heading mission.json does not state walks in the
/// INS's own frame: its covariance carries UnknownHeadingCovariance instead of a start heading
/// sigma (steps.csv's are in the navigation frame by the spec: the stated or default sigma). Agents
/// are independent: each agent's steps in time order is all it needs.
class DeadReckoningEstimator : public OnlineEstimator {
 public:
  explicit DeadReckoningEstimator(MissionInfo info, PdrOptions options = {});
  /// Steps; other rows are counted and ignored. Throws std::invalid_argument for steps of a
  /// node that is not an agent, or of an agent without a start (none in the mission and no
  /// single base).
  void Add(const MissionRow& row, EstimateSink& sink) override;
  void Finish(EstimateSink&) override {}
  /// An agent whose steps come from a foot INS gets PdrOptions::ForFootIns (unless
  /// `foot_ins.own_errors` is off, or its first step carries no heading variance: an INS outside
  /// its noise model, ZuptIns::OwnErrorsHold).
  void StepsFromFootIns(const std::string& agent, bool foot_ins) override {
    if (foot_ins) foot_ins_.insert(agent);
  }
  std::optional<Estimate> Current(const std::string& node) const override;
  EstimatorSummary Summary() const override;

 private:
  struct Agent {
    DeadReckoning dr;
    TimeS t = 0;
    std::size_t steps = 0;
    /// A foot INS without a stated heading, or whose mounting was not found (its steps stop
    /// carrying the INS's heading variance after the first did: MultiAgentIns::MountNotFound).
    std::optional<Vec2> unknown_heading_start;
    bool own_errors = false;  ///< started with the foot INS's own errors
  };
  /// The agent's estimate now (its covariance with the unknown heading's, if any).
  Estimate EstimateOf(const std::string& id, const Agent& a, TimeS t) const;
  MissionInfo info_;
  PdrOptions options_;
  std::map<std::string, Agent> agents_;
  std::set<std::string> foot_ins_;  ///< agents whose steps come from a foot INS
  std::set<std::string> unknown_heading_;  ///< of those, without a stated start heading
  std::set<std::string> mount_not_found_;  ///< of those, their IMU's mounting not found
  std::size_t steps_ = 0, ignored_ = 0;
};

}  // namespace trailmark

// SPDX-License-Identifier: MIT
#pragma once
/// How a foot IMU is mounted about the vertical, from its own strides. The mission format says
/// only that imu.csv is in the IMU's body frame; the INS starts its yaw at the stated start
/// heading, which puts the IMU's forward axis along it. An IMU mounted with another axis forward
/// (a unit strapped sideways, an axis convention with y forward) turns the whole walk by that
/// angle, and a boot's toe-out by a few degrees (measured: a 90-degree mount, 41 m p75 on the
/// landmark office). A walker walks forward: each stride, taken between two landings of the foot,
/// points the same way relative to the foot, whatever the walk's turns. So the angle between a
/// stride and a body-fixed horizontal reference — the body vector along the stated heading at the
/// start — is the same at every straight stride, and its median over the first ones is the turn
/// that brings the walk onto the stated heading. No I/O.

#include <Eigen/Geometry>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "trailmark/core/types.h"

namespace trailmark::ins {

struct MountYawOptions {
  /// Straight strides to decide on (0: off, the IMU's forward axis is taken as the foot's). 3:
  /// decided within the first metres (the steps before it are in the INS's frame and made up
  /// after), their median rejects one taken sideways; more are counted while they disagree.
  int strides = 3;
  /// A stride shorter than this (m, horizontal) says little about its direction: not counted.
  double min_stride_m = 0.3;
  /// A stride over which the foot turned more than this (rad, 10 deg) is a turn, not counted: the
  /// foot turns in the air and the stride is the chord of the turn.
  double max_turn_rad = 0.17;
  /// A stride further than this from the strides' median is not walking forward (a side step);
  /// decided when three in four lie within it (all of the first three), else keep counting (rad,
  /// 15 deg; side steps, crawling and zig-zags never decide).
  double max_spread_rad = 0.26;
  /// Landings after which it decides with what it has (a walk that never settles): the median if
  /// the spread holds, else no turn and a note.
  int max_landings = 40;
  /// A correction smaller than this is not applied (rad, 1 deg): not worth turning the walk for.
  double min_turn_rad = 0.0175;
  /// A straight stride further than this from the reference before it is decided (rad, 15 deg:
  /// beyond a boot's toe-out) says the IMU is mounted turned: the INS's steps and states wait
  /// until it is decided (at most a few strides), so that no consumer walks into walls sideways.
  /// Within it nothing waits (a mounting within a few degrees costs little until it is decided).
  double hold_above_rad = 0.26;
  /// From the first step on, the INS's steps and states wait until it is decided, for at most
  /// this many landings (then they go out as they are and the decision's catch-up follows):
  /// steps given out in the INS's frame are where consumers drop beacons and crumbs, metres
  /// off after a turn or two at the start (0: only a stride beyond hold_above_rad holds). 0 for
  /// `ins` (its own output places nothing; waiting is only latency), 12 for the steps of every
  /// other pipeline (StepFrontEndOptions).
  int hold_first_landings = 0;
  /// Turning strides as bounds (0: off, the default since session 45: they hold for a foot that
  /// lands along its stride and for an arc, not for one that lands turned toward its next stride,
  /// see gait_min_strides). A stride over which the foot turned by tau lies, for those gaits,
  /// between the foot's heading at lift-off and at landing: a circular arc's chord along
  /// their mean (the median above takes that), a foot that turns as it lifts along the landing
  /// one. So its angle from the reference at lift-off and at landing bound the mounting, widened
  /// by `interval_margin_rad` each way (the stride's own scatter). Strides that turned up to this
  /// (rad, 90 deg) give such a bound; a search walk that turns at every stride (house searches
  /// counted 3 straight strides in 13-34 landings) then decides in a few. Decided by the bounds
  /// when at least `interval_min_strides` of them, three in four of all, share one stretch no
  /// wider than a straight stride's bounds (2 margins + max_turn_rad: a walk circling one way
  /// shares one as wide as its turns), and its centre is a turn worth taking (beyond 3 sigma,
  /// sigma its width over 2 sqrt 3) that leaves zero outside the stretch; a mounting about the
  /// foot's waits for the straight strides' median.
  double interval_max_turn_rad = 0.0;
  double interval_margin_rad = 0.087;
  int interval_min_strides = 4;
  /// The gait's regression (ours, the default; supersedes the bounds above, off since session
  /// 45). A foot lands turned toward where it goes next, by a gait's share of the next stride's
  /// turn (the recorded figure-8: about two thirds), and a stride's chord follows the foot's own
  /// turn by another share (an arc's chord: half of it). So each stride's angle from the
  /// reference at landing is alpha_k = mu - a dnext_k - b tau_k, mu the mounting's angle, dnext_k
  /// the turn of the next stride's chord (the INS frame's: independent of the mounting), tau_k
  /// the foot's turn over the stride. mu, a, b by Huber-weighted least squares (weak priors a, b ~
  /// N(0, 10^2): a straight walk gives the mean), over every stride of at least `min_stride_m`
  /// whose turns are within `gait_max_turn_rad`; decided with at least `gait_min_strides` of them,
  /// three in four within `max_spread_rad` of the fit, once mu's standard error (the residuals'
  /// robust scale, at least `gait_noise_floor_rad`) is at most `gait_max_sigma_rad`. A pivot on the
  /// standing foot (a = b = 0: the bounds' gait), a foot that anticipates its next stride, and an
  /// arc all fit; the `imu` family's house searches drawn with each (0-0.5 of the next turn)
  /// within 0.5 deg, the recorded figure-8 within 0.3-0.8 deg of its straight strides' median
  /// (docs/ins.md). 0 strides: off.
  int gait_min_strides = 6;
  double gait_max_turn_rad = 1.5708;
  double gait_max_sigma_rad = 0.035;
  double gait_noise_floor_rad = 0.0087;
  /// That hold ends sooner at a straight stride within this of the reference (rad, 5 deg: a
  /// mounting about the foot's, the common case; the decision's catch-up makes up the rest), so
  /// that only a turned IMU keeps everyone's rows waiting (the step consumers need global time
  /// order: a hold holds every agent's rows).
  double hold_first_release_rad = 0.087;
  bool IsValid(std::string* why) const;
};

class MountYawEstimator {
 public:
  /// `stated_heading_rad`: where the INS's yaw was started (the mission's start heading).
  MountYawEstimator(MountYawOptions options, double stated_heading_rad);
  /// The attitude at the INS's first state: fixes the body-frame reference (the body vector
  /// along the stated heading then).
  void Start(const Eigen::Quaterniond& q_nb);
  /// The foot landed: at rest at `position_n` with attitude `q_nb`. Decides when enough strides
  /// agree (Decided()).
  void AddLanding(const Vec3& position_n, const Eigen::Quaterniond& q_nb);
  /// End of data: decides with what there is (at least 3 strides within the spread), else no
  /// turn.
  void Settle();
  bool Decided() const { return decided_; }
  /// Settled without strides that agree (Note() says why): the walk's turn is unknown.
  bool NotFound() const { return decided_ && !note_.empty(); }
  /// The turn (rad, about the vertical) that takes the INS's frame to the stated one: minus the
  /// strides' median angle from the reference. 0 until decided and when undecidable.
  double CorrectionRad() const { return correction_rad_; }
  /// The correction if it is worth a turn (beyond 3 standard errors and `min_turn_rad`), else 0:
  /// a mounting within a degree of the foot's is left as it is (no jump for nothing).
  double TurnWorthTakingRad() const;
  /// Its standard error: the standard deviation of the strides within the spread over the root
  /// of their number (0 without).
  double SigmaRad() const { return sigma_rad_; }
  /// The strides counted so far, and the angle of the last one from the reference (rad).
  std::size_t Strides() const { return angles_rad_.size(); }
  /// Decided by the strides' bounds (turning strides included), not the straight ones' median.
  bool DecidedByBounds() const { return by_bounds_; }
  /// Decided by the gait's regression (every stride), not the straight ones' median.
  bool DecidedByGait() const { return by_gait_; }
  /// The regression's gait shares (a: toward the next stride, b: the chord's share of the
  /// foot's turn) when decided by it.
  std::pair<double, double> GaitShares() const { return gait_shares_; }
  int Landings() const { return landings_; }
  std::optional<double> LastStrideRad() const {
    return angles_rad_.empty() ? std::nullopt : std::optional<double>(angles_rad_.back());
  }
  /// Why no turn was applied, if one could not be decided (empty otherwise).
  const std::string& Note() const { return note_; }

 private:
  /// Decides if the strides so far agree (or `force`: with at least 3 that do).
  void TryDecide(bool force);
  /// Decides if the strides' bounds (turning strides included) share one stretch away from zero.
  void TryDecideByBounds();
  /// Decides by the gait's regression if it is sure enough (gait_max_sigma_rad).
  void TryDecideByGait();
  double HeadingOf(const Eigen::Quaterniond& q_nb) const;

  MountYawOptions options_;
  double stated_heading_rad_;
  std::optional<Vec3> reference_b_;  ///< body vector along the stated heading at the start
  std::optional<Vec3> last_landing_n_;
  double last_heading_rad_ = 0;
  int landings_ = 0;
  std::vector<double> angles_rad_;  ///< each stride's angle from the reference, unwrapped
  /// Each stride's bounds on the mounting's angle (lift-off and landing, widened), unwrapped.
  std::vector<std::pair<double, double>> bounds_rad_;
  std::optional<double> unwrap_anchor_rad_;  ///< the first stride's angle: every angle near it
  /// The gait regression's rows (alpha_k, dnext_k, tau_k) and the last stride's, waiting for the
  /// next chord.
  struct GaitRow {
    double alpha_rad = 0, next_turn_rad = 0, foot_turn_rad = 0;
  };
  std::vector<GaitRow> gait_rows_;
  struct GaitPending {
    double chord_rad = 0, alpha_rad = 0, foot_turn_rad = 0;
  };
  std::optional<GaitPending> gait_pending_;
  std::optional<double> last_chord_rad_;  ///< the last stride's chord (of min_stride_m or more)
  std::optional<double> straight_pending_rad_;  ///< a straight stride's angle, until the next
  std::optional<double> gait_anchor_rad_;
  std::pair<double, double> gait_shares_{0.0, 0.0};
  bool decided_ = false, by_bounds_ = false, by_gait_ = false;
  double correction_rad_ = 0, sigma_rad_ = 0;
  std::string note_;
};

}  // namespace trailmark::ins

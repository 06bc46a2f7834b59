// SPDX-License-Identifier: MIT
#pragma once
/// The ultrasound-beacons paper's estimators as one online estimator over an incident:
///  - the beacon map (beacon_map.h) from beacon-to-beacon ultrasound ranges, by MDS with
///    shortest-path completion and SMACOF, anchored online to surveyed beacons or to where the
///    responder's estimate dropped each beacon (`beacons-mds` reports the beacons only);
///  - the responder tracked by the SCAAT EKF (u, v, psi, scale; scaat_ekf.h) on PDR steps and
///    every ultrasound range/bearing between a beacon and the agent (`beacons-ekf`), or by the
///    paper's ultrasound-only Kalman filter (filter us-only). Agents without a start are
///    initialized from their first ultrasound measurements (InitializeFromUltrasound);
///  - the way back out (sec. 4): the beacons heard last, the route by the smallest-id rule.
/// Beacons: every crumb, and every landmark or base that appears in an ultrasound range; their
/// deployment order is the order of the drop events, else of mission.json. Needs every row in
/// global time order (the registry feeds it through a StepFrontEnd). No I/O.

#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "trailmark/beacons/beacon_map.h"
#include "trailmark/beacons/scaat_ekf.h"
#include "trailmark/core/mission.h"
#include "trailmark/core/online_estimator.h"
#include "trailmark/core/options.h"
#include "trailmark/ins/dead_reckoning.h"
#include "trailmark/integrity/consistency.h"
#include "trailmark/integrity/dead_reckoning_first.h"

namespace trailmark::beacons {

/// How agents are tracked: not at all (the map only: `beacons-mds`), by the SCAAT EKF, or by
/// the paper's ultrasound-only Kalman filter.
enum class Tracker { kNone, kScaat, kUltrasoundOnly };
/// How a range + bearing pair updates the EKF: as two scalar updates (ours), or converted to a
/// position fix (the paper's).
enum class UpdateMode { kRangeBearing, kPosition };

struct BeaconTrailOptions {
  Tracker tracker = Tracker::kScaat;
  UpdateMode update = UpdateMode::kRangeBearing;
  bool init_from_ultrasound = false;  ///< ignore mission starts: initialize from ultrasound
  double mds_period_s = 2.0;          ///< s; the map is re-solved at most this often
  /// s; the map solved at a tick is put in place this much mission time later, solved on a
  /// worker thread meanwhile (ours, issue 20: a live incident's rows and estimates are not held
  /// up by the solve; BeaconMap::BeginSolve). Deterministic: batch and live give the same map.
  /// 0: solved and put in place at its tick, on the estimator's thread. At most mds_period_s
  /// (a longer lag is taken as mds_period_s).
  double map_lag_s = 0.0;
  double drop_sigma_m = 0.3;   ///< m; where a dropped beacon lands around the dropper's estimate
  /// A drop is placed where the dropper was at the drop's time: within the step that spans it
  /// (steps arrive at their end), for the map's drop prior and the tracker's consider state
  /// alike (ours, issue 22). false: at the last step's end before the drop, up to a step
  /// behind along the walk (the map's beacons lagged the trail by 0.2 m on average).
  bool drop_within_step = true;
  /// The drop priors of agents with a start come from their own dead reckoning (rotated by
  /// the entry-heading fix), with its covariance of shared errors (heading, drift rate, scale):
  /// not from the tracker, whose estimate is built on the map (issue 22). Set a priori. The
  /// track's own heading offset is entry_track_heading_sigma_rad's here.
  PdrOptions drop_dead_reckoning{.track_heading_offset_sigma_rad = 0.0};
  double entry_track_m = 1.0;  ///< m; PDR track compared with the entry heading (0: never)
  /// An agent with a start but no start_heading: the rotation of its PDR into the navigation
  /// frame is estimated from its first ultrasound measurements of placed beacons, the start as
  /// a prior (issue 22; the spec: a pipeline estimates what is absent or says so); until then
  /// its position is the start within the distance walked, its drops wait for their priors.
  /// false: its PDR frame is taken as the navigation frame within
  /// drop_dead_reckoning.start_heading_sigma_rad.
  bool estimate_entry_heading = true;
  /// m walked without a heading estimate (no surveyed beacon heard): then the PDR's frame is
  /// taken as the navigation frame after all, and the summary says so. Estimated only where
  /// mission.json surveys a node more than 2 m from the start (else taken at once).
  double entry_heading_fallback_m = 30.0;
  double close_pass_m = 1.5;   ///< m; a beacon with no drop event is anchored at a range this short
  /// Such a close pass anchors the beacon as a drop would (2026-12-06): on the passer's
  /// dead-reckoning track in the map (its shared errors solved with the links) and as a consider
  /// state of the passer's tracker. false: at the tracker's estimate as an independent prior
  /// (before; the tracker follows the map, so each pass anchored the map where the map had put
  /// it, and the ellipses held the truth 62-65 % of the time on variants without drop events).
  bool close_pass_on_track = true;
  /// An agent's ranges to beacons from its dead-reckoning track go into the map (issue 22,
  /// item 1; BeaconMap::AddSighting, `map.sightings`): an agent walking back past beacons it
  /// dropped long before, or hearing them across a U-shaped trail, closes the loop that
  /// neighbour-only beacon links leave open. A range counts when the agent has walked
  /// `sighting_loop_m` since it dropped or passed that beacon (a range to a beacon just dropped
  /// says what the drop prior and the links say) or the beacon is another's or surveyed, at
  /// most one per beacon per `sighting_spacing_m` walked. Set a priori: a few beacon spacings,
  /// and the length over which the dead reckoning's white errors decorrelate.
  double sighting_loop_m = 10.0;
  double sighting_spacing_m = 2.0;
  /// The gyro's turn-scale error (drop_dead_reckoning.turn_scale_sigma) is a shared error of
  /// each track in the map, with the other three (2026-12-06): every turn adds its share to the
  /// heading of the walk after it (a search that has turned 5 rad at 3 % is 9 deg off), which
  /// no heading offset, rate or scale explains. false: left out (before; held at a negligible
  /// prior). docs/beacons.md.
  bool map_turn_scale = true;
  /// rad; a turn between two steps larger than this is a reversal whose sign the steps do not
  /// tell (the gyro knew): left out of the turn-scale lever, its share of the turn-scale error
  /// a heading error of its own (a wrong guess would turn the lever by 2 pi).
  double map_turn_ambiguous_rad = 2.5;
  /// Dead-reckoning drift of the drop hints without a tracker: 1 sigma per metre (ours: 5 %).
  double pdr_drift_per_m = 0.05;
  /// PDR direction noise over the entry track, added to the start heading's own sigma.
  double entry_track_heading_sigma_rad = 0.05;
  double default_entry_heading_sigma_rad = 0.05;  ///< a start_heading without its sigma
  double way_out_window_s = 3.0;  ///< s; beacons heard this recently start the way out
  /// s; SCAAT EKF: a measurement waits for the step that spans its time (steps arrive at their
  /// end) and is applied where the foot was then, the step split at that instant; with no step
  /// within this hold the node was standing and it is applied where the node stands. 0: each
  /// measurement at the last step's position at once (the node's motion since then ignored).
  double measurement_hold_s = 1.5;
  /// With a hold: between steps, each measurement's arrival also emits the position ahead of the
  /// last step end by the last step's velocity (at most one step's duration), its covariance
  /// grown by `extrapolation_speed_sigma` x that speed x the time ahead per axis (walking on,
  /// slowing, stopping): what is known online then. false: the last step's estimate only.
  /// Off by default since 2026-12-07: the step front end's view between rows (view_period_s,
  /// ins/step_front_end.h) is this model for every steps-based pipeline, with this tracker's
  /// StepTransform; on with it, the view would move on from a row already ahead.
  bool extrapolate = false;
  double extrapolation_speed_sigma = 0.5;
  /// s; with `extrapolate` and a hold: an agent's estimate is never older than this when the
  /// next row comes (ours, issue 22): before a row at t, every `output_period_s` after the
  /// agent's last estimate and before t gets the extrapolated one (steps-only missions give the
  /// estimator rows at ~3 Hz; a view held for 0.3 s of walking was outside its own ellipse).
  /// Deterministic in the rows, so live = batch; each from the rows before it only. 0: at steps
  /// and measurements only (as before 2026-12-03). 0.1: a 10 Hz display (a priori).
  double output_period_s = 0.0;
  ScaatEkfOptions ekf;
  UltrasoundOnlyKfOptions us_kf;
  BeaconMapOptions map;
  InitOptions init;
  /// SCAAT EKF: each beacon's ranges and bearings checked against their stated noise (issue
  /// 21); an inconsistent beacon (moved, offset, its NLOS) is left out until it agrees again.
  integrity::ConsistencyOptions integrity;
  /// SCAAT EKF (ours, issues 21 and 22: never worse than dead reckoning): an agent on a foot INS
  /// within its noise model, with a start and a stated heading, is written as its dead reckoning
  /// (`pdr`'s estimate of the same steps) while that is inside the filter's own 99 % region, the
  /// filter's estimate beyond 99.99 %, a blend between (integrity/dead_reckoning_first.h; the
  /// landmark tracker's `dr_first`, docs/landmarks.md). Measured on the `imu` family: the filter
  /// at its ranges' resolution pulled a good INS's walk (docs/robustness.md).
  bool dr_first = true;
  integrity::DeadReckoningFirstOptions dr_test;
  bool IsValid(std::string* why) const;
  /// Whether the agents' starts of mission.json are used (not with init=ultrasound): the
  /// dead-reckoning guard (integrity/) only checks estimators that trust the same start.
  bool UsesMissionStart() const { return !init_from_ultrasound; }
};
/// `beacons-mds`: the map's keys (beacons, refine, entry_track_m, mds_period_s).
const OptionTable<BeaconTrailOptions>& BeaconMapOptionTable();
/// `beacons-ekf`: the map's keys and the tracker's (filter, update, init, sigmas, gate).
const OptionTable<BeaconTrailOptions>& BeaconTrackerOptionTable();

/// The way back out for one agent at a time: the beacons heard in the last window, the route
/// by the smallest-id rule, and where each beacon of it is (when placed).
struct WayOutReport {
  std::vector<std::string> heard;
  std::vector<std::string> route;     ///< beacon ids to follow, ending at the entry beacon
  std::optional<std::string> broken;  ///< why the route does not reach the entry
  std::vector<std::optional<Vec2>> route_positions_n;
};

class BeaconTrailEstimator : public OnlineEstimator {
 public:
  BeaconTrailEstimator(const MissionInfo& info, BeaconTrailOptions options);
  /// Rows in global time order: drop events, steps, ultrasound ranges (beacon-beacon and
  /// beacon-agent) and bearings (beacon to agent); others are counted and ignored. Throws
  /// std::invalid_argument for steps of a node that is not an agent.
  void Add(const MissionRow& row, EstimateSink& sink) override;
  /// The pending ranges, a last map solve, the beacons' final estimates.
  void Finish(EstimateSink& sink) override;
  std::optional<Estimate> Current(const std::string& node) const override;
  /// The SCAAT EKF's scale x R(psi): how it moves the agent's steps.
  std::optional<Mat2> StepTransform(const std::string& agent) const override;
  /// An agent on a foot INS's steps: no entry-heading measurement from its first metre (the INS
  /// aligned its yaw to the stated heading and finds its mounting from its strides, ins/
  /// mount_yaw.h; the steps before that decision are not in the stated frame). Its heading gets
  /// the stated sigma at once, as an entry heading of zero.
  void StepsFromFootIns(const std::string& agent, bool foot_ins) override {
    if (foot_ins) foot_ins_.insert(agent);
  }
  EstimatorSummary Summary() const override;
  /// The way out of `agent` at time `at_s` from the map as it is now.
  WayOutReport WayOut(const std::string& agent, TimeS at_s, double window_s) const;
  const BeaconMap& map() const { return map_; }
  /// The time of the latest row.
  TimeS last_t() const { return last_t_; }

 private:
  struct PendingRange {
    TimeS t;
    std::string agent;
    int beacon;
    double range_m, sigma_m;
  };
  struct Deferred {
    TimeS t;
    int beacon;
    std::optional<PendingRange> range;
    std::optional<double> bearing;
    double bearing_sigma;
    std::string dropped;  ///< not empty: the agent dropped this beacon at t (consider state)
    double drop_sigma_m = 0;  ///< with `dropped`: within this of the agent (0: drop_sigma_m)
  };
  /// The drop priors' dead reckoning at one instant: position, white covariance, lever arms.
  struct DropDeadReckoningState {
    Vec2 position_n = Vec2::Zero();
    Mat2 white = Mat2::Zero();
    Vec2 sum_d_n = Vec2::Zero(), sum_t_perp_n = Vec2::Zero(), sum_turn_perp_n = Vec2::Zero();
    /// The white covariance of [x, y, heading] (the sightings' chains), and that of the walk
    /// since the last sighting alone.
    Mat3 white3 = Mat3::Zero(), segment3 = Mat3::Zero();
    /// d position / d e (MapPrior::along).
    TrackLever Lever() const;
  };
  struct Agent {
    std::string id;
    std::vector<Deferred> deferred;  ///< measurements waiting for their step
    TimeS step_t0 = 0, step_t1 = -std::numeric_limits<double>::infinity();  ///< the last step
    Vec2 step_velocity_n = Vec2::Zero();  ///< of the last step, in the navigation frame
    Vec2 pdr_n = Vec2::Zero();  ///< dead reckoning (from the start, or from the init buffer)
    double pdr_var_m2 = 0.01;
    bool has_start = false;
    std::optional<ScaatEkf> ekf;
    /// dr_first: decided at the agent's first step; its foot INS's dead reckoning and the
    /// filter's verdict on it.
    bool dr_first_decided = false;
    bool range_scale_flagged = false;  ///< its ranges' scale contradicts the stated sigma
    std::optional<DeadReckoning> own_dr;
    std::optional<integrity::DeadReckoningFirst> dr_first;
    std::optional<UltrasoundOnlyKf> us_kf;
    std::vector<InitMeasurement> init_buffer;
    std::string init_why;
    TimeS initialized_at = 0;
    TimeS t = 0;                 ///< of the latest estimate
    std::map<int, TimeS> heard;  ///< beacon -> last time heard
    // Entry heading (mission.json start_heading): the PDR's direction over its first metre is
    // compared with it once, which fixes the PDR heading offset in the navigation frame.
    std::optional<double> entry_heading_rad;
    double entry_heading_sigma_rad = 0.05;
    Vec2 first_track_n = Vec2::Zero();
    /// The steps and the drops (time, beacon id) of that first track: at the fix the drop
    /// priors' dead reckoning is run again over them turned by it (ReplayFirstTrack).
    std::vector<Step> first_track_steps;
    std::vector<std::pair<TimeS, std::string>> first_track_drops;
    bool heading_fixed = false;
    Vec2 start_n = Vec2::Zero();
    double pdr_rotation_rad = 0;  ///< applied to the dead reckoning of the map-only mode
    /// Dead reckoning for the drop priors (agents with a start), rotated by the entry fix: its
    /// white errors (step noise, heading walk) here, its shared ones as the map's track
    /// `map_track` with the lever arms below (MapPrior::along).
    std::optional<DeadReckoning> drop_dr;
    /// The same white dead reckoning from the last sighting on, from no error there: the
    /// covariance of the walk between two sightings (MapSighting).
    std::optional<DeadReckoning> segment_dr;
    double drop_dr_rotation_rad = 0;
    int map_track = -1;
    std::optional<TimeS> first_step_t;
    // No start_heading (options.estimate_entry_heading): the PDR's rotation into the
    // navigation frame, estimated from the first ultrasound measurements with the start as a
    // prior (heading_fixed once done); the steps and drops until then, replayed for the drop
    // priors.
    bool heading_unknown = false;
    double start_sigma_m = 0.1;
    double walked_m = 0;
    std::vector<Step> steps_before_fix;
    std::vector<std::pair<TimeS, int>> drops_before_fix;
    double estimated_heading_rad = 0, estimated_heading_sigma_rad = 0;
    bool heading_assumed = false;  ///< fixed by the fallback, not estimated
    /// No start heading and none estimated or assumed yet.
    bool AwaitingHeading() const { return heading_unknown && !heading_fixed; }
    Vec2 sum_d_n = Vec2::Zero(), sum_t_perp_n = Vec2::Zero(), sum_turn_perp_n = Vec2::Zero();
    /// The walking direction's turn since the first step (DeadReckoning's turn-scale model).
    double turned_rad = 0;
    std::optional<double> last_direction_rad;
    int last_drop = -1;                      ///< beacon of the previous drop
    /// Drops waiting for the step that spans them (drop_within_step): time, beacon.
    std::vector<std::pair<TimeS, std::string>> pending_drops;
    /// Ranges waiting for the step that spans them to become the map's sightings.
    std::vector<PendingRange> pending_sightings;
    /// Walked (walked_m) when each beacon was dropped or passed by this agent, and when it was
    /// last a sighting of it.
    std::map<int, double> walked_at_drop, walked_at_sighting;
    Mat2 last_drop_white_cov = Mat2::Zero();  ///< drop_dr's covariance there
  };

  int Beacon(const std::string& id);
  /// The drop priors' dead reckoning without its shared errors (the map's track errors).
  PdrOptions WhiteDeadReckoning() const;
  void StartDropDeadReckoning(Agent& a, double heading_sigma_rad);
  void AdvanceDropDeadReckoning(Agent& a, const Step& step, const Vec2& d);
  /// Whether the agent is on its first track, before the entry heading fixes its steps' turn.
  bool OnFirstTrack(const Agent& a) const;
  /// dr_first: decided at the agent's first step; then the step to its dead reckoning and the
  /// filter's verdict on it (an integrity note when it changes).
  void TestDeadReckoning(Agent& a, const Step& step);
  static bool WritesDeadReckoning(const Agent& a) {
    return a.dr_first && a.dr_first->WritesDeadReckoning();
  }
  /// The drop priors' dead reckoning from the start again, the first track's steps turned by the
  /// entry fix as every later step is, its drops hinted again (FixEntryHeading).
  void ReplayFirstTrack(Agent& a);
  /// The drop priors' dead reckoning over `steps` (each turned by `step_rotation_rad` before the
  /// dead reckoning's own rotation), the `drops` (time, beacon id) on them hinted where they
  /// were made (FixHeading, ReplayFirstTrack).
  void ReplayDrops(Agent& a, const std::vector<Step>& steps,
                   std::vector<std::pair<TimeS, std::string>> drops, double step_rotation_rad);
  DropDeadReckoningState DropState(const Agent& a) const;
  /// The map's prior of `beacon` dropped by `a` at `at`.
  void HintDrop(Agent& a, int beacon, const DropDeadReckoningState& at);
  /// A point of a's dead-reckoning track as the map's prior of `beacon` (a close pass of a
  /// beacon that has no drop event), its white covariance as given; not a link of the chain of
  /// drops.
  void HintTrackPoint(Agent& a, int beacon, const DropDeadReckoningState& at);
  /// The pending sightings up to `until`, placed as the drops are.
  void HintPendingSightings(Agent& a, TimeS until, TimeS t0, TimeS t1,
                            const DropDeadReckoningState& before);
  /// Whether a's range to `beacon` becomes a sighting of the map (options.sighting_loop_m).
  bool WantsSighting(const Agent& a, int beacon) const;
  /// The pending drops up to `until`, placed at the share of the step from `before` to now.
  void HintPendingDrops(Agent& a, TimeS until, TimeS t0, TimeS t1,
                        const DropDeadReckoningState& before);
  void TryEstimateHeading(Agent& a, TimeS t, const BeaconPosition& beacon,
                          const std::optional<PendingRange>& range, std::optional<double> bearing,
                          double bearing_sigma, EstimateSink& sink);
  /// The PDR's heading in the navigation frame is `psi_rad` (sigma): estimated (`init`) or
  /// assumed (the fallback); the drop priors replayed, the tracker started.
  void FixHeading(Agent& a, TimeS t, double psi_rad, double sigma_rad,
                  const std::optional<InitResult>& init, EstimateSink& sink);
  std::vector<int> Ranks() const;
  std::vector<std::vector<int>> Neighbours() const;
  std::pair<std::optional<Vec2>, std::optional<Mat2>> AgentEstimate(const Agent& a) const;
  void Ignore(const std::string& reason) { ++ignored_[reason]; }
  void FixEntryHeading(Agent& a, const Vec2& d);
  void FlushPending(EstimateSink& sink);
  void Measure(Agent& a, TimeS t, int beacon, const std::optional<PendingRange>& range,
               std::optional<double> bearing, double bearing_sigma, EstimateSink& sink);
  /// The map's solve begun at its last tick is put in place and every beacon written (with
  /// `begin`: a new solve begun first, put in place now when map_lag_s is 0).
  void SolveAndEmit(TimeS t, EstimateSink& sink, bool begin);
  double MapLag() const { return std::min(options_.map_lag_s, options_.mds_period_s); }
  void EmitBeacons(TimeS t, EstimateSink& sink);
  void Emit(TimeS t, Agent& a, EstimateSink& sink);
  /// The position at `t` ahead of the last step by its velocity (options.extrapolate).
  /// The agent's position ahead of its last step end at t (false, nothing written: no step yet,
  /// t not after the step end or not after its last estimate).
  bool EmitAhead(TimeS t, Agent& a, EstimateSink& sink);
  bool Apply(Agent& a, const Deferred& m);
  /// After a range of the agent's: its range scale against the stated sigma (an integrity note
  /// when the verdict changes; the filter keeps estimating the scale either way).
  void CheckRangeScale(Agent& a, TimeS t);
  /// The step (t0, t1, d) with the measurements it spans applied at their instants.
  void PredictWithMeasurements(Agent& a, TimeS t0, TimeS t1, const Vec2& d, const Mat2& cov);
  /// Measurements older than `before` that no step spans: applied where the node stands.
  void ApplyStanding(TimeS before, TimeS now, EstimateSink& sink);

  BeaconTrailOptions options_;
  BeaconMap map_;
  std::map<std::string, Agent> agents_;
  std::map<std::string, std::pair<Vec2, double>> surveyed_;
  std::map<std::string, int> declared_rank_, drop_rank_;
  std::vector<PendingRange> pending_;
  std::vector<TimeS> beacon_t_;  ///< when each beacon was last emitted
  TimeS pending_t_ = std::numeric_limits<double>::infinity();
  TimeS last_t_ = 0;
  TimeS last_solve_ = -std::numeric_limits<double>::infinity();  ///< the last solve's tick
  std::size_t implausible_links_ = 0, no_position_ = 0;
  integrity::ConsistencyMonitor beacon_integrity_;
  /// Whether the last map solve rejected a part (issue 22: the fallback to drop priors and
  /// surveys is an integrity note, raised live as an alert), and those notes.
  bool map_rejected_ = false;
  std::vector<IntegrityNote> map_notes_;
  std::map<std::string, std::size_t> ignored_;
  std::size_t rows_ignored_ = 0, close_pass_anchors_ = 0, entry_fixes_ = 0;
  std::set<std::string> foot_ins_;  ///< agents on a foot INS's steps (StepsFromFootIns)
  std::vector<IntegrityNote> dr_notes_;
  /// The ranges' scale of an agent against its stated sigma (`CheckRangeScale`).
  std::vector<IntegrityNote> range_scale_notes_;
  double range_scale_threshold_ = 0;       ///< chi-square(1) at 1 - integrity.false_alarm
  bool range_scale_unobservable_ = false;  ///< fewer than two surveyed nodes: k fixed at 1  ///<
                                           ///< dr_first: the filter's verdicts on dead reckoning
};

}  // namespace trailmark::beacons

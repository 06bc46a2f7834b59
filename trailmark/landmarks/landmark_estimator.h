// SPDX-License-Identifier: MIT
#pragma once
/// The radio-landmarks paper's estimators as one online estimator over an incident:
///  - stop-and-go (sec. 5.3, 6.2): dead reckoning between stops; at every stop (events stop/go)
///    the RSSI of each landmark is averaged; after each stop the stop-and-go problem
///    (stop_and_go.h) is solved over all stops so far with the standing positions from the
///    PDR, giving the unknown landmarks; the handheld is then re-localized at the stop with
///    the landmarks and dead reckoning continues from that fix (information-weighted);
///  - UKF (sec. 5.4): the same landmark estimation, plus the UKF (landmark_ukf.h) with the
///    steps as motion model (ours: the ZUPT INS displacement, `PredictWithDisplacement`) and
///    every RSSI answer of a localized landmark as an update.
/// Landmarks with a `position` are known (surveyed, with `position_sigma`); the others are
/// estimated. The radio model comes from mission.json, else it is fitted online
/// (radio::CalibratePathLoss) from the stops' averaged RSSI of surveyed landmarks at the PDR
/// distance. Needs every row in global time order (the registry feeds it through a
/// StepFrontEnd). No I/O.

#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "trailmark/core/mission.h"
#include "trailmark/core/online_estimator.h"
#include "trailmark/core/options.h"
#include "trailmark/ins/dead_reckoning.h"
#include "trailmark/ins/dead_reckoning_clones.h"
#include "trailmark/integrity/consistency.h"
#include "trailmark/integrity/dead_reckoning_first.h"
#include "trailmark/landmarks/landmark_tracker.h"
#include "trailmark/landmarks/landmark_ukf.h"
#include "trailmark/landmarks/stop_and_go.h"
#include "trailmark/landmarks/tracker_bank.h"
#include "trailmark/radio/path_loss.h"

namespace trailmark::landmarks {

enum class Tracking { kStopAndGo, kUkf };
/// How stop-and-go tracking combines a stop's landmark fix with the dead reckoning.
enum class FixFusion {
  /// The paper's: an information-weighted update, as if the fix were independent of the dead
  /// reckoning, whose covariance grows by white drift (drift_per_m).
  kIndependent,
  /// The dead reckoning's own error model (its shared heading, drift-rate and scale errors,
  /// ins/dead_reckoning.h) and covariance intersection with the fix, whose correlation with it is
  /// unknown (the map was built from the same dead reckoning); the map from the dead reckoning's
  /// standing positions. Honest (docs/landmarks.md), less accurate on the corridor.
  kIntersection,
  /// Ours (issue 21): the agent's standing positions solved together with the landmarks, under
  /// the dead reckoning's joint prior of those positions (its shared heading, drift-rate and scale
  /// errors make them correlated: ins/dead_reckoning_clones.h), surveyed landmarks with their
  /// survey's sigma; the current position conditioned on that solution. A fix counts only for
  /// what the radio adds to the dead reckoning; the map is no longer built from positions taken
  /// as exact.
  kJoint,
};

/// The covariance stop-and-go tracking reports between fixes (FixFusion::kIndependent). Both
/// fuse each fix with the paper's weights (white drift, `drift_per_m`): the estimate is the same.
enum class DriftModel {
  /// The paper's: white drift, `drift_per_m` sigma per metre walked.
  kWhite,
  /// The dead reckoning's own error model (its shared heading, drift-rate and scale errors,
  /// ins/dead_reckoning.h, as `pdr` reports them), set at each fix to what the paper's
  /// estimate can claim whatever the fix's correlation with the dead reckoning: the covariance
  /// intersection's covariance plus the paper's offset from the intersection's estimate. A
  /// track without a fix is as honest as `pdr`'s; a fix's error grows with the heading error
  /// over the distance walked since (ours, issue 21).
  kDeadReckoning,
};

/// The continuous tracker of `landmarks-ukf`.
enum class TrackingFilter {
  /// The paper's UKF (sec. 5.4): position, velocity, acceleration; white PDR drift; every packet
  /// an independent update at the model's sigma; the radio model as calibrated.
  kPaper,
  /// Ours (issue 24, landmark_tracker.h): the PDR's heading, heading-rate and scale errors, the
  /// path-loss model and each link's shadowing as states; iterated, robust updates in 3-D.
  kErrorState,
};

struct LandmarkEstimatorOptions {
  Tracking tracking = Tracking::kStopAndGo;
  TrackingFilter filter = TrackingFilter::kErrorState;
  LandmarkTrackerOptions tracker;  ///< TrackingFilter::kErrorState
  /// Error-state: the typical device's tracker and a poor device's, weighed by the radio
  /// (tracker_bank.h; models = 1: the typical one alone).
  TrackerBankOptions bank;
  /// Error-state: also fuse landmarks placed by the stop-and-go solver. Off: they were placed
  /// from this dead reckoning's standing positions, so they share its heading and scale errors,
  /// which their covariance does not say; fused as independent, they turn the heading onto the
  /// dead reckoning's own error (measured on the corridor's `start` variants, docs/landmarks.md).
  bool track_with_estimated_landmarks = false;
  /// Error-state: unknown landmarks placed by each agent's tracker from its moving packets and
  /// then estimated jointly with its track (LandmarkTracker::UpdateRssiUnknown; issue 24 item 3).
  bool slam = true;
  /// Ours: kJoint (2026-12-05; the paper's kIndependent before, docs/landmarks.md). Continuous
  /// tracking (Tracking::kUkf) has no stop fixes and takes kIndependent only.
  FixFusion fix_fusion = FixFusion::kJoint;
  DriftModel drift = DriftModel::kDeadReckoning;
  /// Stop-and-go: the dead reckoning between the stops (its joint prior for FixFusion::kJoint,
  /// the drift of kIntersection and of kDeadReckoning). The steps' own heading offset
  /// (`track_heading_offset_sigma_rad`, ins/dead_reckoning.h) is a consider parameter there: as
  /// a state of the prior it let the stops' ranges rotate right corridor walks
  /// (docs/robustness.md, measured 2026-12-05), so the fixes are weighed without it and the
  /// reported covariance carries what it leaves (2026-12-06).
  PdrOptions stop_dead_reckoning{.track_heading_offset_considered = true};
  /// PDR drift, 1 sigma per metre walked (ours: 5 %); not used by FixFusion::kIntersection,
  /// which propagates the dead reckoning's own error model (`pdr`'s defaults and the agent's
  /// start_heading_sigma).
  double drift_per_m = 0.05;
  double rssi_sigma_db = 6.0;     ///< dB; UKF: one wake-up answer (the paper inflates it, 6.3)
  /// Robust loss (ours: Huber, the paper's future work); grid searches on at most 50 stops
  /// (ours: a search over hundreds of stops stalled a live incident for a second).
  StopAndGoOptions stop_and_go = [] {
    StopAndGoOptions o;
    o.init_max_anchors = 50;
    return o;
  }();
  /// The online fit when mission.json has no radio calibration: plain log-distance, no trim
  /// (the stops' RSSI are averages already), 0.5 m bins.
  radio::PathLossCalibrationOptions calibration = {0.0, 0.5, false};
  std::size_t calibration_min_pairs = 4;
  double calibration_min_spread = 2.0;    ///< the farthest pair at least this x the nearest
  double calibration_min_distance_m = 0.3;  ///< closer stops are taken as this far
  double min_radio_sigma_db = 1.0;        ///< a fitted shadowing sigma is never below this
  int min_stops_heard = 3;                ///< an unknown landmark is placed once heard at this many stops
  /// Each solve starts an unknown landmark from a grid search over every stop that heard it
  /// (stop_and_go.h) — while it was heard at up to `regrid_below_stops`, when an estimate can
  /// still jump to another basin; beyond, only once its stops have grown by `regrid_growth`
  /// since the last search, else from its current estimate (ours: a grid search over all stops
  /// at every stop made an incident of 20 firefighters quadratic in its stops; with warm starts
  /// from 4 stops on, 2 of 8 corridor seeds ended 0.4-0.8 m worse, so few stops keep the grid).
  int regrid_below_stops = 20;
  double regrid_growth = 1.5;
  /// FixFusion::kJoint: an agent's latest stops solved with its dead reckoning's prior; older
  /// stops stay in the map's problem at their last solution (ours: bounds each solve's size).
  int joint_window_stops = 30;
  /// FixFusion::kJoint: when a solve fails its chi-square test at `joint_false_alarm` (the
  /// ranges disagree with the dead reckoning's prior beyond their stated noise: a stale or
  /// default radio model, or none), it is solved again with the ranges' calibration (an
  /// intercept and an exponent error common to every link, StopAndGoProblem::range_calibration)
  /// as unknowns, a priori sigmas 1 in the log (about 10 dB at exponent 2.3) and 0.5 in the
  /// exponent's ratio (ours, issues 21 and 24). Off: never.
  bool joint_range_calibration = true;
  double joint_false_alarm = 0.01;
  double min_range_sigma_m = 0.1;         ///< m; floor of an RSSI range's sigma
  double known_start_sigma_m = 0.05;      ///< m; a start without start_sigma
  double unknown_start_sigma_m = 100.0;   ///< m; an agent without a start
  double surveyed_sigma_m = 0.01;         ///< m; a landmark position without position_sigma
  /// UKF: each landmark's RSSI innovations checked against their stated noise (issue 21); an
  /// inconsistent landmark (moved, offset, frozen) is left out until it agrees again.
  integrity::ConsistencyOptions integrity;
  /// Ours (issue 26): a packet between an agent and a landmark on another level (the agent's
  /// level from its height channel, the landmark's from its surveyed z) is not used: the
  /// path-loss model has no floors (a floor costs 10-20 dB).
  bool gate_other_floors = true;
  /// Ours (issue 24 item 2): an agent whose steps come from a foot INS moves with the INS's
  /// own errors (PdrOptions::ForFootIns of `tracker.pdr` for the error-state tracker's typical
  /// device, of `stop_dead_reckoning` for the stops), not a phone PDR's; false: the PDR's.
  bool foot_ins_own_errors = true;
  /// Error-state (ours, issues 21 and 24: never worse than dead reckoning): an agent whose
  /// steps come from a foot INS within its noise model (with its own errors, above), with a
  /// known start and a stated heading, is written as its dead reckoning (`pdr`'s estimate:
  /// PdrOptions::ForFootIns of `tracker.pdr`) while the tracker does not doubt it. Why: such an
  /// INS dead-reckons a floor's search to decimetres, RSSI places a handheld to metres (walls,
  /// each landmark's offset, shadowing that stays over a room: errors the log-distance model
  /// does not have), and the motion's a-priori errors (PdrOptions::ForFootIns, set for any foot
  /// INS) are wider than a good one's; fused, the radio pulled right tracks off by a metre or two
  /// (docs/landmarks.md, "A good foot INS and the radio"). The tracker runs all along; d2 is the
  /// dead reckoning's squared Mahalanobis distance from the tracker's estimate under the
  /// tracker's own covariance (its most probable model's, without the steps' heading offset,
  /// which the dead reckoning shares): if the dead reckoning is right, d2 is the tracker's error,
  /// chi-square with 2 dof when the tracker is honest. Inside the `dr_accept_probability`
  /// quantile the dead reckoning is written; beyond `dr_reject_probability`'s the tracker's
  /// estimate (the dead reckoning is rejected: an integrity note, and another when it is
  /// accepted again); in between, a blend linear in d2, with the mixture's covariance. false:
  /// always the tracker's estimate.
  bool dr_first = true;
  integrity::DeadReckoningFirstOptions dr_test;
  bool IsValid(std::string* why) const;
};
/// The `--option` keys (docs/pipeline-options.md).
/// The options of landmarks-stopgo (kStopAndGo) or landmarks-ukf (kUkf: also its tracker's).
const OptionTable<LandmarkEstimatorOptions>& LandmarkOptionTable(Tracking tracking);

class LandmarkEstimator : public OnlineEstimator {
 public:
  /// Throws std::invalid_argument with fewer than 3 landmarks in `info` or invalid options.
  LandmarkEstimator(const MissionInfo& info, LandmarkEstimatorOptions options);
  /// Rows in global time order: steps, RSSI between an agent and a landmark, stop/go events;
  /// others are counted and ignored.
  void Add(const MissionRow& row, EstimateSink& sink) override;
  void UseLevels(const LevelSource* levels) override { levels_ = levels; }
  /// An agent whose steps come from a foot INS: from its first step on its motion's errors are
  /// the INS's own (PdrOptions::ForFootIns; the error-state tracker's typical device, the stops'
  /// dead reckoning), unless `foot_ins_own_errors` is off or that step carries no heading
  /// variance (an INS outside its noise model, ZuptIns::OwnErrorsHold).
  void StepsFromFootIns(const std::string& agent, bool foot_ins) override;
  /// The landmarks' final estimates.
  void Finish(EstimateSink& sink) override;
  std::optional<Estimate> Current(const std::string& node) const override;
  /// The error-state tracker's (its most probable motion model's): (1 + s) R(psi), the step
  /// scale and heading corrections it moves each step by; none for the other trackers.
  std::optional<Mat2> StepTransform(const std::string& agent) const override;
  EstimatorSummary Summary() const override;
  /// The radio model in use (mission.json's, the default, or the latest online fit).
  const radio::LogDistanceModel& radio_model() const { return model_; }

 private:
  struct Agent {
    Vec2 position = Vec2::Zero();
    Mat2 cov = Mat2::Identity();
    /// Stop-and-go, FixFusion::kIntersection or DriftModel::kDeadReckoning: the dead reckoning
    /// with its shared errors (heading, drift rate, scale: issue 21), into which each stop's
    /// fix is fused (intersection) or set (independent).
    std::optional<DeadReckoning> dr;
    Vec2 pdr_position = Vec2::Zero();  ///< the start plus every step, no fix (the map's frame)
    bool stopped = false;
    TimeS t = 0;
    std::vector<double> sum;
    std::vector<int> count;
    std::optional<LandmarkUkf> ukf;
    std::optional<LandmarkTrackerBank> tracker;
    double z_m = 0;  ///< the start's z plus every step's dz (when no height channel)
    bool stepped = false;  ///< a step was seen (the error-state tracker writes its start first)
    /// FixFusion::kJoint: the dead reckoning with its error at each of the latest stops, and
    /// those stops' indices in stops_ (one per clone, in order).
    std::optional<DeadReckoningClones> clones;
    std::vector<std::size_t> clone_stops;
    /// dr_first: the foot INS's dead reckoning and the tracker's verdict on it.
    std::optional<DeadReckoning> own_dr;
    std::optional<integrity::DeadReckoningFirst> dr_first;
  };
  struct Stop {
    /// The standing position: the dead reckoning's, or with FixFusion::kJoint the latest
    /// solution's.
    Vec2 standing = Vec2::Zero();
    std::vector<std::optional<double>> rssi;  ///< averaged per landmark
  };
  void EmitAgent(TimeS t, const std::string& id, Agent& a, EstimateSink& sink);
  /// The stops' dead reckoning of stop-and-go from the agent's start (a.position, a.cov) with
  /// these errors: a.dr for intersection or independent fixes with DriftModel::kDeadReckoning,
  /// a.clones for joint ones; none for continuous tracking.
  void StartStopDeadReckoning(Agent& a, const PdrOptions& pdr,
                              std::optional<double> start_heading_sigma_rad);
  /// Before the agent's first step: its motion's errors become the foot INS's own.
  void UseFootInsErrors(const std::string& agent, Agent& a);
  /// dr_first: the agent's dead reckoning checked against the tracker's region after the
  /// tracker moved; a change of the verdict is an integrity note. Returns whether it changed.
  bool TestDeadReckoning(TimeS t, const std::string& agent, Agent& a);
  /// Whether the agent's estimate is its dead reckoning now (dr_first, not rejected).
  static bool WritesDeadReckoning(const Agent& a) {
    return a.dr_first && a.dr_first->WritesDeadReckoning();
  }
  void EmitLandmarks(TimeS t, EstimateSink& sink);
  void EmitLandmark(TimeS t, std::size_t j, EstimateSink& sink);
  /// A landmark's estimate: surveyed, stop-and-go's, or (unknown) the most certain tracker's.
  std::optional<std::pair<Vec2, Mat2>> LandmarkOf(std::size_t j) const;
  void RangesOf(const Stop& s, std::vector<std::optional<double>>* r, std::vector<double>* sg) const;
  void EndOfStop(TimeS t, const std::string& id, Agent& a, EstimateSink& sink);
  /// FixFusion::kJoint's solve at the end of a stop (stops_.back(), the agent's).
  void SolveJoint(TimeS t, const std::string& id, Agent& a, EstimateSink& sink);
  /// Where each landmark's descent starts (`prob.landmarks`, `landmark_start_given`) given how
  /// many stops heard it: a warm start from its estimate, or a grid search (regrid_*).
  void StartLandmarks(const std::vector<int>& heard, StopAndGoProblem* prob);
  /// How many stops heard each landmark.
  std::vector<int> HeardAtStops() const;
  void Refit();
  Vec2 PositionOf(const Agent& a) const;
  Mat2 CovarianceOf(const Agent& a) const;
  double HeightOf(const std::string& id, const Agent& a) const;

  LandmarkEstimatorOptions options_;
  radio::LogDistanceModel model_;
  /// mission.json's shadowing sigma when its radio block is not a whole calibration.
  std::optional<double> stated_sigma_db_;
  bool calibrated_ = false;
  std::vector<std::string> ids_;
  std::map<std::string, int> index_;
  std::vector<bool> known_;
  std::vector<std::optional<Vec2>> estimate_;
  std::vector<Mat2> estimate_cov_;
  std::vector<std::optional<double>> landmark_z_;  ///< surveyed landmarks' z
  std::optional<double> unknown_landmark_z_m_;     ///< the surveyed ones' mean z
  std::vector<TimeS> estimate_t_;
  std::vector<int> grid_heard_;  ///< stops that had heard each landmark at its last grid search
  std::map<std::string, Agent> agents_;
  std::set<std::string> foot_ins_;  ///< agents whose steps come from a foot INS
  std::vector<Stop> stops_;
  std::vector<radio::CalibrationPair> calibration_;
  std::vector<std::string> setup_notes_;
  std::set<std::string> solve_notes_;  ///< the latest solve's geometry report
  std::vector<IntegrityNote> dr_notes_;  ///< dr_first: the tracker's verdicts on dead reckoning
  TimeS t_last_ = -1e300;  ///< the latest row's time
  bool first_ = true;
  int refits_ = 0;
  double range_log_scale_ = 0, range_exponent_ratio_ = 1;  ///< the latest joint solve's
  std::size_t joint_inconsistent_ = 0;  ///< joint solves that failed the chi-square test
  std::size_t fixes_ = 0, ukf_updates_ = 0, ignored_ = 0, other_floor_ = 0;
  const LevelSource* levels_ = nullptr;
  MissionInfo info_;
  MissionLevels mission_levels_;  ///< mission.json's levels by id (every packet asks)
  integrity::ConsistencyMonitor landmark_integrity_;
};

}  // namespace trailmark::landmarks

// SPDX-License-Identifier: MIT
#pragma once
/// Radio-landmark tracking with the motion's real error (issue 24; ours, not the paper's): one
/// agent's iterated extended Kalman filter over
///   x = [p_x, p_y, psi, omega, s, g, alpha, n, b_1 .. b_L]
/// - p: position (navigation frame, m);
/// - psi, omega, s: the dead reckoning's heading correction (rad), its rate (rad/s: the gyro
///   bias left after calibration, integrating while standing too) and step-scale correction;
///   a step d of the PDR moves p by (1 + s) R(psi) d (the error model of ins/dead_reckoning.h,
///   here estimated instead of only propagated);
/// - g: the turn-scale error (a gyro's scale factor): every turn of the PDR's walking direction
///   by dtheta adds g dtheta to psi — on a search through rooms, the heading error that grows
///   fastest (1-3 % of every turn, MEMS datasheets), which a per-step random walk cannot hold;
/// - alpha, n: this agent's path-loss model (dBm at 1 m, its device's offset included; the
///   exponent), from mission.json's calibration as a prior when given, else from a wide prior
///   (self-calibration: no stop/go events needed);
/// - b_j: the shadowing of the link to landmark j, a Gauss-Markov process in distance walked
///   (Gudmundson 1991: correlation exp(-d / d_c)) and, slowly, in time: packets heard while
///   standing share one realization and are not independent evidence.
/// RSSI (the paper's eq. 5 with the link's bias):
///   z = alpha - 10 n log10(d3) + b_j + v,   v ~ N(0, sigma_fast^2),
/// d3 the 3-D distance between the handheld (the agent's z plus the handheld's height) and the
/// landmark. Each packet is an iterated update (Gauss-Newton on the prior and the packet:
/// re-linearized at the posterior, not committed at the prior), robust (Huber weights on the
/// normalized innovation) and gated. Until the agent's motion has started and its radio model is
/// known to `calibrated_*`, the packet updates only the radio states (alpha, n, b): the motion
/// states are consider states (Schmidt-Kalman), so that packets while the handheld is held still
/// before the walk cannot move the start. The used packets' NIS is watched: while its mean is
/// above 1 the RSSI variances are scaled up (never below the stated ones). Unknown landmarks are
/// placed from the walk and then estimated jointly (UpdateRssiUnknown). Covariances are kept
/// symmetric positive definite (Joseph-form updates). No I/O.

#include <Eigen/Core>
#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "trailmark/core/measurements.h"
#include "trailmark/core/types.h"
#include "trailmark/ins/dead_reckoning.h"
#include "trailmark/radio/path_loss.h"

namespace trailmark::landmarks {

struct LandmarkTrackerOptions {
  /// The dead reckoning's error model as the prior of psi, omega, s, g (turn scale: shorter
  /// steps than pdr.turn_min_step_m do not say where the walker turned) and the step noise
  /// (`pdr`'s defaults, set a priori: ins/dead_reckoning.h). The track's own heading offset
  /// (`pdr.track_heading_offset_sigma_rad`) is a consider parameter, not a state: estimated,
  /// the few landmarks of a corridor rotated straight walks that were right (docs/robustness.md,
  /// measured 2026-12-05). Its effect on the estimate is carried as a sensitivity and added to
  /// the reported covariance only (reported_position_cov).
  PdrOptions pdr;
  /// The radio model's prior when mission.json gives one: a device's offset (about 10 dB
  /// between two phones on recorded BLE, issue 24) and a stale exponent are still possible.
  double given_alpha_sigma_db = 4.0;
  double given_exponent_sigma = 0.3;
  /// Without one: a prior wide enough for 868 MHz, BLE and UWB (alpha -75..-30 dBm, n 1.3-4).
  double default_alpha_dbm = -55.0;
  double default_alpha_sigma_db = 15.0;
  double default_exponent = 2.5;
  double default_exponent_sigma = 1.0;
  double default_sigma_db = 6.0;  ///< total RSSI sigma without a calibration
  double min_exponent = 1.0, max_exponent = 8.0;  ///< n is kept in this range
  /// Share of the RSSI variance that is shadowing (correlated along the walk); the rest is
  /// fast fading, independent per packet. Indoor channels: shadowing dominates (a priori).
  double shadowing_variance_share = 0.7;
  double shadowing_length_m = 3.0;   ///< d_c: shadowing decorrelation distance (indoor 1-5 m)
  double shadowing_time_s = 30.0;    ///< and time (people and doors move)
  double handheld_height_m = 1.2;    ///< the receiving handheld above the agent's z
  double min_distance_m = 0.3;       ///< d3 is taken at least this
  /// The radio's noise checked against its stated sigma: while the packets' mean NIS is above 1
  /// the RSSI variances are scaled up (at most noise_scale_max), back toward 1 when below.
  bool adapt_noise = true;
  double noise_scale_max = 4.0;
  /// A surveyed landmark whose position has a covariance: its position is a state (from its
  /// first packet, at the survey): the survey's error is one draw that every packet of it shares,
  /// not noise of each packet. false: the survey's covariance is added to each packet's variance.
  bool survey_error_states = true;
  int iterations = 4;                ///< Gauss-Newton iterations of one packet's update
  double huber_k = 2.0;              ///< normalized innovation beyond which weights fall
  double gate_sigma = 4.0;           ///< a packet beyond this many sigmas is not used (the paper UKF's)
  /// The position moves with radio only once the radio model is this well known.
  double calibrated_alpha_sigma_db = 3.0;
  double calibrated_exponent_sigma = 0.3;
  /// Unknown landmarks (UpdateRssiUnknown): placed after this many packets heard from positions
  /// this far apart (the farthest two), while the radio moves the position.
  int slam_min_packets = 30;
  double slam_min_spread_m = 6.0;
  double slam_min_width_m = 1.0;  ///< and spread across their main direction (1 sigma)
  double slam_search_margin_m = 10.0;  ///< the grid search spans the positions plus this
  /// Placed only when every place farther than slam_ambiguity_m fits worse by this chi-square
  /// (counted in independent looks): a mirror image or a flat basin waits for more packets.
  double slam_ambiguity_m = 3.0;
  double slam_decisive_chi2 = 9.0;
  double slam_grid_m = 1.0;
  int slam_grid_packets = 60;   ///< the grid search's packets (evenly spread); the fit uses all
  int slam_max_packets = 400;   ///< the latest this many packets are kept for a fit
  bool IsValid(std::string* why) const;
};

class LandmarkTracker {
 public:
  enum : int { kPx = 0, kPy, kHeading, kRate, kScale, kTurnScale, kAlpha, kExponent, kFixed };
  /// `start_sigma_m`, `start_heading_sigma_rad` (empty: the PDR options' default); `radio`:
  /// mission.json's calibration, if any. Throws std::invalid_argument for invalid options.
  LandmarkTracker(const Vec3& start_n, double start_sigma_m,
                  std::optional<double> start_heading_sigma_rad,
                  const std::optional<radio::LogDistanceModel>& radio,
                  LandmarkTrackerOptions options = {});

  /// Moves the state to time t (the heading correction integrates its rate; shadowing decays
  /// with time). Earlier times are ignored.
  void Propagate(TimeS t);
  /// One PDR step (its t1 is propagated to first).
  void AddStep(const Step& step);
  /// The motion's error model replaced before the first step (e.g. a foot INS's own,
  /// PdrOptions::ForFootIns): the drift-rate, step-scale and turn-scale errors' rows and
  /// columns of the covariance are scaled to the new sigmas (a change of their prior: before
  /// the walk only the prior is in them; the heading variance the old drift rate added while
  /// standing before the walk is kept). Returns false, changing nothing, once a step was added.
  bool UseMotionErrors(const PdrOptions& pdr);
  /// One packet from landmark `landmark` (any stable index) at `landmark_n` (z: empty for
  /// a landmark whose height is unknown: the handheld's height is taken), whose horizontal
  /// position has covariance `landmark_cov`; `agent_z_m`: the agent's height now (feet).
  /// `admit` sees the packet's normalized innovation squared at the prior (1 dof) and may
  /// refuse it (the integrity monitor). With `survey_error_states` and a non-zero
  /// `landmark_cov`, the landmark's position becomes two states at its first packet (later
  /// packets' `landmark_n` and `landmark_cov` are not read again). Returns whether the packet
  /// was used.
  bool UpdateRssi(TimeS t, int landmark, const Vec2& landmark_n,
                  std::optional<double> landmark_z_m, const Mat2& landmark_cov,
                  double agent_z_m, double rssi_dbm,
                  const std::function<bool(double nis)>& admit = nullptr);

  /// A packet from an unknown landmark (no surveyed position): SLAM over the walk (issue 24,
  /// item 3). Until the landmark is in the state, its packets heard at radio-corrected positions
  /// are kept; once `slam_min_packets` were heard over `slam_min_spread_m`, it is placed by a
  /// robust least-squares fit of them (a grid search, then Gauss-Newton, with this agent's
  /// path-loss model), with the fit's covariance widened for the correlated shadowing (one
  /// independent look per correlation length walked) and for the positions' own uncertainty,
  /// and becomes two states updated jointly with the track by every later packet; its link's
  /// offset is fitted with it. `dz_m`: the landmark's height above the handheld as assumed (its
  /// height is not estimated). Returns whether the packet updated the state.
  bool UpdateRssiUnknown(TimeS t, int landmark, double dz_m, double rssi_dbm,
                         const std::function<bool(double nis)>& admit = nullptr);
  /// The estimate of an unknown landmark in the state, with its covariance.
  std::optional<std::pair<Vec2, Mat2>> LandmarkEstimate(int landmark) const;

  Vec2 position() const { return x_.head<2>(); }
  Mat2 position_cov() const { return P_.topLeftCorner<2, 2>(); }
  /// The position covariance with the consider parameter's share (consider covariance analysis,
  /// Tapley, Schutz & Born 2004, sec. 6.3): P + sigma_c^2 S S^T, where S is the state error's
  /// sensitivity to the track's heading offset, which no update estimates. The estimate is the
  /// filter's own; only what it claims of its error grows.
  Mat2 reported_position_cov() const;
  /// The sensitivity S (one entry per state).
  const Eigen::VectorXd& offset_sensitivity() const { return sens_; }
  double heading_correction_rad() const { return x_(kHeading); }
  double heading_rate_rad_per_s() const { return x_(kRate); }
  double scale_correction() const { return x_(kScale); }
  double turn_scale_correction() const { return x_(kTurnScale); }
  double alpha_dbm() const { return x_(kAlpha); }
  double exponent() const { return x_(kExponent); }
  double alpha_sigma_db() const;
  double exponent_sigma() const;
  /// Whether radio moves the position now (the motion started and the radio is calibrated).
  bool RadioMovesPosition() const;
  const Eigen::VectorXd& state() const { return x_; }
  const Eigen::MatrixXd& covariance() const { return P_; }
  /// Packets refused by the gate so far.
  std::size_t gated() const { return gated_; }
  /// Packets that only calibrated (the motion not started or the radio not yet known).
  std::size_t calibration_only() const { return calibration_only_; }
  /// The factor on the stated RSSI variances (adapt_noise; 1: as stated).
  double noise_scale() const { return noise_scale_; }
  /// Mean normalized innovation squared of the packets so far (1 when the stated noise holds).
  double mean_nis() const { return nis_count_ ? nis_sum_ / nis_count_ : 0.0; }
  /// The last packet that reached the filter (gated or not): its log predictive density at the
  /// prior, log N(z; h(x), H P H^T + R), with the normalized innovation capped at huber_k: a
  /// packet beyond it is an outlier, whose density is the outlier process's, the same whatever
  /// the motion (the evidence that decides a bank's estimate, LandmarkTrackerBank: one fading dip
  /// cannot). NaN before any packet, and for a packet the filter did not reach (an unplaced
  /// landmark).
  double last_log_likelihood() const { return last_log_likelihood_; }
  /// The same density with Huber's tails beyond huber_k and the innovation capped at the gate
  /// (the evidence that sizes a bank's ellipse: it also counts moderate outliers).
  double last_huber_log_likelihood() const { return last_huber_log_likelihood_; }

 private:
  int BiasState(int landmark);
  int LandmarkState(int landmark) const;  ///< x state of a landmark's position, -1 if none
  /// Appends a landmark's two position states (at `position_n`, covariance `cov`, uncorrelated
  /// with the rest; the offset's sensitivity given); returns the first's index.
  int AddLandmarkStates(int landmark, const Vec2& position_n, const Mat2& cov,
                        const Vec2& offset_sensitivity);
  void PlaceLandmark(int landmark);
  /// One packet's iterated update; the landmark at `landmark_n` (cov `landmark_cov`) or, when
  /// `state` >= 0, the two states from there.
  bool Update(int landmark, const Vec2& landmark_n, int state, double dz_m,
              const Mat2& landmark_cov, double rssi_dbm,
              const std::function<bool(double nis)>& admit);
  void DecayShadowing(double distance_m, double dt_s);
  void DropStaleBiases();
  void Symmetrize();
  double VarShadow() const { return noise_scale_ * sigma_shadow_db_ * sigma_shadow_db_; }
  double VarFast() const { return noise_scale_ * sigma_fast_db_ * sigma_fast_db_; }

  LandmarkTrackerOptions options_;
  double sigma_shadow_db_ = 0, sigma_fast_db_ = 0;
  Eigen::VectorXd x_;
  Eigen::MatrixXd P_;
  /// d(state error) / d(track heading offset): starts at e_psi (the offset acts as a heading
  /// error at the start), transformed as the error is by every propagation and update.
  Eigen::VectorXd sens_;
  /// The states after kFixed: a link's shadowing bias ('b') or an unknown landmark's x or y
  /// ('x', 'y'); the landmark of each; for a bias, the distance walked when it was last heard.
  std::vector<char> extra_kind_;
  std::vector<int> extra_landmark_;
  std::vector<double> extra_walked_m_;
  struct Heard {
    Vec2 position;
    double position_var_m2;
    double dz_m;
    double rssi_dbm;
  };
  struct Unplaced {
    std::vector<Heard> heard;
    std::size_t received = 0;  ///< packets heard in all
    std::size_t tried_at = 0;  ///< `received` at the last fit tried
  };
  std::map<int, Unplaced> unplaced_;  ///< packets of unknown landmarks not yet placed
  std::optional<TimeS> t_;
  double walked_m_ = 0;
  std::optional<double> direction_rad_;  ///< the PDR's walking direction at the last long step
  bool moving_ = false;                   ///< a step that moved was seen
  bool stepped_ = false;                  ///< a step was seen
  std::size_t gated_ = 0, calibration_only_ = 0;
  double noise_scale_ = 1.0;  ///< the RSSI variances' factor (adapt_noise)
  double nis_ema_ = 1.0;
  double nis_sum_ = 0;
  std::size_t nis_count_ = 0;
  double last_log_likelihood_ = std::numeric_limits<double>::quiet_NaN();
  double last_huber_log_likelihood_ = std::numeric_limits<double>::quiet_NaN();
};

}  // namespace trailmark::landmarks

// SPDX-License-Identifier: MIT
#pragma once
/// Tracking along an ultrasound beacon trail (ultrasound-beacons paper, sec. 6).
///
/// `ScaatEkf`: the paper's extended Kalman filter with state x = (u, v, psi, scale) — position
/// and the corrections applied to the PDR's step heading and step length — and, ours, the
/// ultrasound's range scale k (issue 21: a wrong speed of sound scales every range alike).
/// Measurements are processed one at a time in time order (SCAAT, Welch & Bishop 1997):
///  - an inertial step d (navigation frame of the PDR) moves the position by
///        p <- p + scale R(psi) d                                            (sec. 6)
///    i.e. the step heading corrected by psi and the step length by scale;
///  - an ultrasound measurement of range r and bearing b from a beacon at B updates the state.
///    The paper converts (r, b) to a position B + r (cos b, sin b) (`UpdatePosition`); ours,
///    by default, updates with the range and the bearing as two scalar measurements of
///    h_r = |p - B|, h_b = atan2(p - B), which keeps the long-tailed bearing from corrupting the
///    range and lets each be gated on its own. The range is k |p - B|: ultrasound measures time
///    of flight, and a range is that time at the speed of sound the device assumes; the speed in
///    the room's air differs with its temperature (c ~ sqrt(T): 1.7 % for 10 deg C at 20 deg C),
///    so every range of one device shares one factor. Its prior (`range_scale_sigma`) is the
///    stated calibration; with surveyed beacons the ranges' geometry measures it, and a
///    factor its prior does not allow is an integrity lie (`RangeScaleTest`).
/// Deviation from the text, stated: the paper "does not update the state" on an inertial step and
/// only applies the last (psi, scale); we propagate the covariance through the step (the
/// Jacobians in psi and scale), without which psi and scale would never become observable from
/// position measurements. Beyond the paper: chi-square gating of every scalar update (NLOS
/// ranges are biased long), beacon position uncertainty added to the measurement noise (MDS
/// beacons), Joseph-form updates so the covariance stays symmetric positive definite.
///
/// `UltrasoundOnlyKf`: the paper's baseline (sec. 7.C) — position and velocity, constant
/// velocity, each range/bearing converted to a position fix.
///
/// `InitializeFromUltrasound`: a start without a surveyed position — the position and PDR
/// heading correction that best explain the first ultrasound measurements along the PDR track
/// (robust non-linear least squares from a grid of headings; the paper suggests "averaging the
/// first few ultrasound measurements through non-linear regression", sec. 6). No I/O.

#include <Eigen/Core>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "trailmark/core/types.h"

namespace trailmark::beacons {

/// A beacon as the tracker sees it: its position and that position's uncertainty.
struct BeaconPosition {
  Vec2 position_n = Vec2::Zero();
  Mat2 cov = Mat2::Zero();
};

/// Measurement models, with the optional Jacobian in the node's position next to them.
double UltrasoundRange(const Vec2& position_n, const Vec2& beacon_n,
                       Eigen::RowVector2d* H = nullptr);
double UltrasoundBearing(const Vec2& position_n, const Vec2& beacon_n,
                         Eigen::RowVector2d* H = nullptr);

struct ScaatEkfOptions {
  double initial_position_sigma_m = 0.1;    ///< surveyed start (paper: Ubisense fix)
  double initial_heading_sigma_rad = 0.17;  ///< PDR heading offset prior, ~10 deg
  double initial_scale_sigma = 0.1;         ///< step length scale prior
  /// Random walk of the heading correction per metre walked (PDR heading drift; sec. 3.B: the
  /// drift occurs incrementally).
  double heading_walk_rad_per_sqrt_m = 0.03;
  double scale_walk_per_sqrt_m = 0.002;
  double step_sigma_floor_m = 0.02;         ///< per axis, added to every step's covariance
  double range_sigma_m = 0.30;              ///< when a measurement gives none (moving foot)
  double bearing_sigma_rad = 0.57;          ///< when none given: p90 of 60 deg (sec. 3.B)
  double gate_sigma = 3.0;                  ///< scalar innovations beyond this are rejected
  /// Scalar range and bearing updates against a mixture likelihood (issue 22): with probability
  /// 1 - p the measurement is the Gaussian of its sigma, with p an outlier spread uniformly
  /// (ranges over [0, range_outlier_span_m], bearings over the circle: multipath and NLOS). The
  /// posterior of that mixture (one Gaussian updated, one not, weighted by the measurement's
  /// inlier probability) is collapsed to its mean and covariance — a one-measurement PDA
  /// (Bar-Shalom & Tse 1975) — so a doubtful measurement pulls less and widens the ellipse by
  /// the spread of the two hypotheses, instead of being either trusted whole or cut at
  /// `gate_sigma` (false: that hard gate, the paper's reading). Defaults from the paper's
  /// characterization of moving-foot ultrasound (sec. 3.B: 90 % of ranges within 1 m, 90 % of
  /// bearings within 60 deg): 10 % of each outside the Gaussian core.
  bool mixture_updates = true;
  double range_outlier_probability = 0.10;
  double range_outlier_span_m = 8.0;         ///< = the beacon map's max_link_m
  double bearing_outlier_probability = 0.10;
  /// Mixture updates: a measurement whose inlier probability is below this is not applied
  /// (counted as gated).
  double min_inlier_probability = 1e-3;
  double gate_chi2_2dof = 11.83;            ///< position fixes (99.73 %)
  double min_range_for_bearing_m = 0.3;     ///< bearing of a node on top of the beacon: skip
  double scale_min = 0.5, scale_max = 1.5;  ///< physical bounds on the step-length correction
  /// A beacon's position error is shared by all its measurements (issue 22): with a beacon key,
  /// the filter keeps the cross-covariance between its state and each beacon it used (a
  /// Schmidt-Kalman "consider" filter: the beacon is not estimated, its error is accounted for
  /// once, not added as fresh white noise to every range). false: the white model (the paper's).
  bool consider_beacons = true;
  /// The considered beacons kept (the least recently used beyond this is marginalized out).
  int max_considered_beacons = 64;
  /// Prior sigma of the range scale k (ours, issue 21): the spread of the speed of sound about
  /// the one the device assumes — 10 deg C about 20 deg C is 1.7 % (c = 331.3 sqrt(1 + T/273.15)
  /// m/s). 0: k is fixed at 1 (the paper's ranges are taken as they are).
  double range_scale_sigma = 0.02;
  double range_scale_min = 0.5, range_scale_max = 1.5;  ///< physical bounds on k

  bool IsValid(std::string* why) const;
};

/// What happened to one measurement (kRefused: by the caller's integrity check, `Admit`).
enum class UpdateResult { kAccepted, kGated, kSkipped, kRefused };

/// Sees an update's normalized innovation squared and its dimension before it is committed;
/// false refuses it (integrity/consistency.h: a beacon inconsistent with its stated noise).
using Admit = std::function<bool(double nis, int dof)>;

struct ScaatEkfSummary {
  std::size_t steps = 0;
  std::size_t range_updates = 0, bearing_updates = 0, position_updates = 0;
  std::size_t gated = 0, skipped = 0, refused = 0;
  /// Mixture updates applied with an inlier probability below 1/2 (doubtful, down-weighted).
  std::size_t down_weighted = 0;
  std::size_t beacons_marginalized = 0;  ///< considered beacons dropped beyond the cap
  std::string BriefReport() const;
};

class ScaatEkf {
 public:
  using Options = ScaatEkfOptions;
  static constexpr int kDim = 5;
  using State = Eigen::Matrix<double, kDim, 1>;  ///< (u, v, psi, scale, range scale)
  using Cov = Eigen::Matrix<double, kDim, kDim>;
  enum Index { kU = 0, kV = 1, kPsi = 2, kScale = 3, kRangeScale = 4 };

  ScaatEkf(const Vec2& position_n, const Mat2& position_cov, double psi_rad, double psi_sigma_rad,
           double scale, double scale_sigma, Options options = {});
  /// Starts with the options' priors around (position, psi 0, scale 1, range scale 1); the first
  /// constructor's range scale too.
  ScaatEkf(const Vec2& position_n, Options options = {});
  /// Any state and covariance (e.g. from InitializeFromUltrasound).
  ScaatEkf(const State& x, const Cov& P, Options options = {});

  /// One PDR step `delta_n` (PDR navigation frame) with its covariance; `fraction` < 1: that
  /// share of a step (a step split at a measurement's instant: the per-step floor scales).
  void PredictStep(const Vec2& delta_n, const Mat2& delta_cov, double fraction = 1.0);
  /// Scalar range update; sigma <= 0 uses the options' value. `beacon_key` >= 0 names the
  /// beacon (options.consider_beacons: its error is a consider state, see there); -1: white.
  UpdateResult UpdateRange(const BeaconPosition& beacon, double range_m, double sigma_m = 0,
                           const Admit& admit = nullptr, int beacon_key = -1);
  /// Scalar bearing update (from the beacon to the node, navigation frame).
  UpdateResult UpdateBearing(const BeaconPosition& beacon, double bearing_rad,
                             double sigma_rad = 0, const Admit& admit = nullptr,
                             int beacon_key = -1);
  /// The paper's update: range and bearing converted to a position fix.
  UpdateResult UpdatePosition(const BeaconPosition& beacon, double range_m, double bearing_rad,
                              double range_sigma_m = 0, double bearing_sigma_rad = 0,
                              const Admit& admit = nullptr);

  /// A direct measurement of the heading correction, e.g. from the entry: the known heading
  /// through the door minus the PDR's direction over the first metre (ours).
  UpdateResult UpdateHeadingCorrection(double psi_rad, double sigma_rad);

  const State& state() const { return x_; }
  const Cov& covariance() const { return P_; }
  Vec2 position() const { return x_.head<2>(); }
  Mat2 position_cov() const { return P_.topLeftCorner<2, 2>(); }
  double psi() const { return x_(kPsi); }
  double scale() const { return x_(kScale); }
  double range_scale() const { return x_(kRangeScale); }
  /// The range scale against its prior (issue 21: a wrong speed of sound): (k - 1)^2 over
  /// (sigma0^2 - P_kk), the estimate's departure from the prior's mean over its variance about
  /// that mean (the prior's variance minus the posterior's, as for any linear-Gaussian
  /// posterior mean) — chi-square of one degree of freedom while the device's scale is within
  /// its prior. 0 while the ranges have said little of k (P_kk above half the prior's
  /// variance) and when k is fixed (range_scale_sigma 0).
  double RangeScaleNis() const;
  /// Normalized innovation squared of the last processed update (accepted or gated).
  double last_nis() const { return last_nis_; }
  /// The node dropped beacon `beacon_key` where it is, within `drop_sigma_m`: the beacon's error
  /// is its own position error (cross-covariance P_x,p, covariance P_pp + drop^2), so ranging it
  /// later says how far the node moved, not where it is (options.consider_beacons).
  void ConsiderDrop(int beacon_key, double drop_sigma_m);
  /// Cross-covariance of the state with a considered beacon's position (zero when unused).
  Eigen::Matrix<double, kDim, 2> BeaconCrossCovariance(int beacon_key) const;
  std::size_t considered_beacons() const { return considered_.size(); }
  const ScaatEkfSummary& summary() const { return summary_; }
  const Options& options() const { return options_; }

 private:
  using Cross = Eigen::Matrix<double, kDim, 2>;
  // Joseph-form update with a measurement of dimension M.
  template <int M>
  // `outlier_density` > 0 (scalar updates only): the mixture update (options.mixture_updates)
  // with that density of the outlier component at the measurement; 0: the hard gate.
  UpdateResult Update(const Eigen::Matrix<double, M, 1>& innovation,
                      const Eigen::Matrix<double, M, kDim>& H, const Eigen::Matrix<double, M, M>& R,
                      double gate, const Admit& admit = nullptr, double outlier_density = 0,
                      double outlier_probability = 0);
  // The measurement's inlier probability under the mixture (1 without one) given its
  // innovation y and innovation variance S; < options.min_inlier_probability: not applied.
  double InlierProbability(double y, double S, double outlier_density,
                           double outlier_probability) const;
  // Scalar update that depends on a considered beacon (H_b = dh / d beacon position).
  UpdateResult UpdateConsider(double innovation, const Eigen::Matrix<double, 1, kDim>& H,
                              const Eigen::RowVector2d& H_b, double r, int beacon_key,
                              const BeaconPosition& beacon, double gate, const Admit& admit,
                              double outlier_density = 0, double outlier_probability = 0);
  // Column (of cross_, in pairs) of the considered beacon `key`, added when new (uncorrelated
  // with the state, covariance `beacon_cov`); when the map's covariance of it changed, its rows
  // and columns are rescaled to it with their correlations kept (a
  // congruence with T = B_old^-1/2 B_new^1/2: the joint covariance stays positive semidefinite).
  int Consider(int key, const Mat2& beacon_cov);
  int AppendBeacon(int key);
  void Condition();


  Options options_;
  State x_ = State::Zero();
  Cov P_ = Cov::Identity();
  // The considered beacons (Schmidt): cov(state, beacons) kDim x 2n and cov(beacons) 2n x 2n,
  // the beacons in the order of slots_ (beacon key per pair of columns), at most
  // options.max_considered_beacons (the least recently used is marginalized out).
  Eigen::MatrixXd cross_, beacons_;
  std::vector<int> slots_;
  std::vector<std::size_t> last_used_;
  std::size_t uses_ = 0;
  std::map<int, int> considered_;  ///< key -> slot
  double last_nis_ = 0;
  double step_fraction_ = 0;
  ScaatEkfSummary summary_;
};

struct UltrasoundOnlyKfOptions {
  double accel_sigma_mps2 = 0.7;  ///< white-noise acceleration (walking)
  double initial_position_sigma_m = 0.1;
  double initial_velocity_sigma_mps = 1.0;
  double range_sigma_m = 0.30;
  double bearing_sigma_rad = 0.57;
  double gate_chi2_2dof = 11.83;
};

/// The paper's ultrasound-only baseline (sec. 7.C): (x, y, vx, vy), constant velocity, every
/// range/bearing converted to a position.
class UltrasoundOnlyKf {
 public:
  using Options = UltrasoundOnlyKfOptions;
  UltrasoundOnlyKf(const Vec2& position_n, TimeS t, Options options = {});
  void PredictTo(TimeS t);
  UpdateResult UpdatePosition(TimeS t, const BeaconPosition& beacon, double range_m,
                              double bearing_rad, double range_sigma_m = 0,
                              double bearing_sigma_rad = 0);
  Vec2 position() const { return x_.head<2>(); }
  Mat2 position_cov() const { return P_.topLeftCorner<2, 2>(); }
  std::size_t accepted() const { return accepted_; }
  std::size_t gated() const { return gated_; }

 private:
  Options options_;
  TimeS t_;
  Eigen::Vector4d x_ = Eigen::Vector4d::Zero();
  Eigen::Matrix4d P_ = Eigen::Matrix4d::Identity();
  std::size_t accepted_ = 0, gated_ = 0;
};

/// The paper's conversion of (range, bearing) from a beacon to a position with its covariance
/// (first-order propagation of the polar noise plus the beacon's uncertainty).
void PolarToPosition(const BeaconPosition& beacon, double range_m, double bearing_rad,
                     double range_sigma_m, double bearing_sigma_rad, Vec2* position_n, Mat2* cov);

/// One ultrasound measurement for the initialization: at the moment the PDR track (cumulative
/// PDR displacement from the first buffered sample) was at `pdr_n`.
struct InitMeasurement {
  Vec2 pdr_n = Vec2::Zero();
  Vec2 beacon_n = Vec2::Zero();
  double range_m = 0, range_sigma_m = 0.30;
  std::optional<double> bearing_rad;
  double bearing_sigma_rad = 0.57;
};

struct InitOptions {
  int min_measurements = 10;
  int min_beacons = 2;               ///< or one beacon once the walk is long enough:
  double min_track_m = 3.0;          ///< PDR track length that makes a single beacon enough
  double min_heading_track_m = 2.0;  ///< the heading needs this much walk in any case
  int heading_grid = 24;             ///< initial headings tried (15 deg apart)
  double huber_k = 1.5;              ///< robust loss threshold (in sigmas)
  double max_rms_normalized = 2.0;   ///< reject a solution whose residuals are too large
};

struct InitResult {
  bool ok = false;
  Vec2 origin_n = Vec2::Zero();  ///< position at the first buffered sample
  double psi_rad = 0;            ///< rotation from the PDR frame to the navigation frame
  Eigen::Matrix3d cov = Eigen::Matrix3d::Identity();  ///< of (origin x, origin y, psi)
  double rms_normalized = 0;
  std::string why;  ///< when not ok
  /// The position of a PDR-track point in the navigation frame.
  Vec2 Map(const Vec2& pdr_n) const;
};

/// The filter that continues from an initialization at the PDR-track point `pdr_n` (position,
/// heading correction and their covariance propagated; scale from the options' prior).
ScaatEkf StartFromInit(const InitResult& init, const Vec2& pdr_n, const ScaatEkfOptions& options);

/// Where the PDR track's origin is known to be (a start without a heading: only the rotation
/// from the PDR frame to the navigation frame is unknown).
struct OriginPrior {
  Vec2 position_n = Vec2::Zero();
  double sigma_m = 0.1;  ///< > 0
};

/// `origin`: a Gaussian prior on the origin (the grid's starts are placed there).
InitResult InitializeFromUltrasound(const std::vector<InitMeasurement>& measurements,
                                    const InitOptions& options = {},
                                    const std::optional<OriginPrior>& origin = std::nullopt);

}  // namespace trailmark::beacons

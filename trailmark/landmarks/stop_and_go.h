// SPDX-License-Identifier: MIT
#pragma once
/// Stop-and-go localization of radio landmarks and standing positions (radio-landmarks paper,
/// sec. 5.3, eqs. (6)-(17)). The handheld stops at q positions H_p and measures a range z_pj to
/// each of B landmarks S_j (from averaged RSSI through eq. (5)); the residuals
///   f_pj = |H_p - S_j| - z_pj                                                     (6)
/// are minimized over the unknowns (eq. 9) by gradient descent with an adaptive step (eq. 16)
/// until the cost is steady, then Gauss-Newton with an SVD pseudo-inverse (eq. 17). Jacobian
/// rows: df/dS_j = -(H_p - S_j)/|H_p - S_j| (13), df/dH_p = +(H_p - S_j)/|H_p - S_j| (14).
///
/// Beyond the paper: a robust loss (Huber or Cauchy, by iteratively reweighted least squares)
/// for NLOS outliers — the paper's future work; an honest initialization (grid search of each
/// unknown landmark against the standing positions, instead of starting "on the side of the true
/// value"); solvability (eq. 8) and degenerate geometry (collinear standing positions or
/// landmarks: a mirror solution) checked and reported. Positions may be known (fixed), e.g.
/// standing positions from the IMU, or landmarks for handheld localization. No I/O.

#include <Eigen/Core>
#include <optional>
#include <string>
#include <vector>

#include "trailmark/core/types.h"

namespace trailmark::landmarks {

enum class Loss { kSquared, kHuber, kCauchy };

struct StopAndGoOptions {
  Loss loss = Loss::kHuber;
  double robust_k = 2.0;             ///< Huber/Cauchy k, in sigmas of the normalized residual
  int max_gd_iterations = 500;
  double gd_initial_step = 0.05;     ///< lambda of eq. (16), adapted: x1.2 on success, /2 on failure
  double steady_relative_change = 1e-3;  ///< GD -> GN when the cost changes less than this
  int max_gn_iterations = 50;
  double gn_tolerance_m = 1e-6;
  double svd_relative_threshold = 1e-9;  ///< pseudo-inverse cut-off (eq. 17 "with SVD")
  double init_grid_m = 0.25;
  double init_margin_m = 5.0;
  /// > 0: the grid search of an unknown position uses at most this many of its measurements,
  /// evenly spaced (it only finds the basin; the descent uses them all). 0: all.
  int init_max_anchors = 0;
};

struct StopAndGoProblem {
  std::vector<Vec2> landmarks;          ///< initial/known positions S_j (B)
  std::vector<bool> landmark_known;     ///< fixed when true
  /// Unknown landmarks whose entry in `landmarks` is the starting point of the descent (a
  /// previous solution); the others are initialized by grid search. Empty: all by grid search.
  std::vector<bool> landmark_start_given;
  std::vector<Vec2> standing;           ///< initial/known positions H_p (q)
  std::vector<bool> standing_known;
  /// Measured ranges z[p][j] (metres); empty when landmark j was not heard at stop p.
  std::vector<std::vector<std::optional<double>>> range_m;
  /// Per-measurement sigma (metres; same shape), e.g. from the distance-dependent RSSI model.
  std::vector<std::vector<double>> sigma_m;
  /// Ours, beyond the paper: a joint Gaussian prior on the unknown standing positions, e.g. the
  /// dead reckoning's (its heading and scale errors are shared by all of them, so the prior is
  /// not diagonal). Its mean is their entries in `standing` (where the descent starts; no grid
  /// search), this its information matrix (inverse covariance), 2u x 2u over the u unknown
  /// standing positions in their order. Empty: no prior.
  Eigen::MatrixXd standing_prior_information;
  /// Ours: > 0 gives an unknown landmark a prior N(landmarks[j], sigma^2 I) and starts it there
  /// (a surveyed landmark with its survey's sigma, instead of fixed). Empty or 0: none.
  std::vector<double> landmark_prior_sigma_m;
  /// Ours: the ranges' calibration estimated with the positions. Ranges read from RSSI through
  /// a log-distance model whose intercept or exponent is off (stale, default, another radio)
  /// are z = e^a d^b of the true distance d for every link alike (a: the intercept's error,
  /// b: the exponent's ratio), so each range is corrected to (ln z - a) / b in the log and two
  /// unknowns with priors a ~ N(0, log_scale_sigma^2), b ~ N(1, exponent_ratio_sigma^2) join
  /// the problem. Empty: the ranges are taken as they are (the paper).
  struct RangeCalibration {
    double log_scale_sigma = 1.0;
    double exponent_ratio_sigma = 0.5;
  };
  std::optional<RangeCalibration> range_calibration;
};

struct StopAndGoResult {
  std::vector<Vec2> landmarks, standing;
  /// Marginal covariances from the final Gauss-Newton information (pseudo-inverse), scaled by
  /// the residual variance when it exceeds the stated sigmas; zero for known positions.
  std::vector<Mat2> landmark_cov, standing_cov;
  /// With a standing prior: the joint covariance of the unknown standing positions (2u x 2u, in
  /// their order), scaled as the marginals are.
  Eigen::MatrixXd standing_joint_cov;
  /// With range_calibration: the estimated a (log scale) and b (exponent ratio) and their sigmas.
  double range_log_scale = 0, range_exponent_ratio = 1;
  double range_log_scale_sigma = 0, range_exponent_ratio_sigma = 0;
  int gd_iterations = 0, gn_iterations = 0;
  double cost = 0;                 ///< final robust cost
  /// Degrees of freedom: measurements (priors included) minus unknowns; 2 x cost against the
  /// chi-square quantile of these is the solve's consistency test.
  int dof = 0;
  double rms_residual_m = 0;
  bool solvable = true;            ///< eq. (8) / observation count check
  bool degenerate = false;         ///< mirror ambiguity from collinear geometry
  std::vector<std::string> notes;  ///< why not solvable / degenerate, which landmark
};

/// Eq. (8): q >= 2B / (B - 2) (both landmarks and standing positions unknown).
bool SolvableStopAndGo(int landmarks, int standing_positions);

/// Solves the problem; unknown landmarks are initialized by grid search from the known (or
/// initial) standing positions. Never throws on bad geometry: reports it.
StopAndGoResult SolveStopAndGo(StopAndGoProblem problem, const StopAndGoOptions& options = {});

}  // namespace trailmark::landmarks

// SPDX-License-Identifier: MIT
#pragma once
/// The beacon map as one sparse nonlinear least-squares problem (issue 22; beyond the paper,
/// whose map is MDS of the completed distance matrix): every beacon-to-beacon range as a
/// residual under a robust loss, every surveyed beacon and every drop position as a Gaussian
/// prior on its beacon, solved by Levenberg-Marquardt (Ceres) from one or several starts, the
/// lowest cost kept (a chain of triangles folds either way; the priors say which). Marginal
/// covariances of each beacon from the Jacobian at the solution, and the test of the solution's
/// residuals against their stated noise (a map that disagrees with its noise is not to be
/// used). No I/O.

#include <optional>
#include <string>
#include <vector>

#include "trailmark/core/types.h"

namespace trailmark::beacons {

struct MapLink {
  int i = 0, j = 0;       ///< beacon indices, i != j
  double range_m = 0;     ///< the pair's measured distance (e.g. the median of its samples)
  double sigma_m = 0.1;   ///< of `range_m` (for a median of n: 1.2533 sigma / sqrt(n))
  /// Timed at the speed of sound (ultrasound): read as k |p_i - p_j| with the problem's range
  /// scale k when it has one (MapProblem::range_scale_sigma).
  bool scaled = false;
};

/// The errors a dead reckoning shares between all the positions it gives (ins/dead_reckoning.h):
/// e = [heading offset rad, heading rate rad/s, step scale, turn scale], zero mean, covariance
/// `cov`. Drop priors of one track are correlated through e: its states are estimated with the
/// map.
inline constexpr int kTrackErrors = 4;
using TrackVec = Eigen::Matrix<double, kTrackErrors, 1>;
using TrackCov = Eigen::Matrix<double, kTrackErrors, kTrackErrors>;
/// d position / d e at a point of a track.
using TrackLever = Eigen::Matrix<double, 2, kTrackErrors>;
struct MapTrack {
  TrackCov cov = TrackCov::Identity();  ///< symmetric positive definite
  /// Of its errors, how many the positions depend on (the chi-square tests' degrees of
  /// freedom): 3 when the turn scale is held at a negligible prior with no lever.
  int dof = kTrackErrors;
};

/// A Gaussian prior on a beacon: position_n + along e (its track's shared errors, when `track`
/// >= 0) + white noise of covariance `cov`.
struct MapPrior {
  int i = 0;
  Vec2 position_n = Vec2::Zero();
  Mat2 cov = Mat2::Identity();  ///< symmetric positive definite
  int track = -1;
  /// d position / d e at this prior: [perp(sum d), sum (t - t0) perp(d), sum d, sum turned
  /// perp(d)] over the track's steps up to the drop (perp(x, y) = (-y, x); turned: the walking
  /// direction's turn since the first step, up to that step).
  TrackLever along = TrackLever::Zero();
  /// >= 0: the prior is on the displacement from beacon `from` (the same track's previous
  /// drop, whose position_n and along are `from_position_n`, `from_along`): the dead
  /// reckoning's white errors are independent between drops, not at each drop. `cov` is then
  /// the covariance of that displacement.
  int from = -1;
  Vec2 from_position_n = Vec2::Zero();
  TrackLever from_along = TrackLever::Zero();
};

/// An agent's range to a beacon from a point of its dead-reckoning track (issue 22, item 1: an
/// agent walking back hears beacons dropped long before, across the trail — the loop closure
/// that neighbour-only beacon links lack). The agent's state there is a nuisance of the problem,
/// [x, y, h]: its position and its dead reckoning's white heading error h (the heading random
/// walk's accumulated part; the shared errors are its track's e). A chain of sightings is the
/// dead reckoning's own Markov chain: from the track's previous sighting A,
///     p = p_A + D + h_A perp(D) + (along - along_A) e + w,   h = h_A + v,
/// D = position_n - position_n_A, [w; v] of covariance `cov` (the walk between the two alone:
/// step noise and heading walk, from no error at A). A chain's first sighting has the absolute
/// prior p = position_n + along e + w, h = v, `cov` the white covariance there. The range ties p
/// to beacon `i` under a redescending loss (a moving foot's ranges have ~10 % outliers: sec. 3.B).
struct MapSighting {
  int i = 0;  ///< the beacon heard
  double range_m = 0;
  double sigma_m = 0.3;  ///< of one range from a moving foot (the tracker's)
  int track = 0;         ///< >= 0
  Vec2 position_n = Vec2::Zero();
  TrackLever along = TrackLever::Zero();
  /// d heading / d e there: [1, t - t0, 0, turned] (the offset, the rate's time, the turn
  /// scale's angle turned since the track's first step).
  TrackVec heading_along = TrackVec::Zero();
  Mat3 cov = Mat3::Identity();  ///< symmetric positive definite
  int from_sighting = -1;       ///< the same track's previous sighting, an earlier index; -1: none
  /// Where the solver starts it (e.g. the last solve's): empty, its dead reckoning moved as
  /// its chain's previous sighting was (a redescending loss needs a start near the answer).
  std::optional<Vec3> start;
};

struct MapProblem {
  int beacons = 0;
  std::vector<MapLink> links;
  /// > 0: the scaled links share one unknown scale k (the speed of sound the devices assume
  /// over the air's), prior 1 +- this; observable through two or more surveyed beacons, whose
  /// distance the ranges do not set. 0: the ranges as they are.
  double range_scale_sigma = 0;
  std::vector<MapPrior> priors;
  std::vector<MapTrack> tracks;
  std::vector<MapSighting> sightings;
  /// Where the solver starts each track's e (e.g. the last solve's); empty: zero.
  std::vector<TrackVec> track_start;
};

struct MapLeastSquaresOptions {
  /// Huber loss on each link's whitened residual beyond this many sigmas (a pair whose every
  /// sample was long, NLOS, pulls linearly, not quadratically).
  double link_huber_sigma = 2.0;
  /// Tukey's biweight on each sighting's whitened range residual: beyond this many sigmas a
  /// range has no weight (4.685: 95 % efficiency at the Gaussian; Huber's linear pull of a 3 m
  /// outlier from a 0.3 m sigma would bend the track).
  double sighting_tukey_sigma = 4.685;
  /// A chain of sightings turns each displacement by its heading error exactly (a rotation),
  /// not to first order (false: D + phi perp(D)).
  bool sighting_chain_rotation = true;
  /// A chain's first state has the dead reckoning's marginal there as its prior (the shared
  /// errors' share J cov_e J^T added to the white covariance, J = [along; heading_along]), not
  /// the first-order lever on e (14 m from the entry at a heading error of 0.3 rad that lever
  /// is 0.6 m off; the chain's displacements keep their exact hold on e). False: the lever.
  bool sighting_start_marginal = true;
  /// Ceres' Levenberg-Marquardt iterations (Gauss-Newton's J^T J) at most, from each start.
  int max_iterations = 100;
  /// Then Newton's method on the exact Hessian (ours; J^T J plus the terms Gauss-Newton leaves
  /// out: each range's curvature across its line of sight times its residual, the robust
  /// losses' second derivative, a chain's turn of its displacement), damped only where that
  /// Hessian is not positive definite or a step does not lower the cost, until a step moves no
  /// unknown by more than `newton_step_tolerance`. Gauss-Newton converges only linearly where a
  /// beacon's position across its links is held by its ranges' curvature (beacons nearly in a
  /// line with their neighbours on a trail): Ceres crawled to its cap there and stopped at a
  /// point that depended on the frame by millimetres (docs/beacons.md). 0: Ceres alone.
  int newton_iterations = 20;
  double newton_step_tolerance = 1e-10;  ///< m, rad and the scale's units
  /// ... or when no |gradient| of the cost is above this (cost per unit of the unknowns; a
  /// direction held as loosely as 10 m sigma is then within 1e-7 m of its minimum).
  double newton_gradient_tolerance = 1e-9;
  /// The solution's robust chi-square is tested against its degrees of freedom at this false
  /// alarm rate (a map that disagrees with its noise: wrong fold, a moved anchor).
  double false_alarm = 1e-3;
  bool covariances = true;
  /// The marginals by ceres::Covariance (SPARSE_QR) instead of our sparse Cholesky: the
  /// reference the tests compare with (slower: 0.9 s against 0.1 s at 1,000 beacons).
  bool reference_covariance = false;
  bool IsValid(std::string* why) const;
};

struct MapSolution {
  bool ok = false;                   ///< solved and covariances (when asked) computed
  std::string why;                   ///< when not ok
  std::vector<Vec2> position_n;      ///< per beacon
  std::vector<Mat2> cov;             ///< per beacon (marginal), when options.covariances
  double chi2 = 0;                   ///< 2 x the final robust cost (whitened residuals)
  double chi2_links = 0;             ///< the links' part of chi2 (robust)
  double chi2_priors = 0;            ///< the priors' part (surveys, drops, tracks' errors)
  /// The sightings' part (their ranges, robust, and their displacement priors). Not in the
  /// consistency test: a moving foot's heavy-tailed ranges under a redescending loss have no
  /// chi-square distribution; reported.
  double chi2_sightings = 0;
  int prior_residuals = 0;  ///< scalar residuals of the priors (2 each, a track's dof)
  /// Of the test: links + priors' scalar residuals - 2 x beacons (the sightings add one range
  /// and two prior residuals for two unknowns each, and are left out with their chi2).
  int dof = 0;
  double chi2_threshold = 0;         ///< the chi-square quantile at 1 - false_alarm (dof > 0)
  bool consistent = true;            ///< chi2 <= chi2_threshold (or dof <= 0)
  int start = 0;                     ///< index of the start that won
  int iterations = 0;                ///< Ceres' iterations at the start that won
  int newton_iterations = 0;         ///< Newton's steps taken after them
  /// The largest |gradient| of the cost at the solution, in cost per unit of the unknowns
  /// (converged: round-off, ~1e-9 and below; 0 without Newton's steps).
  double max_gradient = 0;
  /// The marginals are the exact Hessian's, J^T J being singular at the solution (a beacon on
  /// the line through its two neighbours; MapLeastSquaresOptions::newton_iterations > 0).
  bool exact_hessian_covariance = false;
  std::vector<double> start_chi2;    ///< per start
  std::vector<TrackVec> track_errors;  ///< the estimated e of each track
  std::vector<Vec3> sighting_state;    ///< [x, y, h] of the agent at each sighting
  int sighting_outliers = 0;           ///< sightings whose range is beyond the Tukey bound
  /// The scaled links' k and its marginal variance (1 and 0 without one).
  double range_scale = 1.0;
  double range_scale_var = 0.0;
};

/// Solves `problem` from each of `starts` (each a position per beacon) and keeps the lowest
/// cost. Throws std::invalid_argument for indices out of range, non-finite values, sigmas <= 0,
/// a prior covariance that is not positive definite, or a start of the wrong size. The gauge
/// must be fixed by the priors (two beacons with priors in every connected part): otherwise the
/// solution is not ok ("not anchored").
MapSolution SolveMapLeastSquares(const MapProblem& problem, const std::vector<std::vector<Vec2>>& starts,
                                 const MapLeastSquaresOptions& options = {});

/// The cost SolveMapLeastSquares minimizes (half the robust chi-square) at x, and its exact
/// Hessian as Newton's steps use it (J^T J and the second-order terms), for the tests. x holds 2
/// unknowns per beacon, kTrackErrors per track, 3 per sighting and the range scale last when
/// the problem has one; throws std::invalid_argument for another size.
double MapCost(const MapProblem& problem, const MapLeastSquaresOptions& options,
               std::vector<double> x);
Eigen::MatrixXd MapCostHessian(const MapProblem& problem, const MapLeastSquaresOptions& options,
                               std::vector<double> x);

}  // namespace trailmark::beacons

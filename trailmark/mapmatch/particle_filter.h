// SPDX-License-Identifier: MIT
#pragma once
/// The information fusion of the map-aided search paper (sec. IV-E): a particle filter whose
/// particles carry a position and the heading offset between the odometry frame and the map.
///  - time update: the odometry displacement rotated by each particle's offset, plus Gaussian
///    noise (0.12 m per axis; 2 deg per metre walked on the offset); ours, for a step that states
///    its own errors (a foot INS): that step's noise, and each particle's own draw of the dead
///    reckoning's shared errors (StatedStep, SharedStepErrorPrior);
///  - map: a particle whose step crosses a wall is eliminated (spatial index of the walls);
///  - pseudo observations (eq. 2-3): each particle takes the pattern observation at its nearest
///    node whose heading is closest to its walking heading; weight x exp(-E / sigma^2);
///    particles below the floor eps = 0.01 / N are replaced by copies of the others;
///  - resampling from the pseudo observations: the q = 10 % lowest-weight particles are
///    redrawn from (Pos, Hea) in proportion to the likelihood, with noise (0.5 m, 25 deg).
/// Beyond the paper, stated: systematic resampling when the effective sample size falls below
/// N/3 (the floor alone lets weights degenerate); when every particle hits a wall, the step is
/// retried from the same particles with wider noise (backtracking, up to 3 times) and only then
/// restarted (uniform, or around the last estimate); a softer likelihood (tracking sigma) once
/// the track has been found; optionally a robust likelihood. The estimate
/// is the MMSE mean with its covariance. Deterministic per seed. No I/O.

#include <cstdint>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "trailmark/core/random.h"
#include "trailmark/geometry/distance_field.h"
#include "trailmark/mapmatch/pattern_comparison.h"

namespace trailmark::mapmatch {

struct MapParticleFilterOptions {
  int particles = 500;                        ///< N_p (sec. V-B)
  double position_noise_m = 0.12;             ///< per time update, per axis (sec. V-B)
  double heading_noise_rad_per_m = 0.0349;    ///< 2 deg per metre walked (sec. V-B)
  double likelihood_sigma = 0.1;              ///< sigma of eq. (2), sqrt(m) (sec. V-B)
  double weight_floor = 0.01;                 ///< eps = weight_floor / N (sec. V-B)
  bool pseudo_observations = true;            ///< eq. (2)-(3)
  bool resample_from_patterns = true;         ///< sec. IV-E, last paragraph
  double resample_fraction = 0.10;            ///< q (sec. V-B)
  double resample_position_sigma_m = 0.5;     ///< sec. V-B
  double resample_heading_sigma_rad = 0.436;  ///< 25 deg (sec. V-B)
  double ess_resample_fraction = 1.0 / 3;     ///< ours: systematic resampling below N/3
  /// Ours: a particle that ends a step outside the building (1 m grid cells not enclosed by
  /// the walls, e.g. through an entry the map shows open) is eliminated like one that crossed a
  /// wall, unless every particle would be (the walker left). false: the paper.
  bool stay_inside = true;
  /// The inside test of stay-inside and of every draw: false, the 1 m grid cells (a point is
  /// inside when its nearest node is); true, SearchGrid::Contains (exact: the point reaches a
  /// nearby inside node without crossing a wall or a closed door; issue 23). Exact is no better
  /// on the houses (unknown start, house 1, 300 held-out searches: mean from 2 min 0.60 against
  /// 0.55 m, errors above 2 m 8 against 5 of 1,800; docs/mapmatch.md), so not the default: on
  /// the grid along the walls the cells misjudge only points near walls at other angles.
  bool exact_inside = false;
  /// Ours: the pattern likelihood as a mixture alpha + (1 - alpha) exp(-E/sigma^2), relative
  /// to the best match — a match can be wrong (furniture, a search that leaves the pattern),
  /// and alpha bounds what one wrong match can do to the particles at the true position.
  /// 0 is the paper's likelihood.
  double outlier_weight = 0.0;
  /// Ours: a comparison whose best match anywhere is worse than this is not used (the walk
  /// is not a directional search along the map's walls, e.g. down the middle of a corridor, or
  /// the map is wrong there). Infinity = always use (the paper).
  double max_match_rmse_m = 0.6;
  /// Ours, after the paper's own conclusion ("the pattern comparison is of most use before the
  /// filter has converged ... or when the uncertainty has increased due to map errors"): pseudo
  /// observations are used only while the position variance (trace) exceeds this. 0 = always
  /// (the paper; `trailmark reproduce mapmatch` shows both).
  double use_patterns_above_variance_m2 = 2.0;
  /// Ours: once the filter has converged (variance at or below the level above), the pattern
  /// observations come back only when it is lost again: variance above this (hysteresis; a
  /// converged filter that drifts a little is better served by the walls than by a comparison
  /// that furniture can fool). 0 = no hysteresis.
  double relocalize_above_variance_m2 = 0.0;
  /// Ours: the same for a known start, whose filter is on track from the first step: it
  /// compares again only when its variance exceeds this (or after a wall alarm). Walking a
  /// corridor spreads the belief along it; on a large floor with repeating corridors (a real
  /// office floor: 2,500 m^2) a comparison then draws particles into the wrong corridors and
  /// a known start was lost by 6-25 m, against 0.3-1.0 m without (docs/mapmatch.md). 0 = as a
  /// uniform start.
  double known_start_relocalize_above_variance_m2 = 8.0;
  /// Ours: from an unknown start, the filter counts as converged (and skips comparisons) only
  /// after this many pattern comparisons have been used: walls and the wall-following model
  /// alone can settle a confident belief in the wrong corridor of a large building.
  int confirm_pattern_updates = 5;
  /// Ours (issue 23): only a distinctive comparison confirms — every match whose RMSE is within
  /// 3 sigma^2 of the best (a likelihood ratio of e^-3 or more by eq. 2) lies within this
  /// distance of those matches' mean position. On a large floor with repeating corridors a straight
  /// stretch matches equally well in a hundred places 50 m apart; such a comparison still weights
  /// and draws particles (the paper), but it does not tell the filter where it is. 0: every
  /// comparison confirms (as before).
  double confirm_distinct_m = 3.0;
  /// Ours: map-error and lost-track evidence — the share of the belief that a step drives into
  /// walls (LastBlockedMass) accumulated as a one-sided CUSUM with reference k; above h, a
  /// wall alarm: the walk keeps crossing the map's walls (a map error, or a converged filter
  /// that has drifted off the track). Chosen on house-1 searches, seeds 1-10 (docs/mapmatch.md).
  double wall_alarm_k = 0.2;
  double wall_alarm_h = 1.75;
  /// Ours: on a wall alarm, with pseudo observations on, the filter recovers: every particle is
  /// spread by these (staying inside the building) and the pattern observations are used for
  /// the next recover_pattern_updates comparisons whatever the variance. A converged filter's
  /// particles collapse (wall eliminations replace them by copies of the survivors) and then
  /// drift off the track with the odometry's heading error; the walls tell. Chosen on seeds
  /// 1-30 of both houses, checked on seeds 31-60 (docs/mapmatch.md). false: alarm only.
  bool recover_on_wall_alarm = true;
  double recover_position_sigma_m = 2.0;
  double recover_heading_sigma_rad = 0.3;
  int recover_pattern_updates = 5;
  /// Whether those forced comparisons also weight the particles (eq. 2) once the filter has
  /// settled again (variance at or below the pattern level); false: they only draw new ones.
  bool recover_reweight_converged = false;
  /// Ours: the directional search as a motion model. A firefighter searching left- or
  /// right-hand keeps a hand on the wall, so after each step the map should have a wall about
  /// `wall_follow_offset_m` to the particle's search side (each particle carries the hand, left
  /// or right, as a hypothesis; particles drawn from a pattern observation take its hand).
  /// Furniture that the map does not show is followed too, for metres at a time, so each
  /// particle also carries whether the walker is following something the map does not have
  /// (a two-state hidden Markov chain, per step: leave the map's walls with probability
  /// `wall_follow_leave`, come back with `wall_follow_return`). Following a map wall, the step's
  /// likelihood is exp(-dd^2 / 2 s^2), dd = distance from the point at the offset on the search
  /// side to the nearest wall; following something else it is `wall_follow_off_likelihood`.
  /// leave + return = 1 makes it the memoryless mixture leave + (1 - leave) exp(...). Used at
  /// every step while the filter is uncertain; once converged, raised to
  /// `wall_follow_converged_power` (1: the same; 0: not used, as the pattern observations).
  /// Defaults chosen on house searches with seeds 1-60 and checked on seeds 61-120
  /// (docs/mapmatch.md); false: the paper.
  bool wall_follow = true;
  double wall_follow_offset_m = 0.55;  ///< arm's length (sec. II: hand on the wall)
  double wall_follow_sigma_m = 0.25;
  double wall_follow_leave = 0.05;
  double wall_follow_return = 0.15;
  double wall_follow_off_likelihood = 0.6;
  double wall_follow_converged_power = 1.0;
  /// The same power for a step with its own statement (Predict with a StatedStep: a foot INS
  /// within its noise model). The model's likelihood is evidence about where the walker stands,
  /// taken at every step as if new: true while the paper's motion noise (0.12 m a step) moves
  /// each particle's distance to the wall between steps, but a foot INS's steps (2-3 cm) carry
  /// that distance from step to step, and the same evidence counted a hundred times pulls the
  /// belief onto the model's offset from the wall (the landmark office's corridor walks, foot
  /// IMU seeds 430-435: the map matcher 0.51-0.64 m p75 with 1, 0.39-0.43 m with 0, dead
  /// reckoning 0.42-0.43 m; docs/mapmatch.md). 0: only while uncertain (finding the place,
  /// after a wall alarm), as the pattern comparisons.
  double stated_wall_follow_converged_power = 0.0;
  /// Ours: a walker who does not search (walks a corridor's middle along a beacon trail,
  /// crosses a room) as a second motion model beside the wall-following one. A share
  /// `free_walk_share` of the belief is free walkers (hand 2): the wall-following likelihood is
  /// not applied to them; applied to the searchers, it is renormalized within them (a prior on
  /// where a searcher stands). Walls eliminate particles within each model and the model keeps
  /// its share: a searcher's prior keeps its particles away from walls that a free walker's
  /// particles diffuse into, so weighing the models by eliminations made the searchers win on
  /// a trail walked down the middle (the free share fell 0.5 -> 0.15), where they are wrong. In
  /// a plain corridor the data cannot tell the two apart; the share is a stated prior, and
  /// only the pattern comparisons move belief between the models. Per step a particle becomes
  /// a free walker with probability free_walk_switch x share and a searcher with
  /// free_walk_switch x (1 - share). The filter's "uncertain" (pattern comparisons, the
  /// wall-following weight's power, convergence) reads the searchers' variance: the free
  /// walkers' wider spread is the reported uncertainty, not a reason to compare patterns (a
  /// known start on the multi-floor building compared, and was lost, where the searchers were
  /// sure). 0: the wall-following model alone (before 2026-12-06). 0.5 and 0.1 chosen on the
  /// neighbour trail 401-410 and house searches 1-10, checked on 511-530 / 611-630
  /// (docs/mapmatch.md).
  double free_walk_share = 0.5;
  double free_walk_switch = 0.1;
  /// Weight (x 1/N) of a particle drawn from the pseudo observations; 1 = as much as an
  /// average particle (ours: the paper does not say).
  double new_particle_weight = 1.0;
  /// Ours: sigma of eq. (2) for weighting the particles once the track has been found (the
  /// filter has converged, and from an unknown start been confirmed, at least once since its
  /// last uniform start); before that, likelihood_sigma. Finding the track among every place
  /// of the building needs the paper's sharp likelihood. Once found, a comparison mostly
  /// re-checks a belief that the walls carry, and a wrong match (furniture walked round, a
  /// room like the one searched) must not override it: consecutive comparisons share 90 % of
  /// their points and are not independent evidence. Draws from the observations keep
  /// likelihood_sigma. 0.3 chosen on seeds 1-60 and 361-420 of both houses, checked on
  /// 421-480, 601-660 and 661-720; 0.5 once the simulated odometry no longer had spurious
  /// heading jumps (2026-11-23: the same seeds, checked on 721-840; docs/mapmatch.md).
  /// 0 = likelihood_sigma throughout (the paper).
  double tracking_likelihood_sigma = 0.5;
  /// KLD-sampling (Fox 2003, "Adapting the sample size in particle filters through
  /// KLD-sampling", IJRR 22(12); ours, not the paper's): at each systematic resampling the
  /// number of particles becomes the one that bounds, with probability `kld_quantile`, the
  /// Kullback-Leibler distance between the particles' histogram and the belief by
  /// `kld_epsilon`: n = chi^2_{k-1}(kld_quantile) / (2 epsilon), k the histogram bins the
  /// resampled particles occupy (bins of `kld_bin_m` along the search grid's axes, of
  /// `kld_bin_rad` of heading offset, and the search hand), within [kld_min_particles,
  /// particles]. A uniform start, a recovery and a restart go back to `particles`. 0: off, a
  /// fixed number of particles (the paper).
  double kld_epsilon = 0.0;
  double kld_quantile = 0.99;   ///< 1 - delta (Fox: delta = 0.01)
  double kld_bin_m = 0.5;       ///< bin size of position (m; AMCL's default)
  double kld_bin_rad = 0.1745;  ///< bin size of heading offset (10 deg; AMCL's default)
  int kld_min_particles = 100;  ///< the fewest particles (AMCL's default)
  std::uint64_t seed = 1;
  bool IsValid(std::string* why) const;
};

/// The dead reckoning's shared errors (ins/dead_reckoning.h: one value for every step of an
/// agent) as each particle's own hypotheses, their prior sigmas (MapParticleFilter::
/// UseSharedErrors). Ours (issue 23): the paper's motion noise is white per step; a foot INS's
/// error is mostly not (its step-length scale, its gyro's scale over turns, the bias its stance
/// updates leave), and a particle that carries them moves as a dead reckoning with those errors
/// would, the walls deciding between them.
struct SharedStepErrorPrior {
  double step_scale_sigma = 0.0;               ///< step-length scale (fraction)
  double turn_scale_sigma = 0.0;               ///< gyro scale factor over turns (fraction)
  double heading_drift_sigma_rad_per_s = 0.0;  ///< heading drift rate, standing included
};

/// A step's own statement of its white errors, with what the shared errors act on: the time
/// update of MapParticleFilter::Predict for steps of a source within its noise model.
struct StatedStep {
  double position_sigma_m = 0.0;   ///< per axis, the step's own noise
  double heading_sigma_rad = 0.0;  ///< the heading's random walk over the step
  double turn_rad = 0.0;           ///< the odometry's walking direction turned since the last step
  double dt_s = 0.0;               ///< time since the last step (standing included)
};

/// KLD-sampling's sample size (Fox 2003, eq. (9) before its Wilson-Hilferty approximation):
/// the number of samples that bounds the KL distance between the maximum-likelihood histogram
/// of k occupied bins and the true one by epsilon with probability `quantile`:
/// chi^2_{k-1}(quantile) / (2 epsilon); 1 for k <= 1.
double KldSampleSize(int occupied_bins, double epsilon, double quantile);

struct MapParticleFilterSummary {
  std::size_t time_updates = 0, pattern_updates = 0, uninformative_updates = 0;
  std::size_t ambiguous_updates = 0;  ///< used, but not distinctive (confirm_distinct_m)
  std::size_t wall_eliminations = 0, floor_replacements = 0, pattern_resamples = 0;
  std::size_t systematic_resamples = 0, backtracks = 0, restarts = 0, skipped_converged = 0;
  std::size_t wall_alarms = 0, recoveries = 0, outside_eliminations = 0;
  /// KLD-sampling: the particles after the last resampling, the fewest and the most, and the
  /// particle-steps (time updates x particles) the filter has carried.
  std::size_t particles_now = 0, particles_min = 0, particles_max = 0;
  std::size_t particle_steps = 0;
  std::string BriefReport() const;
};

/// The wall-following model's step (see MapParticleFilterOptions::wall_follow): the
/// likelihood of a step that ended at `position_n` walking along `heading_n_rad` (map frame)
/// for a search with the wall on the `left_hand` side (else right), given the walls' distance
/// field; `p_off_wall` (the probability that the walker follows something the map does not
/// show) is advanced by one step of the chain's forward recursion.
double WallFollowingLikelihood(const DistanceField& walls, const Vec2& position_n,
                               double heading_n_rad, bool left_hand,
                               const MapParticleFilterOptions& options, float& p_off_wall);

/// The distance field the wall-following model reads (0.1 m cells, clamped at 2 m), its raster
/// along `axis_rad` (the search grid's axes: a plan drawn rotated reads the same distances).
std::shared_ptr<const DistanceField> MakeWallDistanceField(const FloorPlan& plan,
                                                           double axis_rad = 0);

class MapParticleFilter {
 public:
  using Options = MapParticleFilterOptions;
  struct Particle {
    Vec2 position_n = Vec2::Zero();
    double heading_offset_rad = 0;  ///< odometry frame -> map frame
    double weight = 0;
    Vec2 step_from_n = Vec2::Zero();  ///< where its last time update started (for checks)
    std::uint8_t hand = 0;            ///< 0 left-hand search, 1 right-hand, 2 free walker
    float p_off_wall = 0;             ///< probability it follows no wall of the map
    /// Its shared step errors (UseSharedErrors; zero otherwise): the step-length scale, the
    /// gyro's scale over turns, the heading drift rate (rad/s).
    float step_scale = 0, turn_scale = 0, drift_rad_per_s = 0;
  };

  /// `grid` and the sequences must outlive the filter. `wall_distance`: the walls' distance
  /// field for the wall-following model, shared by the filters of one map (built here when
  /// null and the model is on).
  MapParticleFilter(const SearchGrid& grid, const std::vector<NodeSequence>& sequences,
                    Options options = {},
                    std::shared_ptr<const DistanceField> wall_distance = nullptr);
  ~MapParticleFilter();

  /// Known initial state (position, heading offset) with the given spread.
  void InitializeKnown(const Vec2& position_n, double heading_offset_rad, double position_sigma_m,
                       double heading_sigma_rad);
  /// Unknown initial state: uniform over the inside of the building and over the heading.
  void InitializeUniform();

  /// Continues the belief of `from`, a filter of another level of the same building (same
  /// frame; its number of particles): its particles where `keep` is non-zero, the others
  /// replaced by copies of those (by weight; every particle when none is kept), and its
  /// convergence state; the wall alarm's CUSUM starts again.
  void ContinueFrom(const MapParticleFilter& from, const std::vector<char>& keep);

  /// Each particle carries the dead reckoning's shared errors, drawn from `prior` for every
  /// particle drawn from now on (the initial ones included: call before Initialize*).
  void UseSharedErrors(const SharedStepErrorPrior& prior);
  /// Odometry displacement (odometry frame) since the last update. Without `stated`, the
  /// paper's motion noise; with it, the step's own white noise, and each particle's shared
  /// errors (UseSharedErrors) act on the displacement, the turn and the time.
  void Predict(const Vec2& delta_odometry, const StatedStep* stated = nullptr);
  /// Eq. (2)-(3) and the resampling from the pseudo observations. `odometry_heading_rad` is
  /// the odometry's current walking direction (odometry frame).
  void UpdatePatterns(const PatternComparison& comparison, double odometry_heading_rad);

  /// Whether the next UpdatePatterns would use a comparison (pseudo observations on, and the
  /// filter uncertain enough): callers skip the costly comparison otherwise.
  bool WantsPatterns() const;

  /// Share (by weight) of the belief whose last time update crossed a wall (before any
  /// backtracking): near 1 when the walk went where the map has a wall — a map error, or
  /// furniture-free odometry error — the map-error evidence of the mapmatch pipeline.
  double LastBlockedMass() const { return last_blocked_mass_; }
  /// Whether the last time update raised a wall alarm (see wall_alarm_h).
  bool LastStepRaisedWallAlarm() const { return last_step_alarm_; }

  Vec2 Mean() const;
  /// The particles' covariance (what the filter's own rules read).
  Mat2 Covariance() const;
  /// The covariance to report (ours, issue 23): the particles' covariance, plus, from an unknown
  /// start until distinctive comparisons have confirmed the place (confirm_pattern_updates,
  /// confirm_distinct_m), the building's own spread about the mean (the second moment of its
  /// inside about it). Walls and the wall-following model alone can gather every particle in
  /// the wrong corridor of a large floor with a spread of a few decimetres; until a comparison
  /// has said where the walker is, the ellipse says "somewhere in the building".
  Mat2 ReportedCovariance() const;
  /// Whether the place from an unknown start is not yet confirmed by distinctive comparisons
  /// (see ReportedCovariance). Without pattern observations nothing confirms it: a uniform
  /// start stays unconfirmed (the conventional filter from an unknown start is 5-10 m off on
  /// the houses, its particles' spread a few decimetres).
  bool Unconfirmed() const;
  double MeanHeadingOffset() const;
  const std::vector<Particle>& particles() const { return particles_; }
  const MapParticleFilterSummary& summary() const { return summary_; }

 private:
  void Normalize();
  void ReplaceFromSurvivors(const std::vector<char>& dead);
  /// A survivor drawn by weight: `cdf` its survivors' running weight (last > 0), `alive` their
  /// indices.
  int DrawSurvivor(const std::vector<double>& cdf, const std::vector<int>& alive);
  /// With free walkers (free_walk_share > 0): the dead replaced by survivors of their own
  /// model, each model keeping its share of the belief.
  void ReplaceWithinModels(const std::vector<char>& dead);
  /// Systematic resampling to the same number of particles, or with KLD-sampling on to the
  /// number the resampled particles' histogram asks for.
  void SystematicResample();
  /// n particles drawn systematically by weight (the weights summing to 1), each of weight 1/n.
  std::vector<Particle> DrawSystematic(std::size_t n);
  /// Resamples (systematically) up to `particles` when KLD-sampling has made fewer.
  void GrowToMaximum();
  /// The number of histogram bins (KLD-sampling) the given particles occupy.
  int OccupiedBins(const std::vector<Particle>& particles) const;
  void NoteParticleCount();
  /// Systematic resampling when the effective sample size is below ess_resample_fraction N.
  void ResampleIfDegenerate();
  Vec2 RandomInsidePoint();
  /// Two independent N(0, sigma_m^2) draws along the grid's axes, in the navigation frame.
  Vec2 GridNoise(double sigma_m);
  bool InsideBuilding(const Vec2& p) const;
  double PatternThreshold() const;
  /// The variance the filter's own rules read (see free_walk_share): the searchers' when the
  /// belief holds free walkers too, else the belief's.
  double TriggerVariance() const;
  void NoteConvergence();
  double Uniform() { return rng_.Uniform(); }
  std::uint8_t RandomHand();
  /// A new particle's shared errors, drawn from the prior (no draw without one).
  void DrawSharedErrors(Particle& q);

  const SearchGrid& grid_;
  const std::vector<NodeSequence>& sequences_;
  Options options_;
  Random rng_;
  std::vector<Particle> particles_;
  std::vector<Particle> before_step_;  ///< Predict's particles before the step (scratch)
  std::vector<char> dead_;             ///< Predict's eliminated particles (scratch)
  std::vector<Vec2> inside_centers_;
  Vec2 inside_mean_ = Vec2::Zero();    ///< of the inside centres
  Mat2 inside_second_ = Mat2::Zero();  ///< their mean of p p^T
  bool uniform_start_ = false;
  // Unique node positions (nanoflann k-d tree) and the (sequence, node) pairs at each.
  struct NodeIndex;
  std::unique_ptr<NodeIndex> nodes_;
  MapParticleFilterSummary summary_;
  std::optional<SharedStepErrorPrior> shared_;
  double last_blocked_mass_ = 0;
  bool converged_ = false;
  bool tracking_ = false;  ///< has converged (and been confirmed) since the last uniform start
  double wall_cusum_ = 0;
  bool last_step_alarm_ = false;
  int forced_pattern_updates_ = 0;
  int pattern_updates_applied_ = 0;
  /// The filter's own rule: comparisons are wanted (and the filter cannot count as converged)
  /// while this holds — Unconfirmed() with pattern observations on.
  bool AwaitingConfirmation() const { return options_.pseudo_observations && Unconfirmed(); }
  /// Whether a comparison whose best RMSE is best_rmse_m is distinctive (confirm_distinct_m).
  bool Distinctive(const PatternComparison& pc, double best_rmse_m) const;
  void Recover();
  void WeighWallFollowing(double step_heading_odometry_rad, double power);
  std::shared_ptr<const DistanceField> wall_distance_;
};

}  // namespace trailmark::mapmatch

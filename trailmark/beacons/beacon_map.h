// SPDX-License-Identifier: MIT
#pragma once
/// The beacon trail as a tracker needs it, built online from beacon-to-beacon ultrasound ranges
/// (median per pair) and what is known in the navigation frame — surveyed beacons, and where the
/// responder's dead reckoning dropped each beacon ("anchor hints"; sec. 5: "the base position
/// and entry heading" in the paper's words). Two solvers:
///  - least squares (default; issue 22, map_least_squares.h): links, surveys and drop positions
///    in one robust problem, from the priors and from the MDS layout, the lower cost kept;
///    marginal covariances; a solution whose residuals disagree with their noise is rejected
///    (the beacons fall back to their drop priors, and the summary says so);
///  - MDS (the paper's): shortest-path completion, classical MDS, SMACOF refinement
///    (beacons/mds.h), anchored afterwards by Procrustes; per-beacon covariances from the
///    information of its measured links plus the anchoring residual. Also the initializer of
///    the least squares, and the answer where fewer than two beacons of a part have priors.
/// Also the way back out (sec. 4): move towards the smallest id you can hear. No I/O.

#include <algorithm>
#include <functional>
#include <future>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <queue>
#include <string>
#include <vector>

#include "trailmark/beacons/map_least_squares.h"
#include "trailmark/beacons/mds.h"
#include "trailmark/beacons/scaat_ekf.h"
#include "trailmark/core/types.h"

namespace trailmark::beacons {

enum class MapSolver { kLeastSquares, kMds };

/// The median of values as they arrive (two heaps: O(log n) per value, read in O(1)): the
/// middle value, or the mean of the two middle values of an even count. (Until 2026-12-07 the
/// upper of the two: for a pair measured twice the larger range, +0.56 sigma long and with a
/// sigma of 0.83 sigma, not the 0.71 the link was given.) Median() of an empty one is undefined.
class RunningMedian {
 public:
  void Add(double x);
  double Median() const {
    return lower_.size() == upper_.size() ? 0.5 * (lower_.top() + upper_.top()) : upper_.top();
  }
  std::size_t size() const { return lower_.size() + upper_.size(); }
  bool empty() const { return upper_.empty(); }

 private:
  std::priority_queue<double> lower_;  ///< the smallest floor(n/2)
  std::priority_queue<double, std::vector<double>, std::greater<double>> upper_;  ///< the rest
};

struct BeaconMapOptions {
  MapSolver solver = MapSolver::kLeastSquares;  ///< least squares (ours) or MDS (the paper's)
  bool refine = true;             ///< SMACOF after MDS (ours)
  bool mds_for_surveyed = false;  ///< surveyed beacons too from MDS (Fig. 8); survey only anchors
  double link_sigma_m = 0.10;     ///< static ultrasound range (Hazas et al. 2005: ~10 cm)
  double max_link_m = 8.0;        ///< beacon ranges longer than this are outliers
  MapLeastSquaresOptions least_squares;
  /// Least squares: a solution that fails its chi-square test is not used (the beacons keep
  /// their drop priors); false: used anyway, only reported.
  bool reject_inconsistent = true;
  /// Least squares: a drop prior on the displacement from the same track's previous drop (the
  /// dead reckoning's white errors independent between drops); false: on each drop's position.
  /// Default false: measured on the lab trail, whose PDR turns are less accurate than the dead
  /// reckoning's model says, the displacements rotate the map (docs/beacons.md).
  bool relative_drop_priors = false;
  /// A part is solved again when a beacon, a pair, a survey or a hint joins or changes, and when
  /// a pair's ranges have changed what the last solve used: their number grown by this factor
  /// (the median's sigma down by its square root) or their median moved by more than
  /// `resolve_median_shift_sigma` of that sigma. Else the new ranges wait (as iSAM2 re-linearizes
  /// only past a threshold: Kaess et al. 2012). 1 and 0: solved again on every range.
  double resolve_count_growth = 1.25;
  double resolve_median_shift_sigma = 0.5;
  /// Least squares: the agents' ranges to beacons from their dead-reckoning tracks
  /// (AddSighting) in the map, the loop closure across a trail (issue 22, item 1). A part
  /// keeps its latest `max_sightings`, and is solved again for a beacon's new ones when they
  /// have grown by `resolve_count_growth` since its last solve. Used by a part with at least
  /// `sightings_min_surveyed` surveyed beacons (2: its rotation held by them): where the map's
  /// rotation is held by the droppers' heading priors alone, a trace's dead-reckoning misfit of
  /// a few centimetres per range turns it (the paper's deployed trail, design seeds: map 0.44
  /// -> 0.58 m with sightings; the neighbour trail, three surveyed: 0.243 -> 0.203 m;
  /// docs/beacons.md). 0: every part. Off by default: with sightings the solver needs 100-500
  /// iterations where 100 are allowed (a run 0.2 -> 8 s on the neighbour trail, and the map
  /// not converged to round-off: docs/beacons.md).
  bool sightings = false;
  int sightings_min_surveyed = 2;
  int max_sightings = 200;
  /// Least squares: a track's shared errors found beyond their sigma are inflated each apart
  /// (a chi-square test of 1 dof each); false: the track's chi-square and one scale for all.
  bool inflate_track_errors_apart = true;
  /// Least squares: a track whose shared errors are found beyond their sigma has its drops' (and
  /// sightings') white covariances scaled by the largest of those factors too, in a part
  /// without surveyed beacons (with one, the fault may be the survey's): a dead
  /// reckoning that far outside its model (phone steps, a drift 10x its prior, steps 10 % short)
  /// is off in its white errors as well, and drop priors held at their stated white sigma bend
  /// the map with confidence (beacon-trail variants K 1-20, `phone`: beacons-ekf p75 3.21 ->
  /// 2.64 m, in95 42 -> 51 %; docs/beacons.md). false: the shared errors alone (before).
  bool inflate_track_white = true;
  /// Prior sigma of the ranges' common scale k (the speed of sound the devices assume over the
  /// air's; ours, issue 21): estimated with the map in a part that holds two or more surveyed
  /// beacons (a length the ranges do not set); 0, or fewer surveys: the ranges as they are.
  /// The beacon pipelines set it to their tracker's `range_scale_sigma`.
  double range_scale_sigma = 0.0;
  bool IsValid(std::string* why) const;
};

struct BeaconMapSummary {
  std::size_t solves = 0;
  std::size_t part_solves = 0;  ///< connected parts solved (a part that did not change is not)
  std::size_t components = 0;  ///< at the last solve (with >= 3 beacons)
  std::size_t from_mds = 0, from_survey = 0, from_hint = 0, unknown = 0;
  double anchor_rms_m = 0;  ///< rms of the anchors' residuals at the last solve
  bool reflected = false;   ///< the MDS layout needed a flip
  // Least squares, at the last solve (worst part):
  std::size_t least_squares_parts = 0;  ///< parts solved by least squares
  std::size_t rejected_parts = 0;       ///< of them, rejected as inconsistent
  std::size_t rejected_solves = 0;      ///< solves (over the mission) with a part rejected
  std::size_t fold_starts_won = 0;      ///< solves in which the MDS start beat the priors' start
  double chi2_per_dof = 0;              ///< worst part
  std::size_t inflated_solves = 0;      ///< solves whose drop priors were found too tight
  std::size_t track_inflated_solves = 0;  ///< solves with a track's shared errors too tight
  double track_inflation = 1;             ///< at the last solve: that variance scale (worst)
  double prior_inflation = 1;           ///< at the last solve: their variance scale (worst)
  std::size_t sightings = 0;            ///< agents' ranges from their tracks, added
  std::size_t sightings_used = 0;       ///< at the last solve, in the solved parts
  std::size_t sighting_outliers = 0;    ///< at the last solve: beyond the Tukey bound
  /// Tracks whose sightings were left out (their shared errors beyond their stated sigma).
  std::size_t tracks_without_sightings = 0;
  std::string rejected_why;             ///< of the latest rejection
  /// At the last solve, of the largest part whose ranges' scale was estimated (1 and 0: none).
  double range_scale = 1.0, range_scale_sigma = 0.0;
  /// At the last solve, the largest |gradient| of a least-squares part's cost at its solution
  /// (MapSolution::max_gradient; converged to round-off: ~1e-9 and below).
  double max_gradient = 0;
  std::string BriefReport() const;
};

class BeaconMap {
 public:
  using Options = BeaconMapOptions;
  explicit BeaconMap(Options options = {});

  /// Index of `id`, adding it (in deployment order: call in drop order).
  int Add(const std::string& id);
  std::optional<int> Find(const std::string& id) const;
  std::size_t size() const { return ids_.size(); }
  const std::string& id(int i) const { return ids_[i]; }

  void SetSurveyed(int i, const Vec2& position_n, double sigma_m);
  /// Where the beacon is believed to be from outside the trail (e.g. the dropper's estimate).
  void SetAnchorHint(int i, const Vec2& position_n, const Mat2& cov);
  /// A dead reckoning whose errors [heading offset, heading rate, scale, turn scale] are shared
  /// by the hints it gives; returns its index.
  int AddTrack(const MapTrack& track);
  /// A hint from track `track`: position_n + along e + white noise of `white_cov` (along: see
  /// MapPrior). Its marginal covariance is white_cov + along cov_e along^T.
  /// `from` >= 0: the track's previous hint (beacon index), `increment_cov` the covariance of
  /// the white errors between the two (the least squares then uses the displacement).
  void SetTrackHint(int i, int track, const Vec2& position_n, const Mat2& white_cov,
                    const TrackLever& along, int from = -1,
                    const Mat2& increment_cov = Mat2::Identity());
  /// A range from an agent on track `track` to beacon `i` (in time order per track), the
  /// track's dead reckoning there (MapSighting): position, lever arms (MapPrior::along), the
  /// white covariance of [x, y, heading] there, and that of the walk since the track's
  /// previous sighting (`segment_cov`; its first: any). In a part's solve a sighting follows
  /// the track's previous one when that one is in the part too, else starts a chain with the
  /// white covariance.
  void AddSighting(int i, int track, const Vec2& position_n, const TrackLever& along,
                   const TrackVec& heading_along, const Mat3& white_cov, const Mat3& segment_cov,
                   double range_m, double sigma_m);
  bool HasAnchor(int i) const { return surveyed_[i].has_value() || hint_[i].has_value(); }
  /// A beacon-to-beacon range; returns false (and ignores it) when implausible.
  bool AddRange(int i, int j, double range_m);
  /// True when ranges or hints arrived since the last Solve().
  bool dirty() const { return dirty_; }
  /// Recomputes the positions of every connected part that changed since the last Solve() (a
  /// beacon, range, survey or hint added to one of its members); a part that did not change
  /// keeps its solution and its share of the summary (its inputs are those it was solved on).
  /// BeginSolve(false) then EndSolve().
  void Solve();
  /// Solve() in two halves, so that a live incident's rows are not held up by it (issue 20):
  /// BeginSolve() takes what every changed part needs (a snapshot: its ranges' medians, priors
  /// and last solution) and returns; the parts are solved from the snapshot alone, on a worker
  /// thread when `on_worker`, else in EndSolve(); EndSolve() waits for them and puts their
  /// solution in place. Until then Position() and summary() are the previous solve's, and the
  /// map takes new beacons, ranges and hints for the next solve. The solution depends on the
  /// snapshot only: the same calls give the same map however long the worker takes.
  void BeginSolve(bool on_worker);
  void EndSolve();
  /// Between BeginSolve() and EndSolve().
  bool solving() const { return pending_ != nullptr; }

  std::optional<BeaconPosition> Position(int i) const;
  /// Beacons with a measured link to `i`.
  const std::vector<int>& Neighbours(int i) const { return neighbours_[i]; }
  const BeaconMapSummary& summary() const { return summary_; }

 private:
  Options options_;
  std::vector<std::string> ids_;
  std::vector<std::optional<BeaconPosition>> surveyed_, hint_, solved_;
  struct TrackHint {
    int track = -1;
    Mat2 white_cov = Mat2::Identity();
    TrackLever along = TrackLever::Zero();
    int from = -1;
    Mat2 increment_cov = Mat2::Identity();
  };
  std::vector<TrackHint> hint_track_;
  struct Sighting {
    int beacon = 0, track = 0;
    std::size_t sequence = 0;  ///< of its track's sightings
    Vec2 position_n = Vec2::Zero();
    TrackLever along = TrackLever::Zero();
    TrackVec heading_along = TrackVec::Zero();
    Mat3 white = Mat3::Identity(), segment = Mat3::Identity();
    double range_m = 0, sigma_m = 0.3;
  };
  std::vector<std::size_t> track_sightings_;  ///< per track: sightings added
  std::vector<Sighting> sightings_;
  /// The last solve's state of each sighting and e of each track (the next solve starts there).
  std::vector<std::optional<Vec3>> sighting_state_;
  std::map<int, TrackVec> track_state_;
  /// Tracks whose sightings are no longer used (their errors came out beyond their sigma).
  std::vector<int> tracks_without_sightings_;
  /// Per beacon: sightings of it added since its part's last solve, and used then.
  std::vector<std::size_t> sightings_new_, sightings_used_;  ///< track -1: the hint's cov is white
  std::vector<MapTrack> tracks_;
  std::vector<std::vector<int>> neighbours_;
  struct PairRanges {
    RunningMedian ranges_m;
    double used_median_m = 0;    ///< at the last solve of its part
    std::size_t used_count = 0;  ///< 0: not used yet
  };
  std::vector<std::map<int, PairRanges>> samples_;  ///< [i][j], i < j: the measured pairs only
  /// What one connected part contributes to the summary (BeaconMapSummary: "at the last solve").
  struct PartResult {
    bool placed = false;        ///< counted in `components`
    bool least_squares = false;
    bool rejected = false;
    bool reflected = false;
    double anchor_rms_m = 0, chi2_per_dof = 0, prior_inflation = 1, track_inflation = 1;
    std::size_t sightings = 0, sighting_outliers = 0;
    double range_scale = 1.0, range_scale_sigma = 0.0;  ///< the ranges' scale, when estimated
    double max_gradient = 0;                            ///< of the least squares' solution
    std::size_t members = 0;                            ///< beacons in the part
  };
  /// What solving one connected part needs, copied at BeginSolve() (indices are the part's
  /// own: member a is beacon members[a]; members[0] is the smallest, the part's key).
  struct PartInput {
    std::vector<int> members;
    std::string first_id;  ///< the id of members[0] (for the summary's notes)
    RangeMatrix measured;  ///< median range per measured pair
    std::vector<std::size_t> counts;  ///< ranges behind each median, [a * m + b]
    std::vector<std::optional<BeaconPosition>> surveyed, hint, previous;
    std::vector<TrackHint> hint_track;  ///< `from` as a member index (-1: not in the part)
    /// The part's sightings, beacons as member indices, `track` the map's, each following the
    /// previous one of its track in the part; their indices in sightings_.
    std::vector<MapSighting> sightings;
    std::vector<std::size_t> sighting_ids;
    std::map<int, TrackVec> track_start;  ///< the map's track -> its e at the last solve
    int SurveyedCount() const {
      return static_cast<int>(std::count_if(surveyed.begin(), surveyed.end(),
                                            [](const auto& s) { return s.has_value(); }));
    }
  };
  /// A part's solution and its share of the summary.
  struct PartOutput {
    PartResult part;
    std::vector<std::optional<BeaconPosition>> solved;  ///< per member
    std::size_t track_inflated_solves = 0, inflated_solves = 0, fold_starts_won = 0;
    std::optional<std::string> rejected_why;
    std::vector<std::optional<Vec3>> sighting_state;  ///< per input sighting, when solved
    std::map<int, TrackVec> track_errors;             ///< the map's track -> e, when solved
    std::vector<int> sighting_fallback_tracks;  ///< the map's tracks whose sightings were left out
  };
  struct Pending {
    std::map<int, PartResult> kept;  ///< the parts that did not change
    std::vector<int> reset;          ///< members of every changed part
    std::vector<PartInput> inputs;
    std::vector<MapTrack> tracks;                  ///< tracks_ at the snapshot
    std::future<std::vector<PartOutput>> outputs;  ///< on a worker
  };
  /// The sightings of a part's members for its snapshot (`local`: beacon -> member index).
  std::vector<MapSighting> PartSightings(const std::vector<int>& local,
                                         std::vector<std::size_t>* ids) const;
  /// Solves one connected part (pure: the snapshot and the options only).
  static PartOutput SolvePart(const PartInput& in, const std::vector<MapTrack>& tracks,
                              const Options& options);
  /// Solves one connected part by least squares; false when its priors do not fix it.
  static bool SolveLeastSquares(const PartInput& in, const std::vector<MapTrack>& tracks,
                                const Options& options,
                                const std::optional<std::vector<Vec2>>& mds_start, PartOutput* out);
  void Touch(int i) {
    changed_[i] = true;
    dirty_ = true;
  }
  std::vector<bool> changed_;          ///< since the last BeginSolve()
  std::map<int, PartResult> parts_;    ///< by the part's smallest member, at the last solve
  bool dirty_ = false;
  BeaconMapSummary summary_;
  std::unique_ptr<Pending> pending_;  ///< between BeginSolve() and EndSolve()
};

/// The way back out (sec. 4; Souryal et al. 2007): from the beacon of smallest deployment rank
/// heard, go to its neighbour of smallest rank, and so on, until the beacon of smallest rank of
/// all (the entry). `rank[i]` is beacon i's deployment order. `why` says where the trail breaks
/// when the entry cannot be reached. Empty when nothing is heard.
std::vector<int> WayOut(const std::vector<std::vector<int>>& neighbours,
                        const std::vector<int>& rank, const std::vector<int>& heard,
                        std::string* why = nullptr);

}  // namespace trailmark::beacons

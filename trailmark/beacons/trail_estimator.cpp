// SPDX-License-Identifier: MIT
#include "trailmark/beacons/trail_estimator.h"

#include <fmt/format.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

namespace trailmark::beacons {

bool BeaconTrailOptions::IsValid(std::string* why) const {
  if (!(entry_track_m >= 0) || !(mds_period_s >= 0)) {
    if (why) *why = "entry_track_m and mds_period_s must be >= 0";
    return false;
  }
  if (!(output_period_s == 0 || (output_period_s >= 0.01 && std::isfinite(output_period_s)))) {
    if (why) *why = "output_period_s must be 0 or at least 0.01 s";
    return false;
  }
  if (!(map_lag_s >= 0)) {
    if (why) *why = "map_lag_s must be >= 0";
    return false;
  }
  if (!(drop_sigma_m > 0) || !(close_pass_m >= 0) || !(pdr_drift_per_m >= 0) ||
      !(way_out_window_s >= 0) || !(measurement_hold_s >= 0) || !(entry_heading_fallback_m >= 0) ||
      !(sighting_loop_m >= 0) || !(sighting_spacing_m >= 0)) {
    if (why)
      *why =
          "drop_sigma_m > 0; close_pass_m, pdr_drift_per_m, way_out_window_s, "
          "measurement_hold_s, entry_heading_fallback_m, sighting_loop_m, sighting_spacing_m >= 0";
    return false;
  }
  return ekf.IsValid(why) && map.IsValid(why) && integrity.IsValid(why) && dr_test.IsValid(why);
}

namespace {

/// Output instants this close to a row's time are the row's own (round-off).
constexpr double kTickTolS = 1e-9;

// A surveyed crumb or landmark (a node that can be a beacon; not the base, which stays at the
// entry) more than 2 m from `start_n`: with the start it fixes the navigation frame's heading
// for an agent's PDR.
bool HasSurveyedNodeAwayFrom(const MissionInfo& info, const Vec2& start_n) {
  return std::any_of(info.nodes.begin(), info.nodes.end(), [&](const NodeInfo& n) {
    return (n.kind == NodeKind::kCrumb || n.kind == NodeKind::kLandmark) && n.position &&
           (n.position->head<2>() - start_n).norm() > 2.0;
  });
}

void AddMapOptions(OptionTable<BeaconTrailOptions>& t) {
  using O = BeaconTrailOptions;
  t.Choice("beacons", [](O& o) -> bool& { return o.map.mds_for_surveyed; },
           std::vector<std::pair<std::string, bool>>{{"auto", false}, {"mds", true}},
           "auto: surveyed beacons at their survey; mds: every beacon from MDS (Fig. 8)");
  t.Choice("map", [](O& o) -> MapSolver& { return o.map.solver; },
           std::vector<std::pair<std::string, MapSolver>>{{"least-squares", MapSolver::kLeastSquares},
                                                          {"mds", MapSolver::kMds}},
           "least-squares: links, surveys and drop priors in one robust problem (ours); mds: "
           "MDS + SMACOF placed by Procrustes (the paper's)");
  t.Flag("reject_inconsistent_map", [](O& o) -> bool& { return o.map.reject_inconsistent; },
         "a least-squares map failing its chi-square test is not used (drop priors instead)");
  t.Flag("relative_drop_priors", [](O& o) -> bool& { return o.map.relative_drop_priors; },
         "least squares: drop priors on the displacement between consecutive drops");
  t.Flag("refine", [](O& o) -> bool& { return o.map.refine; }, "SMACOF after MDS (ours)");
  t.Real(
      "range_scale_sigma", [](O& o) -> double& { return o.ekf.range_scale_sigma; }, "",
      OptionBounds::Between(0, 0.5),
      "prior sigma of the ultrasound ranges' scale, the speed of sound (the map's with two "
      "surveyed beacons, the filter's with two surveyed nodes; 0: ranges taken as they are, "
      "the paper's); the filter names a scale beyond it in an integrity note");
  t.Flag("map_turn_scale", &O::map_turn_scale,
         "least squares: the gyro's turn-scale error a shared error of each track in the map "
         "(with heading offset, rate and scale)");
  t.Flag(
      "map_inflate_apart", [](O& o) -> bool& { return o.map.inflate_track_errors_apart; },
      "least squares: a track's shared errors found beyond their sigma inflated each apart "
      "(false: all by the track's chi-square)");
  t.Flag(
      "map_inflate_white", [](O& o) -> bool& { return o.map.inflate_track_white; },
      "least squares: a track whose shared errors are inflated has its drops' white "
      "covariances scaled by the largest factor too (false: the shared errors alone)");
  t.Real("map_turn_ambiguous_rad", &O::map_turn_ambiguous_rad, "rad", OptionBounds::Positive(),
         "a turn between two steps larger than this (a reversal, its sign unknown) is left out "
         "of the turn-scale lever, its share of the turn-scale error a heading error of its own");
  t.Integer(
      "map_newton_iterations", [](O& o) -> int& { return o.map.least_squares.newton_iterations; },
      OptionBounds::NonNegative(),
      "least squares: Newton's steps on the exact Hessian after Ceres' Gauss-Newton, until the "
      "map is converged to round-off (0: Ceres alone, to its 100-iteration cap)");
  t.Flag(
      "sightings", [](O& o) -> bool& { return o.map.sightings; },
      "least squares: the agents' ranges to beacons from their dead-reckoning tracks in the "
      "map (the loop closure across a trail)");
  t.Integer(
      "sightings_min_surveyed", [](O& o) -> int& { return o.map.sightings_min_surveyed; },
      OptionBounds::NonNegative(),
      "a part of the map uses sightings when at least this many of its beacons are surveyed (2: "
      "its rotation held by them; 0: every part)");
  t.Real("sighting_loop_m", &O::sighting_loop_m, "m", OptionBounds::NonNegative(),
         "a range to a beacon the agent dropped or passed is a sighting once it has walked this "
         "far since");
  t.Real("sighting_spacing_m", &O::sighting_spacing_m, "m", OptionBounds::NonNegative(),
         "at most one sighting of a beacon per agent per this distance walked");
  t.Integer(
      "max_sightings", [](O& o) -> int& { return o.map.max_sightings; },
      OptionBounds::NonNegative(), "the latest sightings a part of the map keeps");
  t.Flag("close_pass_on_track", &O::close_pass_on_track,
         "a beacon without drop event is anchored at a close pass as a drop would be: on the "
         "passer's dead-reckoning track and as a consider state of its tracker (false: at the "
         "tracker's estimate)");
  t.Flag("drop_within_step", &O::drop_within_step,
         "a drop placed within the step that spans it (false: at the last step's end before it)");
  t.Real("entry_track_m", &O::entry_track_m, "m", OptionBounds::NonNegative(),
         "PDR track compared with the entry heading (0: never)");
  t.Flag("estimate_entry_heading", &O::estimate_entry_heading,
         "no start_heading: estimate the PDR's heading from the first ultrasound measurements "
         "(false: take the PDR's frame as the navigation frame within 5 deg)");
  t.Real("entry_heading_fallback_m", &O::entry_heading_fallback_m, "m",
         OptionBounds::NonNegative(),
         "walked without a heading estimate: the PDR's frame is then taken after all");
  t.Real("mds_period_s", &O::mds_period_s, "s", OptionBounds::NonNegative(),
         "the beacon map is re-solved at most this often");
  t.Real("map_lag_s", &O::map_lag_s, "s", OptionBounds::NonNegative(),
         "the map solved at a tick is put in place this much later (at most mds_period_s), "
         "solved on a worker meanwhile (0: at once, holding up the rows behind it)");
  t.Real("map_resolve_count_growth", [](O& o) -> double& { return o.map.resolve_count_growth; },
         "", OptionBounds::AtLeast(1.0),
         "a part of the map is solved again when a pair's ranges have grown by this factor since "
         "its last solve (or a beacon, pair or hint joined; 1: on every range)");
  t.Real("map_resolve_median_shift_sigma",
         [](O& o) -> double& { return o.map.resolve_median_shift_sigma; }, "",
         OptionBounds::NonNegative(),
         "... or a pair's median range moved by more than this many of its sigmas");
}

}  // namespace

const OptionTable<BeaconTrailOptions>& BeaconMapOptionTable() {
  static const OptionTable<BeaconTrailOptions> table = [] {
    OptionTable<BeaconTrailOptions> t;
    AddMapOptions(t);
    return t;
  }();
  return table;
}

const OptionTable<BeaconTrailOptions>& BeaconTrackerOptionTable() {
  static const OptionTable<BeaconTrailOptions> table = [] {
    using O = BeaconTrailOptions;
    OptionTable<O> t;
    t.Choice("filter", &O::tracker,
             std::vector<std::pair<std::string, Tracker>>{{"scaat", Tracker::kScaat},
                                                          {"us-only", Tracker::kUltrasoundOnly}},
             "scaat: the SCAAT EKF on PDR and ultrasound; us-only: the paper's ultrasound-only KF");
    t.Choice("update", &O::update,
             std::vector<std::pair<std::string, UpdateMode>>{
                 {"range-bearing", UpdateMode::kRangeBearing}, {"position", UpdateMode::kPosition}},
             "range-bearing: two scalar updates (ours); position: converted to a fix (the paper)");
    t.Choice("init", &O::init_from_ultrasound,
             std::vector<std::pair<std::string, bool>>{{"auto", false}, {"ultrasound", true}},
             "auto: the mission's start when given; ultrasound: always from ultrasound");
    t.Choice("beacon_errors", [](O& o) -> bool& { return o.ekf.consider_beacons; },
             std::vector<std::pair<std::string, bool>>{{"consider", true}, {"white", false}},
             "consider: each beacon's map error shared by all its measurements (Schmidt); "
             "white: added to every measurement as independent noise (the paper's)");
    t.Real("measurement_hold_s", &O::measurement_hold_s, "s", OptionBounds::NonNegative(),
           "a measurement waits this long for the step spanning its time (0: at once)");
    t.Flag("extrapolate", &O::extrapolate,
           "between steps, emit the position ahead of the last step by its velocity (the tracker's "
           "own view, before 2026-12-07; the step front end's view_period_s does it by default: "
           "with both, the view moves on from a row already ahead)");
    t.Real("output_period_s", &O::output_period_s, "s", OptionBounds::NonNegative(),
           "with extrapolate: an agent's estimate is never older than this at the next row "
           "(0: at steps and measurements only)");
    t.Choice("outliers", [](O& o) -> bool& { return o.ekf.mixture_updates; },
             std::vector<std::pair<std::string, bool>>{{"mixture", true}, {"gate", false}},
             "mixture: ranges and bearings weighed by their inlier probability under a "
             "Gaussian + uniform-outlier mixture (ours); gate: cut at gate_sigma");
    t.Real("range_outlier_probability",
           [](O& o) -> double& { return o.ekf.range_outlier_probability; }, "",
           OptionBounds::Between(0, 0.99), "mixture: prior share of outlier ranges");
    t.Real("bearing_outlier_probability",
           [](O& o) -> double& { return o.ekf.bearing_outlier_probability; }, "",
           OptionBounds::Between(0, 0.99), "mixture: prior share of outlier bearings");
    t.Real("gate_sigma", [](O& o) -> double& { return o.ekf.gate_sigma; }, "",
           OptionBounds::Positive(), "EKF innovation gate, in sigmas (outliers=gate)");
    t.Real("heading_sigma_rad", [](O& o) -> double& { return o.ekf.initial_heading_sigma_rad; },
           "rad", OptionBounds::Positive(), "initial sigma of the PDR heading correction");
    t.Real("heading_walk_rad_per_sqrt_m",
           [](O& o) -> double& { return o.ekf.heading_walk_rad_per_sqrt_m; }, "rad/sqrt(m)",
           OptionBounds::NonNegative(), "random walk of the heading correction per metre");
    t.Real("range_sigma_m", [](O& o) -> double& { return o.ekf.range_sigma_m; }, "m",
           OptionBounds::Positive(), "sigma of an ultrasound range without one");
    t.Real(
        "bearing_sigma_rad", [](O& o) -> double& { return o.ekf.bearing_sigma_rad; }, "rad",
        OptionBounds::Positive(), "sigma of a bearing without one");
    t.Include("", &O::integrity, integrity::ConsistencyOptionTable());
    t.Flag("dr_first", &O::dr_first,
           "an agent on a foot INS within its noise model (start and heading stated) is written "
           "as its dead reckoning while the filter does not doubt it");
    t.Include("", &O::dr_test, integrity::DeadReckoningFirstOptionTable());
    AddMapOptions(t);
    return t;
  }();
  return table;
}

namespace {

// The map's options with the tracker's prior on the ranges' scale: one speed of sound for both.
BeaconMapOptions MapOptionsOf(const BeaconTrailOptions& o) {
  BeaconMapOptions map = o.map;
  map.range_scale_sigma = o.ekf.range_scale_sigma;
  return map;
}

}  // namespace

BeaconTrailEstimator::BeaconTrailEstimator(const MissionInfo& info, BeaconTrailOptions options)
    : options_(std::move(options)),
      map_(MapOptionsOf(options_)),
      beacon_integrity_("beacon", options_.integrity) {
  std::string why;
  if (!options_.IsValid(&why)) throw std::invalid_argument("beacons: " + why);
  range_scale_threshold_ = integrity::ChiSquareQuantile(1, 1 - options_.integrity.false_alarm);
  // The ranges' scale is observable against surveyed nodes only: a map placed from the ranges
  // alone has their scale, against which every range reads k = 1 — there the state would only
  // soak up NLOS excess and PDR errors (measured: the beacon trail's `phone` family p75 2.51 ->
  // 2.63 m with k estimated, k 1.00-1.05 where it is 1). Two surveyed nodes set a length.
  std::size_t surveyed_nodes = 0;
  for (const NodeInfo& n : info.nodes) surveyed_nodes += n.kind != NodeKind::kAgent && n.position;
  if (surveyed_nodes < 2 && options_.ekf.range_scale_sigma > 0) {
    range_scale_unobservable_ = true;
    options_.ekf.range_scale_sigma = 0;
  }
  for (const NodeInfo& n : info.nodes) {
    if (n.kind == NodeKind::kAgent) {
      Agent a;
      a.id = n.id;
      const auto start = info.AgentStart(n);
      if (start && !options_.init_from_ultrasound) {
        a.has_start = true;
        a.pdr_n = a.start_n = start->head<2>();
        a.entry_heading_rad = n.start_heading_rad;
        a.entry_heading_sigma_rad =
            n.start_heading_sigma_rad.value_or(options_.default_entry_heading_sigma_rad);
        const double s = n.start_sigma_m.value_or(options_.ekf.initial_position_sigma_m);
        a.start_sigma_m = s;
        // No start heading: the PDR's rotation into the navigation frame is estimated from the
        // first ultrasound measurements (the start as a prior); until then no drop prior.
        a.heading_unknown = !n.start_heading_rad && options_.estimate_entry_heading &&
                            HasSurveyedNodeAwayFrom(info, start->head<2>());
        if (!a.heading_unknown) {
          // With an entry heading the first metre fixes the PDR's heading to that sigma.
          const double heading_sigma =
              a.entry_heading_rad
                  ? std::hypot(a.entry_heading_sigma_rad, options_.entry_track_heading_sigma_rad)
                  : n.start_heading_sigma_rad.value_or(
                        options_.drop_dead_reckoning.start_heading_sigma_rad);
          StartDropDeadReckoning(a, heading_sigma);
          if (options_.tracker == Tracker::kScaat) {
            a.ekf.emplace(a.pdr_n, Mat2::Identity() * s * s, 0.0,
                          options_.ekf.initial_heading_sigma_rad, 1.0,
                          options_.ekf.initial_scale_sigma, options_.ekf);
          }
        }
      }
      agents_[n.id] = std::move(a);
    } else {
      declared_rank_[n.id] = static_cast<int>(declared_rank_.size());
      // Surveyed nodes (landmarks, the base) are beacons once they range.
      if (n.position)
        surveyed_[n.id] = {n.position->head<2>(), n.position_sigma_m.value_or(0.05)};
    }
  }
}

int BeaconTrailEstimator::Beacon(const std::string& id) {
  if (const auto i = map_.Find(id)) return *i;
  const int i = map_.Add(id);
  beacon_t_.push_back(0);
  const auto s = surveyed_.find(id);
  if (s != surveyed_.end()) map_.SetSurveyed(i, s->second.first, s->second.second);
  return i;
}

PdrOptions BeaconTrailEstimator::WhiteDeadReckoning() const {
  PdrOptions white = options_.drop_dead_reckoning;
  white.heading_drift_sigma_rad_per_s = white.step_scale_sigma = white.turn_scale_sigma = 0;
  return white;
}

void BeaconTrailEstimator::StartDropDeadReckoning(Agent& a, double heading_sigma_rad) {
  // The drop priors' dead reckoning: white errors in drop_dr, the shared ones (heading offset,
  // drift rate, step scale, turn scale) a track of the map (the turn scale since 2026-12-06;
  // map_turn_scale=false leaves it out of both, as before).
  const PdrOptions& pdr = options_.drop_dead_reckoning;
  const PdrOptions white = WhiteDeadReckoning();
  a.drop_dr.emplace(Vec3(a.start_n.x(), a.start_n.y(), 0), a.start_sigma_m, white, 0.0);
  a.segment_dr.emplace(Vec3::Zero(), 0.0, white, 0.0);
  const double turn_sigma = options_.map_turn_scale ? pdr.turn_scale_sigma : 1e-9;
  MapTrack track;
  track.cov = TrackVec(heading_sigma_rad * heading_sigma_rad,
                       pdr.heading_drift_sigma_rad_per_s * pdr.heading_drift_sigma_rad_per_s,
                       pdr.step_scale_sigma * pdr.step_scale_sigma, turn_sigma * turn_sigma)
                  .asDiagonal();
  track.dof = options_.map_turn_scale ? kTrackErrors : kTrackErrors - 1;
  a.map_track = map_.AddTrack(track);
}

TrackLever BeaconTrailEstimator::DropDeadReckoningState::Lever() const {
  TrackLever along;
  along << Vec2(-sum_d_n.y(), sum_d_n.x()), sum_t_perp_n, sum_d_n, sum_turn_perp_n;
  return along;
}

void BeaconTrailEstimator::AdvanceDropDeadReckoning(Agent& a, const Step& step, const Vec2& d) {
  Step rotated = step;
  const Vec2 d_n = Eigen::Rotation2Dd(a.drop_dr_rotation_rad) * d;
  rotated.delta_n.head<2>() = d_n;
  // The turn-scale error's lever (DeadReckoning::AddStep): a step of at least turn_min_step_m
  // says where the body faces; the heading error is the scale error x the angle turned. A
  // reversal's sign is a guess (a half turn left and a half turn right look alike in the
  // steps; the gyro knew): it is left out of the lever, so that a wrong guess does not turn
  // it by 2 pi x the scale error, and its share of that error is a heading error of its own.
  if (options_.map_turn_scale &&
      d_n.norm() >= std::max(options_.drop_dead_reckoning.turn_min_step_m, 1e-9)) {
    const double direction = std::atan2(d_n.y(), d_n.x());
    if (a.last_direction_rad) {
      const double turn = WrapAngle(direction - *a.last_direction_rad);
      if (std::abs(turn) < options_.map_turn_ambiguous_rad) {
        a.turned_rad += turn;
      } else {
        const double v = std::pow(options_.drop_dead_reckoning.turn_scale_sigma * turn, 2);
        a.drop_dr->AddHeadingVariance(v);
        a.segment_dr->AddHeadingVariance(v);
      }
    }
    a.last_direction_rad = direction;
  }
  a.drop_dr->AddStep(rotated);
  a.segment_dr->AddStep(rotated);
  // Lever arms of the shared errors (DeadReckoning's model): heading offset, rate x time.
  if (!a.first_step_t) a.first_step_t = step.t0;
  a.sum_d_n += d_n;
  a.sum_t_perp_n += (step.t1 - *a.first_step_t) * Vec2(-d_n.y(), d_n.x());
  a.sum_turn_perp_n += a.turned_rad * Vec2(-d_n.y(), d_n.x());
}

BeaconTrailEstimator::DropDeadReckoningState BeaconTrailEstimator::DropState(const Agent& a) const {
  return {a.drop_dr->position_n().head<2>(),
          a.drop_dr->covariance(),
          a.sum_d_n,
          a.sum_t_perp_n,
          a.sum_turn_perp_n,
          a.drop_dr->error_covariance().topLeftCorner<3, 3>(),
          a.segment_dr->error_covariance().topLeftCorner<3, 3>()};
}

void BeaconTrailEstimator::HintTrackPoint(Agent& a, int i, const DropDeadReckoningState& at) {
  map_.SetTrackHint(i, a.map_track, at.position_n, at.white, at.Lever(), -1, at.white);
  a.walked_at_drop[i] = a.walked_m;
}

void BeaconTrailEstimator::HintDrop(Agent& a, int i, const DropDeadReckoningState& at) {
  const Mat2 drop = Mat2::Identity() * options_.drop_sigma_m * options_.drop_sigma_m;
  const TrackLever along = at.Lever();
  // Between two drops: the white errors accrued since the last (and both drops' scatter).
  Mat2 increment = at.white - a.last_drop_white_cov + 2 * drop;
  increment = 0.5 * (increment + increment.transpose());
  map_.SetTrackHint(i, a.map_track, at.position_n, at.white + drop, along,
                    a.last_drop != i ? a.last_drop : -1, increment);
  a.walked_at_drop[i] = a.walked_m;
  a.last_drop = i;
  a.last_drop_white_cov = at.white;
}

void BeaconTrailEstimator::HintPendingDrops(Agent& a, TimeS until, TimeS t0, TimeS t1,
                                            const DropDeadReckoningState& before) {
  if (a.pending_drops.empty()) return;
  // A drop within the step from t0 to t1 is where that share of the step had taken the
  // dropper (the step's displacement, its white covariance and lever arms interpolated).
  const DropDeadReckoningState after = DropState(a);
  std::vector<std::pair<TimeS, std::string>> later;
  for (const auto& [t, id] : a.pending_drops) {
    if (t > until) {
      later.emplace_back(t, id);
      continue;
    }
    const double f = t1 > t0 ? std::clamp((t - t0) / (t1 - t0), 0.0, 1.0) : 1.0;
    const auto lerp = [f](const auto& x0, const auto& x1) { return (x0 + f * (x1 - x0)).eval(); };
    HintDrop(a, Beacon(id),
             {lerp(before.position_n, after.position_n), lerp(before.white, after.white),
              lerp(before.sum_d_n, after.sum_d_n), lerp(before.sum_t_perp_n, after.sum_t_perp_n),
              lerp(before.sum_turn_perp_n, after.sum_turn_perp_n)});
  }
  a.pending_drops = std::move(later);
}

bool BeaconTrailEstimator::WantsSighting(const Agent& a, int beacon) const {
  // A mission with fewer surveyed beacons than a part needs to use them keeps none.
  if (!options_.map.sightings || options_.map.solver != MapSolver::kLeastSquares ||
      static_cast<int>(surveyed_.size()) < options_.map.sightings_min_surveyed || !a.drop_dr ||
      a.AwaitingHeading() || a.map_track < 0)
    return false;
  if (const auto d = a.walked_at_drop.find(beacon);
      d != a.walked_at_drop.end() && a.walked_m - d->second < options_.sighting_loop_m)
    return false;
  const auto s = a.walked_at_sighting.find(beacon);
  return s == a.walked_at_sighting.end() || a.walked_m - s->second >= options_.sighting_spacing_m;
}

void BeaconTrailEstimator::HintPendingSightings(Agent& a, TimeS until, TimeS t0, TimeS t1,
                                                const DropDeadReckoningState& before) {
  if (a.pending_sightings.empty()) return;
  const DropDeadReckoningState after = DropState(a);
  std::vector<PendingRange> later;
  bool placed = false;
  for (const PendingRange& r : a.pending_sightings) {
    if (r.t > until) {
      later.push_back(r);
      continue;
    }
    // Asked again once its step has come: a drop within the same step is placed by now.
    if (!WantsSighting(a, r.beacon)) continue;
    a.walked_at_sighting[r.beacon] = a.walked_m;
    const double f = t1 > t0 ? std::clamp((r.t - t0) / (t1 - t0), 0.0, 1.0) : 1.0;
    const auto lerp = [f](const auto& x0, const auto& x1) { return (x0 + f * (x1 - x0)).eval(); };
    const DropDeadReckoningState at{lerp(before.position_n, after.position_n),
                                    lerp(before.white, after.white),
                                    lerp(before.sum_d_n, after.sum_d_n),
                                    lerp(before.sum_t_perp_n, after.sum_t_perp_n),
                                    lerp(before.sum_turn_perp_n, after.sum_turn_perp_n),
                                    lerp(before.white3, after.white3),
                                    lerp(before.segment3, after.segment3)};
    // Kept positive definite where no step lies between (1 cm, 0.06 deg).
    const Mat3 floor = Vec3(1e-4, 1e-4, 1e-6).asDiagonal();
    // The heading's sensitivity to the track's errors there: offset, rate x time, turn scale x
    // the angle turned (the step's end's, within a step).
    const TrackVec heading_along(1.0, a.first_step_t ? r.t - *a.first_step_t : 0.0, 0.0,
                                 options_.map_turn_scale ? a.turned_rad : 0.0);
    map_.AddSighting(r.beacon, a.map_track, at.position_n, at.Lever(), heading_along,
                     at.white3 + floor, at.segment3 + floor, r.range_m,
                     r.sigma_m > 0 ? r.sigma_m : options_.ekf.range_sigma_m);
    placed = true;
  }
  a.pending_sightings = std::move(later);
  // The next sighting's walk is counted from here (the step's end: within a step, the rest of
  // it is counted twice, a few centimetres).
  if (placed) a.segment_dr.emplace(Vec3::Zero(), 0.0, WhiteDeadReckoning(), 0.0);
}

void BeaconTrailEstimator::TryEstimateHeading(Agent& a, TimeS t, const BeaconPosition& beacon,
                                              const std::optional<PendingRange>& range,
                                              std::optional<double> bearing,
                                              double bearing_sigma, EstimateSink& sink) {
  if (!range) return;
  InitMeasurement m;
  m.pdr_n = a.pdr_n - a.start_n;  // the track from the start, in the PDR's frame
  m.beacon_n = beacon.position_n;
  m.range_m = range->range_m;
  // The beacon's own uncertainty widens its measurements (its largest axis, conservatively).
  const double beacon_sigma_m =
      std::sqrt(std::max(Eigen::SelfAdjointEigenSolver<Mat2>(beacon.cov).eigenvalues().maxCoeff(), 0.0));
  m.range_sigma_m =
      std::hypot(range->sigma_m > 0 ? range->sigma_m : options_.ekf.range_sigma_m, beacon_sigma_m);
  m.bearing_rad = bearing;
  m.bearing_sigma_rad =
      std::hypot(bearing_sigma > 0 ? bearing_sigma : options_.ekf.bearing_sigma_rad,
                 beacon_sigma_m / std::max(range->range_m, 0.5));
  a.init_buffer.push_back(m);
  InitResult init = InitializeFromUltrasound(a.init_buffer, options_.init,
                                             OriginPrior{a.start_n, a.start_sigma_m});
  if (!init.ok) {
    a.init_why = init.why;
    return;
  }
  // Its covariance scaled by the residuals' reduced chi-square where above 1, and the PDR's
  // direction noise over the track added to the heading (as to a given start heading: the
  // PDR's heading then is no better known than its track's direction).
  init.cov *= std::max(1.0, init.rms_normalized * init.rms_normalized);
  init.cov(2, 2) += options_.entry_track_heading_sigma_rad * options_.entry_track_heading_sigma_rad;
  FixHeading(a, t, init.psi_rad, std::sqrt(std::max(init.cov(2, 2), 0.0)), init, sink);
}

void BeaconTrailEstimator::FixHeading(Agent& a, TimeS t, double psi_rad, double sigma_rad,
                                      const std::optional<InitResult>& init, EstimateSink& sink) {
  a.heading_fixed = true;
  a.heading_assumed = !init;
  a.initialized_at = t;
  a.estimated_heading_rad = psi_rad;
  a.estimated_heading_sigma_rad = sigma_rad;
  a.init_buffer.clear();
  // The drop priors from here on, and those of the drops made so far (their steps replayed).
  a.drop_dr_rotation_rad = psi_rad;
  StartDropDeadReckoning(a, sigma_rad);
  std::vector<std::pair<TimeS, std::string>> drops;
  for (const auto& [t_drop, beacon_index] : a.drops_before_fix)
    drops.emplace_back(t_drop, map_.id(beacon_index));
  ReplayDrops(a, a.steps_before_fix, std::move(drops), 0.0);
  a.steps_before_fix.clear();
  a.drops_before_fix.clear();
  const Vec2 track_n = a.pdr_n - a.start_n;  // in the PDR's frame
  const Vec2 position_n = a.start_n + Eigen::Rotation2Dd(psi_rad) * track_n;
  if (options_.tracker == Tracker::kScaat) {
    if (init) {
      a.ekf.emplace(StartFromInit(*init, track_n, options_.ekf));
    } else {
      // Assumed: as an agent with a start heading starts (the filter's heading prior), the
      // dead reckoning's own uncertainty and the heading's lever arm in the position, with the
      // position's correlation with that heading: p = start + R(psi) track, dp/dpsi = perp.
      const Vec2 lever(-track_n.y(), track_n.x());
      const double psi_sigma = std::max(sigma_rad, options_.ekf.initial_heading_sigma_rad);
      const double psi_var = psi_sigma * psi_sigma;
      ScaatEkf::State x;
      x << position_n, 0.0, 1.0, 1.0;
      ScaatEkf::Cov P = ScaatEkf::Cov::Zero();
      P.topLeftCorner<2, 2>() = a.drop_dr->covariance() + lever * lever.transpose() * psi_var;
      P.block<2, 1>(0, ScaatEkf::kPsi) = lever * psi_var;
      P.block<1, 2>(ScaatEkf::kPsi, 0) = lever.transpose() * psi_var;
      P(ScaatEkf::kPsi, ScaatEkf::kPsi) = psi_var;
      P(ScaatEkf::kScale, ScaatEkf::kScale) =
          options_.ekf.initial_scale_sigma * options_.ekf.initial_scale_sigma;
      P(ScaatEkf::kRangeScale, ScaatEkf::kRangeScale) =
          options_.ekf.range_scale_sigma * options_.ekf.range_scale_sigma;
      a.ekf.emplace(x, P, options_.ekf);
    }
    Emit(t, a, sink);
  } else if (options_.tracker == Tracker::kNone) {
    // The map-only mode rotates the steps themselves (FixEntryHeading's convention).
    a.pdr_rotation_rad = psi_rad;
    a.drop_dr_rotation_rad = 0;
  }
  a.pdr_n = position_n;
}

std::vector<int> BeaconTrailEstimator::Ranks() const {
  // Deployment order: drops first (in drop order), then the others in the order mission.json
  // declares them, then in order of first sight.
  std::vector<int> rank;
  const int n = static_cast<int>(map_.size());
  for (int i = 0; i < n; ++i) {
    const auto d = drop_rank_.find(map_.id(i));
    const auto m = declared_rank_.find(map_.id(i));
    rank.push_back(d != drop_rank_.end()
                       ? d->second
                       : (m != declared_rank_.end() ? 1000000 + m->second : 2000000 + i));
  }
  return rank;
}

std::vector<std::vector<int>> BeaconTrailEstimator::Neighbours() const {
  std::vector<std::vector<int>> nb;
  for (int i = 0; i < static_cast<int>(map_.size()); ++i) nb.push_back(map_.Neighbours(i));
  return nb;
}

std::pair<std::optional<Vec2>, std::optional<Mat2>> BeaconTrailEstimator::AgentEstimate(
    const Agent& a) const {
  if (a.ekf && a.dr_first) {
    const Vec2 dr = a.own_dr->position_n().head<2>();
    return {a.dr_first->Position(a.ekf->position(), dr),
            a.dr_first->Covariance(a.ekf->position(), a.ekf->position_cov(), dr,
                                   a.own_dr->covariance())};
  }
  if (a.ekf) return {a.ekf->position(), a.ekf->position_cov()};
  if (a.us_kf) return {a.us_kf->position(), a.us_kf->position_cov()};
  if (a.AwaitingHeading()) {
    // Somewhere within the distance walked from the start: all that is known before the
    // PDR's heading is.
    const double r = std::hypot(a.start_sigma_m, a.walked_m);
    return {a.start_n, Mat2::Identity() * r * r};
  }
  if (a.has_start) return {a.pdr_n, Mat2::Identity() * a.pdr_var_m2};
  return {std::nullopt, std::nullopt};
}

void BeaconTrailEstimator::Add(const MissionRow& row, EstimateSink& sink) {
  const bool used = std::holds_alternative<MissionEvent>(row) || std::holds_alternative<Step>(row) ||
                    std::holds_alternative<RangeMeasurement>(row) ||
                    (std::holds_alternative<BearingMeasurement>(row) &&
                     options_.tracker != Tracker::kNone);
  if (!used) {
    ++rows_ignored_;
    return;
  }
  const TimeS t = RowTime(row);
  if (const auto* step = std::get_if<Step>(&row); step && !agents_.count(step->agent)) {
    throw std::invalid_argument("'" + step->agent + "' has steps but is not an agent");
  }
  if (t > pending_t_) FlushPending(sink);
  // The view between rows: each agent's estimate extrapolated every output_period_s up to this
  // row (from the rows before it only).
  if (options_.extrapolate && options_.measurement_hold_s > 0 && options_.output_period_s > 0) {
    for (auto& [id, a] : agents_) {
      if (!a.ekf) continue;
      for (TimeS tk = a.t + options_.output_period_s; tk < t - kTickTolS;
           tk = a.t + options_.output_period_s) {
        if (!EmitAhead(tk, a, sink)) break;
      }
    }
  }
  last_t_ = t;
  if (const auto* e = std::get_if<MissionEvent>(&row)) {
    if (e->event == "drop" && agents_.count(e->node)) {
      Ignore("drops whose node is an agent");  // the readers refuse them; live rows too
    } else if (e->event == "drop" && !e->node.empty()) {
      drop_rank_.emplace(e->node, static_cast<int>(drop_rank_.size()));
      auto it = agents_.find(e->agent);
      if (it != agents_.end() && OnFirstTrack(it->second))
        it->second.first_track_drops.emplace_back(e->t, e->node);
      if (it != agents_.end() && options_.drop_within_step && it->second.drop_dr &&
          !it->second.AwaitingHeading()) {
        // Where the dropper was at the drop: within the step that spans it, when that step
        // comes — the map's prior and the tracker's consider state alike. The beacon joins
        // the map then, with its prior.
        Agent& a = it->second;
        a.pending_drops.emplace_back(e->t, e->node);
        if (a.ekf) a.deferred.push_back({e->t, -1, std::nullopt, std::nullopt, 0.0, e->node});
      } else {
        const int i = Beacon(e->node);
        if (it != agents_.end() && it->second.ekf)
          it->second.ekf->ConsiderDrop(i, options_.drop_sigma_m);
        if (it != agents_.end()) {
          const Mat2 drop = Mat2::Identity() * options_.drop_sigma_m * options_.drop_sigma_m;
          if (Agent& a = it->second; a.AwaitingHeading()) {
            // Where it lies depends on the heading still unknown; a drop at the start does not.
            if (a.walked_m == 0)
              map_.SetAnchorHint(i, a.start_n,
                                 Mat2::Identity() * a.start_sigma_m * a.start_sigma_m + drop);
            else
              a.drops_before_fix.emplace_back(e->t, i);
          } else if (a.drop_dr) {
            HintDrop(a, i, DropState(a));
          } else {
            const auto [p, cov] = AgentEstimate(it->second);
            if (p) map_.SetAnchorHint(i, *p, *cov + drop);
          }
        }
      }
    }
  } else if (const auto* step = std::get_if<Step>(&row)) {
    Agent& a = agents_.at(step->agent);
    const Vec2 d = Eigen::Rotation2Dd(a.pdr_rotation_rad) * Vec2(step->delta_n.head<2>());
    if (a.AwaitingHeading()) a.steps_before_fix.push_back(*step);
    if (OnFirstTrack(a)) a.first_track_steps.push_back(*step);
    if (a.drop_dr && (!a.pending_drops.empty() || !a.pending_sightings.empty())) {
      const DropDeadReckoningState before = DropState(a);
      AdvanceDropDeadReckoning(a, *step, d);
      HintPendingDrops(a, step->t1, step->t0, step->t1, before);
      HintPendingSightings(a, step->t1, step->t0, step->t1, before);
    } else if (a.drop_dr) {
      AdvanceDropDeadReckoning(a, *step, d);
    }
    a.walked_m += d.norm();
    if (a.AwaitingHeading() &&
        a.walked_m > options_.entry_heading_fallback_m) {
      FixHeading(a, step->t1, 0.0, options_.drop_dead_reckoning.start_heading_sigma_rad,
                 std::nullopt, sink);
    }
    a.pdr_n += d;
    // Dead-reckoning drift for the drop hints of the map-only mode.
    a.pdr_var_m2 += std::pow(options_.pdr_drift_per_m * d.norm(), 2) +
                    step->variance_m2.value_or(Vec3::Zero()).x();
    if (a.ekf) {
      const Vec3 v = step->variance_m2.value_or(Vec3::Constant(0.0));
      Mat2 cov = Mat2::Zero();
      cov(0, 0) = v.x();
      cov(1, 1) = v.y();
      PredictWithMeasurements(a, step->t0, step->t1, d, cov);
      FixEntryHeading(a, d);
      TestDeadReckoning(a, *step);
      a.step_t0 = step->t0;
      a.step_t1 = step->t1;
      // The step's velocity as the filter moved the node (updates within it excluded).
      a.step_velocity_n = step->t1 > step->t0
                              ? Vec2(a.ekf->scale() * (Eigen::Rotation2Dd(a.ekf->psi()) * d) /
                                     (step->t1 - step->t0))
                              : Vec2::Zero();
      Emit(step->t1, a, sink);
    } else {
      FixEntryHeading(a, d);
    }
  } else if (const auto* r = std::get_if<RangeMeasurement>(&row)) {
    if (!r->kind.empty() && r->kind != "ultrasound")
      return Ignore("ranges of another kind than ultrasound");
    const bool a_agent = agents_.count(r->a) != 0, b_agent = agents_.count(r->b) != 0;
    if (a_agent && b_agent) return Ignore("agent-to-agent ranges");
    if (!a_agent && !b_agent) {
      if (r->a == r->b) return Ignore("ranges of a node to itself");
      const int i = Beacon(r->a), j = Beacon(r->b);
      if (!map_.AddRange(i, j, r->range_m)) ++implausible_links_;
      return;
    }
    const std::string& agent = a_agent ? r->a : r->b;
    const int beacon = Beacon(a_agent ? r->b : r->a);
    agents_[agent].heard[beacon] = t;
    // A beacon without drop event or survey: anchored where an agent first passes close by.
    Agent& passer = agents_[agent];
    // (A beacon whose drop event has come is placed by it, within the step that spans it.)
    if (!map_.HasAnchor(beacon) && r->range_m <= options_.close_pass_m &&
        !passer.AwaitingHeading() && !drop_rank_.count(map_.id(beacon))) {
      const double pass_var = r->range_m * r->range_m + 0.1;
      if (passer.drop_dr && options_.close_pass_on_track) {
        // As a drop would be: on the passer's dead-reckoning track, whose shared heading,
        // drift-rate and scale errors the map solves with, and a consider state of the tracker
        // (not the tracker's estimate, which follows the map: each pass anchored the map where
        // the map had put it).
        DropDeadReckoningState at = DropState(passer);
        at.white += Mat2::Identity() * pass_var;
        HintTrackPoint(passer, beacon, at);
        if (passer.ekf)
          passer.deferred.push_back(
              {t, -1, std::nullopt, std::nullopt, 0.0, map_.id(beacon), std::sqrt(pass_var)});
        ++close_pass_anchors_;
      } else if (const auto [p, cov] = AgentEstimate(passer); p) {
        map_.SetAnchorHint(beacon, *p, *cov + Mat2::Identity() * pass_var);
        ++close_pass_anchors_;
      }
    }
    pending_.push_back({t, agent, beacon, r->range_m, r->sigma_m.value_or(0.0)});
    pending_t_ = t;
    if (r->range_m > 0 && r->range_m <= options_.map.max_link_m && WantsSighting(passer, beacon))
      passer.pending_sightings.push_back(pending_.back());
  } else if (const auto* b = std::get_if<BearingMeasurement>(&row)) {
    // Bearing from a beacon (a) to the agent (b).
    auto it = agents_.find(b->b);
    if (it == agents_.end() || agents_.count(b->a))
      return Ignore("bearings not from a beacon to an agent");
    const int beacon = Beacon(b->a);
    std::optional<PendingRange> range;
    for (auto p = pending_.begin(); p != pending_.end(); ++p) {
      if (p->agent == b->b && p->beacon == beacon && std::abs(p->t - t) < 1e-6) {
        range = *p;
        pending_.erase(p);
        break;
      }
    }
    Measure(it->second, t, beacon, range, b->bearing_rad, b->sigma_rad.value_or(0.0), sink);
  }
  if (options_.measurement_hold_s > 0) ApplyStanding(t - options_.measurement_hold_s, t, sink);
  if (map_.solving() && t - last_solve_ >= MapLag())
    SolveAndEmit(t, sink, /*begin=*/false);
  if (map_.dirty() && t - last_solve_ >= options_.mds_period_s) SolveAndEmit(t, sink, true);
}

void BeaconTrailEstimator::PredictWithMeasurements(Agent& a, TimeS t0, TimeS t1, const Vec2& d,
                                                   const Mat2& cov) {
  std::stable_sort(a.deferred.begin(), a.deferred.end(),
                   [](const Deferred& x, const Deferred& y) { return x.t < y.t; });
  std::vector<Deferred> later;
  double done = 0;  // fraction of the step predicted so far
  for (const Deferred& m : a.deferred) {
    if (m.t > t1) {
      later.push_back(m);
      continue;
    }
    // Before the step began the node stood where it is; within it, moved a share of d.
    const double alpha = t1 > t0 ? std::clamp((m.t - t0) / (t1 - t0), 0.0, 1.0) : 1.0;
    if (alpha > done) {
      a.ekf->PredictStep((alpha - done) * d, (alpha - done) * cov, alpha - done);
      done = alpha;
    }
    Apply(a, m);
  }
  if (done < 1) a.ekf->PredictStep((1 - done) * d, (1 - done) * cov, 1 - done);
  a.deferred = std::move(later);
}

void BeaconTrailEstimator::ApplyStanding(TimeS before, TimeS now, EstimateSink& sink) {
  for (auto& [id, a] : agents_) {
    // Drops made while standing: where the dropper stands (no step spans them).
    if (a.drop_dr && !a.pending_drops.empty())
      HintPendingDrops(a, std::nextafter(before, -1e300), 0, 0, DropState(a));
    if (a.drop_dr && !a.pending_sightings.empty())
      HintPendingSightings(a, std::nextafter(before, -1e300), 0, 0, DropState(a));
    if (a.deferred.empty() || !a.ekf) continue;
    bool accepted = false;
    std::vector<Deferred> keep;
    for (const Deferred& m : a.deferred) {
      if (m.t < before)
        accepted |= Apply(a, m);
      else
        keep.push_back(m);
    }
    a.deferred = std::move(keep);
    // (Not while dead reckoning is written: the ranges do not move it; its row would be the
    // last step's, late.)
    if (accepted && !WritesDeadReckoning(a)) Emit(now, a, sink);
  }
}

void BeaconTrailEstimator::Finish(EstimateSink& sink) {
  FlushPending(sink);
  ApplyStanding(std::numeric_limits<double>::infinity(), last_t_, sink);
  // The last solve in place and the map of every range at the end.
  map_.EndSolve();
  if (map_.dirty()) map_.Solve();
  SolveAndEmit(last_t_, sink, /*begin=*/false);
}

void BeaconTrailEstimator::TestDeadReckoning(Agent& a, const Step& step) {
  if (!a.dr_first_decided) {
    // At the first step: a foot INS within its noise model (its steps carry the INS's heading
    // variance, ZuptIns::OwnErrorsHold), a start and a stated heading.
    a.dr_first_decided = true;
    if (options_.dr_first && foot_ins_.contains(a.id) && step.heading_var_rad2 && a.has_start &&
        a.entry_heading_rad) {
      a.own_dr.emplace(Vec3(a.start_n.x(), a.start_n.y(), 0), a.start_sigma_m,
                       PdrOptions{}.ForFootIns(), a.entry_heading_sigma_rad);
      a.dr_first.emplace(options_.dr_test);
    }
  }
  if (!a.dr_first) return;
  a.own_dr->AddStep(step);
  if (!step.heading_var_rad2) {  // the IMU's mounting not found
    if (auto note = a.dr_first->Abandon(step.t1, a.id, "the filter"))
      dr_notes_.push_back(std::move(*note));
  }
  auto note = a.dr_first->Test(step.t1, a.id, "the filter", a.ekf->position(),
                               a.ekf->position_cov(), a.own_dr->position_n().head<2>());
  if (note) dr_notes_.push_back(std::move(*note));
}

bool BeaconTrailEstimator::OnFirstTrack(const Agent& a) const {
  return a.entry_heading_rad && !a.heading_fixed && options_.entry_track_m > 0;
}

void BeaconTrailEstimator::FixEntryHeading(Agent& a, const Vec2& d) {
  if (!OnFirstTrack(a)) return;  // entry_track_m = 0: never
  a.first_track_n += d;
  // A foot INS's steps are in the stated frame once its mounting is found (StepsFromFootIns):
  // the heading fixed at its first step, as an entry heading of zero.
  const bool foot_ins = foot_ins_.contains(a.id);
  if (!foot_ins && a.first_track_n.norm() < options_.entry_track_m) return;
  a.heading_fixed = true;
  const double sigma = std::hypot(a.entry_heading_sigma_rad, options_.entry_track_heading_sigma_rad);
  const double psi =
      foot_ins
          ? 0.0
          : WrapAngle(*a.entry_heading_rad - std::atan2(a.first_track_n.y(), a.first_track_n.x()));
  if (options_.tracker != Tracker::kNone) a.drop_dr_rotation_rad = psi;
  if (a.ekf) {
    entry_fixes_ += a.ekf->UpdateHeadingCorrection(psi, sigma) == UpdateResult::kAccepted;
  } else if (options_.tracker == Tracker::kNone) {
    a.pdr_rotation_rad = psi;
    a.pdr_n = a.start_n + Eigen::Rotation2Dd(psi) * Vec2(a.pdr_n - a.start_n);
    ++entry_fixes_;
  }
  if (a.drop_dr && !foot_ins) ReplayFirstTrack(a);  // (not turned: nothing to run again)
}

void BeaconTrailEstimator::ReplayFirstTrack(Agent& a) {
  // The first track's steps went into the drop priors' dead reckoning before the fix turned
  // them: every later drop prior was off by (R(psi) - I) x the first track (0.1-0.5 m at the
  // offsets of 5-20 degrees a boot or a phone has), a shift about the start that no shared
  // error's lever can take. Run again from the start with the steps turned.
  const PdrOptions white = WhiteDeadReckoning();
  a.drop_dr.emplace(Vec3(a.start_n.x(), a.start_n.y(), 0), a.start_sigma_m, white, 0.0);
  a.segment_dr.emplace(Vec3::Zero(), 0.0, white, 0.0);
  a.sum_d_n = a.sum_t_perp_n = a.sum_turn_perp_n = Vec2::Zero();
  a.turned_rad = 0;
  a.last_direction_rad.reset();
  a.first_step_t.reset();
  a.last_drop = -1;
  a.last_drop_white_cov = Mat2::Zero();
  const std::vector<Step> steps = std::move(a.first_track_steps);
  std::vector<std::pair<TimeS, std::string>> drops = std::move(a.first_track_drops);
  a.first_track_steps.clear();
  a.first_track_drops.clear();
  // The first track's drops were pending or hinted: hinted again here, those after its last
  // step pending for the next, as they were.
  a.pending_drops.clear();
  const std::map<int, double> walked_at_drop = a.walked_at_drop;  // as walked then, not now
  ReplayDrops(a, steps, std::move(drops), a.pdr_rotation_rad);
  for (const auto& [i, walked] : walked_at_drop) a.walked_at_drop[i] = walked;
}

void BeaconTrailEstimator::ReplayDrops(Agent& a, const std::vector<Step>& steps,
                                       std::vector<std::pair<TimeS, std::string>> drops,
                                       double step_rotation_rad) {
  auto turned = [&](const Step& st) {
    return Vec2(Eigen::Rotation2Dd(step_rotation_rad) * Vec2(st.delta_n.head<2>()));
  };
  if (options_.drop_within_step) {
    // Each drop within the step that spans it; those after the last step wait for the next.
    for (auto& drop : drops) a.pending_drops.push_back(std::move(drop));
    for (const Step& st : steps) {
      const DropDeadReckoningState before = DropState(a);
      AdvanceDropDeadReckoning(a, st, turned(st));
      HintPendingDrops(a, st.t1, st.t0, st.t1, before);
    }
  } else {
    std::size_t k = 0;
    for (const auto& [t_drop, id] : drops) {
      for (; k < steps.size() && steps[k].t1 <= t_drop; ++k)
        AdvanceDropDeadReckoning(a, steps[k], turned(steps[k]));
      HintDrop(a, Beacon(id), DropState(a));
    }
    for (; k < steps.size(); ++k) AdvanceDropDeadReckoning(a, steps[k], turned(steps[k]));
  }
}

void BeaconTrailEstimator::FlushPending(EstimateSink& sink) {
  auto pending = std::move(pending_);
  pending_.clear();
  for (const auto& p : pending)
    Measure(agents_[p.agent], p.t, p.beacon, p, std::nullopt, 0.0, sink);
  pending_t_ = std::numeric_limits<double>::infinity();
}

void BeaconTrailEstimator::Measure(Agent& a, TimeS t, int beacon,
                                   const std::optional<PendingRange>& range,
                                   std::optional<double> bearing, double bearing_sigma,
                                   EstimateSink& sink) {
  const bool estimating_heading = a.AwaitingHeading();
  if (options_.tracker == Tracker::kNone && !estimating_heading) return;
  const auto pos = map_.Position(beacon);
  if (!pos) {
    ++no_position_;
    return;
  }
  if (estimating_heading) return TryEstimateHeading(a, t, *pos, range, bearing, bearing_sigma, sink);
  if (options_.tracker == Tracker::kUltrasoundOnly && !(range && bearing)) {
    return Ignore("ranges or bearings without their pair (the ultrasound-only filter needs both)");
  }
  if (options_.tracker == Tracker::kUltrasoundOnly) {
    if (!a.us_kf) {
      if (a.has_start) {
        a.us_kf.emplace(a.pdr_n, t, options_.us_kf);
      } else {
        Vec2 z;
        Mat2 R;
        PolarToPosition(*pos, range->range_m, *bearing,
                        range->sigma_m > 0 ? range->sigma_m : options_.us_kf.range_sigma_m,
                        bearing_sigma > 0 ? bearing_sigma : options_.us_kf.bearing_sigma_rad, &z,
                        &R);
        auto o = options_.us_kf;
        o.initial_position_sigma_m = std::sqrt(R.trace());
        a.us_kf.emplace(z, t, o);
        Emit(t, a, sink);
        return;
      }
    }
    if (a.us_kf->UpdatePosition(t, *pos, range->range_m, *bearing, range->sigma_m,
                                bearing_sigma) == UpdateResult::kAccepted) {
      Emit(t, a, sink);
    }
    return;
  }
  if (!a.ekf) {
    InitMeasurement m;
    m.pdr_n = a.pdr_n;
    m.beacon_n = pos->position_n;
    if (!range) return;
    m.range_m = range->range_m;
    m.range_sigma_m = range->sigma_m > 0 ? range->sigma_m : options_.ekf.range_sigma_m;
    m.bearing_rad = bearing;
    m.bearing_sigma_rad = bearing_sigma > 0 ? bearing_sigma : options_.ekf.bearing_sigma_rad;
    a.init_buffer.push_back(m);
    const InitResult init = InitializeFromUltrasound(a.init_buffer, options_.init);
    if (!init.ok) {
      a.init_why = init.why;
      return;
    }
    a.ekf.emplace(StartFromInit(init, a.pdr_n, options_.ekf));
    a.initialized_at = t;
    a.init_buffer.clear();
    Emit(t, a, sink);
    return;
  }
  const Deferred m{t, beacon, range, bearing, bearing_sigma};
  if (options_.measurement_hold_s > 0) {
    a.deferred.push_back(m);
    if (options_.extrapolate) EmitAhead(t, a, sink);
    return;
  }
  if (Apply(a, m) && !WritesDeadReckoning(a)) Emit(t, a, sink);
}

bool BeaconTrailEstimator::Apply(Agent& a, const Deferred& m) {
  if (!m.dropped.empty()) {
    a.ekf->ConsiderDrop(Beacon(m.dropped),
                        m.drop_sigma_m > 0 ? m.drop_sigma_m : options_.drop_sigma_m);
    return false;
  }
  const auto pos = map_.Position(m.beacon);
  if (!pos) {
    ++no_position_;
    return false;
  }
  const TimeS t = m.t;
  const int beacon = m.beacon;
  const auto& range = m.range;
  const auto& bearing = m.bearing;
  const double bearing_sigma = m.bearing_sigma;
  bool accepted = false;
  // Integrity: each beacon's ranges and its bearings are sources of their own (a bearing's
  // outliers do not condemn the beacon's ranges).
  const std::string& id = map_.id(beacon);
  const auto admit = [&](const std::string& source) {
    return Admit([this, source, t](double nis, int dof) {
      return beacon_integrity_.Record(source, t, nis, dof);
    });
  };
  if (options_.update == UpdateMode::kPosition && range && bearing) {
    accepted = a.ekf->UpdatePosition(*pos, range->range_m, *bearing, range->sigma_m,
                                     bearing_sigma, admit(id)) == UpdateResult::kAccepted;
  } else {
    if (range) {
      accepted |= a.ekf->UpdateRange(*pos, range->range_m, range->sigma_m, admit(id + " range"),
                                     beacon) == UpdateResult::kAccepted;
      CheckRangeScale(a, t);
    }
    if (bearing)
      accepted |= a.ekf->UpdateBearing(*pos, *bearing, bearing_sigma, admit(id + " bearing"),
                                       beacon) == UpdateResult::kAccepted;
  }
  return accepted;
}

void BeaconTrailEstimator::CheckRangeScale(Agent& a, TimeS t) {
  const double nis = a.ekf->RangeScaleNis();
  const bool flagged = nis > range_scale_threshold_;
  if (flagged == a.range_scale_flagged) return;
  a.range_scale_flagged = flagged;
  const double k = a.ekf->range_scale();
  const double sd = std::sqrt(a.ekf->covariance()(ScaatEkf::kRangeScale, ScaatEkf::kRangeScale));
  range_scale_notes_.push_back(
      {t, "ultrasound ranges of " + a.id, a.id, flagged ? "scale" : "scale agrees",
       flagged ? fmt::format("the ultrasound ranges of {} read {:.3f} +- {:.3f} times the "
                             "distances from t {:.1f} s, against a stated speed of sound within "
                             "{:.1f} % (chi-square {:.1f} > {:.1f}): a wrong speed of sound or "
                             "a hot room; the filter reads the ranges with that scale",
                             a.id, k, sd, t, 100 * options_.ekf.range_scale_sigma, nis,
                             range_scale_threshold_)
               : fmt::format("the ultrasound ranges of {} agree with the stated speed of sound "
                             "again from t {:.1f} s (scale {:.3f} +- {:.3f}, chi-square {:.1f})",
                             a.id, t, k, sd, nis)});
}

void BeaconTrailEstimator::SolveAndEmit(TimeS t, EstimateSink& sink, bool begin) {
  if (begin) {
    last_solve_ = t;
    const bool lag = MapLag() > 0;
    map_.BeginSolve(/*on_worker=*/lag);
    if (lag) return;  // put in place map_lag_s later
  }
  map_.EndSolve();
  // A map that disagrees with its noise is not used: say so once, and when it agrees again.
  const auto& ms = map_.summary();
  if (const bool rejected = ms.rejected_parts > 0; rejected != map_rejected_) {
    map_rejected_ = rejected;
    map_notes_.push_back(
        {t, "beacon map", "", rejected ? "fallback" : "resumed",
         rejected ? fmt::format("beacon map not used from t {:.1f} s: {}; its beacons are placed "
                                "at their surveys and drop priors, the trackers use those",
                                t, ms.rejected_why)
                  : fmt::format("beacon map used again from t {:.1f} s: its residuals agree with "
                                "their noise (chi-square per degree of freedom {:.2f})",
                                t, ms.chi2_per_dof)});
  }
  EmitBeacons(t, sink);
}

void BeaconTrailEstimator::EmitBeacons(TimeS t, EstimateSink& sink) {
  for (int i = 0; i < static_cast<int>(map_.size()); ++i) {
    const auto p = map_.Position(i);
    if (!p) continue;
    beacon_t_[i] = t;
    sink.Add({t, map_.id(i), Vec3(p->position_n.x(), p->position_n.y(), 0), p->cov(0, 0),
              p->cov(0, 1), p->cov(1, 1)});
  }
}

void BeaconTrailEstimator::Emit(TimeS t, Agent& a, EstimateSink& sink) {
  // Agents are estimated only by the trackers (the map-only mode reports beacons alone).
  if (options_.tracker == Tracker::kNone) return;
  const auto [p, c] = AgentEstimate(a);
  if (!p) return;
  if (a.dr_first) a.dr_first->Count();
  a.t = t;
  sink.Add({t, a.id, Vec3(p->x(), p->y(), 0), (*c)(0, 0), (*c)(0, 1), (*c)(1, 1)});
}

bool BeaconTrailEstimator::EmitAhead(TimeS t, Agent& a, EstimateSink& sink) {
  if (!a.ekf || !std::isfinite(a.step_t1) || !(t > a.step_t1) || t <= a.t) return false;
  if (a.dr_first) return false;  // the step front end's view moves a written dead reckoning on
  const double ahead_s = std::min(t - a.step_t1, a.step_t1 - a.step_t0);
  const double speed = a.step_velocity_n.norm();
  const Vec2 p = a.ekf->position() + a.step_velocity_n * ahead_s;
  const double s = options_.extrapolation_speed_sigma * speed * ahead_s;
  const Mat2 c = a.ekf->position_cov() + Mat2::Identity() * s * s;
  a.t = t;
  sink.Add({t, a.id, Vec3(p.x(), p.y(), 0), c(0, 0), c(0, 1), c(1, 1)});
  return true;
}

std::optional<Mat2> BeaconTrailEstimator::StepTransform(const std::string& agent) const {
  const auto it = agents_.find(agent);
  if (it == agents_.end() || !it->second.ekf) return std::nullopt;
  if (it->second.dr_first && it->second.dr_first->doubt() < 0.5)
    return std::nullopt;  // the steps as they come
  const ScaatEkf& ekf = *it->second.ekf;
  return Mat2(ekf.scale() * Eigen::Rotation2Dd(ekf.psi()).toRotationMatrix());
}

std::optional<Estimate> BeaconTrailEstimator::Current(const std::string& node) const {
  if (const auto it = agents_.find(node); it != agents_.end()) {
    if (options_.tracker == Tracker::kNone) return std::nullopt;
    const auto [p, c] = AgentEstimate(it->second);
    if (!p) return std::nullopt;
    return Estimate{it->second.t, node, Vec3(p->x(), p->y(), 0), (*c)(0, 0), (*c)(0, 1),
                    (*c)(1, 1)};
  }
  const auto i = map_.Find(node);
  if (!i) return std::nullopt;
  const auto p = map_.Position(*i);
  if (!p) return std::nullopt;
  return Estimate{beacon_t_[*i], node, Vec3(p->position_n.x(), p->position_n.y(), 0),
                  p->cov(0, 0), p->cov(0, 1), p->cov(1, 1)};
}

WayOutReport BeaconTrailEstimator::WayOut(const std::string& agent, TimeS at_s,
                                          double window_s) const {
  WayOutReport report;
  std::vector<int> heard;
  if (const auto it = agents_.find(agent); it != agents_.end()) {
    for (const auto& [b, t] : it->second.heard) {
      if (t >= at_s - window_s) heard.push_back(b), report.heard.push_back(map_.id(b));
    }
  }
  std::string why;
  for (int b : beacons::WayOut(Neighbours(), Ranks(), heard, &why)) {
    report.route.push_back(map_.id(b));
    const auto p = map_.Position(b);
    report.route_positions_n.push_back(p ? std::optional<Vec2>(p->position_n) : std::nullopt);
  }
  if (!why.empty()) report.broken = why;
  return report;
}

EstimatorSummary BeaconTrailEstimator::Summary() const {
  EstimatorSummary summary;
  const auto& ms = map_.summary();
  summary.notes.push_back(ms.BriefReport());
  for (const auto& [reason, n] : ignored_) {
    summary.notes.push_back(fmt::format("ignored {} row(s): {}", n, reason));
  }
  if (ms.unknown > 0) {
    summary.notes.push_back(fmt::format(
        "{} beacon(s) could not be placed in the navigation frame: the layout needs two surveyed "
        "beacons, or drop events with steps (the dropper's position), in its connected part",
        ms.unknown));
  }
  if (implausible_links_ > 0) {
    summary.notes.push_back(fmt::format(
        "{} beacon-to-beacon range(s) not used as implausible (not above 0 m, or beyond the "
        "map's max_link_m of {:.1f} m)",
        implausible_links_, options_.map.max_link_m));
  }
  if (range_scale_unobservable_) {
    summary.notes.push_back(
        "the ultrasound ranges' scale (the speed of sound) is not estimated nor checked: fewer "
        "than two surveyed nodes, so the map's lengths are the ranges' own");
  }
  if (no_position_ > 0) {
    summary.notes.push_back(fmt::format(
        "{} ultrasound measurement(s) of beacons not yet placed were not used", no_position_));
  }
  auto& num = summary.numbers;
  num["beacons"] = static_cast<double>(map_.size());
  num["beacons_from_mds"] = static_cast<double>(ms.from_mds);
  num["beacons_surveyed"] = static_cast<double>(ms.from_survey);
  num["beacons_unplaced"] = static_cast<double>(ms.unknown);
  num["mds_solves"] = static_cast<double>(ms.solves);
  num["map_part_solves"] = static_cast<double>(ms.part_solves);
  num["anchor_rms_m"] = ms.anchor_rms_m;
  if (ms.least_squares_parts > 0) num["map_max_gradient"] = ms.max_gradient;
  if (ms.range_scale_sigma > 0) {
    num["map_range_scale"] = ms.range_scale;
    num["map_range_scale_sigma"] = ms.range_scale_sigma;
  }
  num["entry_heading_fixes"] = static_cast<double>(entry_fixes_);
  num["beacons_anchored_by_close_pass"] = static_cast<double>(close_pass_anchors_);
  num["map_sightings"] = static_cast<double>(ms.sightings);
  num["map_sightings_used"] = static_cast<double>(ms.sightings_used);
  num["map_sighting_outliers"] = static_cast<double>(ms.sighting_outliers);
  num["map_tracks_without_sightings"] = static_cast<double>(ms.tracks_without_sightings);
  num["implausible_beacon_links"] = static_cast<double>(implausible_links_);
  num["rows_ignored"] = static_cast<double>(rows_ignored_);
  summary.integrity.insert(summary.integrity.end(), map_notes_.begin(), map_notes_.end());
  summary.integrity.insert(summary.integrity.end(), dr_notes_.begin(), dr_notes_.end());
  summary.integrity.insert(summary.integrity.end(), range_scale_notes_.begin(),
                           range_scale_notes_.end());
  for (const auto& [id, a] : agents_) {
    // dr_first: the share of the agent's estimates that are not its dead reckoning's.
    if (a.dr_first)
      summary.numbers[id + ".dr_first_filter_share"] = a.dr_first->share_not_dead_reckoning();
  }
  for (const auto& [id, a] : agents_) {
    if (!a.heading_unknown) continue;
    if (a.heading_fixed && a.heading_assumed) {
      summary.notes.push_back(fmt::format(
          "{}: no start_heading, and none estimated within {:.0f} m walked: its PDR's frame "
          "taken as the navigation frame (within {:.1f} deg) from t = {:.2f} s",
          id, options_.entry_heading_fallback_m,
          options_.drop_dead_reckoning.start_heading_sigma_rad * 180 / std::numbers::pi,
          a.initialized_at));
    } else if (a.heading_fixed) {
      summary.notes.push_back(fmt::format(
          "{}: no start_heading; the PDR's heading in the navigation frame estimated from "
          "ultrasound at t = {:.2f} s: {:.1f} +- {:.1f} deg",
          id, a.initialized_at, a.estimated_heading_rad * 180 / std::numbers::pi,
          a.estimated_heading_sigma_rad * 180 / std::numbers::pi));
      num[id + ".estimated_heading_rad"] = a.estimated_heading_rad;
    } else {
      summary.notes.push_back(fmt::format(
          "{}: no start_heading, and its PDR's heading could not be estimated ({}): its "
          "position is the start within the distance walked, its drops have no prior",
          id, a.init_why.empty() ? "no ultrasound measurement of a placed beacon" : a.init_why));
    }
  }
  if (options_.tracker == Tracker::kNone) return summary;
  num["measurements_without_beacon_position"] = static_cast<double>(no_position_);
  beacon_integrity_.Report(summary);
  for (const auto& [id, a] : agents_) {
    if (a.ekf) {
      const auto& s = a.ekf->summary();
      summary.notes.push_back(id + ": " + s.BriefReport());
      num[id + ".range_updates"] = static_cast<double>(s.range_updates);
      num[id + ".bearing_updates"] = static_cast<double>(s.bearing_updates);
      num[id + ".position_updates"] = static_cast<double>(s.position_updates);
      num[id + ".gated"] = static_cast<double>(s.gated);
      num[id + ".heading_correction_rad"] = a.ekf->psi();
      num[id + ".scale_correction"] = a.ekf->scale();
      num[id + ".range_scale"] = a.ekf->range_scale();
      if (!a.has_start) {
        summary.notes.push_back(fmt::format(
            "{}: no start; initialized from ultrasound at t = {:.2f} s", id, a.initialized_at));
        num[id + ".initialized_at_s"] = a.initialized_at;
      }
    } else if (a.us_kf) {
      num[id + ".position_updates"] = static_cast<double>(a.us_kf->accepted());
      num[id + ".gated"] = static_cast<double>(a.us_kf->gated());
    } else {
      summary.notes.push_back(id + ": never initialized (" +
                              (a.init_why.empty() ? "no ultrasound measurement" : a.init_why) +
                              ")");
    }
    // The way back out from where the agent last heard beacons (sec. 4).
    const WayOutReport way = WayOut(id, last_t_, options_.way_out_window_s);
    std::string text;
    for (const auto& b : way.route) text += (text.empty() ? "" : " -> ") + b;
    if (!way.route.empty())
      summary.notes.push_back(id + ": way out " + text + (way.broken ? " (" + *way.broken + ")" : ""));
    num[id + ".way_out_hops"] = static_cast<double>(way.route.size());
  }
  return summary;
}

}  // namespace trailmark::beacons

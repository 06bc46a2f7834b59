// SPDX-License-Identifier: MIT
#include "trailmark/beacons/beacon_map.h"

#include <fmt/format.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <stdexcept>

#include "trailmark/beacons/mds.h"
#include "trailmark/geometry/rigid_fit.h"
#include "trailmark/integrity/consistency.h"

namespace trailmark::beacons {
namespace {

// A problem solved again (its priors scaled) starts where its solution is.
void WarmStart(const MapSolution& solution, MapProblem* problem) {
  problem->track_start = solution.track_errors;
  for (std::size_t k = 0; k < problem->sightings.size(); ++k)
    problem->sightings[k].start = solution.sighting_state[k];
}

// The sigma of the median of `count` ranges (1.2533 sigma / sqrt(n) for large n, the mean's for
// n <= 2).
double MedianSigma(const BeaconMapOptions& options, std::size_t count) {
  const double k = static_cast<double>(count);
  return options.link_sigma_m * (k >= 3 ? 1.2533 : 1.0) / std::sqrt(k);
}

}  // namespace

bool BeaconMapOptions::IsValid(std::string* why) const {
  if (!(link_sigma_m > 0) || !(max_link_m > 0)) {
    if (why) *why = "link_sigma_m and max_link_m must be > 0";
    return false;
  }
  if (!(resolve_count_growth >= 1) || !(resolve_median_shift_sigma >= 0) ||
      !std::isfinite(resolve_count_growth) || !std::isfinite(resolve_median_shift_sigma)) {
    if (why) *why = "resolve_count_growth must be >= 1 and resolve_median_shift_sigma >= 0";
    return false;
  }
  if (max_sightings < 0 || sightings_min_surveyed < 0) {
    if (why) *why = "max_sightings and sightings_min_surveyed must be >= 0";
    return false;
  }
  if (!(range_scale_sigma >= 0) || !std::isfinite(range_scale_sigma)) {
    if (why) *why = "range_scale_sigma must be finite and >= 0";
    return false;
  }
  return least_squares.IsValid(why);
}

std::string BeaconMapSummary::BriefReport() const {
  std::string text = fmt::format(
      "beacon map: {} solves ({} of a changed part), {} component(s); {} from the map solve, {} "
      "surveyed, {} from drop estimates, {} unknown; anchoring rms {:.2f} m{}",
      solves, part_solves, components, from_mds, from_survey, from_hint, unknown, anchor_rms_m,
      reflected ? " (layout flipped)" : "");
  if (least_squares_parts > 0)
    text += fmt::format("; least squares chi2/dof {:.2f}", chi2_per_dof);
  if (sightings > 0)
    text += fmt::format(
        "; {} sighting(s) from the agents' tracks ({} in the last solve, {} of "
        "them beyond the robust bound)",
        sightings, sightings_used, sighting_outliers);
  if (tracks_without_sightings > 0)
    text += fmt::format(
        "; the sightings of {} track(s) left out: their dead reckoning drifted "
        "beyond its stated sigma (the sightings' chain is first order in it)",
        tracks_without_sightings);
  if (track_inflated_solves > 0)
    text += fmt::format("; dead-reckoning drift beyond its stated sigma in {} solve(s) (last: "
                        "x{:.1f} in variance)",
                        track_inflated_solves, track_inflation);
  if (inflated_solves > 0)
    text += fmt::format("; drop priors inflated in {} solve(s) (last x{:.1f} in variance: the "
                        "dead reckoning drifted beyond its stated sigma)",
                        inflated_solves, prior_inflation);
  if (rejected_solves > 0)
    text += fmt::format("; {} solve(s) rejected as inconsistent with the link noise, the "
                        "beacons kept their drop priors (latest: {})",
                        rejected_solves, rejected_why);
  return text;
}

BeaconMap::BeaconMap(Options options) : options_(options) {
  std::string why;
  if (!options_.IsValid(&why)) throw std::invalid_argument("BeaconMap options: " + why);
}

int BeaconMap::Add(const std::string& id) {
  if (const auto i = Find(id)) return *i;
  ids_.push_back(id);
  surveyed_.emplace_back();
  hint_.emplace_back();
  solved_.emplace_back();
  hint_track_.emplace_back();
  neighbours_.emplace_back();
  samples_.emplace_back();
  changed_.push_back(false);
  sightings_new_.push_back(0);
  sightings_used_.push_back(0);
  Touch(static_cast<int>(ids_.size()) - 1);
  return static_cast<int>(ids_.size()) - 1;
}

void RunningMedian::Add(double x) {
  if (!upper_.empty() && x < upper_.top())
    lower_.push(x);
  else
    upper_.push(x);
  // Keep |upper| = ceil(n/2), |lower| = floor(n/2): the median is upper's smallest.
  if (lower_.size() > upper_.size()) {
    upper_.push(lower_.top());
    lower_.pop();
  } else if (upper_.size() > lower_.size() + 1) {
    lower_.push(upper_.top());
    upper_.pop();
  }
}

std::optional<int> BeaconMap::Find(const std::string& id) const {
  const auto it = std::find(ids_.begin(), ids_.end(), id);
  if (it == ids_.end()) return std::nullopt;
  return static_cast<int>(it - ids_.begin());
}

void BeaconMap::SetSurveyed(int i, const Vec2& p, double sigma_m) {
  surveyed_[i] = BeaconPosition{p, Mat2::Identity() * sigma_m * sigma_m};
  Touch(i);
}

void BeaconMap::SetAnchorHint(int i, const Vec2& p, const Mat2& cov) {
  hint_[i] = BeaconPosition{p, 0.5 * (cov + cov.transpose())};
  hint_track_[i] = TrackHint{};
  Touch(i);
}

int BeaconMap::AddTrack(const MapTrack& track) {
  tracks_.push_back({0.5 * (track.cov + track.cov.transpose()), track.dof});
  return static_cast<int>(tracks_.size()) - 1;
}

void BeaconMap::SetTrackHint(int i, int track, const Vec2& p, const Mat2& white_cov,
                             const TrackLever& along, int from, const Mat2& increment_cov) {
  if (track < 0 || track >= static_cast<int>(tracks_.size()))
    throw std::invalid_argument(fmt::format("beacon map: no track {}", track));
  if (from >= static_cast<int>(ids_.size()) || from == i)
    throw std::invalid_argument(fmt::format("beacon map: hint of {} from {}", i, from));
  const Mat2 white = 0.5 * (white_cov + white_cov.transpose());
  const Mat2 marginal = white + along * tracks_[track].cov * along.transpose();
  hint_[i] = BeaconPosition{p, 0.5 * (marginal + marginal.transpose())};
  hint_track_[i] = TrackHint{track, white, along, from,
                             0.5 * (increment_cov + increment_cov.transpose())};
  Touch(i);
}

void BeaconMap::AddSighting(int i, int track, const Vec2& position_n, const TrackLever& along,
                            const TrackVec& heading_along, const Mat3& white_cov,
                            const Mat3& segment_cov, double range_m, double sigma_m) {
  if (!options_.sightings || options_.solver != MapSolver::kLeastSquares) return;
  if (i < 0 || i >= static_cast<int>(ids_.size()) || track < 0 ||
      track >= static_cast<int>(tracks_.size()))
    throw std::invalid_argument(
        fmt::format("beacon map: sighting of beacon {} on track {}", i, track));
  if (!position_n.allFinite() || !white_cov.allFinite() || !segment_cov.allFinite() ||
      !along.allFinite() || !heading_along.allFinite() || !std::isfinite(range_m) || range_m < 0 ||
      !(sigma_m > 0) || !std::isfinite(sigma_m))
    throw std::invalid_argument(
        fmt::format("beacon map: a sighting of {} is not finite or has sigma <= 0", ids_[i]));
  track_sightings_.resize(tracks_.size(), 0);
  sighting_state_.emplace_back();
  sightings_.push_back({i, track, track_sightings_[track]++, position_n, along, heading_along,
                        0.5 * (white_cov + white_cov.transpose()),
                        0.5 * (segment_cov + segment_cov.transpose()), range_m, sigma_m});
  ++summary_.sightings;
  // New sightings matter once they have grown by resolve_count_growth (as a pair's ranges do).
  const double used = static_cast<double>(sightings_used_[i]);
  if (++sightings_new_[i] >= std::max(1.0, (options_.resolve_count_growth - 1) * used)) Touch(i);
}

bool BeaconMap::AddRange(int i, int j, double range_m) {
  if (i == j || !std::isfinite(range_m) || range_m <= 0 || range_m > options_.max_link_m)
    return false;
  if (i > j) std::swap(i, j);
  auto& s = samples_[i][j];
  if (s.ranges_m.empty()) {
    neighbours_[i].push_back(j);
    neighbours_[j].push_back(i);
    std::sort(neighbours_[i].begin(), neighbours_[i].end());
    std::sort(neighbours_[j].begin(), neighbours_[j].end());
  }
  s.ranges_m.Add(range_m);
  const bool material =
      s.used_count == 0 ||
      static_cast<double>(s.ranges_m.size()) >=
          options_.resolve_count_growth * static_cast<double>(s.used_count) ||
      std::abs(s.ranges_m.Median() - s.used_median_m) >
          options_.resolve_median_shift_sigma * MedianSigma(options_, s.used_count);
  if (material) Touch(i), Touch(j);
  return true;
}

std::optional<BeaconPosition> BeaconMap::Position(int i) const {
  if (surveyed_[i] && !options_.mds_for_surveyed) return surveyed_[i];
  if (solved_[i]) return solved_[i];
  if (surveyed_[i]) return surveyed_[i];
  return hint_[i];
}

void BeaconMap::Solve() {
  BeginSolve(false);
  EndSolve();
}

std::vector<MapSighting> BeaconMap::PartSightings(const std::vector<int>& local,
                                                  std::vector<std::size_t>* ids) const {
  // The part's latest sightings, in the order they came (time order per track).
  std::vector<std::size_t> chosen;
  for (std::size_t k = sightings_.size(); k-- > 0;) {
    if (static_cast<int>(chosen.size()) >= options_.max_sightings) break;
    if (local[sightings_[k].beacon] >= 0 &&
        std::find(tracks_without_sightings_.begin(), tracks_without_sightings_.end(),
                  sightings_[k].track) == tracks_without_sightings_.end())
      chosen.push_back(k);
  }
  std::reverse(chosen.begin(), chosen.end());
  *ids = chosen;
  // Each follows its track's previous sighting when that one is chosen too; else it starts a
  // chain at the dead reckoning's white covariance there.
  std::map<int, std::pair<std::size_t, int>> last;  // track -> (sequence, index in out)
  std::vector<MapSighting> out;
  for (const std::size_t id : chosen) {
    const Sighting* s = &sightings_[id];
    MapSighting q;
    q.start = sighting_state_[id];
    q.i = local[s->beacon];
    q.range_m = s->range_m;
    q.sigma_m = s->sigma_m;
    q.track = s->track;
    q.position_n = s->position_n;
    q.along = s->along;
    q.heading_along = s->heading_along;
    q.cov = s->white;
    if (const auto l = last.find(s->track); l != last.end() && l->second.first + 1 == s->sequence) {
      q.from_sighting = l->second.second;
      q.cov = s->segment;
    }
    last[s->track] = {s->sequence, static_cast<int>(out.size())};
    out.push_back(q);
  }
  return out;
}

void BeaconMap::BeginSolve(bool on_worker) {
  if (pending_) EndSolve();
  dirty_ = false;
  auto pending = std::make_unique<Pending>();
  pending->tracks = tracks_;
  const int n = static_cast<int>(ids_.size());
  std::vector<int> component(n, -1);
  for (int start = 0; start < n; ++start) {
    if (component[start] >= 0) continue;
    std::vector<int> members{start};
    component[start] = start;
    bool changed = changed_[start];
    for (std::size_t k = 0; k < members.size(); ++k) {
      for (int v : neighbours_[members[k]]) {
        if (component[v] < 0) component[v] = start, members.push_back(v), changed |= changed_[v];
      }
    }
    // Parts only grow (a link joins two parts and touches both): an untouched part is the one
    // solved last time, on the same inputs.
    if (const auto it = parts_.find(start); !changed && it != parts_.end()) {
      pending->kept.emplace(start, it->second);
      continue;
    }
    pending->reset.insert(pending->reset.end(), members.begin(), members.end());
    if (members.size() < 2) continue;
    // The snapshot of this part: median range per measured pair (robust to a long NLOS
    // sample), its priors, its last solution.
    PartInput in;
    const int m = static_cast<int>(members.size());
    in.first_id = ids_[members[0]];
    in.measured.assign(m, std::vector<std::optional<double>>(m));
    in.counts.assign(static_cast<std::size_t>(m) * m, 0);
    std::vector<int> local(n, -1);  // beacon -> index in the part
    for (int a = 0; a < m; ++a) local[members[a]] = a;
    for (int a = 0; a < m; ++a) {
      const int i = members[a];
      for (auto& [j, pair] : samples_[i]) {
        const int b = local[j];  // a measured pair is in one part
        pair.used_median_m = pair.ranges_m.Median();
        pair.used_count = pair.ranges_m.size();
        in.measured[a][b] = in.measured[b][a] = pair.used_median_m;
        in.counts[a * m + b] = in.counts[b * m + a] = pair.used_count;
      }
      in.surveyed.push_back(surveyed_[i]);
      in.hint.push_back(hint_[i]);
      in.previous.push_back(solved_[i]);
      TrackHint h = hint_track_[i];
      h.from = h.from >= 0 ? local[h.from] : -1;
      in.hint_track.push_back(h);
    }
    if (options_.sightings && options_.solver == MapSolver::kLeastSquares &&
        in.SurveyedCount() >= options_.sightings_min_surveyed)
      in.sightings = PartSightings(local, &in.sighting_ids);
    for (const MapSighting& q : in.sightings)
      if (const auto t = track_state_.find(q.track); t != track_state_.end())
        in.track_start.emplace(q.track, t->second);
    for (int i : members) sightings_used_[i] += sightings_new_[i], sightings_new_[i] = 0;
    in.members = std::move(members);
    pending->inputs.push_back(std::move(in));
  }
  std::fill(changed_.begin(), changed_.end(), false);
  if (on_worker && !pending->inputs.empty()) {
    pending->outputs = std::async(std::launch::async, [p = pending.get(), o = options_] {
      std::vector<PartOutput> out;
      for (const PartInput& in : p->inputs) out.push_back(SolvePart(in, p->tracks, o));
      return out;
    });
  }
  pending_ = std::move(pending);
}

void BeaconMap::EndSolve() {
  if (!pending_) return;
  std::unique_ptr<Pending> pending = std::move(pending_);
  std::vector<PartOutput> outputs;
  if (pending->outputs.valid()) {
    outputs = pending->outputs.get();
  } else {
    for (const PartInput& in : pending->inputs)
      outputs.push_back(SolvePart(in, pending->tracks, options_));
  }
  ++summary_.solves;
  for (int i : pending->reset) solved_[i].reset();
  parts_ = std::move(pending->kept);
  for (std::size_t k = 0; k < outputs.size(); ++k) {
    const PartInput& in = pending->inputs[k];
    PartOutput& out = outputs[k];
    for (std::size_t a = 0; a < in.members.size(); ++a) solved_[in.members[a]] = out.solved[a];
    for (std::size_t k = 0; k < out.sighting_state.size(); ++k)
      if (out.sighting_state[k]) sighting_state_[in.sighting_ids[k]] = out.sighting_state[k];
    for (const auto& [track, e] : out.track_errors) track_state_[track] = e;
    for (int track : out.sighting_fallback_tracks)
      if (std::find(tracks_without_sightings_.begin(), tracks_without_sightings_.end(), track) ==
          tracks_without_sightings_.end())
        tracks_without_sightings_.push_back(track);
    parts_.emplace(in.members.front(), out.part);
    ++summary_.part_solves;
    summary_.track_inflated_solves += out.track_inflated_solves;
    summary_.inflated_solves += out.inflated_solves;
    summary_.fold_starts_won += out.fold_starts_won;
    if (out.rejected_why) summary_.rejected_why = std::move(*out.rejected_why);
  }
  // The summary at this solve: the worst part.
  summary_.components = 0;
  summary_.anchor_rms_m = 0;
  summary_.reflected = false;
  summary_.least_squares_parts = summary_.rejected_parts = 0;
  summary_.chi2_per_dof = 0;
  summary_.prior_inflation = 1;
  summary_.track_inflation = 1;
  summary_.sightings_used = summary_.sighting_outliers = 0;
  summary_.range_scale = 1.0;
  summary_.range_scale_sigma = 0.0;
  summary_.max_gradient = 0;
  std::size_t scaled_members = 0;
  summary_.tracks_without_sightings = tracks_without_sightings_.size();
  for (const auto& [first, part] : parts_) {
    if (part.range_scale_sigma > 0 && part.members >= scaled_members) {
      scaled_members = part.members;
      summary_.range_scale = part.range_scale;
      summary_.range_scale_sigma = part.range_scale_sigma;
    }
    summary_.max_gradient = std::max(summary_.max_gradient, part.max_gradient);
    summary_.sightings_used += part.sightings;
    summary_.sighting_outliers += part.sighting_outliers;
    summary_.components += part.placed;
    summary_.least_squares_parts += part.least_squares;
    summary_.rejected_parts += part.rejected;
    summary_.reflected = summary_.reflected || part.reflected;
    summary_.anchor_rms_m = std::max(summary_.anchor_rms_m, part.anchor_rms_m);
    summary_.chi2_per_dof = std::max(summary_.chi2_per_dof, part.chi2_per_dof);
    summary_.prior_inflation = std::max(summary_.prior_inflation, part.prior_inflation);
    summary_.track_inflation = std::max(summary_.track_inflation, part.track_inflation);
  }
  summary_.rejected_solves += summary_.rejected_parts > 0;
  summary_.from_mds = summary_.from_survey = summary_.from_hint = summary_.unknown = 0;
  for (std::size_t i = 0; i < ids_.size(); ++i) {
    if (surveyed_[i] && !options_.mds_for_surveyed)
      ++summary_.from_survey;
    else if (solved_[i])
      ++summary_.from_mds;
    else if (surveyed_[i])
      ++summary_.from_survey;
    else if (hint_[i])
      ++summary_.from_hint;
    else
      ++summary_.unknown;
  }
}

BeaconMap::PartOutput BeaconMap::SolvePart(const PartInput& in, const std::vector<MapTrack>& tracks,
                                           const Options& options) {
  PartOutput out;
  const int m = static_cast<int>(in.members.size());
  out.solved.resize(m);
  const RangeMatrix& measured = in.measured;
  // The paper's layout, placed by Procrustes onto the anchors: surveyed beacons when two or
  // more, else surveyed + drop estimates.
  std::optional<std::vector<Vec2>> mds_n;
  double mds_rms = 0;
  bool mds_reflected = false;
  if (m >= 3) {
    std::vector<std::vector<double>> full;
    FillShortestPaths(measured, &full);
    std::vector<Vec2> layout = ClassicalMds(full);
    if (options.refine) layout = RefineSmacof(measured, layout);
    std::vector<Vec2> from, to;
    int surveyed = 0;
    for (int a = 0; a < m; ++a) surveyed += in.surveyed[a].has_value();
    for (int a = 0; a < m; ++a) {
      const auto& anchor =
          in.surveyed[a] ? in.surveyed[a] : (surveyed >= 3 ? std::nullopt : in.hint[a]);
      if (anchor) from.push_back(layout[a]), to.push_back(anchor->position_n);
    }
    if (from.size() >= 2) {
      const RigidFit2 fit = FitRigid(from, to, from.size() >= 3);
      double sq = 0;
      for (std::size_t k = 0; k < from.size(); ++k)
        sq += (fit.Apply(from[k]) - to[k]).squaredNorm();
      mds_rms = std::sqrt(sq / from.size());
      mds_reflected = fit.rotation.determinant() < 0;
      for (Vec2& p : layout) p = fit.Apply(p);
      mds_n = std::move(layout);
    }
  }
  if (options.solver == MapSolver::kLeastSquares &&
      SolveLeastSquares(in, tracks, options, mds_n, &out)) {
    out.part.placed = true;
    return out;
  }
  if (!mds_n) return out;
  out.part.placed = true;
  out.part.anchor_rms_m = mds_rms;
  out.part.reflected = mds_reflected;
  // Covariance: the information of each beacon's measured links (others held fixed), plus the
  // anchoring residual (the layout's placement in the navigation frame).
  for (int a = 0; a < m; ++a) {
    const Vec2& p = (*mds_n)[a];
    Mat2 info = Mat2::Identity() * 1e-2;
    for (int b = 0; b < m; ++b) {
      if (!measured[a][b]) continue;
      Vec2 u = p - (*mds_n)[b];
      if (u.norm() < 1e-9) continue;
      u.normalize();
      info += u * u.transpose() / (options.link_sigma_m * options.link_sigma_m);
    }
    const double anchor_var = std::max(mds_rms * mds_rms, 0.01);
    out.solved[a] = BeaconPosition{p, Mat2(info.inverse() + Mat2::Identity() * anchor_var)};
  }
  return out;
}

bool BeaconMap::SolveLeastSquares(const PartInput& in, const std::vector<MapTrack>& tracks,
                                  const Options& options,
                                  const std::optional<std::vector<Vec2>>& mds_start,
                                  PartOutput* out) {
  const int m = static_cast<int>(in.members.size());
  PartResult* part = &out->part;
  MapProblem problem;
  problem.beacons = m;
  // The ranges' scale only where two surveys set a length the ranges do not.
  problem.range_scale_sigma = in.SurveyedCount() >= 2 ? options.range_scale_sigma : 0.0;
  Vec2 prior_mean = Vec2::Zero();
  std::vector<const BeaconPosition*> prior(m, nullptr);
  std::map<int, int> track_index;  // the map's track -> the problem's
  for (int a = 0; a < m; ++a) {
    prior[a] = in.surveyed[a] ? &*in.surveyed[a] : (in.hint[a] ? &*in.hint[a] : nullptr);
    if (!prior[a]) continue;
    prior_mean += prior[a]->position_n;
    const TrackHint& h = in.hint_track[a];
    if (in.surveyed[a] || h.track < 0) {
      problem.priors.push_back({a, prior[a]->position_n, prior[a]->cov});
      continue;
    }
    const auto [it, added] = track_index.emplace(h.track, static_cast<int>(problem.tracks.size()));
    if (added) problem.tracks.push_back(tracks[h.track]);
    MapPrior q{a, prior[a]->position_n, h.white_cov, it->second, h.along};
    // The displacement from the track's previous drop when that one is in this part too, and
    // when its increment is a covariance: the difference of the dead reckoning's covariances at
    // two drops is not one where the walk comes back towards its start (then the drop keeps
    // its absolute prior).
    const Mat2& inc = h.increment_cov;
    const bool increment_pd = inc(0, 0) > 0 && inc(0, 0) * inc(1, 1) - inc(0, 1) * inc(1, 0) > 0;
    if (options.relative_drop_priors && h.from >= 0 && !in.surveyed[h.from] && in.hint[h.from] &&
        in.hint_track[h.from].track == h.track && increment_pd) {
      q.cov = h.increment_cov;
      q.from = h.from;
      q.from_position_n = in.hint[h.from]->position_n;
      q.from_along = in.hint_track[h.from].along;
    }
    problem.priors.push_back(q);
  }
  if (problem.priors.size() < 2) return false;
  prior_mean /= static_cast<double>(problem.priors.size());
  for (MapSighting q : in.sightings) {
    const auto [it, added] = track_index.emplace(q.track, static_cast<int>(problem.tracks.size()));
    if (added) problem.tracks.push_back(tracks[q.track]);
    q.track = it->second;
    problem.sightings.push_back(q);
  }
  // Warm: each track's e where the last solve left it (its sightings' states likewise).
  if (!in.track_start.empty()) {
    problem.track_start.assign(problem.tracks.size(), TrackVec::Zero());
    for (const auto& [track, k] : track_index)
      if (const auto e = in.track_start.find(track); e != in.track_start.end())
        problem.track_start[k] = e->second;
  }
  for (int a = 0; a < m; ++a) {
    for (int b = a + 1; b < m; ++b) {
      if (!in.measured[a][b]) continue;
      // Every link of the map is ultrasound (the pipelines give it no other kind): timed.
      problem.links.push_back(
          {a, b, *in.measured[a][b], MedianSigma(options, in.counts[a * m + b]), true});
    }
  }
  // Start 0: the last solution, else the priors, else the MDS layout (the priors' mean when
  // there is none); start 1: the MDS layout. The lower cost wins (the fold the priors favour).
  std::vector<std::vector<Vec2>> starts(1, std::vector<Vec2>(m));
  for (int a = 0; a < m; ++a) {
    starts[0][a] = in.previous[a] ? in.previous[a]->position_n
                   : prior[a]     ? prior[a]->position_n
                   : mds_start    ? (*mds_start)[a]
                                  : Vec2(prior_mean + Vec2(0.1 * a, 0.05 * a));
  }
  if (mds_start) starts.push_back(*mds_start);
  MapSolution solution = SolveMapLeastSquares(problem, starts, options.least_squares);
  // Sightings hold while their track's dead reckoning is what its model says: their chain's
  // lever arms are first order in the shared errors. A track whose errors come out beyond
  // their sigma (a drift 10x the prior's turns the heading 140 deg in 4 min: beacon-trail
  // seed 8) would bend the map with them; its sightings are left out and the part solved
  // again from the same starts, and from now on (the caller stops giving them).
  // The input sighting each of the problem's is (the identity until some are left out).
  std::vector<std::size_t> sighting_of(problem.sightings.size());
  std::iota(sighting_of.begin(), sighting_of.end(), std::size_t{0});
  if (solution.ok && !problem.sightings.empty()) {
    const double limit = integrity::ChiSquareQuantile(1, 1 - options.least_squares.false_alarm);
    std::vector<bool> beyond(problem.tracks.size(), false);
    for (std::size_t k = 0; k < problem.tracks.size(); ++k)
      for (int j = 0; j < kTrackErrors; ++j)
        beyond[k] = beyond[k] || solution.track_errors[k][j] * solution.track_errors[k][j] >
                                     limit * problem.tracks[k].cov(j, j);
    std::vector<MapSighting> kept;
    std::vector<int> index(problem.sightings.size(), -1);
    std::vector<std::size_t> original;
    for (std::size_t k = 0; k < problem.sightings.size(); ++k) {
      MapSighting q = problem.sightings[k];
      if (beyond[q.track]) continue;
      q.from_sighting = q.from_sighting >= 0 ? index[q.from_sighting] : -1;
      index[k] = static_cast<int>(kept.size());
      kept.push_back(q);
      original.push_back(k);
    }
    if (kept.size() < problem.sightings.size()) {
      for (const auto& [track, k] : track_index)
        if (beyond[k]) out->sighting_fallback_tracks.push_back(track);
      problem.sightings = std::move(kept);
      sighting_of = std::move(original);
      problem.track_start.clear();
      solution = SolveMapLeastSquares(problem, starts, options.least_squares);
    }
  }
  // A track whose shared errors came out beyond their stated sigma: its dead reckoning drifts
  // more than assumed a priori (another PDR, a magnetically disturbed heading). Its covariance
  // is scaled to what was found, the map solved again from there (so the map follows the links,
  // not the tighter prior). Each error apart (`inflate_track_errors_apart`, since 2026-12-06):
  // a drift rate beyond its sigma says nothing about the start heading, and scaling all four
  // by the rate's excess let the start heading, the map's only hold on its rotation where no
  // beacon is surveyed, turn the map 40 deg (beacon-trail seed 8); else the track's chi-square
  // with its dof and one scale for all.
  const bool any_surveyed = in.SurveyedCount() > 0;
  if (solution.ok) {
    bool again = false;
    const double alarm = 1 - options.least_squares.false_alarm;
    for (std::size_t k = 0; k < problem.tracks.size(); ++k) {
      MapTrack& track = problem.tracks[k];
      const TrackVec& e = solution.track_errors[k];
      if (options.inflate_track_errors_apart) {
        const double limit = integrity::ChiSquareQuantile(1, alarm);
        double largest = 1;
        for (int j = 0; j < kTrackErrors; ++j) {
          const double q = e[j] * e[j] / track.cov(j, j);
          if (!(q > limit)) continue;
          const double f = std::min(q, 100.0);
          largest = std::max(largest, f);
          track.cov.row(j) *= std::sqrt(f);
          track.cov.col(j) *= std::sqrt(f);
          part->track_inflation = std::max(part->track_inflation, f);
          again = true;
        }
        // Not where a beacon is surveyed: there a shared error beyond its sigma may be a
        // survey's fault (one written 4 m off), and loosened drops would hand the map to it.
        if (largest > 1 && options.inflate_track_white && !any_surveyed) {
          for (MapPrior& q : problem.priors)
            if (q.track == static_cast<int>(k)) q.cov *= largest;
          for (MapSighting& q : problem.sightings)
            if (q.track == static_cast<int>(k)) q.cov *= largest;
        }
        continue;
      }
      const int dof = std::max(track.dof, 1);
      const double limit = integrity::ChiSquareQuantile(dof, alarm);
      const double q = e.dot(track.cov.ldlt().solve(e));
      if (q > limit) {
        const double f = std::min(q / dof, 100.0);
        track.cov *= f;
        part->track_inflation = std::max(part->track_inflation, f);
        again = true;
      }
    }
    if (again) {
      starts = {solution.position_n};
      WarmStart(solution, &problem);
      MapSolution next = SolveMapLeastSquares(problem, starts, options.least_squares);
      if (next.ok) {
        next.start = solution.start;
        solution = std::move(next);
        ++out->track_inflated_solves;
      }
    }
  }
  // Inconsistent, but the links agree among themselves: the drop priors claim more than the
  // dead reckoning has (its drift beyond its a-priori sigma). Their covariances are scaled by
  // their own chi-square per residual and the map solved again; still inconsistent: rejected.
  if (solution.ok && !solution.consistent) {
    const int link_dof = static_cast<int>(problem.links.size()) - (2 * m - 3);
    const bool links_ok =
        link_dof <= 0 ||
        solution.chi2_links <= integrity::ChiSquareQuantile(
                                   link_dof, 1 - options.least_squares.false_alarm);
    const double f =
        solution.chi2_priors / std::max(1.0, solution.prior_residuals - 3.0);
    if (links_ok && f > 1) {
      for (MapPrior& q : problem.priors) q.cov *= f;
      for (MapTrack& t : problem.tracks) t.cov *= f;
      for (MapSighting& q : problem.sightings) q.cov *= f;
      starts = {solution.position_n};
      WarmStart(solution, &problem);
      MapSolution again = SolveMapLeastSquares(problem, starts, options.least_squares);
      if (again.ok) {
        again.start = solution.start;
        solution = std::move(again);
        part->prior_inflation = f;
        ++out->inflated_solves;
      }
    }
  }
  if (!solution.ok) {
    out->rejected_why = solution.why;
    return false;
  }
  part->least_squares = true;
  part->members = static_cast<std::size_t>(m);
  part->range_scale = solution.range_scale;
  part->range_scale_sigma = std::sqrt(std::max(solution.range_scale_var, 0.0));
  part->max_gradient = solution.max_gradient;
  part->sightings = problem.sightings.size();
  part->sighting_outliers = static_cast<std::size_t>(solution.sighting_outliers);
  out->fold_starts_won += solution.start == 1;
  double sq = 0;
  for (const MapPrior& q : problem.priors) sq += (solution.position_n[q.i] - q.position_n).squaredNorm();
  part->anchor_rms_m = std::sqrt(sq / static_cast<double>(problem.priors.size()));
  if (solution.dof > 0) part->chi2_per_dof = solution.chi2 / solution.dof;
  if (!solution.consistent && options.reject_inconsistent) {
    part->rejected = true;
    out->rejected_why = fmt::format(
        "{} beacon(s) from {}: chi-square {:.1f} > {:.1f} for {} degrees of freedom",
        m, in.first_id, solution.chi2, solution.chi2_threshold, solution.dof);
    return true;  // the part keeps its priors (Position() falls back to them)
  }
  for (int a = 0; a < m; ++a) out->solved[a] = BeaconPosition{solution.position_n[a], solution.cov[a]};
  out->sighting_state.assign(in.sightings.size(), std::nullopt);
  for (std::size_t k = 0; k < solution.sighting_state.size(); ++k)
    out->sighting_state[sighting_of[k]] = solution.sighting_state[k];
  for (const auto& [track, k] : track_index) out->track_errors[track] = solution.track_errors[k];
  return true;
}

std::vector<int> WayOut(const std::vector<std::vector<int>>& neighbours,
                        const std::vector<int>& rank, const std::vector<int>& heard,
                        std::string* why) {
  std::vector<int> route;
  if (heard.empty()) {
    if (why) *why = "no beacon heard";
    return route;
  }
  const auto by_rank = [&](int a, int b) { return rank[a] < rank[b]; };
  int entry = 0;
  for (int i = 1; i < static_cast<int>(rank.size()); ++i) entry = by_rank(i, entry) ? i : entry;
  int at = *std::min_element(heard.begin(), heard.end(), by_rank);
  route.push_back(at);
  while (at != entry) {
    int next = at;
    for (int v : neighbours[at]) next = by_rank(v, next) ? v : next;
    if (next == at) {
      if (why) *why = fmt::format("trail broken: beacon {} hears none deployed before it", at);
      break;
    }
    route.push_back(next);
    at = next;
  }
  return route;
}

}  // namespace trailmark::beacons

// SPDX-License-Identifier: MIT
#include "trailmark/beacons/beacon_map.h"

#include <fmt/format.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

#include "trailmark/beacons/mds.h"
#include "trailmark/geometry/rigid_fit.h"

namespace trailmark::beacons {

bool BeaconMapOptions::IsValid(std::string* why) const {
  if (!(link_sigma_m > 0) || !(max_link_m > 0)) {
    if (why) *why = "link_sigma_m and max_link_m must be > 0";
    return false;
  }
  return true;
}

std::string BeaconMapSummary::BriefReport() const {
  return fmt::format(
      "beacon map: {} solves, {} component(s); {} from MDS, {} surveyed, {} from drop "
      "estimates, {} unknown; anchoring rms {:.2f} m{}",
      solves, components, from_mds, from_survey, from_hint, unknown, anchor_rms_m,
      reflected ? " (layout flipped)" : "");
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
  neighbours_.emplace_back();
  for (auto& row : samples_) row.emplace_back();
  samples_.emplace_back(ids_.size());
  dirty_ = true;
  return static_cast<int>(ids_.size()) - 1;
}

std::optional<int> BeaconMap::Find(const std::string& id) const {
  const auto it = std::find(ids_.begin(), ids_.end(), id);
  if (it == ids_.end()) return std::nullopt;
  return static_cast<int>(it - ids_.begin());
}

void BeaconMap::SetSurveyed(int i, const Vec2& p, double sigma_m) {
  surveyed_[i] = BeaconPosition{p, Mat2::Identity() * sigma_m * sigma_m};
  dirty_ = true;
}

void BeaconMap::SetAnchorHint(int i, const Vec2& p, const Mat2& cov) {
  hint_[i] = BeaconPosition{p, 0.5 * (cov + cov.transpose())};
  dirty_ = true;
}

bool BeaconMap::AddRange(int i, int j, double range_m) {
  if (i == j || !std::isfinite(range_m) || range_m <= 0 || range_m > options_.max_link_m)
    return false;
  if (i > j) std::swap(i, j);
  auto& s = samples_[i][j];
  if (s.empty()) {
    neighbours_[i].push_back(j);
    neighbours_[j].push_back(i);
    std::sort(neighbours_[i].begin(), neighbours_[i].end());
    std::sort(neighbours_[j].begin(), neighbours_[j].end());
  }
  s.push_back(range_m);
  dirty_ = true;
  return true;
}

std::optional<BeaconPosition> BeaconMap::Position(int i) const {
  if (surveyed_[i] && !options_.mds_for_surveyed) return surveyed_[i];
  if (solved_[i]) return solved_[i];
  if (surveyed_[i]) return surveyed_[i];
  return hint_[i];
}

void BeaconMap::Solve() {
  dirty_ = false;
  ++summary_.solves;
  const int n = static_cast<int>(ids_.size());
  std::fill(solved_.begin(), solved_.end(), std::nullopt);
  summary_.components = 0;
  summary_.anchor_rms_m = 0;
  summary_.reflected = false;
  // Median range per measured pair (robust to a long NLOS sample).
  auto median = [](std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
  };
  std::vector<int> component(n, -1);
  for (int start = 0; start < n; ++start) {
    if (component[start] >= 0) continue;
    std::vector<int> members{start};
    component[start] = start;
    for (std::size_t k = 0; k < members.size(); ++k) {
      for (int v : neighbours_[members[k]]) {
        if (component[v] < 0) component[v] = start, members.push_back(v);
      }
    }
    if (members.size() < 3) continue;
    const int m = static_cast<int>(members.size());
    RangeMatrix measured(m, std::vector<std::optional<double>>(m));
    for (int a = 0; a < m; ++a) {
      for (int b = a + 1; b < m; ++b) {
        const int i = std::min(members[a], members[b]), j = std::max(members[a], members[b]);
        if (!samples_[i][j].empty()) measured[a][b] = measured[b][a] = median(samples_[i][j]);
      }
    }
    std::vector<std::vector<double>> full;
    FillShortestPaths(measured, &full);
    std::vector<Vec2> layout = ClassicalMds(full);
    if (options_.refine) layout = RefineSmacof(measured, layout);
    // Anchors: surveyed beacons when two or more, else surveyed + drop estimates.
    std::vector<Vec2> from, to;
    int surveyed = 0;
    for (int a = 0; a < m; ++a) surveyed += surveyed_[members[a]].has_value();
    for (int a = 0; a < m; ++a) {
      const auto& anchor = surveyed_[members[a]]
                               ? surveyed_[members[a]]
                               : (surveyed >= 3 ? std::nullopt : hint_[members[a]]);
      if (anchor) from.push_back(layout[a]), to.push_back(anchor->position_n);
    }
    if (from.size() < 2) continue;
    const RigidFit2 fit = FitRigid(from, to, from.size() >= 3);
    double sq = 0;
    for (std::size_t k = 0; k < from.size(); ++k) sq += (fit.Apply(from[k]) - to[k]).squaredNorm();
    const double rms = std::sqrt(sq / from.size());
    ++summary_.components;
    summary_.anchor_rms_m = std::max(summary_.anchor_rms_m, rms);
    summary_.reflected = summary_.reflected || fit.rotation.determinant() < 0;
    // Covariance: the information of each beacon's measured links (others held fixed), plus the
    // anchoring residual (the layout's placement in the navigation frame).
    for (int a = 0; a < m; ++a) {
      const Vec2 p = fit.Apply(layout[a]);
      Mat2 info = Mat2::Identity() * 1e-2;
      for (int b = 0; b < m; ++b) {
        if (!measured[a][b]) continue;
        Vec2 u = p - fit.Apply(layout[b]);
        if (u.norm() < 1e-9) continue;
        u.normalize();
        info += u * u.transpose() / (options_.link_sigma_m * options_.link_sigma_m);
      }
      const double anchor_var = std::max(rms * rms, 0.01);
      solved_[members[a]] = BeaconPosition{p, Mat2(info.inverse() + Mat2::Identity() * anchor_var)};
    }
  }
  summary_.from_mds = summary_.from_survey = summary_.from_hint = summary_.unknown = 0;
  for (int i = 0; i < n; ++i) {
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

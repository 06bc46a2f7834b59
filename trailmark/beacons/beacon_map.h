// SPDX-License-Identifier: MIT
#pragma once
/// The beacon trail as a tracker needs it, built online: beacon-to-beacon ultrasound ranges
/// (median per pair), positions from MDS with shortest-path completion and SMACOF refinement
/// (beacons/mds.h), anchored by Procrustes onto what is known in the navigation frame —
/// surveyed beacons, else the responder's own estimate where each beacon was dropped
/// ("anchor hints"; sec. 5: "the base position and entry heading" in the paper's words).
/// Per-beacon covariances from the information of its measured links plus the anchoring
/// residual. Also the way back out (sec. 4): move towards the smallest id you can hear. No I/O.

#include <optional>
#include <string>
#include <vector>

#include "trailmark/beacons/scaat_ekf.h"
#include "trailmark/core/types.h"

namespace trailmark::beacons {

struct BeaconMapOptions {
  bool refine = true;             ///< SMACOF after MDS (ours)
  bool mds_for_surveyed = false;  ///< surveyed beacons too from MDS (Fig. 8); survey only anchors
  double link_sigma_m = 0.10;     ///< static ultrasound range (Hazas et al. 2005: ~10 cm)
  double max_link_m = 8.0;        ///< beacon ranges longer than this are outliers
  bool IsValid(std::string* why) const;
};

struct BeaconMapSummary {
  std::size_t solves = 0;
  std::size_t components = 0;  ///< at the last solve (with >= 3 beacons)
  std::size_t from_mds = 0, from_survey = 0, from_hint = 0, unknown = 0;
  double anchor_rms_m = 0;  ///< Procrustes residual at the last solve
  bool reflected = false;   ///< the MDS layout needed a flip
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
  bool HasAnchor(int i) const { return surveyed_[i].has_value() || hint_[i].has_value(); }
  /// A beacon-to-beacon range; returns false (and ignores it) when implausible.
  bool AddRange(int i, int j, double range_m);
  /// True when ranges or hints arrived since the last Solve().
  bool dirty() const { return dirty_; }
  /// Recomputes every position.
  void Solve();

  std::optional<BeaconPosition> Position(int i) const;
  /// Beacons with a measured link to `i`.
  const std::vector<int>& Neighbours(int i) const { return neighbours_[i]; }
  const BeaconMapSummary& summary() const { return summary_; }

 private:
  Options options_;
  std::vector<std::string> ids_;
  std::vector<std::optional<BeaconPosition>> surveyed_, hint_, solved_;
  std::vector<std::vector<int>> neighbours_;
  std::vector<std::vector<std::vector<double>>> samples_;  ///< [i][j], i < j
  bool dirty_ = false;
  BeaconMapSummary summary_;
};

/// The way back out (sec. 4; Souryal et al. 2007): from the beacon of smallest deployment rank
/// heard, go to its neighbour of smallest rank, and so on, until the beacon of smallest rank of
/// all (the entry). `rank[i]` is beacon i's deployment order. `why` says where the trail breaks
/// when the entry cannot be reached. Empty when nothing is heard.
std::vector<int> WayOut(const std::vector<std::vector<int>>& neighbours,
                        const std::vector<int>& rank, const std::vector<int>& heard,
                        std::string* why = nullptr);

}  // namespace trailmark::beacons

// SPDX-License-Identifier: MIT
#pragma once
/// Pattern comparison of the map-aided search paper (sec. IV-D, Algorithm 1): the last
/// `pattern_length_m` of odometry is rotated to the building's principal directions (eq. 1),
/// then compared by ICP, from four initial rotations, with every search pattern cut from the
/// node sequences; the result per sequence is the RMSE matrix E_m (N_m x 2: the pattern's
/// first node as a left-hand observation, its last as a right-hand one) with the position and
/// heading observations Pos_m, Hea_m. No I/O.
///
/// ICP is our own point-to-point ICP on these tiny sets (tens of points): the closed-form 2-D
/// rigid fit (geometry/rigid_fit.h, Eigen SVD) and an exact scan for the closest points on the
/// pattern polyline (runs of four segments skipped by their bounding boxes), measured faster than
/// building a nanoflann tree per pattern (docs/mapmatch.md).
/// Beyond the paper: an ICP whose RMSE is above twice `abandon_rmse_m` after one iteration, or
/// above it after two, is stopped (its likelihood exp(-E/sigma^2) = e^-100 is negligible next to
/// any real match).

#include <array>
#include <limits>
#include <string>
#include <vector>

#include "trailmark/mapmatch/search_map.h"

namespace trailmark::mapmatch {

/// Eq. (1): the rotation phi in [-pi/4, pi/4) minimizing the summed distance of the
/// displacement directions of `trajectory` to the nearest principal direction.
double PrincipalRotation(const std::vector<Vec2>& trajectory);

struct IcpOptions {
  int max_iterations = 30;
  double tolerance_m = 1e-3;    ///< stop when the RMSE changes less than this
  double abandon_rmse_m = 1.0;  ///< after two iterations (ours; see above)
  /// Trimmed ICP (Chetverikov et al. 2002; ours): the worst fraction of correspondences is
  /// left out of the fit and of the RMSE, so that a detour round furniture or a sweep does
  /// not hide an otherwise matching pattern. 0 is the paper's plain ICP.
  double trim_fraction = 0.0;
};

struct IcpResult {
  Mat2 rotation = Mat2::Identity();  ///< source -> target
  Vec2 translation = Vec2::Zero();
  double rmse_m = std::numeric_limits<double>::infinity();
  int iterations = 0;
  Vec2 Apply(const Vec2& p) const { return rotation * p + translation; }
};

/// Point-to-point ICP of `source` points onto the polyline `target` (closest points on its
/// segments), from the initial transform (R0, t0). Proper rotations only.
IcpResult Icp(const std::vector<Vec2>& source, const std::vector<Vec2>& target, const Mat2& R0,
              const Vec2& t0, const IcpOptions& options = {});

struct PatternComparisonOptions {
  double pattern_length_m = 20.0;  ///< d (sec. V-B)
  double point_spacing_m = 0.5;    ///< odometry resampled along its length (ours; see docs)
  IcpOptions icp;
  bool IsValid(std::string* why) const;
};

/// E_m, Pos_m, Hea_m of one node sequence (index eta = start node).
struct SequenceComparison {
  std::vector<std::array<double, 2>> rmse_m;       ///< E_m; infinity where not applicable
  std::vector<std::array<Vec2, 2>> position_n;     ///< Pos_m
  std::vector<std::array<double, 2>> heading_rad;  ///< Hea_m
  std::vector<int> last_node;                      ///< eta + Delta N (mod N_m) per start node
};

struct PatternComparison {
  std::vector<SequenceComparison> sequences;
  double principal_rotation_rad = 0;
  std::size_t icp_runs = 0, icp_abandoned = 0;
  /// ICP iterations (closest-point passes) of the abandoned runs and of the others.
  std::size_t icp_iterations_abandoned = 0, icp_iterations_kept = 0;
};

/// Algorithm 1 for the odometry `trajectory` (navigation frame, oldest first; its length
/// should be about pattern_length_m).
PatternComparison ComparePatterns(const std::vector<Vec2>& trajectory,
                                  const std::vector<NodeSequence>& sequences,
                                  const PatternComparisonOptions& options = {});

/// Points every `spacing_m` along the polyline (first and last included).
std::vector<Vec2> ResampleByDistance(const std::vector<Vec2>& polyline, double spacing_m);

}  // namespace trailmark::mapmatch

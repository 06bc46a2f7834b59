// SPDX-License-Identifier: MIT
#pragma once
/// Static localization of dropped beacons (ultrasound-beacons paper, sec. 5): classical
/// multidimensional scaling (Torgerson; Shang et al. 2003) on a distance matrix whose missing
/// entries are filled by shortest paths over the measured links (Ji & Zha 2004) or by RSSI
/// ranges; anchoring by Procrustes (rotation, translation, optionally reflection) to known
/// positions. Beyond the paper: refinement by weighted SMACOF stress majorization (de Leeuw
/// 1977) on the measured links only, so that filled (biased-long) distances no longer distort
/// the layout. No I/O.

#include <optional>
#include <vector>

#include "trailmark/core/types.h"

namespace trailmark::beacons {

/// Symmetric n x n matrix of measured ranges (metres); empty where not measured.
using RangeMatrix = std::vector<std::vector<std::optional<double>>>;

/// Completes the matrix with shortest-path distances over the measured links (Dijkstra from
/// every node). Returns false when the link graph is not connected (unreachable pairs are then
/// left at the largest finite distance x 2).
bool FillShortestPaths(const RangeMatrix& measured, std::vector<std::vector<double>>* full);

/// How classical MDS finds the two leading eigenpairs of B.
enum class MdsEigensolver {
  kAuto,     ///< partial from 64 points on (dense below: it is faster there), dense if it fails
  kDense,    ///< Eigen's dense symmetric solver (Householder tridiagonalization, O(n^3))
  kPartial,  ///< Spectra's implicitly restarted Lanczos for the top two (O(n^2) per iteration)
};

/// Classical MDS: the 2-D configuration whose distances best match `full` (double centring,
/// the two leading eigenpairs of B = -1/2 J D^2 J). Each eigenvector's sign is fixed (its
/// largest component positive), so every solver gives the same layout.
std::vector<Vec2> ClassicalMds(const std::vector<std::vector<double>>& full,
                               MdsEigensolver solver = MdsEigensolver::kAuto);

/// SMACOF on the measured links only (weights 1 on measured pairs, 0 elsewhere), from `start`.
/// Returns the refined configuration; `stress` (optional) receives the final raw stress.
std::vector<Vec2> RefineSmacof(const RangeMatrix& measured, std::vector<Vec2> start,
                               int max_iterations = 300, double tolerance = 1e-7,
                               double* stress = nullptr);

}  // namespace trailmark::beacons

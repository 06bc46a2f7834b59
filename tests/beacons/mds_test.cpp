// SPDX-License-Identifier: MIT
// MDS beacon localization (ultrasound-beacons paper, sec. 5): exact distances give the exact
// layout (up to a rigid motion and flip), shortest-path completion, Procrustes anchoring, and
// SMACOF on the measured links removing the shortest-path bias.
#include "trailmark/beacons/mds.h"
#include "trailmark/geometry/rigid_fit.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "trailmark/core/random.h"

namespace trailmark::beacons {
namespace {

std::vector<Vec2> RandomBeacons(int n, std::uint64_t seed) {
  Random rng(seed);
  std::vector<Vec2> p;
  for (int i = 0; i < n; ++i) p.emplace_back(rng.Uniform(0, 15), rng.Uniform(0, 9));
  return p;
}

double AlignedError(const std::vector<Vec2>& est, const std::vector<Vec2>& truth) {
  const RigidFit2 T = FitRigid(est, truth, true);
  double sum = 0;
  for (std::size_t i = 0; i < est.size(); ++i) sum += (T.Apply(est[i]) - truth[i]).norm();
  return sum / est.size();
}

TEST(Mds, ExactDistancesGiveTheExactLayout) {
  const auto truth = RandomBeacons(21, 1);
  std::vector<std::vector<double>> full(truth.size(), std::vector<double>(truth.size()));
  for (std::size_t i = 0; i < truth.size(); ++i) {
    for (std::size_t j = 0; j < truth.size(); ++j) full[i][j] = (truth[i] - truth[j]).norm();
  }
  EXPECT_LT(AlignedError(ClassicalMds(full), truth), 1e-9);  // issue 4: to 1e-9 up to a rigid motion
}

// The partial eigensolver (Spectra, Lanczos) against the dense one, on exact distances (1,000
// beacons: the layout to 1e-9 m) and on noisy shortest-path-completed ones (a B with many
// negative eigenvalues): the same layout to 1e-6 m, sign fixed by the same rule.
TEST(Mds, PartialEigensolverGivesTheDenseLayout) {
  for (const int n : {80, 1000}) {
    Random rng(n);
    const double side = std::sqrt(n * 13.5);
    std::vector<Vec2> truth;
    for (int i = 0; i < n; ++i) truth.emplace_back(rng.Uniform(0, side), rng.Uniform(0, side));
    std::vector<std::vector<double>> exact(n, std::vector<double>(n));
    RangeMatrix measured(n, std::vector<std::optional<double>>(n));
    for (int i = 0; i < n; ++i) {
      for (int j = 0; j < n; ++j) exact[i][j] = (truth[i] - truth[j]).norm();
      for (int j = i + 1; j < n; ++j) {
        if (exact[i][j] < 8.0) measured[i][j] = measured[j][i] = exact[i][j] + rng.Normal(0, 0.1);
      }
    }
    std::vector<std::vector<double>> paths;
    FillShortestPaths(measured, &paths);
    for (const auto* full : {&exact, &paths}) {
      const auto dense = ClassicalMds(*full, MdsEigensolver::kDense);
      const auto partial = ClassicalMds(*full, MdsEigensolver::kPartial);
      double worst = 0;
      for (int i = 0; i < n; ++i) worst = std::max(worst, (dense[i] - partial[i]).norm());
      EXPECT_LT(worst, full == &exact ? 1e-9 : 1e-6) << n << (full == &exact ? " exact" : " paths");
      if (full == &exact) EXPECT_LT(AlignedError(partial, truth), 1e-9) << n;
    }
  }
}

TEST(Mds, ProcrustesRecoversRotationTranslationAndFlip) {
  const auto from = RandomBeacons(6, 2);
  const Mat2 R = Eigen::Rotation2Dd(0.7).toRotationMatrix();
  Mat2 flip = Mat2::Identity();
  flip(1, 1) = -1;
  std::vector<Vec2> to;
  for (const auto& p : from) to.push_back(R * flip * p + Vec2(3, -4));
  const RigidFit2 T = FitRigid(from, to, true);
  for (std::size_t i = 0; i < from.size(); ++i) EXPECT_LT((T.Apply(from[i]) - to[i]).norm(), 1e-9);
  EXPECT_NEAR(T.rotation.determinant(), -1.0, 1e-9);
  const RigidFit2 proper = FitRigid(from, to, false);
  EXPECT_NEAR(proper.rotation.determinant(), 1.0, 1e-9);
}

TEST(Mds, ShortestPathsCompleteAChainAndReportDisconnection) {
  // 0 - 1 - 2 - 3 on a line, 1 m apart, only neighbours measured.
  RangeMatrix m(4, std::vector<std::optional<double>>(4));
  for (int i = 0; i + 1 < 4; ++i) m[i][i + 1] = m[i + 1][i] = 1.0;
  std::vector<std::vector<double>> full;
  EXPECT_TRUE(FillShortestPaths(m, &full));
  EXPECT_DOUBLE_EQ(full[0][3], 3.0);
  EXPECT_DOUBLE_EQ(full[3][0], 3.0);
  m[2][3] = m[3][2] = std::nullopt;
  EXPECT_FALSE(FillShortestPaths(m, &full));
  // A noisy short link read as negative must not loop (negative cycle): it counts as ~0.
  m[2][3] = m[3][2] = -0.2;
  EXPECT_TRUE(FillShortestPaths(m, &full));
  EXPECT_NEAR(full[0][3], 2.0, 1e-5);
}

TEST(Mds, SmacofOnMeasuredLinksRemovesTheShortestPathBias) {
  const auto truth = RandomBeacons(21, 3);
  RangeMatrix m(truth.size(), std::vector<std::optional<double>>(truth.size()));
  for (std::size_t i = 0; i < truth.size(); ++i) {
    for (std::size_t j = 0; j < truth.size(); ++j) {
      const double d = (truth[i] - truth[j]).norm();
      if (i != j && d < 6.0) m[i][j] = d;  // a 6 m ultrasound range
    }
  }
  std::vector<std::vector<double>> full;
  ASSERT_TRUE(FillShortestPaths(m, &full));
  const auto mds = ClassicalMds(full);
  double stress = 0;
  const auto refined = RefineSmacof(m, mds, 1000, 1e-12, &stress);
  const double e_mds = AlignedError(mds, truth), e_ref = AlignedError(refined, truth);
  EXPECT_GT(e_mds, 0.05);         // shortest paths are longer than straight lines
  EXPECT_LT(e_ref, 0.25 * e_mds);  // refinement on the measured links removes most of it
  EXPECT_LT(stress, 1e-3);
}

}  // namespace
}  // namespace trailmark::beacons

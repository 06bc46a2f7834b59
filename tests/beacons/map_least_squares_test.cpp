// SPDX-License-Identifier: MIT
#include "trailmark/beacons/map_least_squares.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

#include "trailmark/core/random.h"

namespace trailmark::beacons {
namespace {

// A U-shaped trail: beacons 2 m apart along it, links to the next two only (no link across).
std::vector<Vec2> UTrail() {
  std::vector<Vec2> p;
  for (double x = 0; x <= 16; x += 2) p.emplace_back(x, 0);
  for (double y = 2; y <= 8; y += 2) p.emplace_back(16, y);
  for (double x = 14; x >= 0; x -= 2) p.emplace_back(x, 8);
  return p;
}

MapProblem Problem(const std::vector<Vec2>& truth, double link_noise_m, double prior_noise_m,
                   Random& rng) {
  MapProblem p;
  p.beacons = static_cast<int>(truth.size());
  for (int i = 0; i < p.beacons; ++i)
    for (int j = i + 1; j <= i + 2 && j < p.beacons; ++j)
      p.links.push_back({i, j, (truth[i] - truth[j]).norm() + link_noise_m * rng.Normal(), 0.1});
  for (int i = 0; i < p.beacons; ++i) {
    const double s = i == 4 || i == 12 ? 0.05 : 1.0;  // two surveyed, the rest drop priors
    const Vec2 mu = truth[i] + (i == 4 || i == 12 ? 0.0 : prior_noise_m) *
                                   Vec2(rng.Normal(), rng.Normal());
    p.priors.push_back({i, mu, Mat2::Identity() * s * s});
  }
  return p;
}

TEST(MapLeastSquares, RecoversANoiseFreeTrailFromItsPriors) {
  Random rng(3);
  const auto truth = UTrail();
  const MapProblem p = Problem(truth, 0.0, 0.0, rng);
  std::vector<Vec2> start = truth;
  for (auto& s : start) s += Vec2(0.5 * rng.Normal(), 0.5 * rng.Normal());
  const MapSolution s = SolveMapLeastSquares(p, {start});
  ASSERT_TRUE(s.ok) << s.why;
  for (std::size_t i = 0; i < truth.size(); ++i) EXPECT_NEAR((s.position_n[i] - truth[i]).norm(), 0, 1e-6);
  EXPECT_TRUE(s.consistent);
  for (const Mat2& c : s.cov) EXPECT_GT(c.determinant(), 0);
}

TEST(MapLeastSquares, KeepsTheStartOfLowerCostWhenTheOtherIsFolded) {
  Random rng(5);
  const auto truth = UTrail();
  const MapProblem p = Problem(truth, 0.0, 0.3, rng);
  std::vector<Vec2> folded = truth;  // the north leg folded onto the south one
  for (auto& q : folded)
    if (q.y() > 4) q.y() = 8 - q.y();
  const MapSolution s = SolveMapLeastSquares(p, {folded, truth});
  ASSERT_TRUE(s.ok);
  EXPECT_EQ(s.start, 1);
  EXPECT_LT(s.start_chi2[1], s.start_chi2[0]);
}

TEST(MapLeastSquares, MarginalCovariancesAreHonestOverMonteCarlo) {
  // In its exact model (Gaussian links and priors, no robust loss active) the NEES of each
  // beacon averages 2 (2 dof); 100 runs x 21 beacons.
  const auto truth = UTrail();
  double nees = 0;
  int n = 0;
  for (int run = 0; run < 100; ++run) {
    Random rng(100 + run);
    MapProblem p = Problem(truth, 0.1, 1.0, rng);
    const MapSolution s = SolveMapLeastSquares(p, {truth});
    ASSERT_TRUE(s.ok);
    for (std::size_t i = 0; i < truth.size(); ++i) {
      const Vec2 e = s.position_n[i] - truth[i];
      nees += e.dot(s.cov[i].ldlt().solve(e));
      ++n;
    }
  }
  EXPECT_NEAR(nees / n, 2.0, 0.3);
}

// The drop priors (all but the two surveyed) on one track with shared errors.
void OnOneTrack(const std::vector<Vec2>& truth, MapProblem* p) {
  p->tracks.push_back({TrackVec(0.05 * 0.05, 1e-6, 0.03 * 0.03, 0.03 * 0.03).asDiagonal()});
  for (auto& q : p->priors) {
    if (q.i == 4 || q.i == 12) continue;
    q.track = 0;
    q.along << -truth[q.i].y(), 0.5 * q.i, truth[q.i].x(), 0.2 * q.i, truth[q.i].x(), 0.1 * q.i,
        truth[q.i].y(), -0.3 * q.i;
  }
}

// Our sparse-Cholesky marginals against ceres::Covariance (SPARSE_QR); ours returned.
MapSolution ExpectMarginalsEqualCeres(const MapProblem& p, const std::vector<Vec2>& truth) {
  MapLeastSquaresOptions ours, reference;
  reference.reference_covariance = true;
  const MapSolution a = SolveMapLeastSquares(p, {truth}, ours);
  const MapSolution b = SolveMapLeastSquares(p, {truth}, reference);
  EXPECT_TRUE(a.ok) << a.why;
  EXPECT_TRUE(b.ok) << b.why;
  EXPECT_EQ(a.cov.size(), truth.size());
  EXPECT_EQ(b.cov.size(), truth.size());
  for (std::size_t i = 0; i < std::min(a.cov.size(), b.cov.size()); ++i)
    EXPECT_LT((a.cov[i] - b.cov[i]).norm(), 1e-9 * (1 + b.cov[i].norm())) << i;
  return a;
}

TEST(MapLeastSquares, MarginalsEqualCeresCovarianceWithTracksAndTheRobustLossActive) {
  // Our sparse-Cholesky marginals against ceres::Covariance (SPARSE_QR) on a problem with a
  // track's shared errors, drop priors on it and one NLOS link far into the Huber loss.
  Random rng(21);
  const auto truth = UTrail();
  MapProblem p = Problem(truth, 0.1, 0.0, rng);
  p.links[5].range_m += 1.5;  // NLOS
  OnOneTrack(truth, &p);
  ExpectMarginalsEqualCeres(p, truth);
}

TEST(MapLeastSquares, MarginalsEqualCeresCovarianceOnAFieldWhoseFactorFills) {
  // The trail's factor hardly fills; a field does: 150 beacons uniform on 24 x 24 m, every pair
  // within 5 m linked (each beacon ~20 links), drop priors and three surveys, a track's shared
  // errors. Its elimination tree has columns whose patterns are a small part of the columns
  // they reach, the case the selected inversion's one pass must skip rows for.
  Random rng(41);
  std::vector<Vec2> truth;
  for (int i = 0; i < 150; ++i) truth.emplace_back(rng.Uniform(0, 24), rng.Uniform(0, 24));
  MapProblem p;
  p.beacons = static_cast<int>(truth.size());
  for (int i = 0; i < p.beacons; ++i)
    for (int j = i + 1; j < p.beacons; ++j)
      if (const double d = (truth[i] - truth[j]).norm(); d < 5.0)
        p.links.push_back({i, j, std::abs(d + 0.1 * rng.Normal()), 0.1});
  ASSERT_GT(p.links.size(), 1000u);
  for (int i = 0; i < p.beacons; ++i) {
    const double s = i < 3 ? 0.05 : 1.0;
    p.priors.push_back(
        {i, truth[i] + s * Vec2(rng.Normal(), rng.Normal()), Mat2::Identity() * s * s});
  }
  p.tracks.push_back({TrackVec(0.05 * 0.05, 1e-6, 0.03 * 0.03, 0.03 * 0.03).asDiagonal()});
  for (auto& q : p.priors) {
    if (q.i < 3 || q.i % 2) continue;
    q.track = 0;
    q.along << -truth[q.i].y(), 0.01 * q.i, truth[q.i].x(), 0.02 * q.i, truth[q.i].x(), 0.01 * q.i,
        truth[q.i].y(), -0.03 * q.i;
  }
  p.links[7].range_m += 1.5;  // one link deep in the Huber loss
  ExpectMarginalsEqualCeres(p, truth);
}

// The U trail's drop priors on a track with shared errors, and an agent walking back along the
// top arm ranging the beacons of the bottom arm (sightings across the trail, issue 22 item 1):
// two chains of sightings, one range an outlier far into Tukey's bound.
MapProblem WithSightings(const std::vector<Vec2>& truth, Random& rng) {
  MapProblem p = Problem(truth, 0.05, 0.3, rng);
  OnOneTrack(truth, &p);
  for (auto& q : p.priors)
    if (q.track == 0) q.cov = Mat2::Identity() * 0.09;
  for (int k = 0; k < 12; ++k) {
    MapSighting q;
    const Vec2 at(14.0 - 1.2 * k, 7.0);  // walking back along the top arm, 1 m inside it
    q.i = std::min(k, 8);                // a beacon of the bottom arm
    q.range_m = (at - truth[q.i]).norm() + 0.1 * rng.Normal();
    if (k == 5) q.range_m += 3.0;  // an outlier
    q.track = 0;
    q.position_n = at + 0.2 * Vec2(rng.Normal(), rng.Normal());
    q.along << -at.y(), 30.0 + k, at.x(), 1.5, at.x(), 30.0 + k, at.y(), -1.5;
    q.heading_along << 1.0, 30.0 + k, 0.0, 3.0;
    if (k == 0 || k == 6) {  // two chains
      q.cov = Vec3(0.25, 0.25, 0.01).asDiagonal();
    } else {
      q.from_sighting = k - 1;
      q.cov = Vec3(0.02, 0.02, 1e-4).asDiagonal();
    }
    p.sightings.push_back(q);
  }
  return p;
}

// The problem's cost written out: Huber links, Gaussian priors and tracks, the sightings' start
// and chain priors and their ranges under Tukey's biweight (Ceres' rho / 2), by part. A chain's
// displacement D is turned by the heading error there, h_A and the part g e of the shared
// errors' lever that turns D (options.sighting_chain_rotation; else to first order); a chain's
// start has the dead reckoning's marginal as its prior (options.sighting_start_marginal).
struct CostParts {
  double links = 0, priors = 0, sightings = 0;
  double total() const { return links + priors + sightings; }
};

CostParts WrittenOutCostParts(const MapProblem& p, const std::vector<double>& x,
                              const MapLeastSquaresOptions& o = {}) {
  const int n = p.beacons;
  const auto beacon = [&](int i) { return Vec2(x[2 * i], x[2 * i + 1]); };
  const auto track = [&](int k) {
    return Eigen::Map<const TrackVec>(&x[2 * n + kTrackErrors * k]);
  };
  const int t0 = 2 * n + kTrackErrors * static_cast<int>(p.tracks.size());
  const auto state = [&](int k) {
    return Vec3(x[t0 + 3 * k], x[t0 + 3 * k + 1], x[t0 + 3 * k + 2]);
  };
  CostParts cost;
  for (const MapLink& l : p.links) {
    const double r = ((beacon(l.i) - beacon(l.j)).norm() - l.range_m) / l.sigma_m;
    cost.links += std::abs(r) <= 2 ? 0.5 * r * r : 2 * std::abs(r) - 2;
  }
  for (const MapPrior& q : p.priors) {
    const Vec2 d =
        beacon(q.i) - q.position_n - (q.track >= 0 ? Vec2(q.along * track(q.track)) : Vec2::Zero());
    cost.priors += 0.5 * d.dot(q.cov.ldlt().solve(d));
  }
  for (std::size_t k = 0; k < p.tracks.size(); ++k)
    cost.priors += 0.5 * track(k).dot(p.tracks[k].cov.ldlt().solve(TrackVec(track(k))));
  for (std::size_t k = 0; k < p.sightings.size(); ++k) {
    const MapSighting& q = p.sightings[k];
    const Vec3 s = state(k);
    Vec3 u;
    if (q.from_sighting >= 0) {
      const MapSighting& a = p.sightings[q.from_sighting];
      const Vec3 sa = state(q.from_sighting);
      const Vec2 d = q.position_n - a.position_n, perp(-d.y(), d.x());
      const TrackLever da = q.along - a.along;
      Vec2 moved;
      if (o.sighting_chain_rotation) {
        const Eigen::Matrix<double, 1, kTrackErrors> g = perp.transpose() * da / d.squaredNorm();
        const double phi = sa.z() + (g * track(q.track)).value();
        moved = Vec2(std::cos(phi) * d.x() - std::sin(phi) * d.y(),
                     std::sin(phi) * d.x() + std::cos(phi) * d.y()) +
                (da - perp * g) * track(q.track);
      } else {
        moved = d + sa.z() * perp + da * track(q.track);
      }
      u << s.head<2>() - sa.head<2>() - moved, s.z() - sa.z();
      cost.sightings += 0.5 * u.dot(q.cov.ldlt().solve(u));
    } else if (o.sighting_start_marginal) {
      Eigen::Matrix<double, 3, kTrackErrors> j;
      j.topRows<2>() = q.along;
      j.row(2) = q.heading_along.transpose();
      const Mat3 cov = q.cov + j * p.tracks[q.track].cov * j.transpose();
      u << s.head<2>() - q.position_n, s.z();
      cost.sightings += 0.5 * u.dot(cov.ldlt().solve(u));
    } else {
      u << s.head<2>() - q.position_n - q.along * track(q.track), s.z();
      cost.sightings += 0.5 * u.dot(q.cov.ldlt().solve(u));
    }
    const double r = ((s.head<2>() - beacon(q.i)).norm() - q.range_m) / q.sigma_m;
    const double c2 = 4.685 * 4.685, v = 1 - r * r / c2;
    cost.sightings += r * r > c2 ? c2 / 6 : c2 / 6 * (1 - v * v * v);
  }
  return cost;
}

double WrittenOutCost(const MapProblem& p, const std::vector<double>& x,
                      const MapLeastSquaresOptions& o = {}) {
  return WrittenOutCostParts(p, x, o).total();
}

TEST(MapLeastSquares, SightingsSolutionIsTheMinimumOfTheWrittenOutCost) {
  // The sightings' costs and their analytic Jacobians (chain, start, range) against the cost
  // written out here: its numerical gradient vanishes at the solution, and the solution's
  // chi2 is twice it.
  Random rng(31);
  const auto truth = UTrail();
  const MapProblem p = WithSightings(truth, rng);
  // The defaults (turned chains, marginal starts) and the first-order forms.
  MapLeastSquaresOptions first_order;
  first_order.sighting_chain_rotation = first_order.sighting_start_marginal = false;
  for (const MapLeastSquaresOptions& o : {MapLeastSquaresOptions{}, first_order}) {
    const MapSolution s = SolveMapLeastSquares(p, {truth}, o);
    ASSERT_TRUE(s.ok) << s.why;
    ASSERT_EQ(s.sighting_state.size(), p.sightings.size());
    EXPECT_EQ(s.sighting_outliers, 1);
    std::vector<double> x;
    for (const Vec2& b : s.position_n) x.push_back(b.x()), x.push_back(b.y());
    for (const TrackVec& e : s.track_errors) x.insert(x.end(), e.data(), e.data() + kTrackErrors);
    for (const Vec3& v : s.sighting_state) x.insert(x.end(), v.data(), v.data() + 3);
    EXPECT_NEAR(2 * WrittenOutCost(p, x, o), s.chi2, 1e-6 * s.chi2);
    // Each part of chi2 (the consistency test leaves the sightings' out) as written out: twice
    // its cost, a range under Tukey's loss counted once (Ceres' rho), not twice.
    const CostParts parts = WrittenOutCostParts(p, x, o);
    EXPECT_NEAR(s.chi2_links, 2 * parts.links, 1e-6 * s.chi2);
    EXPECT_NEAR(s.chi2_priors, 2 * parts.priors, 1e-6 * s.chi2);
    EXPECT_NEAR(s.chi2_sightings, 2 * parts.sightings, 1e-6 * s.chi2);
    for (std::size_t k = 0; k < x.size(); ++k) {
      const double h = 1e-6;
      std::vector<double> up = x, down = x;
      up[k] += h;
      down[k] -= h;
      EXPECT_NEAR((WrittenOutCost(p, up, o) - WrittenOutCost(p, down, o)) / (2 * h), 0.0, 1e-4)
          << k;
    }
    // A wrong chain (its heading lever left out) is not the minimum.
    MapProblem wrong = p;
    for (auto& q : wrong.sightings) q.position_n.x() += 0.5;
    EXPECT_GT(std::abs(WrittenOutCost(wrong, x, o) - WrittenOutCost(p, x, o)), 1e-3);
  }
}

TEST(MapLeastSquares, AChainTurnedByALargeHeadingErrorFitsExactly) {
  // An agent's walk round a 10 m square of surveyed beacons, its dead reckoning turned by
  // 0.4 rad from the start (a heading error a two-minute trace reaches), exact ranges. Turned
  // exactly, the chain of sightings fits the walk (the states on the true positions, h = the
  // heading error, chi2 ~ 0); to first order D + h perp(D) is 8 % too long and the tight
  // chain cannot fit the ranges.
  const std::vector<Vec2> beacons{{0, 0}, {10, 0}, {10, 10}, {0, 10}};
  MapProblem p;
  p.beacons = 4;
  for (int i = 0; i < 4; ++i) p.priors.push_back({i, beacons[i], Mat2::Identity() * 1e-6});
  MapTrack track;
  track.cov = TrackVec(1e-8, 1e-12, 1e-8, 1e-8).asDiagonal();
  p.tracks.push_back(track);
  const double heading_error = 0.4;
  std::vector<Vec2> walk;
  for (int k = 0; k < 16; ++k) {
    const double a = 2 * std::numbers::pi * k / 16;
    walk.push_back(Vec2(5, 5) + 3.0 * Vec2(std::cos(a), std::sin(a)));
  }
  const Eigen::Rotation2Dd dead_reckoning(-heading_error);  // D = R(-error) x true step
  Vec2 at = walk[0];
  for (int k = 0; k < 16; ++k) {
    if (k > 0) at += dead_reckoning * (walk[k] - walk[k - 1]);
    for (int i = 0; i < 4; ++i) {
      MapSighting q;
      q.i = i;
      q.range_m = (walk[k] - beacons[i]).norm();
      q.position_n = at;
      q.heading_along << 1, 0, 0, 0;
      q.from_sighting = static_cast<int>(p.sightings.size()) - 1;
      // The first: where the walk starts, heading unknown (1 rad); then 4 ranges from one
      // point (no walk between), then a tight walk.
      q.cov = q.from_sighting < 0 ? Mat3(Vec3(1e-6, 1e-6, 1.0).asDiagonal())
              : i > 0             ? Mat3(Vec3(1e-8, 1e-8, 1e-10).asDiagonal())
                                  : Mat3(Vec3(1e-4, 1e-4, 1e-6).asDiagonal());
      p.sightings.push_back(q);
    }
  }
  const MapSolution turned = SolveMapLeastSquares(p, {beacons});
  ASSERT_TRUE(turned.ok) << turned.why;
  EXPECT_LT(turned.chi2, 1.0);
  for (int k = 0; k < 16; ++k) {
    EXPECT_NEAR((turned.sighting_state[4 * k].head<2>() - walk[k]).norm(), 0.0, 1e-3) << k;
    EXPECT_NEAR(turned.sighting_state[4 * k].z(), heading_error, 1e-3) << k;
  }
  MapLeastSquaresOptions first_order;
  first_order.sighting_chain_rotation = false;
  const MapSolution linear = SolveMapLeastSquares(p, {beacons}, first_order);
  ASSERT_TRUE(linear.ok) << linear.why;
  EXPECT_GT(linear.chi2, 10.0);
}

TEST(MapLeastSquares, MarginalsEqualCeresCovarianceWithSightings) {
  Random rng(37);
  const auto truth = UTrail();
  const MapProblem p = WithSightings(truth, rng);
  const MapSolution a = ExpectMarginalsEqualCeres(p, truth);
  ASSERT_TRUE(a.ok);
  // The sightings inform the map: its marginals are smaller than without them.
  MapProblem without = p;
  without.sightings.clear();
  const MapSolution c = SolveMapLeastSquares(without, {truth});
  ASSERT_TRUE(c.ok);
  double with_trace = 0, without_trace = 0;
  for (std::size_t i = 0; i < truth.size(); ++i)
    with_trace += a.cov[i].trace(), without_trace += c.cov[i].trace();
  EXPECT_LT(with_trace, without_trace);
  // Bad sightings are refused.
  MapProblem bad = p;
  bad.sightings[3].from_sighting = 5;  // not an earlier one
  EXPECT_THROW(SolveMapLeastSquares(bad, {truth}), std::invalid_argument);
  bad = p;
  bad.sightings[2].cov(0, 0) = -1;
  EXPECT_THROW(SolveMapLeastSquares(bad, {truth}), std::invalid_argument);
  bad = p;
  bad.sightings[2].range_m = std::nan("");
  EXPECT_THROW(SolveMapLeastSquares(bad, {truth}), std::invalid_argument);
}

TEST(MapLeastSquares, AMovedSurveyIsInconsistent) {
  Random rng(7);
  const auto truth = UTrail();
  MapProblem p = Problem(truth, 0.1, 0.3, rng);
  for (auto& q : p.priors)
    if (q.i == 12) q.position_n += Vec2(3, 0);  // surveyed 3 m off
  const MapSolution s = SolveMapLeastSquares(p, {truth});
  ASSERT_TRUE(s.ok);
  EXPECT_FALSE(s.consistent);
  EXPECT_GT(s.chi2, s.chi2_threshold);
}

TEST(MapLeastSquares, ARangeScaleIsEstimatedAgainstTheSurveys) {
  // Every link timed at a speed of sound 8 % off (ranges x 1.08), the two surveys 16 m apart
  // (Problem's beacons 4 and 12) and the drop priors tight enough to count (0.1 m): with the
  // scale among the unknowns the map is the truth within 5 cm and k is 1.08 less the prior's
  // pull; the ranges as they are stretch the map; the marginals, k's too, equal
  // ceres::Covariance's.
  Random rng(4);
  const auto truth = UTrail();
  MapProblem p = Problem(truth, 0.0, 0.0, rng);
  for (auto& q : p.priors) q.cov = Mat2::Identity() * (q.cov(0, 0) > 0.5 ? 0.01 : 0.0025);
  for (auto& l : p.links) l.range_m *= 1.08, l.scaled = true;
  p.range_scale_sigma = 0.02;
  const MapSolution s = SolveMapLeastSquares(p, {truth});
  ASSERT_TRUE(s.ok) << s.why;
  // The written-out cost is stationary in k at the solution (every link inside Huber's
  // quadratic part here): sum (k d - r) d / sigma^2 + (k - 1) / 0.02^2 = 0 with the solution's
  // distances d, i.e. k = (sum r d / sigma^2 + 1 / 0.02^2) / (sum d^2 / sigma^2 + 1 / 0.02^2).
  double rd = 0, dd = 0;
  for (const auto& l : p.links) {
    const double d = (s.position_n[l.i] - s.position_n[l.j]).norm();
    ASSERT_LT(std::abs(s.range_scale * d - l.range_m) / l.sigma_m, 2.0);  // quadratic part
    rd += l.range_m * d / (l.sigma_m * l.sigma_m);
    dd += d * d / (l.sigma_m * l.sigma_m);
  }
  const double prior = 1.0 / (0.02 * 0.02);
  EXPECT_NEAR(s.range_scale, (rd + prior) / (dd + prior), 1e-9);
  EXPECT_GT(s.range_scale, 1.07);
  double worst = 0;
  for (std::size_t i = 0; i < truth.size(); ++i)
    worst = std::max(worst, (s.position_n[i] - truth[i]).norm());
  EXPECT_LT(worst, 0.05);
  MapProblem as_they_are = p;
  as_they_are.range_scale_sigma = 0;
  const MapSolution t = SolveMapLeastSquares(as_they_are, {truth});
  ASSERT_TRUE(t.ok) << t.why;
  double worst_t = 0;
  for (std::size_t i = 0; i < truth.size(); ++i)
    worst_t = std::max(worst_t, (t.position_n[i] - truth[i]).norm());
  EXPECT_GT(worst_t, 4 * worst);
  EXPECT_EQ(t.range_scale, 1.0);
  EXPECT_EQ(t.range_scale_var, 0.0);
  const MapSolution a = ExpectMarginalsEqualCeres(p, truth);
  MapLeastSquaresOptions reference;
  reference.reference_covariance = true;
  const MapSolution b = SolveMapLeastSquares(p, {truth}, reference);
  EXPECT_GT(a.range_scale_var, 0);
  EXPECT_LT(a.range_scale_var, 0.02 * 0.02);
  EXPECT_NEAR(a.range_scale_var, b.range_scale_var, 1e-9 * b.range_scale_var);
  // Links not timed (radio) keep no scale, and a bad sigma is refused.
  MapProblem radio = p;
  for (auto& l : radio.links) l.scaled = false;
  EXPECT_EQ(SolveMapLeastSquares(radio, {truth}).range_scale, 1.0);
  MapProblem bad = p;
  bad.range_scale_sigma = std::nan("");
  EXPECT_THROW(SolveMapLeastSquares(bad, {truth}), std::invalid_argument);
  bad.range_scale_sigma = -0.1;
  EXPECT_THROW(SolveMapLeastSquares(bad, {truth}), std::invalid_argument);
}

// The Hessian of `cost` at x by central second differences (step h).
template <typename Cost>
Eigen::MatrixXd NumericalHessian(const Cost& cost, const std::vector<double>& x, double h) {
  const int n = static_cast<int>(x.size());
  Eigen::MatrixXd H(n, n);
  for (int i = 0; i < n; ++i)
    for (int j = i; j < n; ++j) {
      const auto at = [&](double a, double b) {
        std::vector<double> y = x;
        y[i] += a * h;
        y[j] += b * h;
        return cost(y);
      };
      H(i, j) = H(j, i) = (at(1, 1) - at(1, -1) - at(-1, 1) + at(-1, -1)) / (4 * h * h);
    }
  return H;
}

TEST(MapLeastSquares, NewtonsHessianIsTheWrittenOutCostsSecondDerivative) {
  // Newton's steps use the exact Hessian: J^T J and the terms Gauss-Newton leaves out (each
  // range's curvature times its residual, the robust losses' second derivative, which Ceres'
  // corrector drops where it is negative, and the chains' turn). Against
  // the written-out cost's second differences, off the minimum (every unknown moved), where
  // links lie in both parts of Huber's loss, sighting ranges inside Tukey's bound and beyond it,
  // and chains are turned by heading states of 0.2-0.4 rad.
  Random rng(31);
  const auto truth = UTrail();
  const MapProblem p = WithSightings(truth, rng);
  const MapSolution s = SolveMapLeastSquares(p, {truth});
  ASSERT_TRUE(s.ok) << s.why;
  std::vector<double> x;
  for (const Vec2& b : s.position_n)
    x.push_back(b.x() + 0.3 * rng.Normal()), x.push_back(b.y() + 0.3 * rng.Normal());
  for (const TrackVec& e : s.track_errors)
    for (int k = 0; k < kTrackErrors; ++k) x.push_back(e(k) + 0.01 * rng.Normal());
  for (const Vec3& v : s.sighting_state)
    x.push_back(v.x() + 0.2 * rng.Normal()), x.push_back(v.y() + 0.2 * rng.Normal()),
        x.push_back(v.z() + 0.2 + 0.2 * rng.Uniform());
  int huber_linear = 0, huber_quadratic = 0;
  for (const MapLink& l : p.links) {
    const double r =
        (Vec2(x[2 * l.i] - x[2 * l.j], x[2 * l.i + 1] - x[2 * l.j + 1]).norm() - l.range_m) /
        l.sigma_m;
    ++(std::abs(r) > 2 ? huber_linear : huber_quadratic);
  }
  ASSERT_GT(huber_linear, 3);
  ASSERT_GT(huber_quadratic, 3);
  EXPECT_NEAR(MapCost(p, {}, x), WrittenOutCost(p, x), 1e-9 * WrittenOutCost(p, x));
  const Eigen::MatrixXd exact = MapCostHessian(p, {}, x);
  const Eigen::MatrixXd numerical =
      NumericalHessian([&](const std::vector<double>& y) { return WrittenOutCost(p, y); }, x, 1e-4);
  // Entries up to 1e6 (the chains' heading sigma 0.01 rad); the differences' own error ~1e-5.
  // Measured 2026-12-07: 1e-5 (without the robust losses' second derivative 217, without the
  // chains' turn 63).
  EXPECT_LT((exact - numerical).cwiseAbs().maxCoeff(), 1e-3);
  EXPECT_LT((exact - exact.transpose()).cwiseAbs().maxCoeff(), 1e-9);
  // The first-order chains (linear in the heading): their Hessian too.
  MapLeastSquaresOptions first_order;
  first_order.sighting_chain_rotation = false;
  const Eigen::MatrixXd linear = MapCostHessian(p, first_order, x);
  const Eigen::MatrixXd linear_numerical = NumericalHessian(
      [&](const std::vector<double>& y) { return WrittenOutCost(p, y, first_order); }, x, 1e-4);
  EXPECT_LT((linear - linear_numerical).cwiseAbs().maxCoeff(), 1e-3);
  // A range scale among the unknowns: against the problem's own cost.
  MapProblem scaled = Problem(truth, 0.05, 0.3, rng);
  for (auto& l : scaled.links) l.range_m *= 1.05, l.scaled = true;
  scaled.range_scale_sigma = 0.02;
  std::vector<double> y;
  for (const Vec2& b : truth) y.push_back(b.x() + 0.3 * rng.Normal()), y.push_back(b.y());
  y.push_back(1.03);
  const Eigen::MatrixXd with_scale = MapCostHessian(scaled, {}, y);
  const Eigen::MatrixXd with_scale_numerical = NumericalHessian(
      [&](const std::vector<double>& z) { return MapCost(scaled, {}, z); }, y, 1e-5);
  EXPECT_LT((with_scale - with_scale_numerical).cwiseAbs().maxCoeff(), 1e-3);
  EXPECT_THROW(MapCost(p, {}, std::vector<double>(3, 0.0)), std::invalid_argument);
}

TEST(MapLeastSquares, TheSolveConvergesWhereGaussNewtonCrawls) {
  // Beacons nearly in a line, each linked to its next two, the two ends surveyed and the rest
  // held by loose drop priors: across the line a beacon is held by its ranges' curvature, which
  // Gauss-Newton leaves out, so it converges linearly (Ceres alone: at its cap here, chi2
  // 14.05 where the minimum is 12.10, measured 2026-12-07). With Newton's steps: converged to
  // round-off in a few steps (5), at a lower cost, and the same map in another frame to 1e-9 m.
  Random rng(12);
  std::vector<Vec2> truth;
  for (int i = 0; i <= 12; ++i) truth.emplace_back(2.0 * i, 0.15 * std::sin(0.9 * i));
  MapProblem p;
  p.beacons = static_cast<int>(truth.size());
  for (int i = 0; i < p.beacons; ++i)
    for (int j = i + 1; j <= i + 2 && j < p.beacons; ++j)
      p.links.push_back({i, j, (truth[i] - truth[j]).norm() + 0.05 * rng.Normal(), 0.05});
  for (int i = 0; i < p.beacons; ++i) {
    const bool surveyed = i == 0 || i == p.beacons - 1;
    const double sigma = surveyed ? 0.02 : 2.0;
    p.priors.push_back({i, truth[i] + (surveyed ? 0.0 : 1.0) * Vec2(rng.Normal(), rng.Normal()),
                        Mat2::Identity() * sigma * sigma});
  }
  std::vector<Vec2> start;
  for (const MapPrior& q : p.priors) start.push_back(q.position_n);
  MapLeastSquaresOptions ceres_alone;
  ceres_alone.newton_iterations = 0;
  const MapSolution gn = SolveMapLeastSquares(p, {start}, ceres_alone);
  const MapSolution s = SolveMapLeastSquares(p, {start});
  ASSERT_TRUE(gn.ok && s.ok) << gn.why << s.why;
  EXPECT_GT(gn.iterations, ceres_alone.max_iterations);  // the crawl
  EXPECT_GE(s.newton_iterations, 1);
  EXPECT_LE(s.newton_iterations, 8);
  EXPECT_LT(s.max_gradient, 1e-8);
  EXPECT_LT(s.chi2, gn.chi2 - 1.0);
  // Another frame: rotated 33 degrees and shifted 1 km.
  const Eigen::Rotation2Dd turn(33.0 * std::numbers::pi / 180.0);
  const Vec2 shift(1000.0, -500.0);
  MapProblem moved = p;
  for (MapPrior& q : moved.priors) {
    q.position_n = turn * q.position_n + shift;
    q.cov = turn.toRotationMatrix() * q.cov * turn.toRotationMatrix().transpose();
  }
  for (Vec2& v : start) v = turn * v + shift;
  const MapSolution t = SolveMapLeastSquares(moved, {start});
  ASSERT_TRUE(t.ok) << t.why;
  for (int i = 0; i < p.beacons; ++i)
    EXPECT_LT((t.position_n[i] - (turn * s.position_n[i] + shift)).norm(), 1e-9) << i;
}

TEST(MapLeastSquares, ABeaconOnTheLineOfItsTwoLinksHasTheExactHessiansCovariance) {
  // Beacon 2, no prior, linked to the surveyed 0 and 1 (10 m apart) by ranges too short to form
  // a triangle (4.8 + 4.9 < 10): its least-squares position lies on the line between them,
  // where J^T J has nothing across the line. Converged exactly there, the marginals come from
  // the exact Hessian (the Laplace approximation at the minimum), which is positive definite:
  // the same as the inverse of MapCostHessian, and wider across the line than along it.
  // Ceres alone stops short of the line with J^T J nearly singular: a variance across it of
  // more than 1e3 m^2, or none at all.
  MapProblem p;
  p.beacons = 3;
  p.priors.push_back({0, Vec2(0, 0), Mat2::Identity() * 1e-4});
  p.priors.push_back({1, Vec2(10, 0), Mat2::Identity() * 1e-4});
  p.links.push_back({0, 2, 4.8, 0.1});
  p.links.push_back({1, 2, 4.9, 0.1});
  const std::vector<Vec2> start = {Vec2(0, 0), Vec2(10, 0), Vec2(5, 0.7)};
  const MapSolution s = SolveMapLeastSquares(p, {start});
  ASSERT_TRUE(s.ok) << s.why;
  EXPECT_TRUE(s.exact_hessian_covariance);
  EXPECT_LT(std::abs(s.position_n[2].y()), 1e-9);
  EXPECT_LT(s.max_gradient, 1e-9);
  std::vector<double> x;
  for (const Vec2& b : s.position_n) x.push_back(b.x()), x.push_back(b.y());
  const Eigen::MatrixXd cov = MapCostHessian(p, {}, x).inverse();
  EXPECT_LT((s.cov[2] - cov.block<2, 2>(4, 4)).cwiseAbs().maxCoeff(), 1e-9 * cov.norm());
  EXPECT_GT(s.cov[2](1, 1), 10 * s.cov[2](0, 0));
  EXPECT_GT(s.cov[2].determinant(), 0);
  MapLeastSquaresOptions ceres_alone;
  ceres_alone.newton_iterations = 0;
  const MapSolution gn = SolveMapLeastSquares(p, {start}, ceres_alone);
  EXPECT_FALSE(gn.exact_hessian_covariance);
  EXPECT_TRUE(!gn.ok || gn.cov[2](1, 1) > 1e3) << gn.cov[2];
}

TEST(MapLeastSquares, BadInputIsRefusedAndAnUnanchoredPartIsNotSolved) {
  Random rng(9);
  const auto truth = UTrail();
  MapProblem p = Problem(truth, 0.0, 0.0, rng);
  MapProblem bad = p;
  bad.links[0].j = 99;
  EXPECT_THROW(SolveMapLeastSquares(bad, {truth}), std::invalid_argument);
  bad = p;
  bad.links[0].range_m = std::nan("");
  EXPECT_THROW(SolveMapLeastSquares(bad, {truth}), std::invalid_argument);
  bad = p;
  bad.priors[0].cov = -Mat2::Identity();
  EXPECT_THROW(SolveMapLeastSquares(bad, {truth}), std::invalid_argument);
  EXPECT_THROW(SolveMapLeastSquares(p, {{Vec2::Zero()}}), std::invalid_argument);
  bad = p;
  MapLeastSquaresOptions o;
  o.newton_iterations = -1;
  EXPECT_THROW(SolveMapLeastSquares(p, {truth}, o), std::invalid_argument);
  o.newton_iterations = 20;
  o.newton_step_tolerance = std::nan("");
  EXPECT_THROW(SolveMapLeastSquares(p, {truth}, o), std::invalid_argument);
  bad.priors.resize(1);  // one prior: rotation free
  const MapSolution s = SolveMapLeastSquares(bad, {truth});
  EXPECT_FALSE(s.ok);
  EXPECT_NE(s.why.find("not anchored"), std::string::npos);
}

}  // namespace
}  // namespace trailmark::beacons

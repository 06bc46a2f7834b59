// SPDX-License-Identifier: MIT
// NEES of the breadcrumb localizer (GEN network with mobile states, breadcrumb paper IV-E) in
// its exact model (issue 21, item 4): PDR steps whose errors are white with the variance each
// step states, ranges to surveyed nodes with Gaussian noise of their stated sigma, the
// surveyed positions drawn from their stated sigma; every heuristic beyond the model off (step
// variance floors, heading/scale nodes, range bias, gating, Huber, integrity exclusion). The
// agent's estimate is then the posterior of a nonlinear least-squares problem linearized near
// the truth, and its NEES has mean ~2.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <cstdio>
#include <numbers>

#include "trailmark/breadcrumb/localizer.h"
#include "trailmark/core/random.h"

namespace trailmark::breadcrumb {
namespace {

struct Nees {
  double final = 0;        ///< at the end of the run
  double time_mean = 0;    ///< over the run's estimates after each step
};

LocalizerOptions ExactModel() {
  LocalizerOptions o;
  o.step_sigma_floor_m = 0;
  o.step_sigma_floor_relative = 0;
  o.estimate_heading_scale = false;
  o.estimate_gyro_scale = false;
  o.estimate_range_bias = false;
  o.gate_sigma = 1e9;
  o.huber_k = 1e9;
  o.integrity.exclude = false;
  o.state_period_s = 0;
  o.track_heading_offset_sigma_rad = 0;  // the simulated steps have none
  return o;
}

/// `stated_range_sigma`: the sigma each range claims (its true noise is 0.3 m).
Nees RunOnce(std::uint64_t seed, LocalizerOptions options, double stated_range_sigma = 0.3) {
  Random rng(seed);
  BreadcrumbLocalizer loc(options);
  // Four surveyed nodes around a 20 x 20 m area, each within its stated 0.1 m.
  const double anchor_sigma = 0.1;
  const std::vector<Vec2> anchors = {{0, 0}, {20, 0}, {20, 20}, {0, 20}};
  for (std::size_t k = 0; k < anchors.size(); ++k) {
    const Vec2 surveyed = anchors[k] + Vec2(rng.Normal(0, anchor_sigma), rng.Normal(0, anchor_sigma));
    loc.AddKnownNode("a" + std::to_string(k), surveyed, anchor_sigma);
  }
  // The walk: 0.7 m steps every 0.6 s, heading a random walk, kept inside the area.
  Vec2 truth(10, 10);
  const double start_sigma = 0.2;
  loc.AddAgent("ff1", truth + Vec2(rng.Normal(0, start_sigma), rng.Normal(0, start_sigma)),
               start_sigma);
  double heading = rng.Uniform(0, 2 * std::numbers::pi);
  const double range_sigma = 0.3;
  double nees_sum = 0;
  int nees_n = 0;
  Nees out;
  for (int k = 0; k < 300; ++k) {
    const double t0 = 0.6 * k, t1 = t0 + 0.6;
    heading += rng.Normal(0, 0.3);
    Vec2 step(0.7 * std::cos(heading), 0.7 * std::sin(heading));
    if (!((truth + step).array() > 1).all() || !((truth + step).array() < 19).all()) {
      heading += std::numbers::pi;
      step = -step;
    }
    truth += step;
    const Vec3 variance(0.05 * 0.05, 0.05 * 0.05, 1e-4);
    loc.AddStep({t0, t1, "ff1",
                 Vec3(step.x() + rng.Normal(0, 0.05), step.y() + rng.Normal(0, 0.05), 0), variance});
    // A range to one anchor at each step end (round robin).
    const std::size_t a = static_cast<std::size_t>(k) % anchors.size();
    const double r = (truth - anchors[a]).norm() + rng.Normal(0, range_sigma);
    loc.AddRange({t1, "ff1", "a" + std::to_string(a), r, stated_range_sigma, "uwb"});
    loc.AdvanceTo(t1);
    if (k >= 20) {  // past the start's transient
      const auto e = loc.Estimate("ff1");
      EXPECT_TRUE(e);
      if (!e) return out;
      const Vec2 err = e->position_n - truth;
      nees_sum += err.dot(e->covariance.ldlt().solve(err));
      ++nees_n;
    }
  }
  loc.Finish();
  const auto e = loc.Estimate("ff1");
  const Vec2 err = e->position_n - truth;
  out.final = err.dot(e->covariance.ldlt().solve(err));
  out.time_mean = nees_sum / nees_n;
  return out;
}

TEST(BreadcrumbLocalizerNees, ExactModelIsConsistent) {
  const int runs = 60;
  double final_sum = 0, time_sum = 0;
  for (int s = 0; s < runs; ++s) {
    const Nees n = RunOnce(100 + s, ExactModel());
    final_sum += n.final;
    time_sum += n.time_mean;
  }
  const double final_mean = final_sum / runs, time_mean = time_sum / runs;
  // The final NEES of 60 independent runs: their sum is chi-square with 120 dof; 99 % two-sided
  // interval of the mean [1.45, 2.64].
  EXPECT_GT(final_mean, 1.45);
  EXPECT_LT(final_mean, 2.64);
  // Over each run's estimates (correlated in time: the same mean, a wider spread).
  EXPECT_GT(time_mean, 1.3);
  EXPECT_LT(time_mean, 2.9);
  RecordProperty("final_mean_nees", std::to_string(final_mean));
  RecordProperty("time_mean_nees", std::to_string(time_mean));
  std::printf("breadcrumb exact model: mean NEES final %.2f, over time %.2f\n", final_mean, time_mean);
}

// The test can fail: the same data with each range claiming a third of its true sigma (the
// estimator believes them 9x more than it should) is far from consistent.
TEST(BreadcrumbLocalizerNees, OverconfidentRangesAreDetected) {
  const int runs = 20;
  double sum = 0;
  for (int s = 0; s < runs; ++s) sum += RunOnce(100 + s, ExactModel(), 0.1).time_mean;
  EXPECT_GT(sum / runs, 3.0);
  std::printf("breadcrumb, ranges claiming a third of their sigma: mean NEES %.2f\n", sum / runs);
}

// The defaults on the same exact-model data (variance floors, heading/scale and gyro-scale
// nodes, range bias, gating): conservative, as their floors intend — not overconfident.
TEST(BreadcrumbLocalizerNees, DefaultsAreNotOverconfidentOnTheExactModel) {
  const int runs = 20;
  double sum = 0;
  for (int s = 0; s < runs; ++s) sum += RunOnce(100 + s, LocalizerOptions{}).time_mean;
  EXPECT_LT(sum / runs, 2.9);
  std::printf("breadcrumb defaults on the exact model: mean NEES %.2f\n", sum / runs);
}

}  // namespace
}  // namespace trailmark::breadcrumb

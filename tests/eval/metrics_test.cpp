// SPDX-License-Identifier: MIT
// Metrics against hand-computed cases.
#include "trailmark/eval/metrics.h"

#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <cmath>
#include <nlohmann/json.hpp>

#include "trailmark/core/random.h"
#include "trailmark/io/metrics_io.h"

namespace trailmark {
namespace {

MissionInfo Info() {
  MissionInfo info;
  info.nodes.push_back({.id = "ff1", .kind = NodeKind::kAgent});
  info.nodes.push_back({.id = "base", .kind = NodeKind::kBase, .position = Vec3::Zero()});
  return info;
}

TEST(Percentile, LinearInterpolationLikeNumpy) {
  EXPECT_DOUBLE_EQ(Percentile({1, 2, 3, 4}, 50), 2.5);
  EXPECT_DOUBLE_EQ(Percentile({1, 2, 3, 4}, 75), 3.25);
  EXPECT_DOUBLE_EQ(Percentile({4, 1, 3, 2}, 95), 3.85);
  EXPECT_DOUBLE_EQ(Percentile({5}, 95), 5.0);
  EXPECT_DOUBLE_EQ(Percentile({}, 50), 0.0);
}

TEST(Evaluate, AgentOnlineSemanticsHandComputed) {
  // Truth walks along x at 1 m/s; samples at t = 0..4.
  std::vector<TruthSample> truth;
  for (int t = 0; t <= 4; ++t) truth.push_back({double(t), "ff1", Vec3(t, 0, 0)});
  // Estimates: none before t=1; at t=1 says (1, 1); at t=2.5 says (3, 0) (z ignored: 7).
  std::vector<Estimate> est{{1.0, "ff1", Vec3(1, 1, 0), 1, 0, 1},
                            {2.5, "ff1", Vec3(3, 0, 7), 1, 0, 1}};
  const Metrics m = Evaluate(Info(), truth, est);
  ASSERT_EQ(m.nodes.size(), 1u);
  const NodeMetrics& n = m.nodes[0];
  EXPECT_EQ(n.uncovered, 1u);  // t = 0
  // t=1: |(1,1)-(1,0)| = 1; t=2: |(1,1)-(2,0)| = sqrt2; t=3: 0; t=4: 1.
  ASSERT_EQ(n.stats.samples, 4u);
  const double s2 = std::sqrt(2.0);
  EXPECT_NEAR(n.stats.mean_m, (1 + s2 + 0 + 1) / 4, 1e-12);
  EXPECT_NEAR(n.stats.max_m, s2, 1e-12);
  EXPECT_NEAR(n.stats.final_m, 1.0, 1e-12);
  EXPECT_NEAR(n.stats.rmse_m, std::sqrt((1 + 2 + 0 + 1) / 4.0), 1e-12);
  EXPECT_NEAR(n.stats.median_m, 1.0, 1e-12);
  EXPECT_NEAR(n.distance_m, 4.0, 1e-12);
  EXPECT_NEAR(*n.mean_pct_of_distance, 100 * (1 + s2 + 1) / 4 / 4.0, 1e-9);
  EXPECT_NEAR(*n.max_pct_of_distance, 100 * s2 / 4.0, 1e-9);
  EXPECT_EQ(m.agents.stats.samples, 4u);
}

TEST(Evaluate, EstimatesWithoutACovarianceAreLeftOutOfTheEllipseCheckNotCountedOutside) {
  // estimates.csv with empty sxx, sxy, syy (spec: empty = unknown): in95 is over the rows that
  // have a covariance, and unknown (NaN, written as null) when none has; the errors count all.
  std::vector<TruthSample> truth;
  for (int t = 0; t <= 4; ++t) truth.push_back({double(t), "ff1", Vec3(t, 0, 0)});
  Estimate unknown{0.0, "ff1", Vec3(0, 0.5, 0)};
  unknown.covariance_known = false;
  Estimate known{2.0, "ff1", Vec3(2, 0.5, 0), 0.25, 0, 0.25};
  const Metrics both = Evaluate(Info(), truth, {unknown, known});
  ASSERT_EQ(both.nodes[0].stats.samples, 5u);
  // Errors at t = 0..4: 0.5, |(1, 0.5)|, then from t = 2 on the second estimate: 0.5,
  // |(1, 0.5)|, |(2, 0.5)|.
  EXPECT_NEAR(both.nodes[0].stats.mean_m,
              (0.5 + std::sqrt(1.25) + 0.5 + std::sqrt(1.25) + std::sqrt(4.25)) / 5, 1e-12);
  // With a covariance (sigma 0.5 m): t = 2, 3, 4, NEES 1, 5, 17: two of three inside.
  EXPECT_NEAR(both.nodes[0].stats.in95, 2.0 / 3.0, 1e-12);
  const Metrics none = Evaluate(Info(), truth, {unknown});
  EXPECT_TRUE(std::isnan(none.nodes[0].stats.in95));
  EXPECT_TRUE(std::isnan(none.nodes[0].at_estimates.in95));
  EXPECT_EQ(none.nodes[0].stats.mean_nees, 0.0);
}

TEST(Evaluate, FloorFiguresHandComputed) {
  // Levels 0 at z = 0 and 1 at z = 3. Truth at t = 0..3 on level 0, then t = 4 on level 1
  // (z = 3); x = t. Estimates held from their time:
  //   t=0: (0, 0, 0.5)  szz 1     floor 0  -> dh 0, dz 0.5, nees 0.25 (in), right floor
  //   t=1: (1, 3, 0)    szz 0.25  floor 0  -> dh 3, dz 0,   nees 0 (in), right floor
  //   t=2: (2, 0, 2.5)  szz 1     floor 1  -> dh 0, dz 2.5, nees 6.25 (out), wrong by 1
  //   t=3: held from t=2 (truth (3, 0, 0)) -> dh 1, dz 2.5, nees 6.25 (out), wrong by 1
  //   t=4: (4, 0, 3)    no szz   floor from z: 1 -> dh 0, dz 0, right; not checked
  MissionInfo info = Info();
  info.floors = {{0, 0.0}, {1, 3.0}};
  std::vector<TruthSample> truth;
  for (int t = 0; t <= 3; ++t) truth.push_back({double(t), "ff1", Vec3(t, 0, 0), 0});
  truth.push_back({4.0, "ff1", Vec3(4, 0, 3), 1});
  std::vector<Estimate> est{{0.0, "ff1", Vec3(0, 0, 0.5), 1, 0, 1, 1.0, 0},
                            {1.0, "ff1", Vec3(1, 3, 0), 1, 0, 1, 0.25, 0},
                            {2.0, "ff1", Vec3(2, 0, 2.5), 1, 0, 1, 1.0, 1},
                            {4.0, "ff1", Vec3(4, 0, 3), 1, 0, 1}};
  const Metrics m = Evaluate(info, truth, est);
  ASSERT_TRUE(m.floors.has_value());
  const FloorMetrics& f = *m.floors;
  EXPECT_EQ(f.samples, 5u);
  EXPECT_DOUBLE_EQ(f.floor_hit_rate, 3.0 / 5);
  EXPECT_DOUBLE_EQ(f.hit_rate_by_agent.at("ff1"), 3.0 / 5);
  // Horizontal {0, 3, 0, 1, 0}; vertical {0.5, 0, 2.5, 2.5, 0}.
  EXPECT_NEAR(f.ce95_m, Percentile({0, 3, 0, 1, 0}, 95), 1e-12);
  EXPECT_NEAR(f.ve95_m, 2.5, 1e-12);
  EXPECT_NEAR(f.vertical_mean_m, 5.5 / 5, 1e-12);
  EXPECT_NEAR(f.se95_m, Percentile({0.5, 3, 2.5, std::hypot(1, 2.5), 0}, 95), 1e-12);
  // IPIN: horizontal + 15 m per wrong floor {0, 3, 15, 16, 0}, 75th percentile.
  EXPECT_NEAR(f.ipin_score_m, Percentile({0, 3, 15, 16, 0}, 75), 1e-12);
  EXPECT_EQ(f.vertical_checked, 4u);
  EXPECT_DOUBLE_EQ(f.vertical_in95, 0.5);
  EXPECT_NEAR(f.vertical_mean_nees, (0.25 + 0 + 6.25 + 6.25) / 4, 1e-12);
}

TEST(Evaluate, EllipsesAreAlsoCheckedAtEachEstimatesOwnInstant) {
  // Truth along x at 1 m/s, samples at t = 0..4. Estimates exact at their own time (t = 1.5 and
  // t = 3.25: between truth samples) with a 0.1 m sigma, and one after the truth ends.
  std::vector<TruthSample> truth;
  for (int t = 0; t <= 4; ++t) truth.push_back({double(t), "ff1", Vec3(t, 0, 0)});
  std::vector<Estimate> est{{1.5, "ff1", Vec3(1.5, 0, 0), 0.01, 0, 0.01},
                            {3.25, "ff1", Vec3(3.25, 0.3, 0), 0.01, 0, 0.01},
                            {9.0, "ff1", Vec3(9, 0, 0), 0.01, 0, 0.01}};
  const Metrics m = Evaluate(Info(), truth, est);
  const NodeMetrics& n = m.nodes[0];
  // Held to the truth instants t = 2, 3 the first row is 0.5 and 1.5 m off: outside its ellipse.
  EXPECT_EQ(n.stats.samples, 3u);
  EXPECT_NEAR(n.stats.in95, 0.0, 1e-12);
  // At their own instants: 0 m (NEES 0) and 0.3 m (NEES 9 > 5.99); t = 9 is past the truth.
  ASSERT_EQ(n.at_estimates.samples, 2u);
  EXPECT_NEAR(n.series_at_estimates[0].error_m, 0.0, 1e-12);
  EXPECT_NEAR(n.series_at_estimates[1].error_m, 0.3, 1e-12);
  EXPECT_NEAR(n.series_at_estimates[1].nees, 9.0, 1e-9);
  EXPECT_NEAR(n.at_estimates.in95, 0.5, 1e-12);
  EXPECT_NEAR(n.at_estimates.mean_nees, 4.5, 1e-9);
  EXPECT_EQ(m.agents.at_estimates.samples, 2u);
  EXPECT_NEAR(m.agents.at_estimates.in95, 0.5, 1e-12);
}

TEST(Evaluate, StaticNodesAtEstimatesAndEndAgainstTruthInForce) {
  // Crumb c1 dropped at (5,0) at t=1, kicked to (6,0) at t=3. Mission ends at t=4 (agent truth).
  std::vector<TruthSample> truth{{0, "ff1", Vec3(0, 0, 0)}, {1, "c1", Vec3(5, 0, 0)},
                                 {3, "c1", Vec3(6, 0, 0)},  {4, "ff1", Vec3(4, 0, 0)}};
  std::vector<Estimate> est{{1, "c1", Vec3(5, 2, 0), 1, 0, 1}, {2, "c1", Vec3(5, 1, 0), 1, 0, 1},
                            {9, "ghost", Vec3(0, 0, 0), 1, 0, 1}};
  const Metrics m = Evaluate(Info(), truth, est);
  EXPECT_EQ(m.estimates_without_truth, 1u);
  const NodeMetrics* c1 = nullptr;
  for (const auto& n : m.nodes) if (n.id == "c1") c1 = &n;
  ASSERT_NE(c1, nullptr);
  EXPECT_EQ(c1->kind, NodeKind::kCrumb);
  // t=1: 2; t=2: 1; end t=4: |(5,1)-(6,0)| = sqrt2.
  ASSERT_EQ(c1->stats.samples, 3u);
  EXPECT_NEAR(c1->stats.mean_m, (2 + 1 + std::sqrt(2.0)) / 3, 1e-12);
  EXPECT_NEAR(c1->stats.final_m, std::sqrt(2.0), 1e-12);
  EXPECT_FALSE(c1->mean_pct_of_distance.has_value());
  EXPECT_EQ(m.static_nodes.stats.samples, 3u);
  // The agent has no estimates at all: every instant uncovered.
  EXPECT_EQ(m.agents.stats.samples, 0u);
  EXPECT_EQ(m.agents.uncovered, 2u);
}

TEST(MetricsJson, ANodeNeverScoredHasNullErrorsNotZero) {
  // ff1 has no estimate: its errors are unknown (null), its samples 0 and its instants
  // uncovered; c1's are numbers.
  std::vector<TruthSample> truth{
      {0, "ff1", Vec3(0, 0, 0)}, {1, "c1", Vec3(5, 0, 0)}, {4, "ff1", Vec3(4, 0, 0)}};
  std::vector<Estimate> est{{1, "c1", Vec3(5, 2, 0), 1, 0, 1}};
  const auto j = nlohmann::json::parse(MetricsToJson(Evaluate(Info(), truth, est)));
  const auto& agents = j["overall"]["agents"];
  EXPECT_EQ(agents["samples"], 0);
  EXPECT_EQ(agents["uncovered"], 2);
  for (const char* key : {"mean_m", "median_m", "p75_m", "p95_m", "max_m", "rmse_m", "final_m",
                          "in95", "mean_nees", "in95_at_estimates", "mean_nees_at_estimates"}) {
    EXPECT_TRUE(agents[key].is_null()) << key;
  }
  bool seen = false;
  for (const auto& n : j["nodes"]) {
    if (n["id"] != "c1") continue;
    seen = true;
    EXPECT_NEAR(n["mean_m"].get<double>(), (2.0 + 2.0) / 2, 1e-12);  // at t = 1 and the end
    EXPECT_TRUE(n["p75_m"].is_number());
  }
  EXPECT_TRUE(seen);
}

TEST(Nees, HandComputedAndClaimedCertainty) {
  // e = (1, 2), S = [2 0.5; 0.5 1]: det 1.75, S^-1 = [1 -0.5; -0.5 2] / 1.75,
  // e^T S^-1 e = (1 - 2 + 8) / 1.75 = 4.
  EXPECT_NEAR(HorizontalNees(Vec2(1, 2), 2.0, 0.5, 1.0), 4.0, 1e-12);
  EXPECT_NEAR(HorizontalNees(Vec2(3, 0), 9.0, 0.0, 1.0), 1.0, 1e-12);
  // A zero or indefinite covariance with an error claims a certainty it does not have.
  EXPECT_TRUE(std::isinf(HorizontalNees(Vec2(0.5, 0), 0, 0, 0)));
  EXPECT_TRUE(std::isinf(HorizontalNees(Vec2(0.5, 0), 1, 2, 1)));
  EXPECT_EQ(HorizontalNees(Vec2(0, 0), 0, 0, 0), 0.0);
  EXPECT_NEAR(kChi2Dof2P95, -2.0 * std::log(0.05), 1e-12);
}

TEST(Nees, HonestGaussianErrorsGiveIn95NearNinetyFivePercentAndMeanNeesTwo) {
  // Errors drawn from the stated covariance: in95 -> 0.95, mean NEES -> 2 (chi-square, 2 dof);
  // the same errors under a covariance four times too small: in95 falls to 1 - exp(-5.99/8).
  const double sxx = 4.0, sxy = 1.2, syy = 1.0;
  Eigen::Matrix2d S;
  S << sxx, sxy, sxy, syy;
  const Eigen::Matrix2d L = S.llt().matrixL();
  Random rng(7);
  std::vector<TruthSample> truth;
  std::vector<Estimate> honest, overconfident;
  for (int i = 0; i < 20000; ++i) {
    const double t = i * 0.1;
    truth.push_back({t, "ff1", Vec3(t, 0, 0)});
    const Vec2 e = L * Vec2(rng.Normal(), rng.Normal());
    const Vec3 p(t + e.x(), e.y(), 0);
    honest.push_back({t, "ff1", p, sxx, sxy, syy});
    overconfident.push_back({t, "ff1", p, sxx / 4, sxy / 4, syy / 4});
  }
  const Metrics m = Evaluate(Info(), truth, honest);
  EXPECT_NEAR(m.agents.stats.in95, 0.95, 0.006);  // binomial sd 0.0015
  EXPECT_NEAR(m.agents.stats.mean_nees, 2.0, 0.06);
  const Metrics o = Evaluate(Info(), truth, overconfident);
  EXPECT_NEAR(o.agents.stats.in95, 1.0 - std::exp(-kChi2Dof2P95 / 8.0), 0.01);
  EXPECT_NEAR(o.agents.stats.mean_nees, 8.0, 0.25);
}

}  // namespace
}  // namespace trailmark

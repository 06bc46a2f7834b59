// SPDX-License-Identifier: MIT
// The incremental GEN (breadcrumb paper sec. IV) against the batch references: BLUE from the
// incidence matrix (eqs. (1)-(5)) on linear graphs, and dense Gauss-Newton with ranges.

#include "trailmark/breadcrumb/gen_network.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <memory>

#include "trailmark/breadcrumb/batch_reference.h"
#include "trailmark/core/random.h"

namespace trailmark::breadcrumb {
namespace {

// Negligible regularization so that the incremental result can be compared at 1e-9.
GenOptions ExactOptions() {
  GenOptions o;
  o.regularization_sigma_m = 1e9;
  return o;
}

Mat2 RandomCov(Random& rng) {
  Eigen::Matrix2d A;
  A << rng.Uniform(0.2, 1.0), rng.Uniform(-0.3, 0.3), rng.Uniform(-0.3, 0.3), rng.Uniform(0.2, 1.0);
  return A * A.transpose() + Mat2::Identity() * 0.05;
}

TEST(GenNetwork, PaperFigure4ExampleEqualsBlue) {
  // Fig. 4: a base (anchor at the origin) and three breadcrumbs, five relative measurements.
  GenNetwork gen(ExactOptions());
  BatchProblem p;
  p.num_nodes = 3;
  Random rng(4);
  const Vec2 truth[3] = {{2, 1}, {4, -1}, {5, 2}};
  auto cov = [&] { return RandomCov(rng); };
  struct E { int i, j; };
  const E edges[] = {{0, -1}, {1, 0}, {2, 1}, {2, 0}, {1, -1}};
  for (int k = 0; k < 3; ++k) gen.AddNode(Vec2::Zero());
  for (const auto& e : edges) {
    const Mat2 P = cov();
    const Vec2 xj = e.j >= 0 ? truth[e.j] : Vec2::Zero();
    const Vec2 zeta = truth[e.i] - xj + Vec2(rng.Normal(0, 0.3), rng.Normal(0, 0.3));
    if (e.j >= 0) gen.AddRelative(e.i, e.j, zeta, P);
    else gen.AddRelativeToAnchor(e.i, Vec2::Zero(), zeta, P);
    p.relative.push_back({e.i, e.j, Vec2::Zero(), zeta, P});
  }
  ASSERT_TRUE(gen.Solve());
  const BatchSolution blue = SolveBlue(p);
  for (int i = 0; i < 3; ++i) {
    EXPECT_LT((gen.Estimate(i) - blue.Position(i)).norm(), 1e-9) << i;
    EXPECT_LT((gen.Covariance(i) - blue.Covariance(i)).norm(), 1e-9) << i;
  }
  // Sigma_ij through the joint covariance too.
  const Eigen::Matrix4d joint = gen.JointCovariance(0, 2);
  EXPECT_LT((joint.block<2, 2>(0, 2) - blue.sigma.block<2, 2>(0, 4)).norm(), 1e-9);
}

// A mobile node walking among breadcrumbs: AddNode/AddMeasurement/DeleteNode (IV-E) must equal
// BLUE over the full extended graph (nothing marginalized), restricted to the kept nodes.
TEST(GenNetwork, MarginalizationEqualsFullBlueOnLinearGraph) {
  for (std::uint64_t seed = 1; seed <= 5; ++seed) {
    Random rng(seed);
    GenNetwork gen(ExactOptions());
    BatchProblem p;
    const int crumbs = 6;
    std::vector<Vec2> crumb_truth;
    for (int c = 0; c < crumbs; ++c) {
      crumb_truth.emplace_back(rng.Uniform(-10, 10), rng.Uniform(-10, 10));
      gen.AddNode(Vec2::Zero());
    }
    p.num_nodes = crumbs;
    // Anchor two crumbs loosely so that the problem is observable.
    for (int c : {0, 3}) {
      const Mat2 P = RandomCov(rng);
      gen.AddPrior(c, crumb_truth[c], P);
      p.relative.push_back({c, -1, Vec2::Zero(), crumb_truth[c], P});
    }
    Vec2 pos(0, 0);
    NodeIndex state = gen.AddNode(Vec2::Zero());
    int batch_state = p.num_nodes++;
    gen.AddPrior(state, pos, Mat2::Identity() * 0.01);
    p.relative.push_back({batch_state, -1, Vec2::Zero(), pos, Mat2::Identity() * 0.01});
    for (int k = 0; k < 40; ++k) {
      const Vec2 step(rng.Normal(0.5, 0.3), rng.Normal(0.0, 0.5));
      pos += step;
      const Mat2 Q = RandomCov(rng) * 0.1;
      const NodeIndex next = gen.AddNode(Vec2::Zero());  // AddNode, eq. (13)
      gen.AddRelative(next, state, step, Q);             // eq. (11)
      gen.DeleteNode(state);                             // eqs. (14)-(17)
      state = next;
      const int next_batch = p.num_nodes++;
      p.relative.push_back({next_batch, batch_state, Vec2::Zero(), step, Q});
      batch_state = next_batch;
      // A relative observation of a random crumb.
      const int c = static_cast<int>(rng.Uniform(0, crumbs - 1e-9));
      const Mat2 R = RandomCov(rng);
      const Vec2 zeta = pos - crumb_truth[c] + Vec2(rng.Normal(0, 0.5), rng.Normal(0, 0.5));
      gen.AddRelative(state, c, zeta, R);
      p.relative.push_back({batch_state, c, Vec2::Zero(), zeta, R});
    }
    ASSERT_TRUE(gen.Solve());
    EXPECT_EQ(gen.active_nodes(), crumbs + 1);
    const BatchSolution blue = SolveBlue(p);
    for (int c = 0; c < crumbs; ++c) {
      EXPECT_LT((gen.Estimate(c) - blue.Position(c)).norm(), 1e-9) << "seed " << seed;
      EXPECT_LT((gen.Covariance(c) - blue.Covariance(c)).norm(), 1e-9) << "seed " << seed;
    }
    EXPECT_LT((gen.Estimate(state) - blue.Position(batch_state)).norm(), 1e-9);
    EXPECT_LT((gen.Covariance(state) - blue.Covariance(batch_state)).norm(), 1e-9);
  }
}

// With ranges, the incremental estimator linearizes each edge once (AddMeasurement+, eqs.
// (18)-(19)) while the batch re-linearizes everything: equal within a stated tolerance when the
// linearization points are good (here: PDR-quality predictions), and persistent edges are
// re-linearized exactly.
TEST(GenNetwork, RangesCloseToBatchNonlinear) {
  Random rng(11);
  GenNetwork gen;
  BatchProblem p;
  const std::vector<Vec2> beacons = {{0, 8}, {12, -4}, {-6, -6}, {15, 10}};
  p.num_nodes = 4;
  for (int b = 0; b < 4; ++b) {
    const Vec2 start = beacons[b] + Vec2(rng.Normal(0, 1), rng.Normal(0, 1));
    const Vec2 prior = beacons[b] + Vec2(rng.Normal(0, 1), rng.Normal(0, 1));
    const NodeIndex i = gen.AddNode(start);
    gen.AddPrior(i, prior, Mat2::Identity() * 4.0);
    p.relative.push_back({b, -1, Vec2::Zero(), prior, Mat2::Identity() * 4.0});
  }
  // A persistent (re-linearized) edge between two beacons.
  ScalarModel range;
  const int edge = gen.AddPersistent(0, 1, range);
  for (int k = 0; k < 5; ++k) {
    const double z = (beacons[0] - beacons[1]).norm() + rng.Normal(0, 0.1);
    gen.AccumulatePersistent(edge, z, 0.01);
    p.scalar.push_back({0, 1, Vec2::Zero(), Vec2::Zero(), z, 0.01, range});
  }
  Vec2 pos(1, 1);
  NodeIndex state = gen.AddNode(pos);
  gen.AddPrior(state, pos, Mat2::Identity() * 0.01);
  int bs = p.num_nodes++;
  p.relative.push_back({bs, -1, Vec2::Zero(), pos, Mat2::Identity() * 0.01});
  for (int k = 0; k < 60; ++k) {
    const Vec2 step(0.3 * std::cos(k * 0.1), 0.3 * std::sin(k * 0.1));
    pos += step;
    const Vec2 meas = step + Vec2(rng.Normal(0, 0.02), rng.Normal(0, 0.02));
    const Mat2 Q = Mat2::Identity() * 4e-4;
    gen.Solve();
    const NodeIndex next = gen.AddNode(gen.Estimate(state) + meas);
    gen.AddRelative(next, state, meas, Q);
    gen.DeleteNode(state);
    state = next;
    const int nb = p.num_nodes++;
    p.relative.push_back({nb, bs, Vec2::Zero(), meas, Q});
    bs = nb;
    const int b = k % 4;
    const double z = (pos - beacons[b]).norm() + rng.Normal(0, 0.2);
    gen.AddScalar(state, b, z, 0.04, range);
    p.scalar.push_back({bs, b, Vec2::Zero(), Vec2::Zero(), z, 0.04, range});
  }
  ASSERT_TRUE(gen.Solve());
  Eigen::VectorXd init = Eigen::VectorXd::Zero(2 * p.num_nodes);
  for (int b = 0; b < 4; ++b) init.segment<2>(2 * b) = beacons[b];
  Vec2 walk(1, 1);
  for (int k = 4; k < p.num_nodes; ++k) {
    init.segment<2>(2 * k) = walk;
    if (k + 1 < p.num_nodes) walk += Vec2(0.3 * std::cos((k - 4) * 0.1), 0.3 * std::sin((k - 4) * 0.1));
  }
  const BatchSolution nls = SolveNonlinear(p, init);
  ASSERT_TRUE(nls.converged);
  // Stated tolerance: the beacons start 1-2 m off, so their first range edges are linearized
  // at poor points; the incremental estimate must stay within half a standard deviation of the
  // batch optimum, and its covariance trace within 30 % of the batch one.
  for (int b = 0; b < 4; ++b) {
    const double sigma = std::sqrt(nls.Covariance(b).trace() / 2);
    EXPECT_LT((gen.Estimate(b) - nls.Position(b)).norm(), 0.5 * sigma) << b;
    EXPECT_NEAR(gen.Covariance(b).trace(), nls.Covariance(b).trace(),
                0.3 * nls.Covariance(b).trace());
  }
  const int last = p.num_nodes - 1;
  EXPECT_LT((gen.Estimate(state) - nls.Position(last)).norm(),
            0.5 * std::sqrt(nls.Covariance(last).trace() / 2));
}

TEST(GenNetwork, DeleteNodeKeepsCovarianceSymmetricPositiveDefinite) {
  Random rng(3);
  GenNetwork gen;
  std::vector<NodeIndex> live;
  for (int k = 0; k < 8; ++k) {
    live.push_back(gen.AddNode(Vec2(k, 0)));
    gen.AddPrior(live.back(), Vec2(k, 0), Mat2::Identity());
  }
  for (int round = 0; round < 300; ++round) {
    const int a = static_cast<int>(rng.Uniform(0, live.size() - 1e-9));
    const int b = static_cast<int>(rng.Uniform(0, live.size() - 1e-9));
    if (a != b) gen.AddRelative(live[a], live[b], Vec2(rng.Normal(0, 3), rng.Normal(0, 3)), RandomCov(rng));
    if (round % 7 == 0) {
      gen.DeleteNode(live.front());
      live.erase(live.begin());
      live.push_back(gen.AddNode(Vec2::Zero()));
      gen.AddRelative(live.back(), live.front(), Vec2(1, 1), RandomCov(rng));
    }
    ASSERT_TRUE(gen.Solve());
    for (NodeIndex i : live) {
      const Mat2 S = gen.Covariance(i);
      ASSERT_TRUE(S.allFinite());
      ASSERT_NEAR(S(0, 1), S(1, 0), 1e-12);
      ASSERT_GT(S.determinant(), 0);
      ASSERT_GT(S(0, 0), 0);
      ASSERT_TRUE(gen.Estimate(i).allFinite());
    }
  }
  EXPECT_EQ(gen.active_nodes(), 8);
}

TEST(GenNetwork, RssiModelSlopeMatchesFiniteDifference) {
  ScalarModel m;
  m.kind = ScalarModel::Kind::kRssiDb;
  for (double d : {0.5, 1.0, 3.0, 20.0}) {
    const double fd = (m.Predict(d + 1e-6) - m.Predict(d - 1e-6)) / 2e-6;
    EXPECT_NEAR(m.Slope(d), fd, 1e-6);
  }
  EXPECT_NEAR(m.Predict(1.0), -40.0, 1e-12);
  EXPECT_NEAR(m.Predict(10.0), -63.0, 1e-12);
}

/// Mean and variance of h(|delta|), delta ~ N(mean, cov), by a 2-D Gauss-Hermite rule of
/// `n` x `n` points (Golub-Welsch nodes of the probabilists' Hermite polynomials): the exact
/// reference of the second-order terms.
std::pair<double, double> QuadratureMoments(const ScalarModel& m, const Vec2& mean, const Mat2& cov,
                                            int n = 40) {
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(n, n);
  for (int k = 1; k < n; ++k) J(k, k - 1) = J(k - 1, k) = std::sqrt(static_cast<double>(k));
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(J);
  const Eigen::VectorXd x = eig.eigenvalues();
  const Eigen::VectorXd w = eig.eigenvectors().row(0).transpose().array().square();
  const Mat2 L = cov.llt().matrixL();
  double s1 = 0, s2 = 0;
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      const double h = m.Predict((mean + L * Vec2(x(i), x(j))).norm());
      s1 += w(i) * w(j) * h;
      s2 += w(i) * w(j) * h * h;
    }
  }
  return {s1, s2 - s1 * s1};
}

// The Gaussian second-order filter's terms against the expectation itself: a range to a node
// uncertain across the line of sight is longer than the estimates' distance (sigma_t^2 / 2d);
// the first-order prediction misses that by the whole shift, the second-order one by the next
// order (sigma^4 / d^3).
TEST(GenNetwork, SecondOrderTermsAreTheExpectationsOfTheModel) {
  const Eigen::Rotation2Dd rot(0.7);
  const Mat2 cov_rt = Vec2(0.5 * 0.5, 3.0 * 3.0).asDiagonal();  // radial 0.5 m, across 3 m
  const Vec2 delta = rot * Vec2(20.0, 0.0);
  const Mat2 cov = rot.toRotationMatrix() * cov_rt * rot.toRotationMatrix().transpose();
  ScalarModel range;
  const auto so = range.SecondOrderTerms(delta, cov);
  EXPECT_NEAR(so.mean_shift, 9.0 / 40.0, 1e-9);
  const auto [mean, var] = QuadratureMoments(range, delta, cov);
  EXPECT_GT(std::abs(mean - 20.0), 0.2);  // the first-order prediction is off by the shift
  EXPECT_NEAR(mean, 20.0 + so.mean_shift, 0.02);
  EXPECT_NEAR(var, 0.25 + so.variance, 0.02);
  EXPECT_GT(so.variance, 0.09);

  ScalarModel rssi;
  rssi.kind = ScalarModel::Kind::kRssiDb;
  rssi.path_loss_exponent = 2.5;
  const Vec2 delta_r = rot * Vec2(10.0, 0.0);
  const Mat2 cov_r = rot.toRotationMatrix() * Mat2(Vec2(1.0, 4.0).asDiagonal()) *
                     rot.toRotationMatrix().transpose();
  const auto sr = rssi.SecondOrderTerms(delta_r, cov_r);
  const auto [mean_r, var_r] = QuadratureMoments(rssi, delta_r, cov_r);
  const double slope = rssi.Slope(10.0);
  EXPECT_GT(std::abs(mean_r - rssi.Predict(10.0)), 0.1);
  EXPECT_NEAR(mean_r, rssi.Predict(10.0) + sr.mean_shift, 0.03);
  // The filter's variance leaves out the third-derivative terms of the logarithm (of the same
  // order here): it is on the safe side, by 6 % of the variance.
  const double var_so = slope * slope * 1.0 + sr.variance;
  EXPECT_LE(var_r, var_so);
  EXPECT_LT(var_so - var_r, 0.07 * var_r);
  EXPECT_GT(var_r, slope * slope * 1.0);  // and the first-order one is short

  // Beyond the expansion's reach (the node's uncertainty as large as the distance) the shift
  // stays within the first-order spread; none at or below the guard distance.
  const auto wide = range.SecondOrderTerms(Vec2(2.0, 0.0), Mat2::Identity() * 100.0);
  EXPECT_LE(wide.mean_shift, std::sqrt(200.0) + 1e-12);
  EXPECT_EQ(range.SecondOrderTerms(Vec2(0.1, 0.0), Mat2::Identity()).mean_shift, 0.0);
}

}  // namespace
}  // namespace trailmark::breadcrumb

namespace trailmark::breadcrumb {
namespace {

// The general linear edge over three nodes (a PDR displacement rotated by an agent's
// heading/scale node) with marginalization of the old states equals BLUE over everything.
TEST(GenNetwork, GeneralLinearEdgesWithMarginalizationEqualBlue) {
  Random rng(21);
  GenNetwork gen(ExactOptions());
  BatchProblem p;
  const NodeIndex crumb = gen.AddNode(Vec2::Zero());
  gen.AddPrior(crumb, Vec2(5, 5), Mat2::Identity() * 0.5);
  p.relative.push_back({0, -1, Vec2::Zero(), Vec2(5, 5), Mat2::Identity() * 0.5});
  NodeIndex x = gen.AddNode(Vec2::Zero()), th = gen.AddNode(Vec2::Zero());
  gen.AddPrior(x, Vec2::Zero(), Mat2::Identity() * 0.01);
  gen.AddPrior(th, Vec2::Zero(), Mat2::Identity() * 0.02);
  p.relative.push_back({1, -1, Vec2::Zero(), Vec2::Zero(), Mat2::Identity() * 0.01});
  p.relative.push_back({2, -1, Vec2::Zero(), Vec2::Zero(), Mat2::Identity() * 0.02});
  int bx = 1, bth = 2;
  p.num_nodes = 3;
  for (int k = 0; k < 30; ++k) {
    Mat2 Jth;
    Jth << rng.Normal(0, 1), rng.Normal(0, 1), rng.Normal(0, 1), rng.Normal(0, 1);
    const Vec2 z(rng.Normal(0.5, 0.1), rng.Normal(0, 0.1));
    const Mat2 Q = RandomCov(rng) * 0.05;
    const NodeIndex xn = gen.AddNode(Vec2::Zero()), thn = gen.AddNode(Vec2::Zero());
    gen.AddRelative(thn, th, Vec2::Zero(), Mat2::Identity() * 1e-3);
    gen.AddLinear({xn, x, th}, {Mat2::Identity(), -Mat2::Identity(), -Jth}, z, Q);
    if (k % 2 == 0) {
      gen.DeleteNodes(x, th);  // joint marginalization (4x4 pivot)
    } else {
      gen.DeleteNode(x);
      gen.DeleteNode(th);
    }
    x = xn;
    th = thn;
    const int nbx = p.num_nodes++, nbth = p.num_nodes++;
    p.relative.push_back({nbth, bth, Vec2::Zero(), Vec2::Zero(), Mat2::Identity() * 1e-3});
    p.linear.push_back({{nbx, bx, bth}, {Mat2::Identity(), -Mat2::Identity(), -Jth}, z, Q});
    bx = nbx;
    bth = nbth;
    if (k % 5 == 4) {
      const Vec2 zeta(rng.Normal(-5, 1), rng.Normal(-5, 1));
      gen.AddRelative(x, crumb, zeta, Mat2::Identity());
      p.relative.push_back({bx, 0, Vec2::Zero(), zeta, Mat2::Identity()});
    }
  }
  ASSERT_TRUE(gen.Solve());
  const BatchSolution blue = SolveBlue(p);
  const Eigen::VectorXd init = Eigen::VectorXd::Zero(2 * p.num_nodes);
  const BatchSolution gn = SolveNonlinear(p, init);
  EXPECT_LT((blue.x - gn.x).norm(), 1e-8);  // the two references agree on a linear problem
  for (auto [inc, ref] : {std::pair{crumb, 0}, std::pair{x, bx}, std::pair{th, bth}}) {
    EXPECT_LT((gen.Estimate(inc) - blue.Position(ref)).norm(), 1e-9);
    EXPECT_LT((gen.Covariance(inc) - blue.Covariance(ref)).norm(), 1e-9);
  }
}

// Consider parameters: each node's sensitivity d x_hat / d theta against finite differences of
// the whole network built again with every observation moved by eps times its rate. The network
// is linear in its observations (linear edges, marginalizations, a slot moved into), so the
// difference is exact to rounding; two parameters (two walkers' heading offsets), the sparse
// and the dense factor.
TEST(GenNetwork, ConsiderSensitivitiesAreTheEstimatesDerivatives) {
  for (const double dense_share : {1.0, 0.0}) {
    auto build = [&](double eps, std::vector<NodeIndex>* nodes) {
      GenOptions o = ExactOptions();
      o.dense_fill_share = dense_share;
      auto gen = std::make_unique<GenNetwork>(o);
      Random rng(23);
      const int c0 = gen->AddConsider(), c1 = gen->AddConsider();
      EXPECT_EQ(gen->considers(), 2);
      const NodeIndex crumb = gen->AddNode(Vec2::Zero());
      gen->AddPrior(crumb, Vec2(5, 5), Mat2::Identity() * 0.5);
      NodeIndex x = gen->AddNode(Vec2::Zero()), th = gen->AddNode(Vec2::Zero());
      NodeIndex y = gen->AddNode(Vec2(3, 0));
      gen->AddPrior(x, Vec2::Zero(), Mat2::Identity() * 0.01);
      gen->AddPrior(th, Vec2::Zero(), Mat2::Identity() * 0.02);
      gen->AddPrior(y, Vec2(3, 0), Mat2::Identity() * 0.04);
      for (int k = 0; k < 24; ++k) {
        Mat2 Jth;
        Jth << rng.Normal(0, 1), rng.Normal(0, 1), rng.Normal(0, 1), rng.Normal(0, 1);
        const Vec2 z(rng.Normal(0.5, 0.1), rng.Normal(0, 0.1));
        const Vec2 dz(rng.Normal(0, 1), rng.Normal(0, 1));
        const Mat2 Q = RandomCov(rng) * 0.05;
        const NodeIndex xn = gen->AddNode(Vec2::Zero()), thn = gen->AddNode(Vec2::Zero());
        gen->AddRelative(thn, th, Vec2::Zero(), Mat2::Identity() * 1e-3);
        gen->AddLinear({xn, x, th}, {Mat2::Identity(), -Mat2::Identity(), -Jth}, z + eps * dz, Q,
                       {{c0, dz}});
        const NodeIndex old_x = x, old_th = th;
        gen->DeleteNodes(old_x, old_th);
        th = gen->MoveNode(thn, old_th);
        x = gen->MoveNode(xn, old_x);
        // The second walker: plain relative steps, the slot kept.
        const Vec2 w(rng.Normal(0, 0.5), rng.Normal(0.4, 0.1)), dw(rng.Normal(0, 1), 0.3);
        const NodeIndex yn = gen->AddNode(gen->Estimate(y) + w);
        gen->AddRelative(yn, y, w + eps * dw, Mat2::Identity() * 0.02, {{c1, dw}});
        gen->DeleteNode(y);
        y = gen->MoveNode(yn, y);
        if (k % 5 == 4) {  // both touch the crumb; one edge moves with both parameters
          const Vec2 zeta(rng.Normal(-5, 1), rng.Normal(-5, 1)), d0(1.0, -0.5), d1(-0.2, 0.7);
          gen->AddRelative(x, crumb, zeta + eps * (d0 + d1), Mat2::Identity(),
                           {{c0, d0}, {c1, d1}});
          gen->AddRelative(y, crumb, zeta, Mat2::Identity() * 2.0);
        }
        if (k == 12) gen->Solve();  // a solve half way does not change the result
      }
      EXPECT_TRUE(gen->Solve());
      *nodes = {crumb, x, th, y};
      return gen;
    };
    std::vector<NodeIndex> nodes, nodes_eps;
    const double eps = 1e-3;
    const auto base = build(0.0, &nodes);
    const auto moved = build(eps, &nodes_eps);
    ASSERT_EQ(nodes, nodes_eps);
    double largest = 0;
    for (NodeIndex i : nodes) {
      const Vec2 fd = (moved->Estimate(i) - base->Estimate(i)) / eps;
      const Vec2 s = base->Sensitivity(i, 0) + base->Sensitivity(i, 1);
      EXPECT_LT((s - fd).norm(), 1e-7 * (1 + fd.norm()))
          << "node " << i << " dense " << dense_share;
      largest = std::max(largest, fd.norm());
    }
    EXPECT_GT(largest, 0.1);
    // Each parameter alone: the first walker's moves only its own chain's edges.
    EXPECT_GT(base->Sensitivity(nodes[1], 0).norm(), 0.1);
    EXPECT_EQ(base->Sensitivity(nodes[1], 7), Vec2::Zero());  // no such parameter: none
  }
}

// With range edges (linearized at the estimate, re-linearized persistent ones) the sensitivity
// is the first-order one: on observations without noise (every residual zero) the finite
// difference agrees to the step's second order.
// A fixed-lag window (LocalizerOptions::fixed_lag_s): scalar edges kept persistent with their
// offsets and a range-bias node are re-linearized at every solve, so while nothing is
// marginalized the network's estimate is the batch non-linear optimum exactly, however poor the
// points the edges were added at (here: beacons 3 m off, a range scale of 5 % to find).
TEST(GenNetwork, PersistentScalarEdgesWithOffsetsAndBiasAreTheBatchOptimum) {
  Random rng(23);
  GenOptions options = ExactOptions();
  options.max_relinearization_iterations = 100;
  options.relinearization_tolerance_m = 1e-12;
  GenNetwork gen(options);
  BatchProblem p;
  const std::vector<Vec2> beacons = {{0, 8}, {12, -4}, {-6, -6}};
  Eigen::VectorXd init = Eigen::VectorXd::Zero(2 * 64);
  for (int b = 0; b < 3; ++b) {
    const Vec2 start = beacons[b] + Vec2(rng.Normal(0, 3), rng.Normal(0, 3));
    const NodeIndex i = gen.AddNode(start);
    gen.AddPrior(i, start, Mat2::Identity() * 25.0);
    p.relative.push_back({b, -1, Vec2::Zero(), start, Mat2::Identity() * 25.0});
    init.segment<2>(2 * b) = start;
  }
  const NodeIndex bias = gen.AddNode(Vec2::Zero());
  const Mat2 bias_prior = Vec2(1.0, 0.01).asDiagonal();
  gen.AddPrior(bias, Vec2::Zero(), bias_prior);
  p.relative.push_back({3, -1, Vec2::Zero(), Vec2::Zero(), bias_prior});
  p.num_nodes = 4;
  Vec2 pos(1, 1);
  NodeIndex state = gen.AddNode(pos);
  gen.AddPrior(state, pos, Mat2::Identity() * 0.01);
  int bs = p.num_nodes++;
  p.relative.push_back({bs, -1, Vec2::Zero(), pos, Mat2::Identity() * 0.01});
  init.segment<2>(2 * bs) = pos;
  ScalarModel range;
  std::vector<int> edges;
  for (int k = 0; k < 40; ++k) {
    const Vec2 step(0.4 * std::cos(k * 0.15), 0.4 * std::sin(k * 0.15));
    pos += step;
    const Vec2 meas = step + Vec2(rng.Normal(0, 0.02), rng.Normal(0, 0.02));
    const Mat2 Q = Mat2::Identity() * 4e-4;
    const NodeIndex next = gen.AddNode(gen.Estimate(state) + meas);
    gen.AddRelative(next, state, meas, Q);
    const int nb = p.num_nodes++;
    p.relative.push_back({nb, bs, Vec2::Zero(), meas, Q});
    init.segment<2>(2 * nb) = gen.Estimate(next);
    state = next;
    bs = nb;
    // A range from a bit further on (the known offset), scaled by 1.05 and 0.3 m long.
    const Vec2 offset(0.1 * std::cos(k), 0.1 * std::sin(k));
    const int b = k % 3;
    const double z = 1.05 * (pos + offset - beacons[b]).norm() + 0.3 + rng.Normal(0, 0.05);
    edges.push_back(gen.AddScalarPersistent(state, b, z, 0.0025, range, offset, bias));
    BatchProblem::Scalar sc;
    sc.i = bs;
    sc.j = b;
    sc.offset = offset;
    sc.z = z;
    sc.variance = 0.0025;
    sc.model = range;
    sc.bias = 3;
    p.scalar.push_back(sc);
    ASSERT_TRUE(gen.Solve());
  }
  EXPECT_EQ(gen.active_persistent(), edges.size());
  init.conservativeResize(2 * p.num_nodes);
  const BatchSolution nls = SolveNonlinear(p, init);
  ASSERT_TRUE(nls.converged);
  for (int n = 0; n < p.num_nodes; ++n) {
    EXPECT_LT((gen.Estimate(n) - nls.Position(n)).norm(), 1e-6) << n;  // added in one order
  }
  EXPECT_LT((gen.Covariance(state) - nls.Covariance(p.num_nodes - 1)).norm(), 1e-6);
  EXPECT_NEAR(gen.Estimate(bias).y(), nls.Position(3).y(), 1e-8);
  EXPECT_GT(nls.Position(3).y(), 0.02);  // the scale is seen
  // The oldest states leave, as from the window: their edges are folded at the current
  // estimates, so the estimate of the rest does not move.
  const Vec2 before = gen.Estimate(state);
  gen.DeleteNode(4);
  gen.DeleteNode(5);
  EXPECT_EQ(gen.active_persistent(), edges.size() - 1);
  ASSERT_TRUE(gen.Solve());
  EXPECT_LT((gen.Estimate(state) - before).norm(), 1e-6);
}

TEST(GenNetwork, ConsiderSensitivitiesThroughRangeEdgesAreFirstOrder) {
  auto build = [&](double eps) {
    auto gen = std::make_unique<GenNetwork>(ExactOptions());
    const int c = gen->AddConsider();
    const std::vector<Vec2> crumbs = {{4, 3}, {-2, 6}, {7, -3}};
    for (const Vec2& x : crumbs) {
      const NodeIndex n = gen->AddNode(x);
      gen->AddPrior(n, x, Mat2::Identity() * 4.0);
    }
    ScalarModel range;
    gen->AccumulatePersistent(gen->AddPersistent(0, 1, range), (crumbs[0] - crumbs[1]).norm(),
                              0.01);
    NodeIndex state = gen->AddNode(Vec2::Zero());
    gen->AddPrior(state, Vec2::Zero(), Mat2::Identity() * 0.01);
    Vec2 pos = Vec2::Zero();
    for (int k = 0; k < 40; ++k) {
      const Vec2 step(0.5 * std::cos(0.1 * k), 0.5 * std::sin(0.1 * k));
      const Vec2 rate(-step.y(), step.x());  // the step turned: a heading offset
      pos += step;
      const NodeIndex next = gen->AddNode(gen->Estimate(state) + step);
      gen->AddRelative(next, state, step + eps * rate, Mat2::Identity() * 0.01, {{c, rate}});
      gen->DeleteNode(state);
      state = gen->MoveNode(next, state);
      // A range from half a step further on (offset), noise-free.
      const Vec2 offset = 0.5 * step;
      const int j = k % 3;
      gen->AddScalar(state, j, (pos + offset - crumbs[j]).norm(), 0.04, range,
                     offset + eps * 0.5 * rate, -1, {{c, 0.5 * rate}});
      gen->Solve();
    }
    return std::make_pair(std::move(gen), state);
  };
  const double eps = 1e-6;
  const auto [base, state] = build(0.0);
  const auto [moved, state_eps] = build(eps);
  for (NodeIndex i : {NodeIndex{0}, NodeIndex{1}, NodeIndex{2}, state}) {
    const Vec2 fd = (moved->Estimate(i) - base->Estimate(i)) / eps;
    EXPECT_LT((base->Sensitivity(i, 0) - fd).norm(), 1e-4 * (1 + fd.norm())) << "node " << i;
  }
  EXPECT_GT(base->Sensitivity(state, 0).norm(), 0.5);
}

// The dense path (GenOptions::dense_fill_share) against the sparse one: a walker among crumbs
// that range to each other, its old states marginalized so that every crumb it heard is linked
// to every other (the fill that makes the network dense), re-solved at every step. Both paths
// must give the same estimates and marginals at every step, through the Gauss-Newton
// re-linearizations of the persistent edges.
TEST(GenNetwork, TheDenseFactorEqualsTheSparseOneAtEveryStep) {
  GenOptions sparse_options;
  sparse_options.dense_fill_share = 1.0;  // never dense
  GenOptions dense_options;
  dense_options.dense_fill_share = 0.0;  // dense whenever the pattern holds
  GenNetwork sparse(sparse_options), dense(dense_options);
  Random rng(31);
  const int crumbs = 12;
  std::vector<Vec2> crumb_truth;
  ScalarModel range;
  for (int c = 0; c < crumbs; ++c) {
    crumb_truth.emplace_back(rng.Uniform(-15, 15), rng.Uniform(-15, 15));
    const Vec2 start = crumb_truth.back() + Vec2(rng.Normal(0, 1), rng.Normal(0, 1));
    for (GenNetwork* g : {&sparse, &dense}) {
      g->AddNode(start);
      g->AddPrior(c, start, Mat2::Identity() * 2.0);
    }
  }
  for (int c = 1; c < crumbs; c += 2) {  // persistent crumb-crumb ranges (re-linearized)
    const double z = (crumb_truth[c] - crumb_truth[c - 1]).norm() + rng.Normal(0, 0.1);
    for (GenNetwork* g : {&sparse, &dense})
      g->AccumulatePersistent(g->AddPersistent(c, c - 1, range), z, 0.01);
  }
  Vec2 pos = Vec2::Zero();
  NodeIndex state = -1;
  for (GenNetwork* g : {&sparse, &dense}) {
    state = g->AddNode(pos);
    g->AddPrior(state, pos, Mat2::Identity() * 0.01);
  }
  for (int k = 0; k < 120; ++k) {
    const Vec2 step(0.6 * std::cos(k * 0.13), 0.6 * std::sin(k * 0.07));
    pos += step;
    const Vec2 meas = step + Vec2(rng.Normal(0, 0.05), rng.Normal(0, 0.05));
    const int c = static_cast<int>(rng.Uniform(0, crumbs - 1e-9));
    const double z = (pos - crumb_truth[c]).norm() + rng.Normal(0, 0.3);
    for (GenNetwork* g : {&sparse, &dense}) {
      // AddNode -> AddMeasurement -> DeleteNode, the new state taking the old one's slot.
      const NodeIndex next = g->AddNode(g->Estimate(state) + meas);
      g->AddRelative(next, state, meas, Mat2::Identity() * 0.01);
      g->DeleteNode(state);
      ASSERT_EQ(g->MoveNode(next, state), state);
      g->AddScalar(state, c, z, 0.09, range);
      ASSERT_TRUE(g->Solve());
    }
    for (NodeIndex i = 0; i <= crumbs; ++i) {
      ASSERT_LT((dense.Estimate(i) - sparse.Estimate(i)).norm(), 1e-9)
          << "step " << k << " node " << i;
    }
    const Mat2 agent = sparse.Covariance(state);
    ASSERT_LT((dense.Covariance(state) - agent).norm(), 1e-9 * agent.norm()) << "step " << k;
    const Eigen::Matrix4d joint = sparse.JointCovariance(c, state);
    ASSERT_LT((dense.JointCovariance(c, state) - joint).norm(), 1e-9 * joint.norm())
        << "step " << k;
  }
  EXPECT_EQ(sparse.dense_factorizations(), 0u);
  EXPECT_GT(dense.dense_factorizations(), 60u);  // most steps keep the pattern
  EXPECT_EQ(sparse.factorizations(), dense.factorizations());
}

}  // namespace
}  // namespace trailmark::breadcrumb

// SPDX-License-Identifier: MIT
#include "trailmark/breadcrumb/batch_reference.h"

#include <Eigen/Dense>
#include <stdexcept>

namespace trailmark::breadcrumb {

BatchSolution SolveBlue(const BatchProblem& p) {
  if (!p.scalar.empty()) throw std::invalid_argument("SolveBlue: linear measurements only");
  const int n = p.num_nodes * 2;
  const int m = static_cast<int>(p.relative.size() + p.linear.size()) * 2;
  // eq. (2)-(3): z' = A^T x + e; anchors move to the left-hand side (z' = zeta + anchor).
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(n, m);
  Eigen::MatrixXd P_inv = Eigen::MatrixXd::Zero(m, m);
  Eigen::VectorXd z(m);
  for (int k = 0; k < static_cast<int>(p.relative.size()); ++k) {
    const auto& r = p.relative[k];
    A.block<2, 2>(2 * r.i, 2 * k) = Mat2::Identity();
    if (r.j >= 0) {
      A.block<2, 2>(2 * r.j, 2 * k) = -Mat2::Identity();
      z.segment<2>(2 * k) = r.zeta;
    } else {
      z.segment<2>(2 * k) = r.zeta + r.anchor;
    }
    P_inv.block<2, 2>(2 * k, 2 * k) = r.cov.inverse();
  }
  for (std::size_t q = 0; q < p.linear.size(); ++q) {
    const int k = static_cast<int>(p.relative.size() + q);
    const auto& l = p.linear[q];
    for (std::size_t a = 0; a < l.nodes.size(); ++a) {
      A.block<2, 2>(2 * l.nodes[a], 2 * k) = l.J[a].transpose();
    }
    z.segment<2>(2 * k) = l.z;
    P_inv.block<2, 2>(2 * k, 2 * k) = l.cov.inverse();
  }
  // eq. (4)-(5): Sigma = (A P^-1 A^T)^-1,  x = Sigma A P^-1 z
  const Eigen::MatrixXd info = A * P_inv * A.transpose();
  BatchSolution s;
  s.sigma = info.inverse();
  s.x = s.sigma * (A * P_inv * z);
  s.iterations = 1;
  s.converged = true;
  return s;
}

BatchSolution SolveNonlinear(const BatchProblem& p, const Eigen::VectorXd& initial,
                             int max_iterations, double tolerance_m) {
  const int n = p.num_nodes * 2;
  BatchSolution s;
  s.x = initial;
  Eigen::MatrixXd H(n, n);
  Eigen::VectorXd g(n);
  for (s.iterations = 0; s.iterations < max_iterations;) {
    H.setZero();
    g.setZero();
    for (const auto& r : p.relative) {
      const Mat2 W = r.cov.inverse();
      const Vec2 xj = r.j >= 0 ? Vec2(s.x.segment<2>(2 * r.j)) : r.anchor;
      const Vec2 res = r.zeta - (s.x.segment<2>(2 * r.i) - xj);
      H.block<2, 2>(2 * r.i, 2 * r.i) += W;
      g.segment<2>(2 * r.i) += W * res;
      if (r.j >= 0) {
        H.block<2, 2>(2 * r.j, 2 * r.j) += W;
        H.block<2, 2>(2 * r.i, 2 * r.j) -= W;
        H.block<2, 2>(2 * r.j, 2 * r.i) -= W;
        g.segment<2>(2 * r.j) -= W * res;
      }
    }
    for (const auto& l : p.linear) {
      const Mat2 W = l.cov.inverse();
      Vec2 res = l.z;
      for (std::size_t a = 0; a < l.nodes.size(); ++a) res -= l.J[a] * s.x.segment<2>(2 * l.nodes[a]);
      for (std::size_t a = 0; a < l.nodes.size(); ++a) {
        g.segment<2>(2 * l.nodes[a]) += l.J[a].transpose() * W * res;
        for (std::size_t c = 0; c < l.nodes.size(); ++c) {
          H.block<2, 2>(2 * l.nodes[a], 2 * l.nodes[c]) += l.J[a].transpose() * W * l.J[c];
        }
      }
    }
    for (const auto& sc : p.scalar) {
      const Vec2 xj = sc.j >= 0 ? Vec2(s.x.segment<2>(2 * sc.j)) : sc.anchor;
      const Vec2 diff = s.x.segment<2>(2 * sc.i) + sc.offset - xj;
      const double d = diff.norm();
      const Vec2 u = d > 1e-9 ? Vec2(diff / d) : Vec2(1.0, 0.0);
      const Vec2 bias = sc.bias >= 0 ? Vec2(s.x.segment<2>(2 * sc.bias)) : Vec2::Zero();
      const Vec2 J = (1.0 + bias.y()) * sc.model.Slope(d) * u;
      const double w = 1.0 / sc.variance;
      const double res = sc.z - (1.0 + bias.y()) * sc.model.Predict(d) - bias.x();
      std::vector<std::pair<int, Vec2>> rows{{sc.i, J}};
      if (sc.j >= 0) rows.emplace_back(sc.j, -J);
      if (sc.bias >= 0) rows.emplace_back(sc.bias, Vec2(1.0, sc.model.Predict(d)));
      for (const auto& [a, Ja] : rows) {
        g.segment<2>(2 * a) += w * Ja * res;
        for (const auto& [c, Jc] : rows) H.block<2, 2>(2 * a, 2 * c) += w * Ja * Jc.transpose();
      }
    }
    const Eigen::LDLT<Eigen::MatrixXd> ldlt(H);
    const Eigen::VectorXd dx = ldlt.solve(g);
    s.x += dx;
    ++s.iterations;
    if (dx.lpNorm<Eigen::Infinity>() < tolerance_m) {
      s.converged = true;
      break;
    }
  }
  s.sigma = H.inverse();
  return s;
}

}  // namespace trailmark::breadcrumb

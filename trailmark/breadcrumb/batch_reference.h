// SPDX-License-Identifier: MIT
#pragma once
/// Batch references for the incremental GEN estimator (tests and benchmarks only).
///
///  - SolveBlue: the best linear unbiased estimator of the breadcrumb paper, eqs. (1)-(5),
///    built from the incidence matrix A (one block column per measurement), the block-diagonal
///    measurement covariance P and the anchors: Sigma = (A P^-1 A^T)^-1, x = Sigma A P^-1 z'.
///  - SolveNonlinear: batch non-linear least squares (dense Gauss-Newton) over every node and
///    every measurement, nothing marginalized.
/// Dense on purpose: they are the exact references the incremental estimator is tested against,
/// and the "re-solve everything at each update" baseline of the benchmark.

#include <Eigen/Core>
#include <vector>

#include "trailmark/breadcrumb/gen_network.h"

namespace trailmark::breadcrumb {

struct BatchProblem {
  int num_nodes = 0;
  /// zeta = x_i - x_j + e (j >= 0), or zeta = x_i - anchor + e (j < 0).
  struct Relative {
    int i = 0, j = -1;
    Vec2 anchor = Vec2::Zero();
    Vec2 zeta = Vec2::Zero();
    Mat2 cov = Mat2::Identity();
  };
  /// z = h(|x_i + offset - x_j|) + e (j >= 0), or with x_j := anchor (j < 0).
  struct Scalar {
    int i = 0, j = -1;
    Vec2 anchor = Vec2::Zero();
    Vec2 offset = Vec2::Zero();
    double z = 0, variance = 1;
    ScalarModel model;
    int bias = -1;  ///< node (offset, scale): z = (1 + scale) h + offset
  };
  /// z = sum_k J_k x_k + e (the general linear edge).
  struct Linear {
    std::vector<int> nodes;
    std::vector<Mat2> J;
    Vec2 z = Vec2::Zero();
    Mat2 cov = Mat2::Identity();
  };
  std::vector<Relative> relative;
  std::vector<Linear> linear;
  std::vector<Scalar> scalar;
};

struct BatchSolution {
  Eigen::VectorXd x;      ///< 2 * num_nodes
  Eigen::MatrixXd sigma;  ///< full covariance
  int iterations = 0;
  bool converged = false;
  Vec2 Position(int i) const { return x.segment<2>(2 * i); }
  Mat2 Covariance(int i) const { return sigma.block<2, 2>(2 * i, 2 * i); }
};

/// Linear measurements only (scalar ones are rejected with std::invalid_argument).
BatchSolution SolveBlue(const BatchProblem& problem);

/// Gauss-Newton from `initial` (2 * num_nodes) until the step is below tolerance_m.
BatchSolution SolveNonlinear(const BatchProblem& problem, const Eigen::VectorXd& initial,
                             int max_iterations = 50, double tolerance_m = 1e-10);

}  // namespace trailmark::breadcrumb

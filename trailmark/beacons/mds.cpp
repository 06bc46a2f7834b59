// SPDX-License-Identifier: MIT
#include "trailmark/beacons/mds.h"

#include "trailmark/geometry/rigid_fit.h"

#include <Eigen/Dense>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <Spectra/MatOp/DenseSymMatProd.h>
#include <Spectra/SymEigsSolver.h>
#include <algorithm>
#include <cmath>
#include <limits>
#include <queue>
#include <stdexcept>

namespace trailmark::beacons {

bool FillShortestPaths(const RangeMatrix& measured, std::vector<std::vector<double>>* full) {
  const std::size_t n = measured.size();
  std::vector<std::vector<std::pair<std::size_t, double>>> adj(n);
  for (std::size_t i = 0; i < n; ++i) {
    if (measured[i].size() != n) throw std::invalid_argument("FillShortestPaths: not square");
    for (std::size_t j = 0; j < n; ++j) {
      // A measured range <= 0 (noise on a very short link) would make a negative cycle:
      // Dijkstra needs positive weights.
      if (i != j && measured[i][j]) adj[i].emplace_back(j, std::max(*measured[i][j], 1e-6));
    }
  }
  constexpr double kInf = std::numeric_limits<double>::infinity();
  full->assign(n, std::vector<double>(n, kInf));
  bool connected = true;
  double largest = 0;
  for (std::size_t s = 0; s < n; ++s) {
    auto& dist = (*full)[s];
    dist[s] = 0;
    using Item = std::pair<double, std::size_t>;
    std::priority_queue<Item, std::vector<Item>, std::greater<>> queue;
    queue.emplace(0.0, s);
    while (!queue.empty()) {
      const auto [d, u] = queue.top();
      queue.pop();
      if (d > dist[u]) continue;
      for (const auto& [v, w] : adj[u]) {
        if (d + w < dist[v]) {
          dist[v] = d + w;
          queue.emplace(dist[v], v);
        }
      }
    }
    for (std::size_t j = 0; j < n; ++j) {
      // Measured links keep their measurement (a shortest path could undercut a noisy one).
      if (j != s && measured[s][j]) dist[j] = *measured[s][j];
      if (std::isinf(dist[j])) connected = false;
      else largest = std::max(largest, dist[j]);
    }
  }
  if (!connected) {
    for (auto& row : *full) {
      for (double& d : row) {
        if (std::isinf(d)) d = 2 * largest;
      }
    }
  }
  // Symmetrize (Dijkstra from both ends agrees up to the measured overrides).
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t j = i + 1; j < n; ++j) {
      const double d = 0.5 * ((*full)[i][j] + (*full)[j][i]);
      (*full)[i][j] = (*full)[j][i] = d;
    }
  }
  return connected;
}

namespace {
constexpr int kPartialFromPoints = 64;
}  // namespace

std::vector<Vec2> ClassicalMds(const std::vector<std::vector<double>>& full, MdsEigensolver solver) {
  const int n = static_cast<int>(full.size());
  if (n < 3) throw std::invalid_argument("ClassicalMds: needs >= 3 points");
  // B = -1/2 J D^2 J (double centring)
  Eigen::MatrixXd B(n, n);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) B(i, j) = full[i][j] * full[i][j];
  }
  const Eigen::VectorXd row_mean = B.rowwise().mean();
  const double mean = row_mean.mean();
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) B(i, j) = -0.5 * (B(i, j) - row_mean(i) - row_mean(j) + mean);
  }
  // The two leading (largest algebraic) eigenpairs.
  Eigen::Vector2d values;
  Eigen::MatrixXd Q(n, 2);
  bool solved = false;
  const bool partial = solver == MdsEigensolver::kPartial ||
                       (solver == MdsEigensolver::kAuto && n >= kPartialFromPoints);
  if (partial) {
    // Implicitly restarted Lanczos (Spectra): only products B v, ~0.05 s for 1,000 beacons
    // against ~0.4 s for the dense solver's full decomposition.
    Spectra::DenseSymMatProd<double> product(B);
    const int ncv = std::min(n, 20);
    Spectra::SymEigsSolver<Spectra::DenseSymMatProd<double>> eigs(product, 2, ncv);
    eigs.init();
    eigs.compute(Spectra::SortRule::LargestAlge, 1000, 1e-12);
    if (eigs.info() == Spectra::CompInfo::Successful) {
      values = eigs.eigenvalues().head<2>();  // descending
      Q = eigs.eigenvectors().leftCols(2);
      solved = true;
    } else if (solver == MdsEigensolver::kPartial) {
      throw std::runtime_error("ClassicalMds: the partial eigensolver did not converge");
    }
  }
  if (!solved) {
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(B);
    const Eigen::VectorXd& all = eig.eigenvalues();  // ascending
    values = Eigen::Vector2d(all(n - 1), all(n - 2));
    Q.col(0) = eig.eigenvectors().col(n - 1);
    Q.col(1) = eig.eigenvectors().col(n - 2);
  }
  for (int c = 0; c < 2; ++c) {  // the sign: largest component positive
    Eigen::Index at = 0;
    Q.col(c).cwiseAbs().maxCoeff(&at);
    if (Q(at, c) < 0) Q.col(c) = -Q.col(c);
  }
  std::vector<Vec2> X(n);
  for (int i = 0; i < n; ++i) {
    X[i] = Vec2(Q(i, 0) * std::sqrt(std::max(values(0), 0.0)), Q(i, 1) * std::sqrt(std::max(values(1), 0.0)));
  }
  return X;
}

std::vector<Vec2> RefineSmacof(const RangeMatrix& measured, std::vector<Vec2> X, int max_iterations,
                               double tolerance, double* stress_out) {
  const int n = static_cast<int>(X.size());
  // V = sum over measured pairs of w (e_i - e_j)(e_i - e_j)^T (a graph Laplacian), regularized
  // on its null space (the translation) by anchoring the centroid.
  std::vector<Eigen::Triplet<double>> t;
  std::vector<std::pair<int, int>> edges;
  std::vector<double> dist;
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j < n; ++j) {
      if (!measured[i][j]) continue;
      edges.emplace_back(i, j);
      dist.push_back(*measured[i][j]);
      t.emplace_back(i, i, 1.0);
      t.emplace_back(j, j, 1.0);
      t.emplace_back(i, j, -1.0);
      t.emplace_back(j, i, -1.0);
    }
  }
  for (int i = 0; i < n; ++i) t.emplace_back(i, i, 1e-9);
  Eigen::SparseMatrix<double> V(n, n);
  V.setFromTriplets(t.begin(), t.end());
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(V);
  auto stress = [&](const std::vector<Vec2>& Y) {
    double s = 0;
    for (std::size_t e = 0; e < edges.size(); ++e) {
      const double r = (Y[edges[e].first] - Y[edges[e].second]).norm() - dist[e];
      s += r * r;
    }
    return s;
  };
  double previous = stress(X);
  Eigen::MatrixXd BX(n, 2), Xm(n, 2);
  for (int it = 0; it < max_iterations; ++it) {
    // Guttman transform: X <- V^+ B(X) X
    BX.setZero();
    for (std::size_t e = 0; e < edges.size(); ++e) {
      const auto [i, j] = edges[e];
      const Vec2 d = X[i] - X[j];
      const double norm = d.norm();
      if (norm < 1e-12) continue;
      const Vec2 f = dist[e] / norm * d;
      BX.row(i) += f.transpose();
      BX.row(j) -= f.transpose();
    }
    Xm = solver.solve(BX);
    for (int i = 0; i < n; ++i) X[i] = Xm.row(i).transpose();
    const double s = stress(X);
    if (previous - s < tolerance * std::max(previous, 1e-12)) {
      previous = s;
      break;
    }
    previous = s;
  }
  if (stress_out) *stress_out = previous;
  return X;
}

}  // namespace trailmark::beacons

// SPDX-License-Identifier: MIT
#include "trailmark/landmarks/stop_and_go.h"

#include <fmt/format.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace trailmark::landmarks {

namespace {

/// With the range calibration, distances and ranges are compared in the log from this up (a
/// landmark overhead reads as near, not as 0 m).
constexpr double kMinLogDistanceM = 0.5;

double Rho(double r, Loss loss, double k) {
  const double a = std::abs(r);
  switch (loss) {
    case Loss::kSquared: return 0.5 * r * r;
    case Loss::kHuber: return a <= k ? 0.5 * r * r : k * (a - 0.5 * k);
    case Loss::kCauchy: return 0.5 * k * k * std::log1p((r / k) * (r / k));
  }
  return 0.5 * r * r;
}

/// IRLS weight w(r) = rho'(r) / r.
double Weight(double r, Loss loss, double k) {
  const double a = std::abs(r);
  switch (loss) {
    case Loss::kSquared: return 1.0;
    case Loss::kHuber: return a <= k ? 1.0 : k / a;
    case Loss::kCauchy: return 1.0 / (1.0 + (r / k) * (r / k));
  }
  return 1.0;
}

/// Second singular value of the centred points (0 for collinear sets), and the first.
std::pair<double, double> Spread(const std::vector<Vec2>& pts) {
  if (pts.size() < 2) return {0.0, 0.0};
  Vec2 c = Vec2::Zero();
  for (const auto& p : pts) c += p;
  c /= static_cast<double>(pts.size());
  Eigen::Matrix2d C = Eigen::Matrix2d::Zero();
  for (const auto& p : pts) C += (p - c) * (p - c).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(C / static_cast<double>(pts.size()));
  return {std::sqrt(std::max(0.0, eig.eigenvalues()(0))), std::sqrt(std::max(0.0, eig.eigenvalues()(1)))};
}

struct Problem {
  const StopAndGoProblem& p;
  const StopAndGoOptions& o;
  std::vector<int> col_s, col_h;  // first column of each unknown, -1 when known
  int n = 0;
  /// The standing prior (ours): columns [h0, h0 + mean.size()) and their mean.
  int h0 = 0;
  Eigen::VectorXd h_mean;
  /// The range calibration's columns a, a + 1 (ours), -1 without.
  int col_cal = -1;

  /// One range's residual and its sigma; `along` (optional) receives df/dH (df/dS is its
  /// negative), `d_cal` df/d(a, b). Without calibration eq. (6), f = |H - S| - z, in metres.
  /// With it (ours) the model z = e^a d^b in the log, f = a + b ln d - ln z, whose sigma is the
  /// range's relative one (the RSSI's shadowing, the same whatever a and b).
  double Residual(const Eigen::VectorXd& u, int q, int j, double* sigma, Vec2* along = nullptr,
                  Vec2* d_cal = nullptr) const {
    const Vec2 d = H(u, q) - S(u, j);
    const double z = *p.range_m[q][j];
    if (col_cal < 0) {
      const double dist = std::max(d.norm(), 1e-6);
      if (along) *along = d / dist;  // eq. (14); eq. (13) is its negative
      *sigma = p.sigma_m[q][j];
      return dist - z;  // eq. (6)
    }
    const double dist = std::max(d.norm(), kMinLogDistanceM);
    const double a = u(col_cal), b = u(col_cal + 1);
    if (along) *along = d.norm() > kMinLogDistanceM ? Vec2(b * d / (dist * dist)) : Vec2::Zero();
    if (d_cal) *d_cal = Vec2(1.0, std::log(dist));
    *sigma = p.sigma_m[q][j] / std::max(z, kMinLogDistanceM);
    return a + b * std::log(dist) - std::log(std::max(z, kMinLogDistanceM));
  }

  bool HasStandingPrior() const { return h_mean.size() > 0; }
  double LandmarkPriorSigma(int j) const {
    return j < static_cast<int>(p.landmark_prior_sigma_m.size()) ? p.landmark_prior_sigma_m[j]
                                                                 : 0.0;
  }
  /// The priors' cost (squared: they are Gaussian), 0.5 d^T Lambda d.
  double PriorCost(const Eigen::VectorXd& u) const {
    double c = 0;
    if (HasStandingPrior()) {
      const Eigen::VectorXd d = u.segment(h0, h_mean.size()) - h_mean;
      c += 0.5 * d.dot(p.standing_prior_information * d);
    }
    for (std::size_t j = 0; j < col_s.size(); ++j) {
      const double s = LandmarkPriorSigma(static_cast<int>(j));
      if (col_s[j] >= 0 && s > 0) {
        c += 0.5 * (u.segment<2>(col_s[j]) - p.landmarks[j]).squaredNorm() / (s * s);
      }
    }
    if (col_cal >= 0) {
      const auto& k = *p.range_calibration;
      c += 0.5 * std::pow(u(col_cal) / k.log_scale_sigma, 2) +
           0.5 * std::pow((u(col_cal + 1) - 1) / k.exponent_ratio_sigma, 2);
    }
    return c;
  }
  void LinearizePriors(const Eigen::VectorXd& u, Eigen::VectorXd* g, Eigen::MatrixXd* N) const {
    if (HasStandingPrior()) {
      const Eigen::Index m = h_mean.size();
      g->segment(h0, m) += p.standing_prior_information * (u.segment(h0, m) - h_mean);
      N->block(h0, h0, m, m) += p.standing_prior_information;
    }
    for (std::size_t j = 0; j < col_s.size(); ++j) {
      const double s = LandmarkPriorSigma(static_cast<int>(j));
      if (col_s[j] >= 0 && s > 0) {
        g->segment<2>(col_s[j]) += (u.segment<2>(col_s[j]) - p.landmarks[j]) / (s * s);
        N->block<2, 2>(col_s[j], col_s[j]) += Mat2::Identity() / (s * s);
      }
    }
    if (col_cal >= 0) {
      const auto& k = *p.range_calibration;
      const double ia = 1 / (k.log_scale_sigma * k.log_scale_sigma);
      const double ib = 1 / (k.exponent_ratio_sigma * k.exponent_ratio_sigma);
      (*g)(col_cal) += ia * u(col_cal);
      (*g)(col_cal + 1) += ib * (u(col_cal + 1) - 1);
      (*N)(col_cal, col_cal) += ia;
      (*N)(col_cal + 1, col_cal + 1) += ib;
    }
  }

  Vec2 S(const Eigen::VectorXd& u, int j) const {
    return col_s[j] >= 0 ? Vec2(u.segment<2>(col_s[j])) : p.landmarks[j];
  }
  Vec2 H(const Eigen::VectorXd& u, int q) const {
    return col_h[q] >= 0 ? Vec2(u.segment<2>(col_h[q])) : p.standing[q];
  }
  double Cost(const Eigen::VectorXd& u, double* rms = nullptr) const {
    double c = 0, ss = 0;
    int m = 0;
    for (std::size_t q = 0; q < p.range_m.size(); ++q) {
      for (std::size_t j = 0; j < p.range_m[q].size(); ++j) {
        if (!p.range_m[q][j]) continue;
        double s = 1;
        const double f = Residual(u, static_cast<int>(q), static_cast<int>(j), &s);
        c += Rho(f / s, o.loss, o.robust_k);
        ss += f * f;
        ++m;
      }
    }
    if (rms) *rms = m ? std::sqrt(ss / m) : 0.0;
    return c + PriorCost(u);
  }
  /// Gradient Q^T W b (eq. 10) and normal matrix Q^T W Q, with IRLS weights.
  void Linearize(const Eigen::VectorXd& u, Eigen::VectorXd* g, Eigen::MatrixXd* N) const {
    g->setZero(n);
    N->setZero(n, n);
    for (std::size_t q = 0; q < p.range_m.size(); ++q) {
      for (std::size_t j = 0; j < p.range_m[q].size(); ++j) {
        if (!p.range_m[q][j]) continue;
        double s = 1;
        Vec2 e, jc;
        const double f = Residual(u, static_cast<int>(q), static_cast<int>(j), &s, &e, &jc);
        const double w = Weight(f / s, o.loss, o.robust_k) / (s * s);
        const int cs = col_s[j], ch = col_h[q];
        if (cs >= 0) g->segment<2>(cs) += w * f * (-e);
        if (ch >= 0) g->segment<2>(ch) += w * f * e;
        if (cs >= 0) N->block<2, 2>(cs, cs) += w * e * e.transpose();
        if (ch >= 0) N->block<2, 2>(ch, ch) += w * e * e.transpose();
        if (cs >= 0 && ch >= 0) {
          N->block<2, 2>(cs, ch) -= w * e * e.transpose();
          N->block<2, 2>(ch, cs) -= w * e * e.transpose();
        }
        if (col_cal >= 0) {
          g->segment<2>(col_cal) += w * f * jc;
          N->block<2, 2>(col_cal, col_cal) += w * jc * jc.transpose();
          if (cs >= 0) {
            N->block<2, 2>(cs, col_cal) += w * (-e) * jc.transpose();
            N->block<2, 2>(col_cal, cs) += w * jc * (-e).transpose();
          }
          if (ch >= 0) {
            N->block<2, 2>(ch, col_cal) += w * e * jc.transpose();
            N->block<2, 2>(col_cal, ch) += w * jc * e.transpose();
          }
        }
      }
    }
    LinearizePriors(u, g, N);
  }
};

/// N^-1 b. Eq. (17)'s SVD pseudo-inverse; with a standing prior (ours) N is positive definite
/// and an LDL^T factor gives the same at a fraction of the cost (the SVD is the fallback when
/// the factor finds it is not).
Eigen::MatrixXd SolveNormal(const Eigen::MatrixXd& N, const Eigen::MatrixXd& b, bool prior,
                            const StopAndGoOptions& o) {
  if (prior) {
    const Eigen::LDLT<Eigen::MatrixXd> ldlt(N);
    if (ldlt.info() == Eigen::Success && ldlt.isPositive() &&
        ldlt.vectorD().minCoeff() > o.svd_relative_threshold * ldlt.vectorD().maxCoeff()) {
      return ldlt.solve(b);
    }
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(N, Eigen::ComputeThinU | Eigen::ComputeThinV);
  svd.setThreshold(o.svd_relative_threshold);
  return svd.solve(b);
}

/// Grid search of one position against fixed anchors with ranges (robust cost).
Vec2 GridInit(std::vector<Vec2> anchors, std::vector<double> ranges, std::vector<double> sigmas,
              const StopAndGoOptions& o) {
  if (o.init_max_anchors > 0 && anchors.size() > static_cast<std::size_t>(o.init_max_anchors)) {
    const std::size_t n = anchors.size(), m = static_cast<std::size_t>(o.init_max_anchors);
    std::vector<Vec2> a;
    std::vector<double> r, s;
    for (std::size_t k = 0; k < m; ++k) {
      const std::size_t i = k * (n - 1) / (m - 1 > 0 ? m - 1 : 1);
      a.push_back(anchors[i]);
      r.push_back(ranges[i]);
      s.push_back(sigmas[i]);
    }
    anchors = std::move(a), ranges = std::move(r), sigmas = std::move(s);
  }
  // The grid lies in the anchors' own frame — their centroid and principal axes, the major axis
  // pointing from the first anchor toward the last — so the same anchors drawn rotated or
  // shifted give the same grid and the same start (issue 21, item 2: an axis-aligned grid
  // started landmarks in another local minimum of the robust cost, up to 3 m apart, when the
  // building was rotated).
  Vec2 centroid = Vec2::Zero();
  for (const Vec2& a : anchors) centroid += a;
  centroid /= static_cast<double>(anchors.size());
  Mat2 spread = Mat2::Zero();
  for (const Vec2& a : anchors) spread += (a - centroid) * (a - centroid).transpose();
  const double theta = 0.5 * std::atan2(2 * spread(0, 1), spread(0, 0) - spread(1, 1));
  Vec2 e1(std::cos(theta), std::sin(theta));
  if ((anchors.back() - anchors.front()).dot(e1) < 0) e1 = -e1;
  const Vec2 e2(-e1.y(), e1.x());
  auto local = [&](const Vec2& p) { return Vec2((p - centroid).dot(e1), (p - centroid).dot(e2)); };
  Vec2 lo = local(anchors.front()), hi = lo;
  double reach = 0;
  for (std::size_t k = 0; k < anchors.size(); ++k) {
    lo = lo.cwiseMin(local(anchors[k]));
    hi = hi.cwiseMax(local(anchors[k]));
    reach = std::max(reach, ranges[k]);
  }
  lo.array() -= reach + o.init_margin_m;
  hi.array() += reach + o.init_margin_m;
  const double step = std::max(o.init_grid_m, (hi - lo).maxCoeff() / 400.0);
  Vec2 best = centroid + 0.5 * (lo.x() + hi.x()) * e1 + 0.5 * (lo.y() + hi.y()) * e2;
  double best_cost = std::numeric_limits<double>::infinity();
  for (double u = lo.x(); u <= hi.x(); u += step) {
    for (double v = lo.y(); v <= hi.y(); v += step) {
      const Vec2 p = centroid + u * e1 + v * e2;
      double c = 0;
      for (std::size_t k = 0; k < anchors.size(); ++k) {
        c += Rho(((p - anchors[k]).norm() - ranges[k]) / sigmas[k], o.loss, o.robust_k);
      }
      if (c < best_cost) best_cost = c, best = p;
    }
  }
  return best;
}

}  // namespace

bool SolvableStopAndGo(int landmarks, int standing_positions) {
  if (landmarks <= 2) return false;
  return standing_positions * (landmarks - 2) >= 2 * landmarks;  // eq. (8) without division
}

StopAndGoResult SolveStopAndGo(StopAndGoProblem problem, const StopAndGoOptions& o) {
  StopAndGoResult result;
  const int B = static_cast<int>(problem.landmarks.size());
  const int q = static_cast<int>(problem.standing.size());
  problem.landmark_known.resize(B, false);
  problem.landmark_start_given.resize(B, false);
  problem.standing_known.resize(q, false);
  problem.range_m.resize(q);
  problem.sigma_m.resize(q);
  for (int p = 0; p < q; ++p) {
    problem.range_m[p].resize(B);
    problem.sigma_m[p].resize(B, 1.0);
  }
  problem.landmark_prior_sigma_m.resize(B, 0.0);
  int unknown_s = 0, unknown_h = 0, measurements = 0, landmark_priors = 0;
  for (int j = 0; j < B; ++j) unknown_s += !problem.landmark_known[j];
  for (int p = 0; p < q; ++p) unknown_h += !problem.standing_known[p];
  for (int p = 0; p < q; ++p) {
    for (int j = 0; j < B; ++j) measurements += problem.range_m[p][j].has_value();
  }
  for (int j = 0; j < B; ++j) {
    landmark_priors += !problem.landmark_known[j] && problem.landmark_prior_sigma_m[j] > 0;
  }
  const bool standing_prior = problem.standing_prior_information.size() > 0;
  if (standing_prior && (problem.standing_prior_information.rows() != 2 * unknown_h ||
                         problem.standing_prior_information.cols() != 2 * unknown_h)) {
    throw std::invalid_argument(fmt::format(
        "SolveStopAndGo: the standing prior's information is {}x{}, the unknown standing "
        "positions need {}x{}",
        problem.standing_prior_information.rows(), problem.standing_prior_information.cols(),
        2 * unknown_h, 2 * unknown_h));
  }
  // Priors are measurements too, and fix the frame.
  const bool calibrate = problem.range_calibration.has_value();
  if (calibrate && !(problem.range_calibration->log_scale_sigma > 0 &&
                     problem.range_calibration->exponent_ratio_sigma > 0)) {
    throw std::invalid_argument("SolveStopAndGo: the range calibration's sigmas must be > 0");
  }
  measurements += (standing_prior ? 2 * unknown_h : 0) + 2 * landmark_priors + (calibrate ? 2 : 0);
  // Nothing known: rigid-motion freedom.
  const bool gauge = unknown_s == B && unknown_h == q && !standing_prior && landmark_priors == 0;
  const int params = 2 * (unknown_s + unknown_h) - (gauge ? 3 : 0) + (calibrate ? 2 : 0);
  if (gauge && !SolvableStopAndGo(B, q)) {
    result.solvable = false;
    result.notes.push_back(fmt::format(
        "eq. (8) not met: {} standing positions for {} landmarks, need q >= 2B/(B-2) = {:.2f}", q, B,
        B > 2 ? 2.0 * B / (B - 2) : std::numeric_limits<double>::infinity()));
  }
  if (measurements < params) {
    result.solvable = false;
    result.notes.push_back(fmt::format("{} ranges for {} unknowns", measurements, params));
  }
  if (gauge) result.notes.push_back("no known position: the solution is defined up to a rigid motion");

  // Degenerate geometry: landmarks seen only from collinear standing positions (and vice versa)
  // have a mirror solution.
  const auto [minor_h, major_h] = Spread(problem.standing);
  const auto [minor_s, major_s] = Spread(problem.landmarks);
  if (unknown_s > 0 && minor_h < std::max(0.2, 0.05 * major_h)) {
    result.degenerate = true;
    result.notes.push_back(fmt::format(
        "standing positions nearly collinear (spread {:.2f} m across): each landmark has a mirror "
        "solution across their line",
        minor_h));
  }
  if (unknown_h > 0 && unknown_s == 0 && minor_s < std::max(0.2, 0.05 * major_s)) {
    result.degenerate = true;
    result.notes.push_back("known landmarks nearly collinear: handheld positions have a mirror");
  }

  // With the range calibration and landmarks to grid-search (ours): the calibration first,
  // from the landmarks that have priors alone, so that the grid searches read corrected ranges
  // (ranges 2x too long place a landmark in another basin).
  double grid_a = 0, grid_b = 1;
  if (calibrate) {
    bool anchored = false, searched = false;
    for (int j = 0; j < B; ++j) {
      if (problem.landmark_known[j]) continue;
      anchored = anchored || problem.landmark_prior_sigma_m[j] > 0;
      searched =
          searched || (problem.landmark_prior_sigma_m[j] <= 0 && !problem.landmark_start_given[j]);
    }
    if (anchored && searched) {
      StopAndGoProblem stage = problem;
      for (int j = 0; j < B; ++j) {
        if (stage.landmark_known[j] || stage.landmark_prior_sigma_m[j] > 0) continue;
        stage.landmark_known[j] = true;
        for (int p = 0; p < q; ++p) stage.range_m[p][j].reset();
      }
      const StopAndGoResult first = SolveStopAndGo(std::move(stage), o);
      if (std::isfinite(first.range_log_scale) && first.range_exponent_ratio > 0.1) {
        grid_a = first.range_log_scale;
        grid_b = first.range_exponent_ratio;
      }
    }
  }
  // Initialization: unknown landmarks by grid search against the standing positions, then
  // unknown standing positions against the landmarks.
  for (int j = 0; j < B; ++j) {
    if (problem.landmark_known[j]) continue;
    std::vector<Vec2> anchors;
    std::vector<double> r, s;
    for (int p = 0; p < q; ++p) {
      if (problem.range_m[p][j]) {
        anchors.push_back(problem.standing[p]);
        // z = e^a d^b read back as d (identity without a calibration).
        const double z = *problem.range_m[p][j];
        const double d = std::exp((std::log(std::max(z, kMinLogDistanceM)) - grid_a) / grid_b);
        r.push_back(calibrate ? d : z);
        s.push_back(calibrate ? problem.sigma_m[p][j] * d / (grid_b * std::max(z, 1e-6))
                              : problem.sigma_m[p][j]);
      }
    }
    const bool prior = problem.landmark_prior_sigma_m[j] > 0;
    if (anchors.size() < 3 && !prior) {
      result.solvable = false;
      result.notes.push_back(fmt::format("landmark {} heard from {} standing positions (< 3)", j,
                                         anchors.size()));
    }
    if (!anchors.empty() && !problem.landmark_start_given[j] && !prior)
      problem.landmarks[j] = GridInit(anchors, r, s, o);
  }
  for (int p = 0; p < q && !standing_prior; ++p) {
    if (problem.standing_known[p]) continue;
    std::vector<Vec2> anchors;
    std::vector<double> r, s;
    for (int j = 0; j < B; ++j) {
      if (problem.range_m[p][j]) {
        anchors.push_back(problem.landmarks[j]);
        r.push_back(*problem.range_m[p][j]);
        s.push_back(problem.sigma_m[p][j]);
      }
    }
    if (anchors.size() < 3) {
      result.solvable = false;
      result.notes.push_back(fmt::format("standing position {} hears {} landmarks (< 3)", p, anchors.size()));
    }
    if (!anchors.empty()) problem.standing[p] = GridInit(anchors, r, s, o);
  }

  Problem pr{problem, o, std::vector<int>(B, -1), std::vector<int>(q, -1), 0};
  for (int j = 0; j < B; ++j) {
    if (!problem.landmark_known[j]) pr.col_s[j] = pr.n, pr.n += 2;
  }
  pr.h0 = pr.n;
  for (int p = 0; p < q; ++p) {
    if (!problem.standing_known[p]) pr.col_h[p] = pr.n, pr.n += 2;
  }
  if (calibrate) pr.col_cal = pr.n, pr.n += 2;
  if (standing_prior) {
    pr.h_mean.resize(2 * unknown_h);
    for (int p = 0; p < q; ++p) {
      if (pr.col_h[p] >= 0) pr.h_mean.segment<2>(pr.col_h[p] - pr.h0) = problem.standing[p];
    }
  }
  Eigen::VectorXd u(pr.n);
  for (int j = 0; j < B; ++j) {
    if (pr.col_s[j] >= 0) u.segment<2>(pr.col_s[j]) = problem.landmarks[j];
  }
  for (int p = 0; p < q; ++p) {
    if (pr.col_h[p] >= 0) u.segment<2>(pr.col_h[p]) = problem.standing[p];
  }
  if (calibrate) u.segment<2>(pr.col_cal) = Vec2(0.0, 1.0);
  if (pr.n > 0) {
    Eigen::VectorXd g;
    Eigen::MatrixXd N;
    // Gradient descent with an adaptive step (eq. 16) until the cost is steady. Not with a
    // standing prior (ours): its mean is a start Gauss-Newton takes from, and the prior's
    // information made the descent's steps halve for hundreds of iterations.
    double cost = pr.Cost(u), lambda = o.gd_initial_step;
    while (!standing_prior && result.gd_iterations < o.max_gd_iterations) {
      ++result.gd_iterations;
      pr.Linearize(u, &g, &N);
      Eigen::VectorXd trial = u - lambda * g;
      double c = pr.Cost(trial);
      int halvings = 0;
      while (c > cost && halvings++ < 30) {
        lambda *= 0.5;
        trial = u - lambda * g;
        c = pr.Cost(trial);
      }
      if (c > cost) break;
      const double change = (cost - c) / std::max(cost, 1e-12);
      u = trial;
      cost = c;
      lambda *= 1.2;
      if (change < o.steady_relative_change) break;
    }
    // Gauss-Newton with an SVD pseudo-inverse (eq. 17), step halving as a safeguard.
    while (result.gn_iterations < o.max_gn_iterations) {
      ++result.gn_iterations;
      pr.Linearize(u, &g, &N);
      Eigen::VectorXd step = -SolveNormal(N, g, standing_prior, o);
      double c = pr.Cost(u + step);
      int halvings = 0;
      while (c > cost && halvings++ < 20) {
        step *= 0.5;
        c = pr.Cost(u + step);
      }
      if (c > cost) break;
      u += step;
      cost = c;
      if (step.norm() < o.gn_tolerance_m) break;
    }
    result.cost = cost;
  }
  result.dof = measurements - params;
  result.landmark_cov.assign(B, Mat2::Zero());
  result.standing_cov.assign(q, Mat2::Zero());
  if (pr.n > 0) {
    Eigen::VectorXd g;
    Eigen::MatrixXd N;
    pr.Linearize(u, &g, &N);
    const Eigen::MatrixXd cov =
        SolveNormal(N, Eigen::MatrixXd::Identity(pr.n, pr.n), standing_prior, o);
    const double dof = std::max(1.0, static_cast<double>(measurements - params));
    const double scale = std::max(1.0, 2.0 * result.cost / dof);
    for (int j = 0; j < B; ++j) {
      if (pr.col_s[j] >= 0) result.landmark_cov[j] = scale * cov.block<2, 2>(pr.col_s[j], pr.col_s[j]);
    }
    for (int p = 0; p < q; ++p) {
      if (pr.col_h[p] >= 0) result.standing_cov[p] = scale * cov.block<2, 2>(pr.col_h[p], pr.col_h[p]);
    }
    if (calibrate) {
      result.range_log_scale = u(pr.col_cal);
      result.range_exponent_ratio = u(pr.col_cal + 1);
      result.range_log_scale_sigma = std::sqrt(scale * cov(pr.col_cal, pr.col_cal));
      result.range_exponent_ratio_sigma = std::sqrt(scale * cov(pr.col_cal + 1, pr.col_cal + 1));
    }
    if (standing_prior) {
      const Eigen::Index m = pr.h_mean.size();
      result.standing_joint_cov = scale * cov.block(pr.h0, pr.h0, m, m);
      result.standing_joint_cov =
          0.5 * (result.standing_joint_cov + result.standing_joint_cov.transpose());
    }
  }
  result.landmarks = problem.landmarks;
  result.standing = problem.standing;
  for (int j = 0; j < B; ++j) result.landmarks[j] = pr.S(u, j);
  for (int p = 0; p < q; ++p) result.standing[p] = pr.H(u, p);
  pr.Cost(u, &result.rms_residual_m);
  return result;
}

}  // namespace trailmark::landmarks

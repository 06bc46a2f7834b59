// SPDX-License-Identifier: MIT
#include "trailmark/beacons/map_least_squares.h"

#include <ceres/ceres.h>
#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <cmath>
#include <memory>
#include <numeric>
#include <stdexcept>

#include "trailmark/integrity/consistency.h"

namespace trailmark::beacons {

bool MapLeastSquaresOptions::IsValid(std::string* why) const {
  if (!(link_huber_sigma > 0) || !(sighting_tukey_sigma > 0) || max_iterations < 1 ||
      !(false_alarm > 0 && false_alarm < 1) || newton_iterations < 0 ||
      !(newton_step_tolerance > 0) || !std::isfinite(newton_step_tolerance) ||
      !(newton_gradient_tolerance >= 0) || !std::isfinite(newton_gradient_tolerance)) {
    if (why)
      *why =
          "link_huber_sigma > 0, sighting_tukey_sigma > 0, max_iterations >= 1, 0 < false_alarm < "
          "1, newton_iterations >= 0, newton_step_tolerance > 0, newton_gradient_tolerance >= 0";
    return false;
  }
  return true;
}

namespace {

// A fixed-size matrix into Ceres' row-major Jacobian block.
template <int R, int C>
void WriteRowMajor(const Eigen::Matrix<double, R, C>& m, double* out) {
  using RowMajor = Eigen::Matrix<double, R, C, (C > 1 ? Eigen::RowMajor : Eigen::ColMajor)>;
  Eigen::Map<RowMajor> block(out);
  block = m;
}

// (|p_i - p_j| - range) / sigma, analytic Jacobians (u / sigma, -u / sigma).
class LinkCost final : public ceres::SizedCostFunction<1, 2, 2> {
 public:
  LinkCost(double range_m, double sigma_m) : range_m_(range_m), inv_sigma_(1.0 / sigma_m) {}
  bool Evaluate(double const* const* x, double* residual, double** jacobians) const override {
    const double dx = x[0][0] - x[1][0], dy = x[0][1] - x[1][1];
    const double d = std::sqrt(dx * dx + dy * dy);
    residual[0] = (d - range_m_) * inv_sigma_;
    if (jacobians) {
      // At coincident points the direction is undefined: any unit vector is a subgradient.
      const double ux = d > 1e-12 ? dx / d : 1.0, uy = d > 1e-12 ? dy / d : 0.0;
      if (jacobians[0]) jacobians[0][0] = ux * inv_sigma_, jacobians[0][1] = uy * inv_sigma_;
      if (jacobians[1]) jacobians[1][0] = -ux * inv_sigma_, jacobians[1][1] = -uy * inv_sigma_;
    }
    return true;
  }

 private:
  double range_m_, inv_sigma_;
};

// (k |p_i - p_j| - range) / sigma: a link timed at a speed of sound off by k (ours, issue 21);
// Jacobians (k u / sigma, -k u / sigma, |p_i - p_j| / sigma).
class ScaledLinkCost final : public ceres::SizedCostFunction<1, 2, 2, 1> {
 public:
  ScaledLinkCost(double range_m, double sigma_m) : range_m_(range_m), inv_sigma_(1.0 / sigma_m) {}
  bool Evaluate(double const* const* x, double* residual, double** jacobians) const override {
    const double dx = x[0][0] - x[1][0], dy = x[0][1] - x[1][1];
    const double d = std::sqrt(dx * dx + dy * dy), k = x[2][0];
    residual[0] = (k * d - range_m_) * inv_sigma_;
    if (jacobians) {
      const double ux = d > 1e-12 ? dx / d : 1.0, uy = d > 1e-12 ? dy / d : 0.0;
      const double g = k * inv_sigma_;
      if (jacobians[0]) jacobians[0][0] = ux * g, jacobians[0][1] = uy * g;
      if (jacobians[1]) jacobians[1][0] = -ux * g, jacobians[1][1] = -uy * g;
      if (jacobians[2]) jacobians[2][0] = d * inv_sigma_;
    }
    return true;
  }

 private:
  double range_m_, inv_sigma_;
};

// (k - 1) / sigma: the range scale's prior.
class ScalePriorCost final : public ceres::SizedCostFunction<1, 1> {
 public:
  explicit ScalePriorCost(double sigma) : inv_sigma_(1.0 / sigma) {}
  bool Evaluate(double const* const* x, double* residual, double** jacobians) const override {
    residual[0] = (x[0][0] - 1.0) * inv_sigma_;
    if (jacobians && jacobians[0]) jacobians[0][0] = inv_sigma_;
    return true;
  }

 private:
  double inv_sigma_;
};

// W (p - mu), W = L^-1 with L L^T = cov: the whitened prior.
class PriorCost final : public ceres::SizedCostFunction<2, 2> {
 public:
  PriorCost(const Vec2& mu, const Mat2& cov) : mu_(mu) {
    const Eigen::LLT<Mat2> llt(cov);
    w_ = llt.matrixL().solve(Mat2::Identity());
  }
  bool Evaluate(double const* const* x, double* residual, double** jacobians) const override {
    const Vec2 r = w_ * (Vec2(x[0][0], x[0][1]) - mu_);
    residual[0] = r.x(), residual[1] = r.y();
    if (jacobians && jacobians[0]) WriteRowMajor(w_, jacobians[0]);
    return true;
  }

 private:
  Vec2 mu_;
  Mat2 w_;
};

// W (p - mu - A e): a drop prior correlated with the others of its track through e.
class TrackPriorCost final : public ceres::SizedCostFunction<2, 2, kTrackErrors> {
 public:
  TrackPriorCost(const Vec2& mu, const Mat2& cov, const TrackLever& along) : mu_(mu) {
    const Eigen::LLT<Mat2> llt(cov);
    w_ = llt.matrixL().solve(Mat2::Identity());
    wa_ = w_ * along;
  }
  bool Evaluate(double const* const* x, double* residual, double** jacobians) const override {
    const Eigen::Map<const TrackVec> e(x[1]);
    const Vec2 r = w_ * (Vec2(x[0][0], x[0][1]) - mu_) - wa_ * e;
    residual[0] = r.x(), residual[1] = r.y();
    if (jacobians) {
      if (jacobians[0]) WriteRowMajor(w_, jacobians[0]);
      if (jacobians[1]) WriteRowMajor(TrackLever(-wa_), jacobians[1]);
    }
    return true;
  }

 private:
  Vec2 mu_;
  Mat2 w_;
  TrackLever wa_;
};

// W ((p_i - p_j) - (mu_i - mu_j) - (A_i - A_j) e): a displacement between two drops of a track.
class RelativeTrackPriorCost final : public ceres::SizedCostFunction<2, 2, 2, kTrackErrors> {
 public:
  RelativeTrackPriorCost(const Vec2& delta, const Mat2& cov, const TrackLever& along)
      : delta_(delta) {
    const Eigen::LLT<Mat2> llt(cov);
    w_ = llt.matrixL().solve(Mat2::Identity());
    wa_ = w_ * along;
  }
  bool Evaluate(double const* const* x, double* residual, double** jacobians) const override {
    const Eigen::Map<const TrackVec> e(x[2]);
    const Vec2 d(x[0][0] - x[1][0], x[0][1] - x[1][1]);
    const Vec2 r = w_ * (d - delta_) - wa_ * e;
    residual[0] = r.x(), residual[1] = r.y();
    if (jacobians) {
      if (jacobians[0]) WriteRowMajor(w_, jacobians[0]);
      if (jacobians[1]) WriteRowMajor(Mat2(-w_), jacobians[1]);
      if (jacobians[2]) WriteRowMajor(TrackLever(-wa_), jacobians[2]);
    }
    return true;
  }

 private:
  Vec2 delta_;
  Mat2 w_;
  TrackLever wa_;
};

// W e: the prior of a track's shared errors (zero mean).
class TrackCost final : public ceres::SizedCostFunction<kTrackErrors, kTrackErrors> {
 public:
  explicit TrackCost(const TrackCov& cov) {
    const Eigen::LLT<TrackCov> llt(cov);
    w_ = llt.matrixL().solve(TrackCov::Identity());
  }
  bool Evaluate(double const* const* x, double* residual, double** jacobians) const override {
    const TrackVec r = w_ * Eigen::Map<const TrackVec>(x[0]);
    for (int k = 0; k < kTrackErrors; ++k) residual[k] = r[k];
    if (jacobians && jacobians[0]) WriteRowMajor(w_, jacobians[0]);
    return true;
  }

 private:
  TrackCov w_;
};

// W [p - mu - A e; h]: a chain of sightings' first state, [x, y, h].
class SightingStartCost final : public ceres::SizedCostFunction<3, 3, kTrackErrors> {
 public:
  SightingStartCost(const Vec2& mu, const Mat3& cov, const TrackLever& along) : mu_(mu) {
    const Eigen::LLT<Mat3> llt(cov);
    w_ = llt.matrixL().solve(Mat3::Identity());
    wa_ = -w_.leftCols<2>() * along;
  }
  bool Evaluate(double const* const* x, double* residual, double** jacobians) const override {
    const Eigen::Map<const Vec3> s(x[0]);
    const Eigen::Map<const TrackVec> e(x[1]);
    const Vec3 r = w_ * Vec3(s.x() - mu_.x(), s.y() - mu_.y(), s.z()) + wa_ * e;
    for (int k = 0; k < 3; ++k) residual[k] = r[k];
    if (jacobians) {
      if (jacobians[0]) WriteRowMajor(w_, jacobians[0]);
      if (jacobians[1]) WriteRowMajor(wa_, jacobians[1]);
    }
    return true;
  }

 private:
  Vec2 mu_;
  Mat3 w_;
  Eigen::Matrix<double, 3, kTrackErrors> wa_;
};

// W [p - p_A - R(phi) D - C e; h - h_A], phi = h_A + g e: a sighting after the previous one of
// its track. The heading error there (the walk's h_A and the part g e of the shared errors'
// lever dA that turns D: offset, rate x time, turn scale) rotates the dead reckoning's D; C e is
// the rest of dA e (the step scale, turns within). `rotate` false: the first-order form
// D + phi perp(D) with g = 0, C = dA (6 % too long at a heading error of 0.35 rad, which a
// two-minute trace reaches).
class SightingChainCost final : public ceres::SizedCostFunction<3, 3, 3, kTrackErrors> {
 public:
  SightingChainCost(const Vec2& d, const Mat3& cov, const TrackLever& d_along, bool rotate)
      : d_(d), rotate_(rotate) {
    const Eigen::LLT<Mat3> llt(cov);
    w_ = llt.matrixL().solve(Mat3::Identity());
    const Vec2 perp(-d.y(), d.x());
    g_.setZero();
    if (rotate && d.squaredNorm() > 1e-12) g_ = perp.transpose() * d_along / d.squaredNorm();
    c_ = d_along - perp * g_;
  }
  bool Evaluate(double const* const* x, double* residual, double** jacobians) const override {
    const Eigen::Map<const Vec3> b(x[0]), a(x[1]);
    const Eigen::Map<const TrackVec> e(x[2]);
    const double phi = a.z() + (g_ * e).value();
    Vec2 rd, drd;  // R(phi) D and its derivative in phi
    if (rotate_) {
      rd = Eigen::Rotation2Dd(phi) * d_;
      drd = Vec2(-rd.y(), rd.x());
    } else {
      drd = Vec2(-d_.y(), d_.x());
      rd = d_ + a.z() * drd;
    }
    const Vec2 p = b.head<2>() - a.head<2>() - rd - c_ * e;
    const Vec3 r = w_ * Vec3(p.x(), p.y(), b.z() - a.z());
    for (int k = 0; k < 3; ++k) residual[k] = r[k];
    if (jacobians) {
      if (jacobians[0]) WriteRowMajor(w_, jacobians[0]);
      if (jacobians[1]) {
        Mat3 ja = -Mat3::Identity();
        ja.block<2, 1>(0, 2) = -drd;
        WriteRowMajor(Mat3(w_ * ja), jacobians[1]);
      }
      if (jacobians[2]) {
        Eigen::Matrix<double, 3, kTrackErrors> je = Eigen::Matrix<double, 3, kTrackErrors>::Zero();
        je.topRows<2>() = -drd * g_ - c_;
        WriteRowMajor(Eigen::Matrix<double, 3, kTrackErrors>(w_ * je), jacobians[2]);
      }
    }
    return true;
  }

  // r^T d2r/dphi2 at x: the residual along the curvature of the turned displacement (d2/dphi2
  // of -R(phi) D is R(phi) D), the factor of this cost's exact-Hessian term (.) v v^T, v =
  // dphi / d(h_A, e) = [1, g]. Zero in the first-order form (linear in phi).
  double PhiCurvature(double const* const* x) const {
    if (!rotate_) return 0.0;
    Vec3 r;
    Evaluate(x, r.data(), nullptr);
    const double phi = x[1][2] + (g_ * Eigen::Map<const TrackVec>(x[2])).value();
    return r.dot(w_.leftCols<2>() * (Eigen::Rotation2Dd(phi) * d_));
  }
  const Eigen::Matrix<double, 1, kTrackErrors>& g() const { return g_; }

 private:
  Vec2 d_;
  bool rotate_;
  Mat3 w_;
  Eigen::Matrix<double, 1, kTrackErrors> g_;
  TrackLever c_;
};

// A chained sighting's displacement prior (sighting k has a previous one).
std::unique_ptr<SightingChainCost> ChainCost(const MapProblem& problem, std::size_t k,
                                             const MapLeastSquaresOptions& options) {
  const MapSighting& q = problem.sightings[k];
  const MapSighting& a = problem.sightings[q.from_sighting];
  return std::make_unique<SightingChainCost>(q.position_n - a.position_n,
                                             Mat3(0.5 * (q.cov + q.cov.transpose())),
                                             q.along - a.along, options.sighting_chain_rotation);
}

// The prior of sighting k: its chain's displacement from the previous one, or the chain's start
// (its parameter blocks: the state, the previous state when chained, its track's e).
std::unique_ptr<ceres::CostFunction> SightingPriorCost(const MapProblem& problem, std::size_t k,
                                                       const MapLeastSquaresOptions& options) {
  const MapSighting& q = problem.sightings[k];
  if (q.from_sighting >= 0) return ChainCost(problem, k, options);
  Mat3 cov = 0.5 * (q.cov + q.cov.transpose());
  if (!options.sighting_start_marginal)
    return std::make_unique<SightingStartCost>(q.position_n, cov, q.along);
  Eigen::Matrix<double, 3, kTrackErrors> j;
  j << q.along, q.heading_along.transpose();
  const TrackCov& e_cov = problem.tracks[q.track].cov;
  cov += j * (0.5 * (e_cov + e_cov.transpose())) * j.transpose();
  return std::make_unique<SightingStartCost>(q.position_n, cov, TrackLever::Zero());
}

// (|p - b| - range) / sigma for a sighting's state [x, y, h] and its beacon.
class SightingRangeCost final : public ceres::SizedCostFunction<1, 3, 2> {
 public:
  SightingRangeCost(double range_m, double sigma_m) : link_(range_m, sigma_m) {}
  bool Evaluate(double const* const* x, double* residual, double** jacobians) const override {
    double j0[2], j1[2];
    double* jac[2] = {j0, j1};
    link_.Evaluate(x, residual, jacobians ? jac : nullptr);
    if (jacobians) {
      if (jacobians[0]) jacobians[0][0] = j0[0], jacobians[0][1] = j0[1], jacobians[0][2] = 0;
      if (jacobians[1]) jacobians[1][0] = j1[0], jacobians[1][1] = j1[1];
    }
    return true;
  }

 private:
  LinkCost link_;
};

void Check(const MapProblem& p) {
  if (!std::isfinite(p.range_scale_sigma) || p.range_scale_sigma < 0)
    throw std::invalid_argument(fmt::format(
        "beacon map: range_scale_sigma {} (need finite and >= 0)", p.range_scale_sigma));
  const auto index_ok = [&](int i) { return i >= 0 && i < p.beacons; };
  for (std::size_t k = 0; k < p.links.size(); ++k) {
    const MapLink& l = p.links[k];
    if (!index_ok(l.i) || !index_ok(l.j) || l.i == l.j)
      throw std::invalid_argument(fmt::format("beacon map: link {} joins {} and {} (of {} beacons)",
                                              k, l.i, l.j, p.beacons));
    if (!std::isfinite(l.range_m) || l.range_m < 0 || !(l.sigma_m > 0) || !std::isfinite(l.sigma_m))
      throw std::invalid_argument(fmt::format(
          "beacon map: link {} has range {} m, sigma {} m (need a finite range >= 0, sigma > 0)", k,
          l.range_m, l.sigma_m));
  }
  for (std::size_t k = 0; k < p.priors.size(); ++k) {
    const MapPrior& q = p.priors[k];
    if (!index_ok(q.i))
      throw std::invalid_argument(fmt::format("beacon map: prior {} on beacon {} (of {})", k, q.i,
                                              p.beacons));
    const Eigen::LLT<Mat2> llt(0.5 * (q.cov + q.cov.transpose()));
    if (!q.position_n.allFinite() || !q.cov.allFinite() || !q.along.allFinite() ||
        llt.info() != Eigen::Success ||
        std::abs(q.cov(0, 1) - q.cov(1, 0)) > 1e-9 * (1 + q.cov.norm()))
      throw std::invalid_argument(fmt::format(
          "beacon map: prior {} on beacon {} is not finite or not symmetric positive definite", k,
          q.i));
    if (q.from != -1 && (q.track < 0 || !index_ok(q.from) || q.from == q.i ||
                         !q.from_position_n.allFinite() || !q.from_along.allFinite()))
      throw std::invalid_argument(fmt::format(
          "beacon map: prior {} on beacon {} is relative to {} (needs a track and another beacon)",
          k, q.i, q.from));
    if (q.track < -1 || q.track >= static_cast<int>(p.tracks.size()))
      throw std::invalid_argument(fmt::format("beacon map: prior {} on track {} (of {})", k,
                                              q.track, p.tracks.size()));
  }
  for (std::size_t k = 0; k < p.sightings.size(); ++k) {
    const MapSighting& q = p.sightings[k];
    const Eigen::LLT<Mat3> llt(0.5 * (q.cov + q.cov.transpose()));
    if (!index_ok(q.i) || q.track < 0 || q.track >= static_cast<int>(p.tracks.size()) ||
        q.from_sighting < -1 || q.from_sighting >= static_cast<int>(k) ||
        (q.from_sighting >= 0 && p.sightings[q.from_sighting].track != q.track))
      throw std::invalid_argument(fmt::format(
          "beacon map: sighting {} of beacon {} on track {} after sighting {} (of {} beacons, {} "
          "tracks; it follows an earlier sighting of its own track)",
          k, q.i, q.track, q.from_sighting, p.beacons, p.tracks.size()));
    if (!std::isfinite(q.range_m) || q.range_m < 0 || !(q.sigma_m > 0) ||
        !std::isfinite(q.sigma_m) || !q.position_n.allFinite() || !q.along.allFinite() ||
        !q.heading_along.allFinite() || !q.cov.allFinite() || llt.info() != Eigen::Success ||
        !q.cov.isApprox(q.cov.transpose(), 1e-9))
      throw std::invalid_argument(fmt::format(
          "beacon map: sighting {} of beacon {} is not finite, has a sigma <= 0 or a covariance "
          "that is not symmetric positive definite",
          k, q.i));
  }
  for (std::size_t k = 0; k < p.tracks.size(); ++k) {
    const TrackCov& c = p.tracks[k].cov;
    if (!c.allFinite() || !c.isApprox(c.transpose(), 1e-9) ||
        Eigen::LLT<TrackCov>(c).info() != Eigen::Success || p.tracks[k].dof < 0 ||
        p.tracks[k].dof > kTrackErrors)
      throw std::invalid_argument(
          fmt::format("beacon map: track {} covariance is not symmetric positive definite", k));
  }
}

// Whether the problem has a range scale among its unknowns (the last of x).
bool HasRangeScale(const MapProblem& problem) {
  if (!(problem.range_scale_sigma > 0)) return false;
  for (const MapLink& l : problem.links)
    if (l.scaled) return true;
  return false;
}

std::size_t Unknowns(const MapProblem& problem) {
  return 2 * problem.beacons + kTrackErrors * problem.tracks.size() + 3 * problem.sightings.size() +
         (HasRangeScale(problem) ? 1 : 0);
}

// The problem's residual blocks on x (2 per beacon, then 4 per track, then 3 per sighting, then
// the range scale when there is one).
void Build(const MapProblem& problem, const MapLeastSquaresOptions& options,
           std::vector<double>& x, ceres::Problem& p) {
  const int n = problem.beacons;
  for (int i = 0; i < n; ++i) p.AddParameterBlock(&x[2 * i], 2);
  double* tracks = x.data() + 2 * n;
  for (std::size_t k = 0; k < problem.tracks.size(); ++k) {
    p.AddParameterBlock(tracks + kTrackErrors * k, kTrackErrors);
    p.AddResidualBlock(new TrackCost(problem.tracks[k].cov), nullptr, tracks + kTrackErrors * k);
  }
  double* scale = HasRangeScale(problem) ? &x.back() : nullptr;
  if (scale) {
    p.AddParameterBlock(scale, 1);
    p.AddResidualBlock(new ScalePriorCost(problem.range_scale_sigma), nullptr, scale);
  }
  for (const MapLink& l : problem.links) {
    if (scale && l.scaled) {
      p.AddResidualBlock(new ScaledLinkCost(l.range_m, l.sigma_m),
                         new ceres::HuberLoss(options.link_huber_sigma), &x[2 * l.i], &x[2 * l.j],
                         scale);
    } else {
      p.AddResidualBlock(new LinkCost(l.range_m, l.sigma_m),
                         new ceres::HuberLoss(options.link_huber_sigma), &x[2 * l.i], &x[2 * l.j]);
    }
  }
  for (const MapPrior& q : problem.priors) {
    const Mat2 cov = 0.5 * (q.cov + q.cov.transpose());
    if (q.track >= 0 && q.from >= 0)
      p.AddResidualBlock(
          new RelativeTrackPriorCost(q.position_n - q.from_position_n, cov, q.along - q.from_along),
          nullptr, &x[2 * q.i], &x[2 * q.from], tracks + kTrackErrors * q.track);
    else if (q.track >= 0)
      p.AddResidualBlock(new TrackPriorCost(q.position_n, cov, q.along), nullptr, &x[2 * q.i],
                         tracks + kTrackErrors * q.track);
    else
      p.AddResidualBlock(new PriorCost(q.position_n, cov), nullptr, &x[2 * q.i]);
  }
  double* sightings = tracks + kTrackErrors * problem.tracks.size();
  for (std::size_t k = 0; k < problem.sightings.size(); ++k) {
    const MapSighting& q = problem.sightings[k];
    double* state = sightings + 3 * k;
    double* e = tracks + kTrackErrors * q.track;
    p.AddParameterBlock(state, 3);
    if (q.from_sighting >= 0)
      p.AddResidualBlock(SightingPriorCost(problem, k, options).release(), nullptr, state,
                         sightings + 3 * q.from_sighting, e);
    else
      p.AddResidualBlock(SightingPriorCost(problem, k, options).release(), nullptr, state, e);
    p.AddResidualBlock(new SightingRangeCost(q.range_m, q.sigma_m),
                       new ceres::TukeyLoss(options.sighting_tukey_sigma), state, &x[2 * q.i]);
  }
}

// Tukey's biweight as Ceres writes it (rho(s) for s the squared residual, bound c): the
// sightings' range cost at a solution.
double TukeyRho(double s, double c) {
  const double c2 = c * c;
  if (s > c2) return c2 / 3.0;
  const double v = 1.0 - s / c2;
  return c2 / 3.0 * (1.0 - v * v * v);
}

// The same by ceres::Covariance (SPARSE_QR): the reference of the tests.
bool ReferenceMarginalCovariances(ceres::Problem& p, std::vector<double>& x, int beacons,
                                  std::vector<Mat2>* cov, double* scale, double* scale_var) {
  ceres::Covariance::Options co;
  co.algorithm_type = ceres::SPARSE_QR;
  co.num_threads = 1;
  ceres::Covariance covariance(co);
  std::vector<std::pair<const double*, const double*>> blocks;
  for (int i = 0; i < beacons; ++i) blocks.emplace_back(&x[2 * i], &x[2 * i]);
  if (scale) blocks.emplace_back(scale, scale);
  if (!covariance.Compute(blocks, &p)) return false;
  if (scale) covariance.GetCovarianceBlock(scale, scale, scale_var);
  cov->resize(beacons);
  for (int i = 0; i < beacons; ++i) {
    double c[4];
    covariance.GetCovarianceBlock(&x[2 * i], &x[2 * i], c);
    Mat2 m;
    m << c[0], c[1], c[2], c[3];
    (*cov)[i] = 0.5 * (m + m.transpose());
  }
  return true;
}

// The 2 x 2 marginal covariance of each beacon from the information at the solution (J^T J
// with the robust loss applied, as ceres::Covariance does; or the exact Hessian) over x's
// unknowns in x's order, factored as P (J^T J) P^T = L D L^T (sparse,
// AMD ordering), then the entries of its inverse Z on the pattern of L by the Takahashi
// recurrence (Takahashi, Fagan & Chen 1973; Erisman & Tinney 1975): from the last column back,
// Z_ji = -sum_k L_ki Z_kj over k in column i's pattern, Z_ii = 1/d_i - sum_k L_ki Z_ki. Every
// Z_kj it needs lies on the pattern (column i's rows form a clique of the filled graph), and
// each beacon's 2 x 2 block does too (its two parameters share residuals). ceres::Covariance
// (SPARSE_QR) gives the same to round-off (tested) but took ~0.9 s at 1,000 beacons and 20,000
// links. False when the information is not positive definite (to round-off).
// `scalar_column` >= 0: that parameter's variance too, in *scalar_var.
bool MarginalCovariances(const Eigen::SparseMatrix<double>& information, int beacons,
                         std::vector<Mat2>* cov, int scalar_column = -1,
                         double* scalar_var = nullptr) {
  using Sparse = Eigen::SparseMatrix<double>;
  const Eigen::SimplicialLDLT<Sparse, Eigen::Lower, Eigen::AMDOrdering<int>> ldlt(information);
  if (ldlt.info() != Eigen::Success) return false;
  const Eigen::VectorXd d = ldlt.vectorD();
  // Singular to round-off (a pivot 1e-12 of the largest diagonal entry, or below): no
  // covariance (a variance of 1e60 m^2 is not one).
  if (!(d.minCoeff() > 1e-12 * information.diagonal().cwiseAbs().maxCoeff())) return false;
  // L: unit lower triangular, strictly lower part stored by column, rows ascending.
  const Sparse& L = ldlt.matrixL().nestedExpression();
  const int* outer = L.outerIndexPtr();
  const int* rows = L.innerIndexPtr();
  const double* values = L.valuePtr();
  const int n = static_cast<int>(L.cols());
  std::vector<double> z(static_cast<std::size_t>(L.nonZeros()), 0.0), z_diag(n, 0.0);
  // Z at (r, c), r > c, on the pattern of L (the blocks' entries at the end only).
  const auto at = [&](int r, int c) -> double {
    if (r == c) return z_diag[r];
    if (r < c) std::swap(r, c);
    const int* first = rows + outer[c];
    const int* last = rows + outer[c + 1];
    const int* it = std::lower_bound(first, last, r);
    return it != last && *it == r ? z[it - rows] : 0.0;
  };
  // Column i's sums s_j = sum_k L_ki Z_kj (j, k in column i's pattern P) in one pass over the
  // columns j of P, each already complete: an entry Z_rj of column j (r > j) adds L_ri Z_rj to
  // s_j and, by symmetry, L_ji Z_rj to s_r, both counted only where r is in P too (`mark`); the
  // diagonal adds L_ji Z_jj. So every Z_kj is read in place, once per column i, without a
  // search: the work is the factor's own order (sum over P of its columns' lengths).
  std::vector<double> l_col(n, 0.0), s(n, 0.0);
  std::vector<int> mark(n, -1);
  for (int i = n - 1; i >= 0; --i) {
    const int begin = outer[i], end = outer[i + 1];
    for (int b = begin; b < end; ++b) {
      l_col[rows[b]] = values[b];
      s[rows[b]] = 0.0;
      mark[rows[b]] = i;
    }
    for (int b = begin; b < end; ++b) {
      const int j = rows[b];
      const double l_j = values[b];
      double s_j = l_j * z_diag[j];
      for (int e = outer[j]; e < outer[j + 1]; ++e) {
        const int r = rows[e];
        if (mark[r] != i) continue;
        s_j += l_col[r] * z[e];
        s[r] += l_j * z[e];
      }
      s[j] += s_j;
    }
    double diag = 1.0 / d(i);
    for (int b = begin; b < end; ++b) {
      z[b] = -s[rows[b]];
      diag -= values[b] * z[b];
    }
    z_diag[i] = diag;
  }
  // Back to the parameters' order: parameter a is row P(a) of the factored matrix.
  const auto& perm = ldlt.permutationP().indices();
  cov->assign(beacons, Mat2::Zero());
  for (int i = 0; i < beacons; ++i) {
    const int u = perm(2 * i), v = perm(2 * i + 1);
    Mat2 c;
    c << at(u, u), at(u, v), at(v, u), at(v, v);
    (*cov)[i] = c;
    if (!c.allFinite()) return false;
  }
  if (scalar_column >= 0) {
    const int u = perm(scalar_column);
    *scalar_var = at(u, u);
    if (!std::isfinite(*scalar_var)) return false;
  }
  return true;
}

// x's parameter blocks in x's order (beacons, tracks' e, sightings' states, the range scale):
// a column of the Jacobian Ceres evaluates on them is the same index of x.
std::vector<double*> BlocksInOrder(const MapProblem& problem, std::vector<double>& x) {
  const int n = problem.beacons;
  std::vector<double*> blocks;
  for (int i = 0; i < n; ++i) blocks.push_back(&x[2 * i]);
  for (std::size_t k = 0; k < problem.tracks.size(); ++k)
    blocks.push_back(&x[2 * n + kTrackErrors * k]);
  for (std::size_t k = 0; k < problem.sightings.size(); ++k)
    blocks.push_back(&x[2 * n + kTrackErrors * problem.tracks.size() + 3 * k]);
  if (HasRangeScale(problem)) blocks.push_back(&x.back());
  return blocks;
}

// Evaluation of the problem over x's blocks in x's order, the robust losses applied (the cost,
// gradient and Jacobian the solver and the marginals see).
ceres::Problem::EvaluateOptions InOrder(const MapProblem& problem, std::vector<double>& x) {
  ceres::Problem::EvaluateOptions eo;
  eo.parameter_blocks = BlocksInOrder(problem, x);
  eo.apply_loss_function = true;
  eo.num_threads = 1;
  return eo;
}

using Triplets = std::vector<Eigen::Triplet<double>>;

// The part of a robust range residual's exact Hessian that Gauss-Newton leaves out (ours).
// For the cost rho(s) / 2, s = r^2, r = (k |p_a - p_b| - range) / sigma, the Hessian is
// rho' (dr dr^T + r d2r) + 2 rho'' s dr dr^T. Ceres' J^T J holds rho' dr dr^T: its corrector
// adds the rho'' term only where rho'' > 0, and Huber's and Tukey's rho'' are <= 0 everywhere.
// So added here: rho' r d2r, whose blocks are M = k (I - u u^T) / (d sigma) at (a, a) and
// (b, b), -M at (a, b), and u / sigma, -u / sigma between p_a, p_b and k; and 2 rho'' s dr dr^T,
// dr = (k u, -k u, d) / sigma. `ik` < 0: k is 1, not an unknown.
void AddRangeCurvature(const ceres::LossFunction& loss, const double* pa, const double* pb, int ia,
                       int ib, double k, int ik, double range_m, double sigma_m, Triplets& t) {
  const Vec2 dp(pa[0] - pb[0], pa[1] - pb[1]);
  const double d = dp.norm();
  if (!(d > 1e-12)) return;  // coincident: no direction (the Jacobian's subgradient holds)
  const Vec2 u = dp / d;
  const double r = (k * d - range_m) / sigma_m, s = r * r;
  double rho[3];
  loss.Evaluate(s, rho);
  const std::pair<int, double> dr[5] = {{ia, k * u.x() / sigma_m},
                                        {ia + 1, k * u.y() / sigma_m},
                                        {ib, -k * u.x() / sigma_m},
                                        {ib + 1, -k * u.y() / sigma_m},
                                        {ik, d / sigma_m}};
  const int m = ik >= 0 ? 5 : 4;
  const double c = 2 * rho[2] * s;
  if (c != 0)
    for (int a = 0; a < m; ++a)
      for (int b = 0; b < m; ++b)
        t.emplace_back(dr[a].first, dr[b].first, c * dr[a].second * dr[b].second);
  const Mat2 M = rho[1] * r * k / (d * sigma_m) * (Mat2::Identity() - u * u.transpose());
  for (int a = 0; a < 2; ++a)
    for (int b = 0; b < 2; ++b) {
      t.emplace_back(ia + a, ia + b, M(a, b));
      t.emplace_back(ib + a, ib + b, M(a, b));
      t.emplace_back(ia + a, ib + b, -M(a, b));
      t.emplace_back(ib + a, ia + b, -M(a, b));
    }
  if (ik >= 0) {
    const Vec2 g = rho[1] * r * u / sigma_m;
    for (int a = 0; a < 2; ++a) {
      t.emplace_back(ia + a, ik, g(a));
      t.emplace_back(ik, ia + a, g(a));
      t.emplace_back(ib + a, ik, -g(a));
      t.emplace_back(ik, ib + a, -g(a));
    }
  }
}

// Every term of the exact Hessian at x that J^T J leaves out: the links' and sightings' ranges,
// and each chained sighting's turn of its displacement, (r^T d2r/dphi2) v v^T over (h_A, e).
// The priors are linear in x.
void AddCurvature(const MapProblem& problem, const MapLeastSquaresOptions& options,
                  const std::vector<double>& x, Triplets& t) {
  const int n = problem.beacons;
  const bool scaled = HasRangeScale(problem);
  const int scale = static_cast<int>(x.size()) - 1;
  const ceres::HuberLoss huber(options.link_huber_sigma);
  for (const MapLink& l : problem.links) {
    const bool k = scaled && l.scaled;
    AddRangeCurvature(huber, &x[2 * l.i], &x[2 * l.j], 2 * l.i, 2 * l.j, k ? x.back() : 1.0,
                      k ? scale : -1, l.range_m, l.sigma_m, t);
  }
  const ceres::TukeyLoss tukey(options.sighting_tukey_sigma);
  const int states = 2 * n + kTrackErrors * static_cast<int>(problem.tracks.size());
  for (std::size_t k = 0; k < problem.sightings.size(); ++k) {
    const MapSighting& q = problem.sightings[k];
    const int at = states + 3 * static_cast<int>(k);
    AddRangeCurvature(tukey, &x[at], &x[2 * q.i], at, 2 * q.i, 1.0, -1, q.range_m, q.sigma_m, t);
    if (q.from_sighting < 0) continue;
    const std::unique_ptr<SightingChainCost> chain = ChainCost(problem, k, options);
    const int from = states + 3 * q.from_sighting;
    const int e = 2 * n + kTrackErrors * q.track;
    const double* blocks[3] = {&x[at], &x[from], &x[e]};
    const double c = chain->PhiCurvature(blocks);
    if (c == 0) continue;
    std::pair<int, double> v[1 + kTrackErrors] = {{from + 2, 1.0}};
    for (int j = 0; j < kTrackErrors; ++j) v[1 + j] = {e + j, chain->g()(j)};
    for (const auto& [ia, va] : v)
      for (const auto& [ib, vb] : v) t.emplace_back(ia, ib, c * va * vb);
  }
}

using Sparse = Eigen::SparseMatrix<double>;

// J^T J of the Jacobian Ceres evaluated (loss-corrected), the Gauss-Newton Hessian.
Sparse GaussNewtonHessian(const ceres::CRSMatrix& crs) {
  const Eigen::Map<const Eigen::SparseMatrix<double, Eigen::RowMajor>> J(
      crs.num_rows, crs.num_cols, static_cast<Eigen::Index>(crs.values.size()), crs.rows.data(),
      crs.cols.data(), crs.values.data());
  return Sparse(J.transpose()) * Sparse(J);
}

// The exact Hessian at x: J^T J plus AddCurvature's terms.
Sparse ExactHessian(const Sparse& jtj, const MapProblem& problem,
                    const MapLeastSquaresOptions& options, const std::vector<double>& x) {
  Triplets t;
  AddCurvature(problem, options, x, t);
  Sparse curvature(jtj.rows(), jtj.cols());
  curvature.setFromTriplets(t.begin(), t.end());
  return jtj + curvature;
}

// The damping's scale per unknown: J^T J's diagonal, averaged over each position's x and y (a
// beacon's, a sighting's), so that damped steps turn with the frame (the diagonal alone would
// not, and a damped step that crosses a ridge between two minima, e.g. a beacon's mirror
// images across its two neighbours, would choose by the frame).
Eigen::VectorXd IsotropicDiagonal(const Sparse& jtj, const MapProblem& problem) {
  Eigen::VectorXd d = jtj.diagonal();
  const auto pair = [&](int a) { d(a) = d(a + 1) = 0.5 * (d(a) + d(a + 1)); };
  for (int i = 0; i < problem.beacons; ++i) pair(2 * i);
  const int states = 2 * problem.beacons + kTrackErrors * static_cast<int>(problem.tracks.size());
  for (std::size_t k = 0; k < problem.sightings.size(); ++k) pair(states + 3 * static_cast<int>(k));
  return d.cwiseMax(1e-12);
}

// Newton's method on the exact Hessian H = J^T J + AddCurvature from x, where Ceres stopped
// (MapLeastSquaresOptions::newton_iterations). Each step solves (H + lambda diag(J^T J)) dx =
// -g (diag averaged over each position's x and y: IsotropicDiagonal) with lambda 0, raised
// tenfold from 1e-6 while the matrix is not positive definite or the
// step does not lower the cost; it ends when a step moves no unknown by more than the
// tolerance or leaves no |gradient| above its tolerance, or after `iterations` (0: the cost and
// gradient at x only). Returns the steps
// taken; x is where they end, *cost its cost, *max_gradient the largest |gradient| there.
int PolishByNewton(ceres::Problem& p, const MapProblem& problem,
                   const MapLeastSquaresOptions& options, int iterations, std::vector<double>& x,
                   double* cost, double* max_gradient) {
  const ceres::Problem::EvaluateOptions eo = InOrder(problem, x);
  std::vector<double> gradient, tried_gradient;
  ceres::CRSMatrix crs, tried_crs;
  *max_gradient = 0;
  if (!p.Evaluate(eo, cost, nullptr, &gradient, iterations > 0 ? &crs : nullptr)) return 0;
  const int unknowns = static_cast<int>(x.size());
  const auto largest = [&](const std::vector<double>& v) {
    return Eigen::Map<const Eigen::VectorXd>(v.data(), unknowns).lpNorm<Eigen::Infinity>();
  };
  if (largest(gradient) <= options.newton_gradient_tolerance) iterations = 0;
  int steps = 0;
  Eigen::SimplicialLDLT<Sparse, Eigen::Lower, Eigen::AMDOrdering<int>> ldlt;
  for (int it = 0; it < iterations; ++it) {
    const Sparse jtj = GaussNewtonHessian(crs);
    const Sparse hessian = ExactHessian(jtj, problem, options, x);
    const Eigen::VectorXd diag = IsotropicDiagonal(jtj, problem);
    const Eigen::Map<const Eigen::VectorXd> g(gradient.data(), unknowns);
    const std::vector<double> before = x;
    bool moved = false, done = false;
    for (double lambda = 0; lambda <= 1e6; lambda = lambda > 0 ? 10 * lambda : 1e-6) {
      Sparse a = hessian;
      if (lambda > 0) a += Sparse(Eigen::VectorXd(lambda * diag).asDiagonal());
      ldlt.compute(a);
      if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > 0)) continue;
      const Eigen::VectorXd dx = -ldlt.solve(g);
      if (!dx.allFinite()) continue;
      const double step = dx.lpNorm<Eigen::Infinity>();
      for (int i = 0; i < unknowns; ++i) x[i] = before[i] + dx(i);
      // The next step's Jacobian with the trial's cost: one evaluation where a step is taken.
      double tried = HUGE_VAL;
      if (!p.Evaluate(eo, &tried, nullptr, &tried_gradient, &tried_crs) || !std::isfinite(tried))
        tried = HUGE_VAL;
      // Where the cost's change is below its round-off, a step that lowers the gradient is
      // taken (a minimum at a robust loss's kink, where the Hessian is the exact one on one
      // side only, is reached that way).
      const bool lower =
          tried < *cost ||
          (tried <= *cost + 1e-13 * std::abs(*cost) &&
           Eigen::Map<const Eigen::VectorXd>(tried_gradient.data(), unknowns).squaredNorm() <
               g.squaredNorm());
      if (lower) {
        *cost = tried;
        moved = true;
        done = step <= options.newton_step_tolerance ||
               largest(tried_gradient) <= options.newton_gradient_tolerance;
        break;
      }
      x = before;
      // A step of a micrometre that lowers neither the cost nor the gradient: round-off.
      if (step <= std::max(options.newton_step_tolerance, 1e-6)) {
        done = true;
        break;
      }
    }
    if (!moved) break;
    ++steps;
    gradient.swap(tried_gradient);
    std::swap(crs, tried_crs);
    if (done) break;
  }
  *max_gradient = largest(gradient);
  return steps;
}

// True when every connected part of the link graph holds two beacons with priors (or is one
// beacon with a prior): the problem's gauge (translation, rotation) is fixed.
bool Anchored(const MapProblem& p, std::string* why) {
  std::vector<int> parent(p.beacons);
  std::iota(parent.begin(), parent.end(), 0);
  const auto find = [&](int i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  };
  for (const MapLink& l : p.links) parent[find(l.i)] = find(l.j);
  for (const MapPrior& q : p.priors)
    if (q.from >= 0) parent[find(q.i)] = find(q.from);
  std::vector<int> size(p.beacons, 0), with_prior(p.beacons, 0);
  std::vector<bool> has_prior(p.beacons, false);
  for (const MapPrior& q : p.priors) has_prior[q.i] = true;
  for (int i = 0; i < p.beacons; ++i) {
    ++size[find(i)];
    with_prior[find(i)] += has_prior[i];
  }
  for (int r = 0; r < p.beacons; ++r) {
    if (size[r] == 0) continue;
    if (with_prior[r] >= 2 || (size[r] == 1 && with_prior[r] == 1)) continue;
    if (why)
      *why = fmt::format("not anchored: {} beacon(s) linked to beacon {} with {} prior(s) (need 2)",
                         size[r], r, with_prior[r]);
    return false;
  }
  return true;
}

}  // namespace

MapSolution SolveMapLeastSquares(const MapProblem& problem,
                                 const std::vector<std::vector<Vec2>>& starts,
                                 const MapLeastSquaresOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) throw std::invalid_argument("beacon map: " + why);
  Check(problem);
  if (starts.empty()) throw std::invalid_argument("beacon map: no start");
  if (!problem.track_start.empty() && problem.track_start.size() != problem.tracks.size())
    throw std::invalid_argument("beacon map: track starts for not every track");
  for (const TrackVec& e : problem.track_start)
    if (!e.allFinite()) throw std::invalid_argument("beacon map: a track start is not finite");
  for (const MapSighting& q : problem.sightings)
    if (q.start && !q.start->allFinite())
      throw std::invalid_argument("beacon map: a sighting's start is not finite");
  for (const auto& s : starts) {
    if (static_cast<int>(s.size()) != problem.beacons)
      throw std::invalid_argument(fmt::format("beacon map: a start of {} positions for {} beacons",
                                              s.size(), problem.beacons));
    for (const Vec2& p : s)
      if (!p.allFinite()) throw std::invalid_argument("beacon map: a start is not finite");
  }
  MapSolution best;
  if (!Anchored(problem, &best.why)) return best;
  const int n = problem.beacons;
  const int residuals = static_cast<int>(problem.links.size() + 2 * problem.priors.size());
  best.dof = residuals - 2 * n;  // the tracks' 3 residuals and 3 unknowns cancel

  double best_cost = std::numeric_limits<double>::infinity();
  std::vector<double> x;
  for (std::size_t s = 0; s < starts.size(); ++s) {
    std::vector<double> xs(Unknowns(problem), 0.0);
    if (HasRangeScale(problem)) xs.back() = 1.0;
    for (int i = 0; i < n; ++i) xs[2 * i] = starts[s][i].x(), xs[2 * i + 1] = starts[s][i].y();
    // Each sighting starts where its chain's previous one is plus the dead reckoning's step
    // between them, a chain's first at its dead reckoning; no white heading error.
    for (std::size_t k = 0; k < problem.track_start.size(); ++k)
      Eigen::Map<TrackVec>(xs.data() + 2 * n + kTrackErrors * k) = problem.track_start[k];
    double* states = xs.data() + 2 * n + kTrackErrors * problem.tracks.size();
    for (std::size_t k = 0; k < problem.sightings.size(); ++k) {
      const MapSighting& q = problem.sightings[k];
      Vec3 at(q.position_n.x(), q.position_n.y(), 0);
      if (q.start) {
        at = *q.start;
      } else if (q.from_sighting >= 0) {
        at.head<2>() = Vec2(states[3 * q.from_sighting], states[3 * q.from_sighting + 1]) +
                       (q.position_n - problem.sightings[q.from_sighting].position_n);
        at.z() = states[3 * q.from_sighting + 2];
      }
      Eigen::Map<Vec3>(states + 3 * k) = at;
    }
    ceres::Problem p;
    Build(problem, options, xs, p);
    ceres::Solver::Options so;
    so.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
    so.max_num_iterations = options.max_iterations;
    so.num_threads = 1;
    // The map must not depend on the frame: converged to round-off (not Ceres' 1e-6 defaults),
    // which Newton's steps finish where Gauss-Newton crawls to the cap. Ceres' path is kept as
    // it was: where a beacon has two mirror images of equal cost (linked to two beacons, no
    // prior yet), which one it reaches depends on the path, and Ceres' path (its diagonal
    // scaling) is not the same in a turned frame; stopped earlier (at Ceres' default
    // tolerances, or at 15 iterations) a turned beacon trail chose the other image
    // (docs/beacons.md).
    so.function_tolerance = 1e-14;
    so.gradient_tolerance = 1e-14;
    so.parameter_tolerance = 1e-12;
    so.logging_type = ceres::SILENT;
    so.minimizer_progress_to_stdout = false;
    ceres::Solver::Summary summary;
    ceres::Solve(so, &p, &summary);
    const double chi2 = 2 * summary.final_cost;
    best.start_chi2.push_back(chi2);
    if (!summary.IsSolutionUsable() || !std::isfinite(chi2)) continue;
    if (chi2 < best_cost) {
      best_cost = chi2;
      best.start = static_cast<int>(s);
      best.iterations = static_cast<int>(summary.iterations.size());
      x = std::move(xs);
    }
  }
  if (x.empty()) {
    best.why = "the solver found no usable solution from any start";
    return best;
  }
  // The problem rebuilt around x (the solvers' copies are gone): Newton's steps from the start
  // that won (the starts are told apart by Ceres' costs: two that reach one minimum give one
  // map; two minima differ by more than Ceres' crawl), then the marginals.
  ceres::Problem at_x;
  Build(problem, options, x, at_x);
  if (options.newton_iterations > 0) {
    double cost = 0;
    best.newton_iterations = PolishByNewton(at_x, problem, options, options.newton_iterations, x,
                                            &cost, &best.max_gradient);
    if (std::isfinite(cost)) best_cost = best.start_chi2[best.start] = 2 * cost;
  }
  best.chi2 = best_cost;
  best.position_n.resize(n);
  for (int i = 0; i < n; ++i) best.position_n[i] = Vec2(x[2 * i], x[2 * i + 1]);
  for (std::size_t k = 0; k < problem.tracks.size(); ++k)
    best.track_errors.push_back(Eigen::Map<const TrackVec>(x.data() + 2 * n + kTrackErrors * k));
  // The two parts of chi2: links (Huber rho of the squared whitened residual) and priors.
  const bool scaled = HasRangeScale(problem);
  if (scaled) best.range_scale = x.back();
  const double d2 = options.link_huber_sigma * options.link_huber_sigma;
  for (const MapLink& l : problem.links) {
    const double k = scaled && l.scaled ? best.range_scale : 1.0;
    const double r =
        (k * (best.position_n[l.i] - best.position_n[l.j]).norm() - l.range_m) / l.sigma_m;
    const double r2 = r * r;
    best.chi2_links += r2 <= d2 ? r2 : 2 * options.link_huber_sigma * std::abs(r) - d2;
  }
  // The sightings' part: each one's robust range cost and its prior (start or chain), by the
  // same cost functions the solver saw.
  double* states = x.data() + 2 * n + kTrackErrors * problem.tracks.size();
  const double c2 = options.sighting_tukey_sigma * options.sighting_tukey_sigma;
  for (std::size_t k = 0; k < problem.sightings.size(); ++k) {
    const MapSighting& q = problem.sightings[k];
    double* state = states + 3 * k;
    double* e = x.data() + 2 * n + kTrackErrors * q.track;
    best.sighting_state.push_back(Eigen::Map<const Vec3>(state));
    double r = 0;
    const double* range_blocks[2] = {state, &x[2 * q.i]};
    SightingRangeCost(q.range_m, q.sigma_m).Evaluate(range_blocks, &r, nullptr);
    best.chi2_sightings += TukeyRho(r * r, options.sighting_tukey_sigma);
    best.sighting_outliers += r * r > c2;
    Vec3 u;
    const double* blocks[3] = {state, q.from_sighting >= 0 ? states + 3 * q.from_sighting : e, e};
    SightingPriorCost(problem, k, options)->Evaluate(blocks, u.data(), nullptr);
    best.chi2_sightings += u.squaredNorm();
  }
  // The range scale's prior is counted with the priors (its residual and unknown cancel in dof).
  best.chi2_priors = best.chi2 - best.chi2_links - best.chi2_sightings;
  best.prior_residuals = static_cast<int>(2 * problem.priors.size());
  for (const MapTrack& t : problem.tracks) best.prior_residuals += t.dof;
  if (best.dof > 0) {
    best.chi2_threshold = integrity::ChiSquareQuantile(best.dof, 1 - options.false_alarm);
    best.consistent = best.chi2 - best.chi2_sightings <= best.chi2_threshold;
  }
  if (options.covariances) {
    bool ok = false;
    if (options.reference_covariance) {
      ok = ReferenceMarginalCovariances(at_x, x, n, &best.cov, scaled ? &x.back() : nullptr,
                                        &best.range_scale_var);
    } else {
      ceres::CRSMatrix crs;
      const int scale = scaled ? static_cast<int>(x.size()) - 1 : -1;
      if (at_x.Evaluate(InOrder(problem, x), nullptr, nullptr, nullptr, &crs)) {
        const Sparse information = GaussNewtonHessian(crs);
        ok = MarginalCovariances(information, n, &best.cov, scale, &best.range_scale_var);
        // Converged exactly onto a point where J^T J is singular — a beacon on the line
        // through its two linked neighbours, where its ranges cannot form a triangle: the
        // Gauss-Newton information has nothing across that line, but the cost's curvature
        // there (the exact Hessian, positive definite at a strict minimum) does: the Laplace
        // approximation at the minimum. (Gauss-Newton, crawling towards that line, stopped
        // short of it with a variance of 1e5 m^2 across it.)
        best.exact_hessian_covariance =
            !ok && options.newton_iterations > 0 &&
            MarginalCovariances(ExactHessian(information, problem, options, x), n, &best.cov, scale,
                                &best.range_scale_var);
        ok = ok || best.exact_hessian_covariance;
      }
    }
    if (!ok) {
      best.cov.clear();
      best.why = "the map's covariance is rank deficient";
      return best;
    }
  }
  best.ok = true;
  return best;
}

namespace {

// The cost (and the loss-corrected Jacobian when `crs`) of `problem` at x, checked.
double EvaluateAt(const MapProblem& problem, const MapLeastSquaresOptions& options,
                  std::vector<double>& x, ceres::CRSMatrix* crs) {
  Check(problem);
  if (x.size() != Unknowns(problem))
    throw std::invalid_argument(
        fmt::format("beacon map: {} unknowns given for {}", x.size(), Unknowns(problem)));
  ceres::Problem p;
  Build(problem, options, x, p);
  double cost = 0;
  p.Evaluate(InOrder(problem, x), &cost, nullptr, nullptr, crs);
  return cost;
}

}  // namespace

double MapCost(const MapProblem& problem, const MapLeastSquaresOptions& options,
               std::vector<double> x) {
  return EvaluateAt(problem, options, x, nullptr);
}

Eigen::MatrixXd MapCostHessian(const MapProblem& problem, const MapLeastSquaresOptions& options,
                               std::vector<double> x) {
  ceres::CRSMatrix crs;
  EvaluateAt(problem, options, x, &crs);
  return Eigen::MatrixXd(ExactHessian(GaussNewtonHessian(crs), problem, options, x));
}

}  // namespace trailmark::beacons

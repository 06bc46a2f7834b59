// SPDX-License-Identifier: MIT
#include "trailmark/landmarks/landmark_tracker.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <limits>
#include <cmath>
#include <stdexcept>

namespace trailmark::landmarks {

namespace {
/// A bias state whose landmark has not been heard over this many correlation lengths is
/// marginalized out (its correlation with the rest has decayed below exp(-5) < 1 %).
constexpr double kStaleLengths = 5.0;
constexpr double kLn10 = 2.302585092994046;
/// The radio noise check: an exponential average over about 100 packets, used from 50 on.
constexpr double kNoiseEmaWeight = 0.01;
constexpr std::size_t kNoiseWarmPackets = 50;
}  // namespace

bool LandmarkTrackerOptions::IsValid(std::string* why) const {
  if (!pdr.IsValid(why)) return false;
  if (!(noise_scale_max >= 1) || !std::isfinite(noise_scale_max)) {
    if (why) *why = "landmark tracker: noise_scale_max must be finite and >= 1";
    return false;
  }
  if (slam_max_packets < slam_min_packets || slam_grid_packets < 3 || !(slam_min_width_m >= 0) || !(slam_ambiguity_m > 0) || !(slam_decisive_chi2 >= 0) ||
      slam_min_packets < 2 || !(slam_min_spread_m >= 0) || !(slam_search_margin_m >= 0) ||
      !(slam_grid_m > 0)) {
    if (why) *why = "landmark tracker: slam_min_packets >= 2, spread and margin >= 0, grid > 0";
    return false;
  }
  if (!(pdr.turn_scale_sigma > 0) || !(pdr.turn_min_step_m > 0)) {
    if (why)
      *why = "landmark tracker: the turn-scale sigma and the turn's minimum step must be > 0";
    return false;
  }
  for (double v :
       {given_alpha_sigma_db, given_exponent_sigma, default_alpha_sigma_db, default_exponent_sigma,
        default_sigma_db, shadowing_length_m, shadowing_time_s, min_distance_m, huber_k, gate_sigma,
        calibrated_alpha_sigma_db, calibrated_exponent_sigma}) {
    if (!(v > 0) || !std::isfinite(v)) {
      if (why) *why = "landmark tracker: sigmas, lengths, times, huber_k and gate must be finite and > 0";
      return false;
    }
  }
  if (!std::isfinite(default_alpha_dbm) || !std::isfinite(handheld_height_m) ||
      !(default_exponent >= min_exponent && default_exponent <= max_exponent) ||
      !(min_exponent > 0) || !(shadowing_variance_share >= 0 && shadowing_variance_share < 1) ||
      iterations < 1) {
    if (why) {
      *why = "landmark tracker: finite alpha and handheld height, min_exponent <= default_exponent "
             "<= max_exponent, 0 <= shadowing_variance_share < 1, iterations >= 1";
    }
    return false;
  }
  return true;
}

LandmarkTracker::LandmarkTracker(const Vec3& start_n, double start_sigma_m,
                                 std::optional<double> start_heading_sigma_rad,
                                 const std::optional<radio::LogDistanceModel>& radio,
                                 LandmarkTrackerOptions options)
    : options_(std::move(options)) {
  std::string why;
  if (!options_.IsValid(&why)) throw std::invalid_argument(why);
  if (!(start_sigma_m > 0) || !start_n.allFinite()) {
    throw std::invalid_argument("landmark tracker: the start must be finite, its sigma > 0");
  }
  const double sigma_db = radio ? radio->sigma_db : options_.default_sigma_db;
  sigma_shadow_db_ = std::sqrt(options_.shadowing_variance_share) * sigma_db;
  sigma_fast_db_ = std::sqrt(1 - options_.shadowing_variance_share) * sigma_db;
  x_ = Eigen::VectorXd::Zero(kFixed);
  P_ = Eigen::MatrixXd::Zero(kFixed, kFixed);
  x_(kPx) = start_n.x();
  x_(kPy) = start_n.y();
  x_(kAlpha) = radio ? radio->alpha_dbm : options_.default_alpha_dbm;
  x_(kExponent) = std::clamp(radio ? radio->path_loss_exponent : options_.default_exponent,
                             options_.min_exponent, options_.max_exponent);
  // The stated heading alone: the track's own offset is the consider parameter (sens_).
  const double heading = start_heading_sigma_rad.value_or(options_.pdr.start_heading_sigma_rad);
  const double alpha_sigma = radio ? options_.given_alpha_sigma_db : options_.default_alpha_sigma_db;
  const double n_sigma = radio ? options_.given_exponent_sigma : options_.default_exponent_sigma;
  P_(kPx, kPx) = P_(kPy, kPy) = start_sigma_m * start_sigma_m;
  // A heading, rate or scale the prior makes exactly known is still kept invertible.
  P_(kHeading, kHeading) = std::max(heading * heading, 1e-12);
  P_(kRate, kRate) = std::max(std::pow(options_.pdr.heading_drift_sigma_rad_per_s, 2), 1e-16);
  P_(kScale, kScale) = std::max(std::pow(options_.pdr.step_scale_sigma, 2), 1e-12);
  P_(kTurnScale, kTurnScale) = options_.pdr.turn_scale_sigma * options_.pdr.turn_scale_sigma;
  P_(kAlpha, kAlpha) = alpha_sigma * alpha_sigma;
  P_(kExponent, kExponent) = n_sigma * n_sigma;
  sens_ = Eigen::VectorXd::Zero(kFixed);
  sens_(kHeading) = 1.0;
}

Mat2 LandmarkTracker::reported_position_cov() const {
  const double c = options_.pdr.track_heading_offset_sigma_rad;
  const Vec2 s = sens_.head<2>();
  return position_cov() + c * c * s * s.transpose();
}

double LandmarkTracker::alpha_sigma_db() const { return std::sqrt(P_(kAlpha, kAlpha)); }
double LandmarkTracker::exponent_sigma() const { return std::sqrt(P_(kExponent, kExponent)); }

bool LandmarkTracker::RadioMovesPosition() const {
  return moving_ && alpha_sigma_db() <= options_.calibrated_alpha_sigma_db &&
         exponent_sigma() <= options_.calibrated_exponent_sigma;
}

void LandmarkTracker::Symmetrize() {
  // In place (no temporary): each pair once, 0.5 (P_ij + P_ji) as the full form gives.
  const Eigen::Index n = P_.rows();
  for (Eigen::Index j = 0; j < n; ++j) {
    for (Eigen::Index i = 0; i < j; ++i) {
      const double v = 0.5 * (P_(i, j) + P_(j, i));
      P_(i, j) = v;
      P_(j, i) = v;
    }
  }
}

void LandmarkTracker::DecayShadowing(double distance_m, double dt_s) {
  if (extra_kind_.empty()) return;
  // Gauss-Markov: b <- rho b + w, Var(w) = (1 - rho^2) sigma^2 (stationary at sigma^2).
  const double rho = std::exp(-distance_m / options_.shadowing_length_m -
                              dt_s / options_.shadowing_time_s);
  const double q = (1 - rho * rho) * VarShadow();
  const int n = static_cast<int>(x_.size());
  for (int i = kFixed; i < n; ++i) {
    if (extra_kind_[i - kFixed] != 'b') continue;
    x_(i) *= rho;
    sens_(i) *= rho;
    P_.row(i) *= rho;
    P_.col(i) *= rho;
    P_(i, i) += q;
  }
}

void LandmarkTracker::DropStaleBiases() {
  const double stale_m = kStaleLengths * options_.shadowing_length_m;
  bool any = false;
  for (std::size_t e = 0; e < extra_kind_.size() && !any; ++e) {
    any = extra_kind_[e] == 'b' && walked_m_ - extra_walked_m_[e] > stale_m;
  }
  if (!any) return;  // every step: no allocation unless a bias goes
  std::vector<int> keep;
  for (int i = 0; i < kFixed; ++i) keep.push_back(i);
  std::vector<char> kind;
  std::vector<int> landmark;
  std::vector<double> walked;
  for (std::size_t e = 0; e < extra_kind_.size(); ++e) {
    if (extra_kind_[e] == 'b' && walked_m_ - extra_walked_m_[e] > stale_m) continue;
    keep.push_back(kFixed + static_cast<int>(e));
    kind.push_back(extra_kind_[e]);
    landmark.push_back(extra_landmark_[e]);
    walked.push_back(extra_walked_m_[e]);
  }
  // Marginalizing a Gaussian: drop its rows and columns.
  x_ = Eigen::VectorXd(x_(keep));
  sens_ = Eigen::VectorXd(sens_(keep));
  P_ = Eigen::MatrixXd(P_(keep, keep));
  extra_kind_ = std::move(kind);
  extra_landmark_ = std::move(landmark);
  extra_walked_m_ = std::move(walked);
}

int LandmarkTracker::BiasState(int landmark) {
  for (std::size_t e = 0; e < extra_kind_.size(); ++e) {
    if (extra_kind_[e] == 'b' && extra_landmark_[e] == landmark) {
      extra_walked_m_[e] = walked_m_;
      return kFixed + static_cast<int>(e);
    }
  }
  const int n = static_cast<int>(x_.size());
  x_.conservativeResize(n + 1);
  x_(n) = 0;
  sens_.conservativeResize(n + 1);
  sens_(n) = 0;  // a new link's shadowing: independent of the track's heading
  P_.conservativeResize(n + 1, n + 1);
  P_.row(n).setZero();
  P_.col(n).setZero();
  P_(n, n) = std::max(VarShadow(), 1e-6);
  extra_kind_.push_back('b');
  extra_landmark_.push_back(landmark);
  extra_walked_m_.push_back(walked_m_);
  return n;
}

int LandmarkTracker::LandmarkState(int landmark) const {
  for (std::size_t e = 0; e < extra_kind_.size(); ++e) {
    if (extra_kind_[e] == 'x' && extra_landmark_[e] == landmark) return kFixed + static_cast<int>(e);
  }
  return -1;
}

std::optional<std::pair<Vec2, Mat2>> LandmarkTracker::LandmarkEstimate(int landmark) const {
  const int i = LandmarkState(landmark);
  if (i < 0) return std::nullopt;
  return std::make_pair(Vec2(x_.segment<2>(i)), Mat2(P_.block<2, 2>(i, i)));
}

void LandmarkTracker::Propagate(TimeS t) {
  if (!std::isfinite(t)) return;
  if (!t_) {
    t_ = t;
    return;
  }
  const double dt = t - *t_;
  if (!(dt > 0)) return;
  t_ = t;
  // psi += omega dt: F = I + dt e_psi e_omega^T, applied to rows then columns.
  x_(kHeading) += x_(kRate) * dt;
  sens_(kHeading) += dt * sens_(kRate);
  P_.row(kHeading) += dt * P_.row(kRate);
  P_.col(kHeading) += dt * P_.col(kRate);
  DecayShadowing(0.0, dt);
}

bool LandmarkTracker::UseMotionErrors(const PdrOptions& pdr) {
  if (stepped_) return false;
  const std::pair<int, double> sigmas[] = {
      {kRate, std::max(pdr.heading_drift_sigma_rad_per_s, 1e-8)},
      {kScale, std::max(pdr.step_scale_sigma, 1e-6)},
      {kTurnScale, pdr.turn_scale_sigma}};
  for (const auto& [i, sigma] : sigmas) {
    const double old = std::sqrt(P_(i, i));
    if (old > 0) {
      const double r = sigma / old;
      P_.row(i) *= r;
      P_.col(i) *= r;
      x_(i) *= r;
      sens_(i) *= r;
    } else {
      P_(i, i) = sigma * sigma;
    }
  }
  options_.pdr = pdr;
  Symmetrize();
  return true;
}

void LandmarkTracker::AddStep(const Step& step) {
  stepped_ = true;
  Propagate(step.t1);
  const Vec2 d = step.delta_n.head<2>();
  const double len = d.norm();
  if (len >= options_.pdr.turn_min_step_m) {
    // The turn since the last long step: psi += g dtheta.
    const double direction = std::atan2(d.y(), d.x());
    if (direction_rad_) {
      const double turn = std::remainder(direction - *direction_rad_, 2 * M_PI);
      x_(kHeading) += x_(kTurnScale) * turn;
      sens_(kHeading) += turn * sens_(kTurnScale);
      P_.row(kHeading) += turn * P_.row(kTurnScale);
      P_.col(kHeading) += turn * P_.col(kTurnScale);
    }
    direction_rad_ = direction;
  }
  const double c = std::cos(x_(kHeading)), s = std::sin(x_(kHeading));
  const Vec2 rd(c * d.x() - s * d.y(), s * d.x() + c * d.y());
  const double f = 1 + x_(kScale);
  // p += (1 + s) R(psi) d; its Jacobians: d/dpsi = (1 + s) (-rd_y, rd_x), d/ds = rd.
  const double jx_psi = -f * rd.y(), jy_psi = f * rd.x();
  x_.head<2>() += f * rd;
  sens_(kPx) += jx_psi * sens_(kHeading) + rd.x() * sens_(kScale);
  sens_(kPy) += jy_psi * sens_(kHeading) + rd.y() * sens_(kScale);
  {
    const Eigen::RowVectorXd r_psi = P_.row(kHeading), r_s = P_.row(kScale);
    P_.row(kPx) += jx_psi * r_psi + rd.x() * r_s;
    P_.row(kPy) += jy_psi * r_psi + rd.y() * r_s;
    const Eigen::VectorXd c_psi = P_.col(kHeading), c_s = P_.col(kScale);
    P_.col(kPx) += jx_psi * c_psi + rd.x() * c_s;
    P_.col(kPy) += jy_psi * c_psi + rd.y() * c_s;
  }
  if (step.variance_m2) {
    P_(kPx, kPx) += step.variance_m2->x();
    P_(kPy, kPy) += step.variance_m2->y();
  } else {
    const double sd = options_.pdr.default_step_noise_m + options_.pdr.default_step_relative_sigma * len;
    P_(kPx, kPx) += sd * sd;
    P_(kPy, kPy) += sd * sd;
  }
  P_(kHeading, kHeading) += options_.pdr.HeadingWalkVariance(step);
  if (len > 0) moving_ = true;
  walked_m_ += len;
  DecayShadowing(len, 0.0);
  DropStaleBiases();
  Symmetrize();
}

bool LandmarkTracker::UpdateRssi(TimeS t, int landmark, const Vec2& landmark_n,
                                 std::optional<double> landmark_z_m, const Mat2& landmark_cov,
                                 double agent_z_m, double rssi_dbm,
                                 const std::function<bool(double nis)>& admit) {
  last_log_likelihood_ = last_huber_log_likelihood_ = std::numeric_limits<double>::quiet_NaN();
  if (!std::isfinite(rssi_dbm) || !landmark_n.allFinite()) return false;
  Propagate(t);
  const double dz = landmark_z_m ? *landmark_z_m - (agent_z_m + options_.handheld_height_m) : 0.0;
  // A survey's error is one draw shared by every packet of the landmark, not noise per packet:
  // its position is a state from its first packet on, at the survey with the survey's covariance.
  if (options_.survey_error_states && landmark_cov.allFinite() && landmark_cov.trace() > 0) {
    int i = LandmarkState(landmark);
    if (i < 0) i = AddLandmarkStates(landmark, landmark_n, landmark_cov, Vec2::Zero());
    return Update(landmark, x_.segment<2>(i), i, dz, Mat2::Zero(), rssi_dbm, admit);
  }
  return Update(landmark, landmark_n, -1, dz, landmark_cov, rssi_dbm, admit);
}

int LandmarkTracker::AddLandmarkStates(int landmark, const Vec2& position_n, const Mat2& cov,
                                       const Vec2& offset_sensitivity) {
  const int i = static_cast<int>(x_.size());
  x_.conservativeResize(i + 2);
  x_.segment<2>(i) = position_n;
  sens_.conservativeResize(i + 2);
  sens_.segment<2>(i) = offset_sensitivity;
  P_.conservativeResize(i + 2, i + 2);
  P_.bottomRows(2).setZero();
  P_.rightCols(2).setZero();
  P_.block<2, 2>(i, i) = 0.5 * (cov + cov.transpose());
  for (const char k : {'x', 'y'}) {
    extra_kind_.push_back(k);
    extra_landmark_.push_back(landmark);
    extra_walked_m_.push_back(walked_m_);
  }
  return i;
}

bool LandmarkTracker::UpdateRssiUnknown(TimeS t, int landmark, double dz_m, double rssi_dbm,
                                        const std::function<bool(double nis)>& admit) {
  last_log_likelihood_ = last_huber_log_likelihood_ = std::numeric_limits<double>::quiet_NaN();
  if (!std::isfinite(rssi_dbm) || !std::isfinite(dz_m)) return false;
  Propagate(t);
  const int i = LandmarkState(landmark);
  if (i >= 0) return Update(landmark, x_.segment<2>(i), i, dz_m, Mat2::Zero(), rssi_dbm, admit);
  // Not placed yet: kept while the radio moves the position (a position worth fitting from).
  if (!RadioMovesPosition()) return false;
  Unplaced& u = unplaced_[landmark];
  u.heard.push_back({position(), 0.5 * position_cov().trace(), dz_m, rssi_dbm});
  ++u.received;
  // The latest slam_max_packets only (a fit's cost stays bounded).
  if (static_cast<int>(u.heard.size()) > options_.slam_max_packets) u.heard.erase(u.heard.begin());
  // A fit is tried from slam_min_packets on, again each time the packets grew by half.
  if (static_cast<int>(u.received) >= options_.slam_min_packets &&
      static_cast<double>(u.received) >= 1.5 * static_cast<double>(u.tried_at)) {
    u.tried_at = u.received;
    PlaceLandmark(landmark);
  }
  return false;
}

void LandmarkTracker::PlaceLandmark(int landmark) {
  const std::vector<Heard>& heard = unplaced_[landmark].heard;
  const double packets = static_cast<double>(heard.size());
  // Heard from a walk that spans two dimensions: along a straight corridor a landmark and its
  // mirror image across the corridor fit alike.
  // Everything in the positions' own frame (their mean, their principal axes), so that the
  // result does not depend on how the building is drawn (a rotated or shifted frame).
  Vec2 mean = Vec2::Zero();
  for (const Heard& h : heard) mean += h.position / packets;
  Mat2 spread = Mat2::Zero();
  for (const Heard& h : heard) spread += (h.position - mean) * (h.position - mean).transpose() / packets;
  const Eigen::SelfAdjointEigenSolver<Mat2> axes(spread);
  const Mat2 frame = axes.eigenvectors();
  Vec2 lo_f = Vec2::Constant(std::numeric_limits<double>::infinity()), hi_f = -lo_f;
  for (const Heard& h : heard) {
    const Vec2 f = frame.transpose() * (h.position - mean);
    lo_f = lo_f.cwiseMin(f);
    hi_f = hi_f.cwiseMax(f);
  }
  if ((hi_f - lo_f).norm() < options_.slam_min_spread_m ||
      axes.eigenvalues().minCoeff() < options_.slam_min_width_m * options_.slam_min_width_m) {
    return;
  }
  // One independent look per shadowing correlation length walked (the packets share their
  // shadowing there): the packets' information is scaled by looks / packets.
  double path_m = 0;
  for (std::size_t k = 1; k < heard.size(); ++k) {
    path_m += (heard[k].position - heard[k - 1].position).norm();
  }
  const double looks = std::min(packets, 1.0 + path_m / options_.shadowing_length_m);
  const double share = looks / packets;
  // Unknowns: the landmark's position and its link's offset o (its transmit power, mounting and
  // shadowing shared by these packets; prior N(0, sigma_shadow^2)): a common offset scales
  // every distance, and only a walk around the landmark separates it from the position.
  const double alpha = x_(kAlpha), n = x_(kExponent);
  const double var_shadow = std::max(VarShadow(), 1e-6);
  const double var_fast = std::max(VarFast(), 1e-6);
  const double huber = options_.huber_k * std::sqrt(var_fast);
  auto distance = [&](const Heard& h, const Vec2& l) {
    return std::max(std::sqrt((h.position - l).squaredNorm() + h.dz_m * h.dz_m), options_.min_distance_m);
  };
  auto residual = [&](const Heard& h, const Vec2& l, double o) {
    return h.rssi_dbm - (alpha + o - 10 * n * std::log10(distance(h, l)));
  };
  // The grid search sees at most slam_grid_packets of them, evenly spread.
  std::vector<const Heard*> sample;
  const std::size_t every =
      std::max<std::size_t>(1, (heard.size() + options_.slam_grid_packets - 1) / options_.slam_grid_packets);
  for (std::size_t k = 0; k < heard.size(); k += every) sample.push_back(&heard[k]);
  const double sample_share = std::min(looks, static_cast<double>(sample.size())) / sample.size();
  // The sample as arrays: the grid's cost is evaluated a packet vector at a time (Eigen's
  // vectorized log: the grid is most of the tracker's time).
  const Eigen::Index m = static_cast<Eigen::Index>(sample.size());
  Eigen::ArrayXd px(m), py(m), dz2(m), rssi(m);
  for (Eigen::Index k = 0; k < m; ++k) {
    px(k) = sample[k]->position.x();
    py(k) = sample[k]->position.y();
    dz2(k) = sample[k]->dz_m * sample[k]->dz_m;
    rssi(k) = sample[k]->rssi_dbm;
  }
  const double min_d2 = options_.min_distance_m * options_.min_distance_m;
  const double per_log_d2 = 10 * n / (2 * kLn10);  // 10 n log10(d) = per_log_d2 ln(d^2)
  Eigen::ArrayXd r0(m);
  auto cost = [&](const Vec2& l) {  // with the offset at its best given l (shrunk to its prior)
    // eq. (5), radio-landmarks paper: the residual of each packet with no offset.
    r0 = rssi - alpha +
         per_log_d2 * ((px - l.x()).square() + (py - l.y()).square() + dz2).max(min_d2).log();
    const double o = r0.sum() / (static_cast<double>(m) + var_fast / var_shadow);
    const double k_huber = options_.huber_k;
    const Eigen::ArrayXd r = (r0 - o).abs() / std::sqrt(var_fast);
    return o * o / var_shadow +
           (r <= k_huber).select(r.square(), 2 * k_huber * r - k_huber * k_huber).sum();
  };
  // Grid search over the positions' box plus a margin, then Gauss-Newton (IRLS) from the best.
  // The grid: centred on the positions' box in their frame, symmetric (an axis's sign does not
  // change it), the box plus a margin. Coarse to fine: the box at twice slam_grid_m, then
  // slam_grid_m around the coarse grid's best (the grid was 80 % of the tracker's time).
  const Vec2 centre = 0.5 * (lo_f + hi_f);
  const double fine = options_.slam_grid_m, coarse = 2 * fine;
  const int ku = static_cast<int>(
      std::ceil((0.5 * (hi_f.x() - lo_f.x()) + options_.slam_search_margin_m) / coarse));
  const int kv = static_cast<int>(
      std::ceil((0.5 * (hi_f.y() - lo_f.y()) + options_.slam_search_margin_m) / coarse));
  Vec2 best_f = centre;  // in the positions' frame
  double best_cost = std::numeric_limits<double>::infinity();
  std::vector<std::pair<Vec2, double>> grid;
  for (int i = -ku; i <= ku; ++i) {
    for (int j = -kv; j <= kv; ++j) {
      const Vec2 f = centre + coarse * Vec2(i, j);
      const double c = cost(mean + frame * f);
      grid.emplace_back(f, c);  // in the positions' frame
      if (c < best_cost) best_cost = c, best_f = f;
    }
  }
  const Vec2 coarse_best = best_f;
  for (int i = -2; i <= 2; ++i) {
    for (int j = -2; j <= 2; ++j) {
      if (i % 2 == 0 && j % 2 == 0) continue;  // on the coarse grid
      const Vec2 f = coarse_best + fine * Vec2(i, j);
      const double c = cost(mean + frame * f);
      if (c < best_cost) best_cost = c, best_f = f;
    }
  }
  const Vec2 best = mean + frame * best_f;
  // Decisive: every place farther than slam_ambiguity_m fits worse by slam_decisive_chi2 (in
  // independent looks); else wait for more packets (a second basin, or a flat one). A coarse
  // cell within twice that of the best may hide a competitor between the coarse points: its
  // fine neighbours are tested too (the test is then the fine grid's wherever it can matter).
  auto competes = [&](const Vec2& f, double c) {
    return ((mean + frame * f) - best).norm() > options_.slam_ambiguity_m &&
           (c - best_cost) * sample_share < options_.slam_decisive_chi2;
  };
  for (const auto& [f, c] : grid) {
    if (competes(f, c)) return;
    if ((c - best_cost) * sample_share >= 2 * options_.slam_decisive_chi2) continue;
    for (int i = -1; i <= 1; ++i) {
      for (int j = -1; j <= 1; ++j) {
        if (i == 0 && j == 0) continue;
        const Vec2 g = f + fine * Vec2(i, j);
        if (competes(g, cost(mean + frame * g))) return;
      }
    }
  }
  using Vec3d = Eigen::Vector3d;
  using Mat3d = Eigen::Matrix3d;
  Vec3d theta(best.x(), best.y(), 0.0);
  Mat3d info = Mat3d::Zero();
  for (int it = 0; it < 20; ++it) {
    Mat3d A = Mat3d::Zero();
    Vec3d g = Vec3d::Zero();
    info.setZero();
    for (const Heard& h : heard) {
      const Vec2 l = theta.head<2>();
      const Vec2 rel = l - h.position;
      const double d = distance(h, l);
      const double r = residual(h, l, theta(2));
      // d h / d l = -10 n / (ln 10 d^2) (l - p), d h / d o = 1; the position's error adds to
      // the packet's variance through dh/dp = -dh/dl.
      Vec3d J(0, 0, 1);
      if (d > options_.min_distance_m) J.head<2>() = -10 * n / (kLn10 * d * d) * rel;
      const double var = var_fast + J.head<2>().squaredNorm() * h.position_var_m2;
      const double w = std::abs(r) <= huber ? 1.0 : huber / std::abs(r);
      A += w * J * J.transpose() / var;
      g += w * J * r / var;
      info += J * J.transpose() / var;
    }
    A(2, 2) += 1 / var_shadow;
    g(2) -= theta(2) / var_shadow;
    const Vec3d step = A.ldlt().solve(g);
    if (!step.allFinite()) return;
    theta += step;
    if (step.head<2>().norm() < 1e-4) break;
  }
  info *= share;  // the prior on the offset is not scaled
  info(2, 2) += 1 / var_shadow;
  Eigen::SelfAdjointEigenSolver<Mat3d> eig(0.5 * (info + info.transpose()));
  if (eig.info() != Eigen::Success || !(eig.eigenvalues().minCoeff() > 1e-9) || !theta.allFinite()) {
    return;  // not yet observable: wait for more packets
  }
  Mat3d cov = eig.eigenvectors() * eig.eigenvalues().cwiseInverse().asDiagonal() *
              eig.eigenvectors().transpose();
  cov.topLeftCorner<2, 2>() += Mat2::Identity() * (0.5 * position_cov().trace());  // the track's own error
  // The landmark's two states (their covariance set below with the bias's), then its link's
  // bias state at the fitted offset. Placed from the track's positions, in the track's frame:
  // it moves with the track's offset error as the position does now (first order).
  const int i = AddLandmarkStates(landmark, theta.head<2>(), Mat2::Zero(), sens_.head<2>());
  const int b = BiasState(landmark);
  x_(b) = theta(2);
  sens_(b) = 0;
  P_.row(b).setZero();
  P_.col(b).setZero();
  const int idx[3] = {i, i + 1, b};
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) P_(idx[r], idx[c]) = 0.5 * (cov(r, c) + cov(c, r));
  }
  unplaced_.erase(landmark);
}

bool LandmarkTracker::Update(int landmark, const Vec2& landmark_n, int state, double dz,
                             const Mat2& landmark_cov, double rssi_dbm,
                             const std::function<bool(double nis)>& admit) {
  const int b = BiasState(landmark);
  const int n = static_cast<int>(x_.size());
  // The model at a linearization point: h and its non-zero Jacobian entries (p, alpha, n, b).
  struct Lin {
    double h, hx, hy, hn, slope;
  };
  auto landmark_at = [&](const Eigen::VectorXd& x) {
    return state >= 0 ? Vec2(x.segment<2>(state)) : landmark_n;
  };
  auto linearize = [&](const Eigen::VectorXd& x) {
    const Vec2 rel = x.head<2>() - landmark_at(x);
    const double d2 = rel.squaredNorm() + dz * dz;
    const double dmin = options_.min_distance_m;
    const bool clamped = d2 < dmin * dmin;
    const double d = clamped ? dmin : std::sqrt(d2);
    Lin l;
    l.h = x(kAlpha) - 10 * x(kExponent) * std::log10(d) + x(b);  // eq. (5), radio-landmarks paper
    const double g = clamped ? 0.0 : -10 * x(kExponent) / (kLn10 * d * d);
    l.hx = g * rel.x();
    l.hy = g * rel.y();
    l.hn = -10 * std::log10(d);
    // |dh/d(horizontal position)|: the landmark's own position error moves the RSSI by this.
    l.slope = clamped ? 0.0 : 10 * x(kExponent) * rel.norm() / (kLn10 * d * d);
    return l;
  };
  // The sparse H: p, alpha, n, b and, for a landmark in the state, its position (dh/dl = -dh/dp).
  auto times_p = [&](const Lin& l) {  // P H^T
    Eigen::VectorXd v = l.hx * P_.col(kPx) + l.hy * P_.col(kPy) + P_.col(kAlpha) +
                        l.hn * P_.col(kExponent) + P_.col(b);
    if (state >= 0) v -= l.hx * P_.col(state) + l.hy * P_.col(state + 1);
    return v;
  };
  auto dot_h = [&](const Lin& l, const Eigen::VectorXd& v) {
    double r = l.hx * v(kPx) + l.hy * v(kPy) + v(kAlpha) + l.hn * v(kExponent) + v(b);
    if (state >= 0) r -= l.hx * v(state) + l.hy * v(state + 1);
    return r;
  };
  const Eigen::VectorXd x0 = x_;
  Lin l = linearize(x0);
  const Vec2 rel0 = x0.head<2>() - landmark_at(x0);
  const Vec2 u = rel0.norm() > 1e-9 ? Vec2(rel0 / rel0.norm()) : Vec2(1, 0);
  const double r0 = VarFast() + l.slope * l.slope * u.dot(landmark_cov * u);
  Eigen::VectorXd ph = times_p(l);
  const double s0 = dot_h(l, ph) + r0;
  const double nu0 = rssi_dbm - l.h;
  const double e = std::abs(nu0) / std::sqrt(s0);
  nis_sum_ += e * e;
  ++nis_count_;
  // The packet's predictive log-density at the prior, as two evidences for a bank of motion
  // models (LandmarkTrackerBank). To decide which model's estimate to report: Gaussian up to
  // huber_k sigmas and flat beyond, as a contaminated density's outlier floor: a packet the
  // filter takes for an outlier says nothing about the motion (with Huber's linear tails, one
  // fading dip 3-4 sigma out favoured the freer model by ~1.5 nats and handed it the estimate,
  // docs/landmarks.md). To size the ellipse: Huber's tails up to the gate, which also count the
  // moderate outliers a device beyond the typical priors makes.
  {
    const double k = options_.huber_k;
    const double log_norm = 0.5 * std::log(2 * M_PI * s0);
    const double ek = std::min(e, k);
    last_log_likelihood_ = -0.5 * ek * ek - log_norm;
    const double eg = std::min(e, options_.gate_sigma);
    last_huber_log_likelihood_ = -(eg <= k ? 0.5 * eg * eg : k * eg - 0.5 * k * k) - log_norm;
  }
  if (e > options_.gate_sigma) {
    ++gated_;
    return false;
  }
  // The integrity check sees the packet against the model without its link's bias state (as
  // if the link's shadowing were unknown, sigma_shadow): with the state, a landmark that is
  // elsewhere or offset is explained away by its bias and never looks inconsistent.
  if (admit) {
    const double nu_link = nu0 + x0(b);
    const double s_link = s0 - 2 * ph(b) + P_(b, b) + VarShadow();
    if (!admit(nu_link * nu_link / std::max(s_link, 1e-9))) return false;
  }
  // The radio's noise checked against its stated sigma (issue 21): an exponential average of
  // the used packets' NIS (about 100; gated packets and excluded landmarks do not count); once
  // warm, the RSSI variances (shadowing and fading) are scaled by a factor that grows while that
  // mean is above 1 and shrinks while below, between 1 (never below the stated noise) and
  // noise_scale_max.
  if (options_.adapt_noise) {
    nis_ema_ += kNoiseEmaWeight * (std::min(e * e, options_.gate_sigma * options_.gate_sigma) - nis_ema_);
    if (nis_count_ >= kNoiseWarmPackets) {  // integral control toward a mean NIS of 1
      noise_scale_ = std::clamp(noise_scale_ * std::pow(std::max(nis_ema_, 1e-3), kNoiseEmaWeight),
                                1.0, options_.noise_scale_max);
    }
  }
  // Huber: beyond k sigma the packet's weight falls as k / e (its variance grows as e / k).
  const double R = e > options_.huber_k ? r0 * e / options_.huber_k : r0;
  const bool consider_motion = !RadioMovesPosition();
  if (consider_motion) ++calibration_only_;
  auto mask = [&](Eigen::VectorXd& k) {
    if (consider_motion) k.head<kAlpha>().setZero();  // Schmidt: motion states not updated
  };
  // Iterated update: x_{i+1} = x0 + K_i (z - h(x_i) - H_i (x0 - x_i)), with the robust R from
  // the first iteration on.
  Eigen::VectorXd xi = x0, k(n);
  double s = s0 - r0 + R;
  for (int it = 0; it < options_.iterations; ++it) {
    if (it > 0) {
      l = linearize(xi);
      ph = times_p(l);
      s = dot_h(l, ph) + R;
    }
    k = ph / s;
    mask(k);
    const Eigen::VectorXd dx0 = x0 - xi;
    Eigen::VectorXd next = x0 + k * (rssi_dbm - l.h - dot_h(l, dx0));
    next(kExponent) = std::clamp(next(kExponent), options_.min_exponent, options_.max_exponent);
    const double moved = (next - xi).head<2>().norm() + std::abs(next(kAlpha) - xi(kAlpha)) * 0.01;
    xi = std::move(next);
    if (moved < 1e-7) break;  // m (0.01 m per dB of alpha)
  }
  x_ = xi;
  // The consider sensitivity through the update: (I - k h^T) S, the final iterate's gain and
  // Jacobian (the packet does not see the offset, so it corrects only what it sees of it).
  sens_ -= k * dot_h(l, sens_);
  // Joseph form for any gain: P - k u^T - u k^T + S k k^T, u = P H^T (the consider gain too),
  // then symmetrized, 0.5 (A + A^T). One pass over the pairs without temporaries: each entry in
  // the order of the matrix form (P - (k u^T + u k^T)) + (S k) k^T, both of a pair before
  // either is written (the same numbers as the full update followed by Symmetrize()).
  const Eigen::VectorXd sk = s * k;
  for (Eigen::Index j = 0; j < n; ++j) {
    for (Eigen::Index i = 0; i < j; ++i) {
      const double a_ij = (P_(i, j) - (k(i) * ph(j) + ph(i) * k(j))) + sk(i) * k(j);
      const double a_ji = (P_(j, i) - (k(j) * ph(i) + ph(j) * k(i))) + sk(j) * k(i);
      const double v = 0.5 * (a_ij + a_ji);
      P_(i, j) = v;
      P_(j, i) = v;
    }
    P_(j, j) = (P_(j, j) - (k(j) * ph(j) + ph(j) * k(j))) + sk(j) * k(j);
  }
  return true;
}

}  // namespace trailmark::landmarks

// SPDX-License-Identifier: MIT
#include "trailmark/radio/path_loss.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <map>
#include <stdexcept>

namespace trailmark::radio {

namespace {
constexpr double kLn10 = 2.302585092994046;
}

double LogDistanceModel::MeanRssi(double d) const {
  return alpha_dbm - 10.0 * path_loss_exponent * std::log10(std::max(d, 1e-3));
}

double LogDistanceModel::Distance(double rssi_dbm) const {
  return std::pow(10.0, (alpha_dbm - rssi_dbm) / (10.0 * path_loss_exponent));
}

double LogDistanceModel::DistanceSigma(double d) const {
  return d * kLn10 * sigma_db / (10.0 * path_loss_exponent);
}

RangeFromRssi ToRange(const LogDistanceModel& model, double rssi_dbm) {
  const double d = model.Distance(rssi_dbm);
  return {d, model.DistanceSigma(d)};
}

double BodyFactor(const Vec2& wearer, double heading_rad, const Vec2& other) {
  const Vec2 to = other - wearer;
  const double n = to.norm();
  if (n < 1e-9) return 0.0;
  const double c = (to.x() * std::cos(heading_rad) + to.y() * std::sin(heading_rad)) / n;
  return std::clamp(-c, 0.0, 1.0);
}

namespace {

/// Why a fit could not be made (empty: it could).
using FitProblem = const char*;

FitProblem Trimmed(const std::vector<CalibrationPair>& pairs, double trim_fraction,
                   double bin_width_m, std::vector<CalibrationPair>* kept, std::size_t* trimmed) {
  std::map<long, std::vector<CalibrationPair>> bins;
  for (const auto& p : pairs) {
    if (!(p.distance_m > 0) || !std::isfinite(p.rssi_dbm) || !std::isfinite(p.body_factor)) {
      return "distances must be > 0 and RSSI finite";
    }
    bins[std::lround(p.distance_m / bin_width_m)].push_back(p);
  }
  kept->clear();
  *trimmed = 0;
  for (auto& [key, v] : bins) {
    std::sort(v.begin(), v.end(),
              [](const auto& a, const auto& b) { return a.rssi_dbm < b.rssi_dbm; });
    const auto drop = static_cast<std::size_t>(std::floor(trim_fraction * v.size()));
    for (std::size_t k = drop; k + drop < v.size(); ++k) kept->push_back(v[k]);
    *trimmed += 2 * drop;
  }
  return nullptr;
}

/// The pairs kept after trimming, at least `min_pairs` of them.
FitProblem Kept(const std::vector<CalibrationPair>& pairs, double trim_fraction, double bin_width_m,
                std::size_t min_pairs, std::vector<CalibrationPair>* kept, PathLossFit* fit) {
  if (FitProblem p = Trimmed(pairs, trim_fraction, bin_width_m, kept, &fit->pairs_trimmed))
    return p;
  if (kept->size() < min_pairs) return min_pairs == 3 ? "fewer than 3 pairs" : "too few pairs";
  return nullptr;
}

FitProblem TryFitWithBody(const std::vector<CalibrationPair>& pairs, double trim_fraction,
                          double bin_width_m, PathLossFit* fit) {
  std::vector<CalibrationPair> kept;
  if (FitProblem p = Kept(pairs, trim_fraction, bin_width_m, 10, &kept, fit)) return p;
  // rssi = alpha - 10 n log10(d) - L_body * body_factor
  Eigen::MatrixXd A(kept.size(), 3);
  Eigen::VectorXd y(kept.size());
  for (std::size_t k = 0; k < kept.size(); ++k) {
    A(k, 0) = 1.0;
    A(k, 1) = -10.0 * std::log10(kept[k].distance_m);
    A(k, 2) = -kept[k].body_factor;
    y(k) = kept[k].rssi_dbm;
  }
  const Eigen::Matrix3d N = A.transpose() * A;
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(N);
  if (eig.eigenvalues().minCoeff() < 1e-9 * N.trace()) return "degenerate geometry";
  const Eigen::Vector3d x = N.ldlt().solve(A.transpose() * y);
  const double ss = (A * x - y).squaredNorm();
  fit->model = {x(0), x(1), std::sqrt(ss / std::max(1.0, kept.size() - 3.0)), x(2)};
  fit->residual_sigma_db = fit->model.sigma_db;
  fit->pairs_used = kept.size();
  return nullptr;
}

FitProblem TryFit(const std::vector<CalibrationPair>& pairs, double trim_fraction,
                  double bin_width_m, PathLossFit* fit) {
  std::vector<CalibrationPair> kept;
  if (FitProblem p = Kept(pairs, trim_fraction, bin_width_m, 3, &kept, fit)) return p;
  // rssi = alpha + slope * log10(d), slope = -10 n
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (const auto& p : kept) {
    const double x = std::log10(p.distance_m);
    sx += x;
    sy += p.rssi_dbm;
    sxx += x * x;
    sxy += x * p.rssi_dbm;
  }
  const double n = static_cast<double>(kept.size());
  const double den = n * sxx - sx * sx;
  if (den <= 1e-12 * n * n) return "need 2 distinct distances";
  const double slope = (n * sxy - sx * sy) / den;
  const double alpha = (sy - slope * sx) / n;
  double ss = 0;
  for (const auto& p : kept) {
    const double r = p.rssi_dbm - (alpha + slope * std::log10(p.distance_m));
    ss += r * r;
  }
  fit->model = {alpha, -slope / 10.0, std::sqrt(ss / std::max(1.0, n - 2)), 0.0};
  fit->residual_sigma_db = fit->model.sigma_db;
  fit->pairs_used = kept.size();
  return nullptr;
}

}  // namespace

PathLossFit FitLogDistanceWithBody(const std::vector<CalibrationPair>& pairs,
                                   double trim_fraction, double bin_width_m) {
  PathLossFit fit;
  if (FitProblem p = TryFitWithBody(pairs, trim_fraction, bin_width_m, &fit))
    throw std::invalid_argument(std::string("FitLogDistanceWithBody: ") + p);
  return fit;
}

PathLossFit FitLogDistance(const std::vector<CalibrationPair>& pairs, double trim_fraction,
                           double bin_width_m) {
  PathLossFit fit;
  if (FitProblem p = TryFit(pairs, trim_fraction, bin_width_m, &fit))
    throw std::invalid_argument(std::string("FitLogDistance: ") + p);
  return fit;
}

bool PathLossCalibrationOptions::IsValid(std::string* why) const {
  if (trim_fraction >= 0 && trim_fraction < 0.5 && bin_width_m > 0 && min_exponent > 0 &&
      max_exponent > min_exponent && max_body_loss_db >= 0)
    return true;
  if (why) *why = "trim in [0, 0.5), bin width > 0, 0 < min exponent < max exponent";
  return false;
}

PathLossCalibration CalibratePathLoss(const std::vector<CalibrationPair>& pairs,
                                      const PathLossCalibrationOptions& options) {
  PathLossCalibration out;
  bool have = false;
  if (options.body_shadowing) {
    PathLossFit fit;
    // The body term only when the pairs determine it and its loss is physical.
    if (!TryFitWithBody(pairs, options.trim_fraction, options.bin_width_m, &fit) &&
        fit.model.body_loss_db >= 0 && fit.model.body_loss_db <= options.max_body_loss_db) {
      out.fit = fit;
      have = true;
    }
  }
  if (!have) {
    if (FitProblem p = TryFit(pairs, options.trim_fraction, options.bin_width_m, &out.fit)) {
      out.status = CalibrationStatus::kNoFit;
      out.why = p;
      return out;
    }
  }
  const double n = out.fit.model.path_loss_exponent;
  if (!(n >= options.min_exponent && n <= options.max_exponent)) {
    out.status = CalibrationStatus::kImplausible;
    out.why = "path-loss exponent " + std::to_string(n) + " outside the plausible indoor range";
    return out;
  }
  out.status = CalibrationStatus::kOk;
  return out;
}

std::optional<TimeS> EncounterDetector::Add(TimeS t, double rssi_dbm) {
  if (!window_.empty() && t - window_.back().first > options_.max_gap_s) window_.clear();
  window_.emplace_back(t, rssi_dbm);
  const std::size_t size = 2 * static_cast<std::size_t>(options_.half_window) + 1;
  if (window_.size() > size) window_.pop_front();
  if (window_.size() < size) return std::nullopt;
  const auto& mid = window_[options_.half_window];
  if (mid.second < options_.threshold_dbm) return std::nullopt;
  for (std::size_t k = 0; k < window_.size(); ++k) {
    if (k == static_cast<std::size_t>(options_.half_window)) continue;
    // strict on the earlier side, non-strict on the later side: one peak per plateau
    if (k < static_cast<std::size_t>(options_.half_window) ? window_[k].second >= mid.second
                                                            : window_[k].second > mid.second) {
      return std::nullopt;
    }
  }
  if (mid.first - last_encounter_ < options_.refractory_s) return std::nullopt;
  last_encounter_ = mid.first;
  return mid.first;
}

std::optional<double> LinkChangeDetector::Add(double rssi_dbm) {
  recent_.push_back(rssi_dbm);
  if (static_cast<int>(recent_.size()) > options_.recent) {
    reference_sum_ += recent_.front();
    ++reference_count_;
    recent_.pop_front();
  }
  if (!Ready()) return std::nullopt;
  const double change = CurrentChange();
  if (std::abs(change) > options_.threshold_db) return change;
  return std::nullopt;
}

double LinkChangeDetector::CurrentChange() const {
  if (!Ready()) return 0.0;
  double recent_sum = 0;
  for (double v : recent_) recent_sum += v;
  return recent_sum / recent_.size() - reference_sum_ / reference_count_;
}

void LinkChangeDetector::Reset() {
  recent_.clear();
  reference_sum_ = 0;
  reference_count_ = 0;
}

}  // namespace trailmark::radio

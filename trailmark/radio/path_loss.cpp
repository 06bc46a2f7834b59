// SPDX-License-Identifier: MIT
#include "trailmark/radio/path_loss.h"

#include <ceres/gradient_problem.h>
#include <ceres/gradient_problem_solver.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
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

/// log Phi(a) and the inverse Mills ratio phi(a) / Phi(a) of the standard normal, with the
/// asymptotic series below a = -30 where Phi underflows.
void LogPhiAndMills(double a, double* log_phi, double* mills) {
  constexpr double kSqrt2 = 1.4142135623730951, kSqrt2Pi = 2.5066282746310002;
  if (a > -30.0) {
    const double phi_cdf = 0.5 * std::erfc(-a / kSqrt2);
    *log_phi = std::log(phi_cdf);
    *mills = std::exp(-0.5 * a * a) / kSqrt2Pi / phi_cdf;
    return;
  }
  const double a2 = a * a, series = 1.0 - 1.0 / a2 + 3.0 / (a2 * a2);
  *log_phi = -0.5 * a2 - std::log(-a) - std::log(kSqrt2Pi) + std::log(series);
  *mills = -a / series;
}

/// TruncatedNegLogLikelihood for Ceres: parameters (alpha, n, log sigma[, body loss]).
class TruncatedNll final : public ceres::FirstOrderFunction {
 public:
  TruncatedNll(const std::vector<CalibrationPair>* pairs, double truncation_dbm, bool body)
      : pairs_(pairs), c_(truncation_dbm), body_(body) {}
  int NumParameters() const override { return body_ ? 4 : 3; }
  bool Evaluate(const double* x, double* cost, double* gradient) const override {
    const double p[4] = {x[0], x[1], x[2], body_ ? x[3] : 0.0};
    double g[4];
    *cost = TruncatedNegLogLikelihood(*pairs_, c_, p, g);
    if (gradient != nullptr) std::copy(g, g + NumParameters(), gradient);
    return std::isfinite(*cost);
  }

 private:
  const std::vector<CalibrationPair>* pairs_;
  double c_;
  bool body_;
};

/// Minimizes the truncated likelihood from x (in place); false when it did not end finite.
bool MinimizeTruncated(const std::vector<CalibrationPair>& pairs, double truncation_dbm, bool body,
                       double x[4]) {
  ceres::GradientProblem problem(new TruncatedNll(&pairs, truncation_dbm, body));
  ceres::GradientProblemSolver::Options o;
  o.max_num_iterations = 200;
  o.function_tolerance = 1e-12;
  o.gradient_tolerance = 1e-10;
  o.parameter_tolerance = 1e-12;
  o.logging_type = ceres::SILENT;
  ceres::GradientProblemSolver::Summary summary;
  ceres::Solve(o, problem, x, &summary);
  return summary.IsSolutionUsable() && std::isfinite(x[0]) && std::isfinite(x[1]) &&
         std::isfinite(x[2]) && std::isfinite(x[3]);
}

/// The fit's status: kOk when its exponent is a plausible indoor channel.
PathLossCalibration Plausible(PathLossCalibration out, const PathLossCalibrationOptions& options) {
  const double n = out.fit.model.path_loss_exponent;
  if (!(n >= options.min_exponent && n <= options.max_exponent)) {
    out.status = CalibrationStatus::kImplausible;
    out.why = "path-loss exponent " + std::to_string(n) + " outside the plausible indoor range";
    return out;
  }
  out.status = CalibrationStatus::kOk;
  out.why.clear();
  return out;
}

}  // namespace

TruncatedMean TruncatedNormalMean(double mu, double sigma, double c) {
  if (!std::isfinite(c) || !(sigma > 0)) return {mu, 1.0};
  const double a = (mu - c) / sigma;
  double log_phi = 0, mills = 0;
  LogPhiAndMills(a, &log_phi, &mills);
  return {mu + sigma * mills, std::clamp(1.0 - mills * (a + mills), 0.0, 1.0)};
}

double TruncatedNegLogLikelihood(const std::vector<CalibrationPair>& pairs, double truncation_dbm,
                                 const double params[4], double gradient[4]) {
  const double alpha = params[0], n = params[1], s = params[2], body_loss = params[3];
  const double sigma = std::exp(s);
  const bool truncated = std::isfinite(truncation_dbm);
  double sum = 0;
  double g[4] = {0, 0, 0, 0};
  for (const auto& p : pairs) {
    const double lg = -10.0 * std::log10(p.distance_m);
    const double mu = alpha + n * lg - body_loss * p.body_factor;
    const double z = (p.rssi_dbm - mu) / sigma;
    double log_phi = 0, mills = 0, a = 0;
    if (truncated) {
      a = (mu - truncation_dbm) / sigma;
      LogPhiAndMills(a, &log_phi, &mills);
    }
    // -log of phi(z) / sigma / Phi(a), without the constant log sqrt(2 pi)
    sum += 0.5 * z * z + s + log_phi;
    const double d_mu = (-z + mills) / sigma;
    g[0] += d_mu;
    g[1] += d_mu * lg;
    g[2] += -z * z + 1.0 - mills * a;
    g[3] += -d_mu * p.body_factor;
  }
  const double count = std::max<double>(1.0, static_cast<double>(pairs.size()));
  if (gradient != nullptr) {
    for (int k = 0; k < 4; ++k) gradient[k] = g[k] / count;
  }
  return sum / count;
}

bool TruncatedPathLossFit(const std::vector<CalibrationPair>& pairs, double truncation_dbm,
                          bool body, const LogDistanceModel& start, std::size_t max_pairs,
                          PathLossFit* fit) {
  std::vector<CalibrationPair> kept;
  std::size_t usable = 0;
  for (const auto& p : pairs) usable += p.rssi_dbm >= truncation_dbm && p.distance_m > 0;
  const std::size_t stride = std::max<std::size_t>(1, (usable + max_pairs - 1) / std::max<std::size_t>(1, max_pairs));
  std::size_t k = 0;
  for (const auto& p : pairs) {
    if (!(p.rssi_dbm >= truncation_dbm && p.distance_m > 0)) continue;
    if (k++ % stride == 0) kept.push_back(p);
  }
  if (kept.size() < (body ? 10u : 3u)) return false;
  double x[4] = {start.alpha_dbm, start.path_loss_exponent,
                 std::log(std::max(start.sigma_db, 0.5)), body ? start.body_loss_db : 0.0};
  if (!MinimizeTruncated(kept, truncation_dbm, body, x)) return false;
  // Once more without the pairs beyond 4 sigma of that fit (gross outliers: a wall, a body).
  const double sigma = std::exp(x[2]);
  const std::size_t before = kept.size();
  kept.erase(std::remove_if(kept.begin(), kept.end(),
                            [&](const CalibrationPair& p) {
                              const double mu = x[0] - 10.0 * x[1] * std::log10(p.distance_m) -
                                                x[3] * p.body_factor;
                              return std::abs(p.rssi_dbm - mu) > 4.0 * sigma;
                            }),
             kept.end());
  if (kept.size() < before && !MinimizeTruncated(kept, truncation_dbm, body, x)) return false;
  fit->model = {x[0], x[1], std::exp(x[2]), x[3]};
  fit->residual_sigma_db = fit->model.sigma_db;
  fit->pairs_used = kept.size();
  fit->pairs_trimmed = before - kept.size();
  return true;
}

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
      max_exponent > min_exponent && max_body_loss_db >= 0 && !std::isnan(truncation_dbm) &&
      truncation_dbm < std::numeric_limits<double>::infinity() && max_likelihood_pairs >= 10)
    return true;
  if (why) {
    *why = "trim in [0, 0.5), bin width > 0, 0 < min exponent < max exponent, truncation a "
           "level in dBm or -inf, at least 10 likelihood pairs";
  }
  return false;
}

PathLossCalibration CalibratePathLoss(const std::vector<CalibrationPair>& pairs,
                                      const PathLossCalibrationOptions& options,
                                      const LogDistanceModel* previous) {
  PathLossCalibration out;
  if (previous != nullptr && std::isfinite(options.truncation_dbm)) {
    // The last fit of a growing set of pairs starts the likelihood fit (no least squares).
    const bool body = previous->body_loss_db != 0.0;
    PathLossFit ml;
    if (TruncatedPathLossFit(pairs, options.truncation_dbm, body, *previous,
                             options.max_likelihood_pairs, &ml) &&
        ml.model.body_loss_db >= 0 && ml.model.body_loss_db <= options.max_body_loss_db) {
      out.fit = ml;
      return Plausible(out, options);
    }
  }
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
  if (std::isfinite(options.truncation_dbm)) {
    // The least-squares fit of a truncated sample is biased flat: it starts the likelihood fit.
    const bool body = out.fit.model.body_loss_db != 0.0;
    PathLossFit ml;
    const bool ok = TruncatedPathLossFit(pairs, options.truncation_dbm, body, out.fit.model,
                                         options.max_likelihood_pairs, &ml);
    if (ok && (!body || (ml.model.body_loss_db >= 0 &&
                         ml.model.body_loss_db <= options.max_body_loss_db))) {
      out.fit = ml;
    } else if (TruncatedPathLossFit(pairs, options.truncation_dbm, false, out.fit.model,
                                    options.max_likelihood_pairs, &ml)) {
      out.fit = ml;
    }
  }
  return Plausible(out, options);
}

bool EncounterDetector::Judge() {
  const double w = options_.half_window_s;
  const auto& mid = window_[next_];
  bool peak = mid.second >= options_.threshold_dbm;
  for (std::size_t k = 0; peak && k < window_.size(); ++k) {
    if (k == next_ || std::abs(window_[k].first - mid.first) > w) continue;
    // strict on the earlier side, non-strict on the later side: one peak per plateau
    peak = k < next_ ? window_[k].second < mid.second : window_[k].second <= mid.second;
  }
  if (!peak || mid.first - last_encounter_ < options_.refractory_s) return false;
  last_encounter_ = mid.first;
  return true;
}

std::optional<TimeS> EncounterDetector::Add(TimeS t, double rssi_dbm) {
  const double w = options_.half_window_s;
  std::optional<TimeS> found;
  auto judge_until = [&](TimeS until) {
    while (next_ < window_.size() && window_[next_].first < until) {
      if (Judge() && !found && t - window_[next_].first <= w + options_.max_gap_s) {
        found = window_[next_].first;
      }
      ++next_;
    }
  };
  if (!window_.empty() && t - window_.back().first > options_.max_gap_s) {
    judge_until(std::numeric_limits<double>::infinity());  // the silence is weaker
    window_.clear();
    next_ = 0;
  }
  window_.emplace_back(t, rssi_dbm);
  judge_until(t - w);  // every packet whose later half window is complete
  // Keep what the packets still to judge need: w before the oldest of them.
  while (next_ > 0 && window_.front().first < window_[next_].first - w) {
    window_.pop_front();
    --next_;
  }
  return found;
}

std::optional<double> LinkChangeDetector::Add(double rssi_dbm) {
  recent_.push_back(rssi_dbm);
  if (static_cast<int>(recent_.size()) > options_.recent) {
    reference_sum_ += recent_.front();
    reference_sum_sq_ += recent_.front() * recent_.front();
    ++reference_count_;
    recent_.pop_front();
  }
  if (!Ready()) return std::nullopt;
  const double change = CurrentChange();
  if (!(std::abs(change) > options_.threshold_db)) return std::nullopt;
  if (options_.min_z > 0) {
    // Welch-style z of the shift with the reference window's sample variance for both windows.
    const double n = reference_count_, mean = reference_sum_ / n;
    const double var = std::max(0.0, (reference_sum_sq_ - n * mean * mean) / std::max(1.0, n - 1));
    const double se = std::sqrt(std::max(var, 1e-6) * (1.0 / options_.recent + 1.0 / n));
    if (std::abs(change) < options_.min_z * se) return std::nullopt;
  }
  return change;
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
  reference_sum_sq_ = 0;
  reference_count_ = 0;
}

}  // namespace trailmark::radio

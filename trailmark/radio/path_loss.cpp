#include "trailmark/radio/path_loss.h"

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

PathLossFit FitLogDistance(const std::vector<CalibrationPair>& pairs, double trim_fraction,
                           double bin_width_m) {
  std::map<long, std::vector<CalibrationPair>> bins;
  for (const auto& p : pairs) {
    if (!(p.distance_m > 0) || !std::isfinite(p.rssi_dbm)) {
      throw std::invalid_argument("FitLogDistance: distances must be > 0 and RSSI finite");
    }
    bins[std::lround(p.distance_m / bin_width_m)].push_back(p);
  }
  std::vector<CalibrationPair> kept;
  PathLossFit fit;
  for (auto& [key, v] : bins) {
    std::sort(v.begin(), v.end(),
              [](const auto& a, const auto& b) { return a.rssi_dbm < b.rssi_dbm; });
    const auto drop = static_cast<std::size_t>(std::floor(trim_fraction * v.size()));
    for (std::size_t k = drop; k + drop < v.size(); ++k) kept.push_back(v[k]);
    fit.pairs_trimmed += 2 * drop;
  }
  if (kept.size() < 3) throw std::invalid_argument("FitLogDistance: fewer than 3 pairs");
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
  if (den <= 1e-12 * n * n) throw std::invalid_argument("FitLogDistance: need 2 distinct distances");
  const double slope = (n * sxy - sx * sy) / den;
  const double alpha = (sy - slope * sx) / n;
  double ss = 0;
  for (const auto& p : kept) {
    const double r = p.rssi_dbm - (alpha + slope * std::log10(p.distance_m));
    ss += r * r;
  }
  fit.model = {alpha, -slope / 10.0, std::sqrt(ss / std::max(1.0, n - 2))};
  fit.residual_sigma_db = fit.model.sigma_db;
  fit.pairs_used = kept.size();
  return fit;
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
  if (reference_count_ < options_.reference || static_cast<int>(recent_.size()) < options_.recent) {
    return std::nullopt;
  }
  double recent_sum = 0;
  for (double v : recent_) recent_sum += v;
  const double change = recent_sum / recent_.size() - reference_sum_ / reference_count_;
  if (std::abs(change) > options_.threshold_db) return change;
  return std::nullopt;
}

void LinkChangeDetector::Reset() {
  recent_.clear();
  reference_sum_ = 0;
  reference_count_ = 0;
}

}  // namespace trailmark::radio

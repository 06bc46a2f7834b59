// SPDX-License-Identifier: MIT
#include "trailmark/landmarks/tracker_bank.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace trailmark::landmarks {

bool TrackerBankOptions::IsValid(std::string* why) const {
  if (models != 1 && models != 2) {
    if (why) *why = "tracker bank: models must be 1 or 2";
    return false;
  }
  if (!(overbound >= 1) || !std::isfinite(overbound)) {
    if (why) *why = "tracker bank: overbound must be finite and >= 1";
    return false;
  }
  if (!(poor_prior >= min_weight && poor_prior <= 1 - min_weight)) {
    if (why) *why = "tracker bank: poor_prior must be within [min_weight, 1 - min_weight]";
    return false;
  }
  if (!(evidence_delay_s >= 0) || !std::isfinite(evidence_delay_s)) {
    if (why) *why = "tracker bank: evidence_delay_s must be finite and >= 0";
    return false;
  }
  if (!(min_weight > 0 && min_weight < 0.5)) {
    if (why) *why = "tracker bank: min_weight must be in (0, 0.5)";
    return false;
  }
  return true;
}

LandmarkTrackerBank::LandmarkTrackerBank(const Vec3& start_n, double start_sigma_m,
                                         std::optional<double> start_heading_sigma_rad,
                                         const std::optional<radio::LogDistanceModel>& radio,
                                         const LandmarkTrackerOptions& options,
                                         const TrackerBankOptions& bank)
    : bank_(bank) {
  std::string why;
  if (!bank_.IsValid(&why)) throw std::invalid_argument(why);
  models_.reserve(static_cast<std::size_t>(bank_.models));
  models_.emplace_back(start_n, start_sigma_m, start_heading_sigma_rad, radio, options);
  if (bank_.models == 2) {
    // The poor device: wider shared errors, and its heading offset estimated (a state of the
    // start heading, in quadrature with the stated sigma) rather than only reported.
    LandmarkTrackerOptions poor = options;
    poor.pdr = options.pdr.SharedErrorsScaled(bank_.overbound);
    const double offset = bank_.overbound * options.pdr.track_heading_offset_sigma_rad;
    if (bank_.poor_offset_state) {
      poor.pdr.track_heading_offset_sigma_rad = 0.0;
      const double stated = start_heading_sigma_rad.value_or(poor.pdr.start_heading_sigma_rad);
      models_.emplace_back(start_n, start_sigma_m, std::hypot(stated, offset), radio, poor);
    } else {
      poor.pdr.track_heading_offset_sigma_rad = offset;
      models_.emplace_back(start_n, start_sigma_m, start_heading_sigma_rad, radio, poor);
    }
  }
  weights_.assign(1, 1.0);
  if (models_.size() == 2) weights_ = {1 - bank_.poor_prior, bank_.poor_prior};
  cover_weights_ = weights_;
}

std::size_t LandmarkTrackerBank::Best() const {
  return static_cast<std::size_t>(std::max_element(weights_.begin(), weights_.end()) -
                                  weights_.begin());
}

void LandmarkTrackerBank::AddStep(const Step& step) {
  for (auto& m : models_) m.AddStep(step);
}

void LandmarkTrackerBank::Weigh(const std::vector<double>& log_likelihoods,
                                std::vector<double>* weights) const {
  std::vector<double>& w = *weights;
  std::vector<double> lw(w.size());
  for (std::size_t k = 0; k < w.size(); ++k) lw[k] = std::log(w[k]) + log_likelihoods[k];
  // Normalize in the log domain, then floor.
  const double top = *std::max_element(lw.begin(), lw.end());
  double sum = 0;
  for (std::size_t k = 0; k < w.size(); ++k) sum += std::exp(lw[k] - top);
  double floored_sum = 0;
  for (std::size_t k = 0; k < w.size(); ++k) {
    w[k] = std::max(std::exp(lw[k] - top) / sum, bank_.min_weight);
    floored_sum += w[k];
  }
  for (std::size_t k = 0; k < w.size(); ++k) w[k] /= floored_sum;
}

void LandmarkTrackerBank::Hold(TimeS t, int landmark, std::optional<bool> verdict) {
  // The packet's densities, when every model has one (the same evidence for all).
  std::vector<double> ll(models_.size()), huber(models_.size());
  bool all = true;
  for (std::size_t k = 0; k < models_.size(); ++k) {
    ll[k] = models_[k].last_log_likelihood();
    huber[k] = models_[k].last_huber_log_likelihood();
    all = all && std::isfinite(ll[k]) && std::isfinite(huber[k]);
  }
  if (verdict.has_value()) {
    excluded_[landmark] = !*verdict;
    if (!*verdict) {  // an excluded landmark's evidence held so far is dropped
      std::erase_if(pending_, [&](const Pending& p) { return p.landmark == landmark; });
    }
  }
  if (all && !excluded_[landmark])
    pending_.push_back({t, landmark, std::move(ll), std::move(huber)});
  // Evidence held for evidence_delay_s without its landmark being excluded weighs the models.
  while (!pending_.empty() && pending_.front().t <= t - bank_.evidence_delay_s) {
    if (!excluded_[pending_.front().landmark]) {
      Weigh(pending_.front().log_likelihoods, &weights_);
      Weigh(pending_.front().huber_log_likelihoods, &cover_weights_);
      ++weighed_;
    }
    pending_.pop_front();
  }
}

bool LandmarkTrackerBank::ToEveryModel(
    const std::function<bool(double nis)>& admit,
    const std::function<bool(LandmarkTracker&, const std::function<bool(double)>&)>& update,
    std::optional<bool>* asked) {
  // The most probable model asks the integrity monitor; the others follow its verdict (and use
  // a packet it gated before asking).
  const std::size_t best = Best();
  std::optional<bool>& verdict = *asked;
  const std::function<bool(double)> ask = [&](double nis) {
    verdict = admit ? admit(nis) : true;
    return *verdict;
  };
  const std::function<bool(double)> follow = [&](double) { return verdict.value_or(true); };
  const bool used = update(models_[best], ask);
  for (std::size_t k = 0; k < models_.size(); ++k) {
    if (k != best) update(models_[k], follow);
  }
  return used;
}

bool LandmarkTrackerBank::UpdateRssi(TimeS t, int landmark, const Vec2& landmark_n,
                                     std::optional<double> landmark_z_m, const Mat2& landmark_cov,
                                     double agent_z_m, double rssi_dbm,
                                     const std::function<bool(double nis)>& admit) {
  std::optional<bool> verdict;
  const bool used = ToEveryModel(
      admit,
      [&](LandmarkTracker& m, const auto& a) {
        return m.UpdateRssi(t, landmark, landmark_n, landmark_z_m, landmark_cov, agent_z_m,
                            rssi_dbm, a);
      },
      &verdict);
  if (models_.size() > 1) Hold(t, landmark, verdict);
  return used;
}

bool LandmarkTrackerBank::UpdateRssiUnknown(TimeS t, int landmark, double dz_m, double rssi_dbm,
                                            const std::function<bool(double nis)>& admit) {
  std::optional<bool> verdict;
  return ToEveryModel(
      admit,
      [&](LandmarkTracker& m, const auto& a) {
        return m.UpdateRssiUnknown(t, landmark, dz_m, rssi_dbm, a);
      },
      &verdict);
}

std::optional<std::pair<Vec2, Mat2>> LandmarkTrackerBank::LandmarkEstimate(int landmark) const {
  // Over the models that placed it (their weights renormalized).
  std::vector<Member> placed;
  for (std::size_t k = 0; k < models_.size(); ++k) {
    if (auto e = models_[k].LandmarkEstimate(landmark)) {
      placed.push_back({k, weights_[k], cover_weights_[k], e->first, e->second});
    }
  }
  if (placed.empty()) return std::nullopt;
  if (placed.size() == 1) return std::make_pair(placed[0].mean, placed[0].cov);
  return Report(placed);
}

std::pair<Vec2, Mat2> LandmarkTrackerBank::Report(const std::vector<Member>& members) const {
  double total = 0;
  for (const Member& m : members) total += m.weight;
  Vec2 mean = Vec2::Zero();
  for (const Member& m : members) mean += (m.weight / total) * m.mean;
  // The typical device's estimate until the radio decides for the poor one: from its weight
  // 0.5 on, the estimate moves linearly to the poor model's at weight 1 (prefer_typical).
  Vec2 estimate = mean;
  if (bank_.prefer_typical && members.size() == 2 && members[0].model == 0) {
    const double w_poor = members[1].weight / total;
    estimate =
        members[0].mean + std::max(0.0, 2 * w_poor - 1) * (members[1].mean - members[0].mean);
  }
  // The mixture's mean squared error about the estimate, with the ellipse's weights: each
  // model's covariance plus its mean's offset from the estimate (the mixture's covariance when
  // the estimate is its mean and the weights are the same).
  double cover_total = 0;
  for (const Member& m : members) cover_total += m.cover;
  Mat2 cov = Mat2::Zero();
  for (const Member& m : members) {
    const Vec2 d = m.mean - estimate;
    cov += (m.cover / cover_total) * (m.cov + d * d.transpose());
  }
  return {estimate, 0.5 * (cov + cov.transpose())};
}

std::pair<Vec2, Mat2> LandmarkTrackerBank::PositionReport() const {
  if (models_.size() == 1) return {models_[0].position(), models_[0].reported_position_cov()};
  std::vector<Member> members;
  for (std::size_t k = 0; k < models_.size(); ++k) {
    members.push_back({k, weights_[k], cover_weights_[k], models_[k].position(),
                       models_[k].reported_position_cov()});
  }
  return Report(members);
}

Vec2 LandmarkTrackerBank::position() const { return PositionReport().first; }
Mat2 LandmarkTrackerBank::reported_position_cov() const { return PositionReport().second; }

}  // namespace trailmark::landmarks

// SPDX-License-Identifier: MIT
#include "trailmark/sim/rssi_channel.h"

#include <algorithm>
#include <cmath>

namespace trailmark {

RssiChannel::RssiChannel(RssiChannelOptions options, const FloorPlan* plan,
                         std::vector<AttenuationZone> zones, Random rng)
    : options_(options), plan_(plan), zones_(std::move(zones)), rng_(rng) {}

double RssiChannel::BodyLoss(const Vec2& self, const Vec2& other,
                             std::optional<double> heading) const {
  if (!heading) return 0.0;
  const Vec2 to = other - self;
  if (to.norm() < 1e-9) return 0.0;
  const double c = (to.x() * std::cos(*heading) + to.y() * std::sin(*heading)) / to.norm();
  // 0 dB in front, full loss straight behind, smooth in between.
  return options_.body_loss_db * std::clamp(-c, 0.0, 1.0);
}

double RssiChannel::ZoneLoss(const Vec2& a, const Vec2& b, double* extra_sigma) const {
  double loss = 0.0;
  *extra_sigma = 0.0;
  if (zones_.empty()) return 0.0;
  constexpr int kSamples = 20;  // length of the link inside each zone, by sampling
  const double len = (b - a).norm();
  for (const auto& z : zones_) {
    int inside = 0;
    for (int i = 0; i < kSamples; ++i) {
      if (PointInPolygon(a + (b - a) * ((i + 0.5) / kSamples), z.ring)) ++inside;
    }
    if (inside > 0) {
      loss += z.loss_db_per_m * len * inside / kSamples;
      *extra_sigma = std::max(*extra_sigma, z.extra_sigma_db);
    }
  }
  return loss;
}

double RssiChannel::MeanRssi(const Vec2& rx, const Vec2& tx, std::optional<double> hrx,
                             std::optional<double> htx, const LinkLevels& levels) const {
  const double d = std::max(std::hypot((rx - tx).norm(), levels.dz_m), options_.min_distance_m);
  double rssi = options_.alpha_dbm - 10.0 * options_.path_loss_exponent * std::log10(d);
  const FloorPlan* plan = levels.plan != nullptr ? levels.plan : plan_;
  if (plan != nullptr) {
    rssi -= options_.wall_loss_db * std::min(plan->WallsBetween(rx, tx), options_.max_walls_counted);
  }
  rssi -= options_.floor_loss_db * levels.floors_crossed;
  rssi -= BodyLoss(rx, tx, hrx) + BodyLoss(tx, rx, htx);
  double extra_sigma = 0;
  rssi -= ZoneLoss(rx, tx, &extra_sigma);
  return rssi;
}

std::optional<double> RssiChannel::Sample(const std::string& rx_id, const Vec2& rx,
                                          const std::string& tx_id, const Vec2& tx,
                                          std::optional<double> hrx, std::optional<double> htx,
                                          const LinkLevels& levels) {
  const double mean = MeanRssi(rx, tx, hrx, htx, levels);
  // Slow shadowing: one AR(1) process per unordered link, decorrelating with distance moved.
  const auto key = rx_id < tx_id ? std::pair(rx_id, tx_id) : std::pair(tx_id, rx_id);
  LinkState& link = links_[key];
  const double slow_sigma = std::sqrt(std::max(
      0.0, options_.shadowing_sigma_db * options_.shadowing_sigma_db -
               options_.fast_fading_sigma_db * options_.fast_fading_sigma_db));
  const Vec2 a = rx_id < tx_id ? rx : tx;
  const Vec2 b = rx_id < tx_id ? tx : rx;
  if (!link.init) {
    link.shadow_db = rng_.Normal(0.0, slow_sigma);
    link.init = true;
  } else {
    const double moved = (a - link.rx).norm() + (b - link.tx).norm();
    const double rho = std::exp(-moved / options_.shadowing_corr_distance_m);
    link.shadow_db = rho * link.shadow_db + std::sqrt(1 - rho * rho) * rng_.Normal(0.0, slow_sigma);
  }
  link.rx = a;
  link.tx = b;
  double extra_sigma = 0;
  ZoneLoss(rx, tx, &extra_sigma);
  const double fast = rng_.Normal(0.0, std::hypot(options_.fast_fading_sigma_db, extra_sigma));
  double gain = 0;
  for (const std::string* id : {&rx_id, &tx_id}) {
    if (auto it = node_gain_db_.find(*id); it != node_gain_db_.end()) gain += it->second;
  }
  const double rssi = mean + gain + link.shadow_db + fast;
  if (rssi < options_.sensitivity_dbm) return std::nullopt;
  return std::round(rssi);  // radios report integer dBm
}

}  // namespace trailmark

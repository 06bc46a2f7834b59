// SPDX-License-Identifier: MIT
#pragma once
/// Received signal strength between two nodes:
///   rssi = alpha - 10 n log10(d / 1 m) - L_walls - L_floors - L_body - L_zones + X,
/// log-distance path loss (Rappaport, "Wireless Communications", 2002, sec. 4.9) with
/// per-wall attenuation (multi-wall model, COST 231), a floor attenuation factor per floor
/// crossed (Seidel and Rappaport 1992: 10-20 dB for one floor; d then includes the height
/// difference), a body-shadowing term for a radio worn
/// on the torso (breadcrumb paper ref. [12]), zones of extra attenuation per metre (fire,
/// water: breadcrumb paper Fig. 8 and sec. V-C), and shadowing X that is log-normal and
/// correlated over distance moved (Gudmundson 1991: exponential, d_corr of a few metres).

#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "trailmark/core/random.h"
#include "trailmark/geometry/floor_plan.h"

namespace trailmark {

struct AttenuationZone {
  std::string name;              ///< e.g. "fire", "water"
  std::vector<Vec2> ring;        ///< polygon
  double loss_db_per_m = 3.0;    ///< extra loss per metre of the link inside the zone
  double extra_sigma_db = 4.0;   ///< extra shadowing while the link crosses the zone
};

struct RssiChannelOptions {
  double alpha_dbm = -40.0;           ///< at 1 m; breadcrumb paper: > -40 dBm within ~1 m
  double path_loss_exponent = 2.3;    ///< indoor line of sight, 2.4 GHz
  double shadowing_sigma_db = 4.0;    ///< log-normal shadowing, 1 sigma
  double fast_fading_sigma_db = 2.0;  ///< per-packet part of the shadowing
  double shadowing_corr_distance_m = 3.0;
  double wall_loss_db = 3.5;          ///< per interior wall crossed (drywall, 2.4 GHz)
  int max_walls_counted = 6;
  double body_loss_db = 8.0;          ///< when the other node is right behind the wearer
  double floor_loss_db = 15.0;        ///< per floor between the nodes (multi-floor links only)
  double sensitivity_dbm = -95.0;     ///< packets below this are not received (CC2420)
  double min_distance_m = 0.1;
};

/// Where the two ends of a link are vertically (multi-floor buildings).
struct LinkLevels {
  int floors_crossed = 0;
  double dz_m = 0;                    ///< height difference, in the path length
  const FloorPlan* plan = nullptr;    ///< the walls to count (the receiver's level); null: the
                                      ///< channel's plan
};

class RssiChannel {
 public:
  RssiChannel(RssiChannelOptions options, const FloorPlan* plan,
              std::vector<AttenuationZone> zones, Random rng);

  /// Mean received power (no random terms), for calibration truth and the dispenser.
  double MeanRssi(const Vec2& rx, const Vec2& tx, std::optional<double> wearer_heading_rx,
                  std::optional<double> wearer_heading_tx, const LinkLevels& levels = {}) const;
  /// One packet on link (rx_id, tx_id); empty when below sensitivity.
  std::optional<double> Sample(const std::string& rx_id, const Vec2& rx, const std::string& tx_id,
                               const Vec2& tx, std::optional<double> wearer_heading_rx,
                               std::optional<double> wearer_heading_tx,
                               const LinkLevels& levels = {});

  const RssiChannelOptions& options() const { return options_; }
  /// Antenna gain offset of a node (dB, added on every link of the node): a breadcrumb knocked
  /// over lies with its antenna at another angle (breadcrumb paper sec. V-C).
  void SetNodeGain(const std::string& id, double gain_db) { node_gain_db_[id] = gain_db; }

 private:
  double BodyLoss(const Vec2& self, const Vec2& other, std::optional<double> heading) const;
  double ZoneLoss(const Vec2& a, const Vec2& b, double* extra_sigma) const;

  RssiChannelOptions options_;
  const FloorPlan* plan_;
  std::vector<AttenuationZone> zones_;
  Random rng_;
  struct LinkState {
    double shadow_db = 0;
    Vec2 rx = Vec2::Zero(), tx = Vec2::Zero();
    bool init = false;
  };
  std::map<std::pair<std::string, std::string>, LinkState> links_;
  std::map<std::string, double> node_gain_db_;
};

}  // namespace trailmark

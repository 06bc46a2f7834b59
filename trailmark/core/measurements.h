// SPDX-License-Identifier: MIT
#pragma once
/// One struct per row kind of the mission format (spec: "Streams"). Plain values, no I/O.

#include <optional>
#include <string>

#include "trailmark/core/types.h"

namespace trailmark {

/// imu.csv: raw foot-mounted IMU sample in the sensor body frame.
struct ImuSample {
  TimeS t = 0;
  std::string agent;
  Vec3 accel_b = Vec3::Zero();  ///< specific force incl. gravity, m/s^2
  Vec3 gyro_b = Vec3::Zero();   ///< angular rate, rad/s
};

/// steps.csv: PDR displacement of an agent between t0 and t1, navigation frame.
struct Step {
  TimeS t0 = 0;
  TimeS t1 = 0;  ///< time the displacement became known; rows ordered by t1
  std::string agent;
  Vec3 delta_n = Vec3::Zero();            ///< displacement, m
  std::optional<Vec3> variance_m2;        ///< per-axis variances; empty when unknown
  /// The step source's own growth of its heading variance over the step (rad^2): a foot
  /// INS's yaw variance (ins/zupt_ins.h); empty when the source does not say (steps.csv).
  std::optional<double> heading_var_rad2 = std::nullopt;
};

/// rssi.csv: one received packet.
struct RssiPacket {
  TimeS t = 0;
  std::string rx;
  std::string tx;
  double rssi_dbm = 0;
};

/// ranges.csv: a direct range between two nodes.
struct RangeMeasurement {
  TimeS t = 0;
  std::string a;
  std::string b;
  double range_m = 0;
  std::optional<double> sigma_m;
  std::string kind;  ///< "ultrasound", "uwb", "rssi" (or empty when unknown)
};

/// bearings.csv: bearing from a to b in the navigation frame, radians from +x, CCW.
struct BearingMeasurement {
  TimeS t = 0;
  std::string a;
  std::string b;
  double bearing_rad = 0;
  std::optional<double> sigma_rad;
};

/// events.csv.
struct MissionEvent {
  TimeS t = 0;
  std::string agent;
  std::string event;  ///< drop, wake, enter, exit, stop, go (others are kept verbatim)
  std::string node;   ///< may be empty
};

/// baro.csv (1.1): barometric pressure at the agent (a phone, a boot sensor).
struct BaroSample {
  TimeS t = 0;
  std::string agent;
  double pressure_hpa = 0;
};

/// truth.csv.
struct TruthSample {
  TimeS t = 0;
  std::string id;
  Vec3 position_n = Vec3::Zero();
  std::optional<int> floor{};  ///< the level the node is on (1.1); empty: derived from z
};

/// estimates.csv: the online estimate of a node with its horizontal covariance.
struct Estimate {
  TimeS t = 0;
  std::string id;
  Vec3 position_n = Vec3::Zero();
  double sxx = 0;
  double sxy = 0;
  double syy = 0;
  std::optional<double> szz{};  ///< vertical variance, m^2 (1.1); empty: no height estimate
  std::optional<int> floor{};  ///< the level the estimator believes (1.1); empty: from z
  /// False when estimates.csv left sxx, sxy or syy empty ("unknown", e.g. a method that gives
  /// no covariance): sxx, sxy, syy are then 0 and mean nothing (evaluation leaves such rows
  /// out of in95 and NEES; written back as empty cells).
  bool covariance_known = true;
};

}  // namespace trailmark

// SPDX-License-Identifier: MIT
#pragma once
/// Landmark battery lifetime (radio-landmarks paper, sec. 4.2, eqs. (1)-(2)). No I/O.
///   Q_left  = Q_bat - t_sleep * I_sleep                                              (1)
///   T_maxOp = Q_left * T_wakeup / (T_send * I_send + (T_wakeup - T_send) * I_sleep)   (2)
/// Units in the names: mAh, uA, mA, ms, s.

namespace trailmark::landmarks {

struct EnergyModel {
  double battery_mAh = 230.0;      ///< CR2032 coin cell
  double sleep_current_uA = 3.044; ///< wake-up receiver listening 2.78 uA + self-discharge 0.263 uA
  double send_current_mA = 15.0;   ///< while answering a wake-up
  double send_time_ms = 13.0;

  /// Lifetime in sleep mode only (never woken), seconds: Q_bat / I_sleep.
  double SleepLifetimeS() const;
  /// Charge left after sleeping t_sleep_s, mAh (eq. 1; 0 when exhausted).
  double ChargeLeftMAh(double t_sleep_s) const;
  /// Operating time after t_sleep_s when woken every wakeup_period_s, seconds (eq. 2).
  double MaxOperatingTimeS(double t_sleep_s, double wakeup_period_s) const;
};

constexpr double kSecondsPerYear = 365.25 * 24 * 3600;

}  // namespace trailmark::landmarks

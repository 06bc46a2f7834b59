// SPDX-License-Identifier: MIT
#include "trailmark/landmarks/energy.h"

#include <algorithm>
#include <stdexcept>

namespace trailmark::landmarks {

double EnergyModel::SleepLifetimeS() const {
  if (!(sleep_current_uA > 0)) throw std::invalid_argument("sleep current must be > 0");
  return battery_mAh * 1e-3 * 3600.0 / (sleep_current_uA * 1e-6);  // A s / A
}

double EnergyModel::ChargeLeftMAh(double t_sleep_s) const {
  // eq. (1): Q_left = Q_bat - t_sleep I_sleep
  return std::max(0.0, battery_mAh - t_sleep_s / 3600.0 * sleep_current_uA * 1e-3);
}

double EnergyModel::MaxOperatingTimeS(double t_sleep_s, double wakeup_period_s) const {
  if (!(wakeup_period_s > 0) || !(send_time_ms >= 0) || !(send_current_mA >= 0)) {
    throw std::invalid_argument("wake-up period must be > 0, send time and current >= 0");
  }
  const double t_send = send_time_ms * 1e-3;
  if (wakeup_period_s < t_send) throw std::invalid_argument("wake-up period shorter than a send");
  const double q_left_As = ChargeLeftMAh(t_sleep_s) * 1e-3 * 3600.0;
  // eq. (2): charge per period = T_send I_send + (T_wakeup - T_send) I_sleep
  const double per_period_As =
      t_send * send_current_mA * 1e-3 + (wakeup_period_s - t_send) * sleep_current_uA * 1e-6;
  return q_left_As * wakeup_period_s / per_period_As;
}

}  // namespace trailmark::landmarks

#include "trailmark/sim/landmark_corridor.h"

#include <cmath>

#include "trailmark/core/random.h"

namespace trailmark {

LandmarkCorridor SimulateLandmarkCorridor(const LandmarkCorridorOptions& o, std::uint64_t seed) {
  Random rng(seed);
  LandmarkCorridor c;
  const double length = o.landmark_spacing_m * (o.landmarks - 1);
  for (int j = 0; j < o.landmarks; ++j) {
    c.landmarks.emplace_back(j * o.landmark_spacing_m + rng.Normal(0, 0.3),
                             (j % 2 == 0 ? 1 : -1) * o.corridor_half_width_m);
  }
  for (int p = 0; p < o.standing_positions; ++p) {
    const double x = o.standing_positions > 1 ? length * p / (o.standing_positions - 1) : 0.0;
    c.standing.emplace_back(x, (p % 2 == 0 ? 1 : -1) * o.standing_zigzag_m);
    c.standing_from_imu.push_back(
        c.standing.back() + Vec2(rng.Normal(0, o.standing_sigma_m), rng.Normal(0, o.standing_sigma_m)));
  }
  for (const auto& h : c.standing) {
    std::vector<std::optional<double>> row;
    for (const auto& s : c.landmarks) {
      const double d = std::max((h - s).norm(), 0.1);
      double mean = o.alpha_dbm - 10 * o.path_loss_exponent * std::log10(d) +
                    rng.Normal(0, o.shadowing_sigma_db);
      if (rng.Uniform(0, 1) < o.nlos_probability) mean -= o.nlos_loss_db;
      double sum = 0;
      int heard = 0;
      for (int k = 0; k < o.packets_per_stop; ++k) {
        const double r = mean + rng.Normal(0, o.fast_fading_sigma_db);
        if (r >= o.sensitivity_dbm) sum += r, ++heard;
      }
      row.push_back(heard > 0 ? std::optional<double>(sum / heard) : std::nullopt);
    }
    c.rssi_dbm.push_back(row);
  }
  return c;
}

}  // namespace trailmark

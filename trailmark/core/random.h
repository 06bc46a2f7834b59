// SPDX-License-Identifier: MIT
#pragma once
/// Deterministic random numbers: the same seed gives the same mission on every platform
/// (std::normal_distribution is implementation-defined, so the normal draw is our own).

#include <cmath>
#include <cstdint>
#include <numbers>
#include <random>

namespace trailmark {

class Random {
 public:
  explicit Random(std::uint64_t seed) : engine_(seed) {}

  /// Uniform in [0, 1).
  double Uniform() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }
  double Uniform(double lo, double hi) { return lo + (hi - lo) * Uniform(); }

  /// Standard normal by Box-Muller (both outputs used).
  double Normal() {
    if (has_spare_) {
      has_spare_ = false;
      return spare_;
    }
    double u1 = Uniform();
    while (u1 <= 0.0) u1 = Uniform();
    const double u2 = Uniform();
    const double r = std::sqrt(-2.0 * std::log(u1));
    spare_ = r * std::sin(2.0 * std::numbers::pi * u2);
    has_spare_ = true;
    return r * std::cos(2.0 * std::numbers::pi * u2);
  }
  double Normal(double mean, double sigma) { return mean + sigma * Normal(); }

  /// A child stream whose draws do not depend on how many draws the parent made later.
  Random Fork() { return Random(engine_()); }

 private:
  std::mt19937_64 engine_;
  bool has_spare_ = false;
  double spare_ = 0.0;
};

}  // namespace trailmark

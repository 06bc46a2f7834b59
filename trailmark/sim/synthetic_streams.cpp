// SPDX-License-Identifier: MIT
#include "trailmark/sim/synthetic_streams.h"

#include <cmath>

#include "trailmark/core/random.h"

namespace trailmark {

std::vector<ImuSample> SyntheticImu(std::size_t rows, std::uint64_t seed, double rate_hz) {
  Random rng(seed);
  std::vector<ImuSample> out(rows);
  for (std::size_t i = 0; i < rows; ++i) {
    const double t = static_cast<double>(i) / rate_hz;
    const double phase = std::sin(2.0 * 3.14159 * 0.9 * t);
    out[i] = {t, "ff1", Vec3(2.0 * phase + rng.Normal(0, 0.05), rng.Normal(0, 0.05), 9.81 + 3.0 * phase),
              Vec3(rng.Normal(0, 0.01), 4.0 * phase, rng.Normal(0, 0.01))};
  }
  return out;
}

std::vector<Step> SyntheticSteps(std::size_t rows, std::uint64_t seed) {
  Random rng(seed);
  std::vector<Step> out(rows);
  double heading = 0;
  for (std::size_t i = 0; i < rows; ++i) {
    heading += rng.Normal(0, 0.05);
    const double t0 = 0.55 * static_cast<double>(i);
    out[i] = {t0, t0 + 0.55, "ff1", Vec3(0.7 * std::cos(heading), 0.7 * std::sin(heading), 0.0),
              Vec3(0.0025, 0.0025, 1e-4)};
  }
  return out;
}

std::vector<RssiPacket> SyntheticRssi(std::size_t rows, std::uint64_t seed) {
  Random rng(seed);
  std::vector<RssiPacket> out(rows);
  const char* crumbs[] = {"base", "c1", "c2", "c3", "c4", "c5", "c6"};
  for (std::size_t i = 0; i < rows; ++i) {
    out[i] = {0.1 * static_cast<double>(i), "ff1", crumbs[i % 7], std::round(rng.Normal(-70, 8))};
  }
  return out;
}

std::vector<TruthSample> SyntheticTruth(std::size_t rows, std::uint64_t seed) {
  Random rng(seed);
  std::vector<TruthSample> out(rows);
  for (std::size_t i = 0; i < rows; ++i) {
    const double t = 0.1 * static_cast<double>(i);
    out[i] = {t, "ff1", Vec3(10 * std::cos(0.01 * t), 10 * std::sin(0.01 * t), 0.0)};
  }
  return out;
}

std::vector<Estimate> SyntheticEstimates(std::size_t rows, std::uint64_t seed) {
  Random rng(seed);
  std::vector<Estimate> out(rows);
  for (std::size_t i = 0; i < rows; ++i) {
    const double t = 0.1 * static_cast<double>(i);
    out[i] = {t, "ff1", Vec3(10 * std::cos(0.01 * t) + rng.Normal(0, 1), 10 * std::sin(0.01 * t), 0),
              1.0 + 0.001 * t, 0.1, 1.0 + 0.001 * t};
  }
  return out;
}

}  // namespace trailmark

// SPDX-License-Identifier: MIT
#pragma once
/// Synthetic rows of every stream kind, for I/O benchmarks and round-trip tests. The values are
/// plausible (a walk at 1.2 m/s, 100 Hz IMU) but carry no scenario.

#include <cstdint>
#include <vector>

#include "trailmark/core/measurements.h"

namespace trailmark {

std::vector<ImuSample> SyntheticImu(std::size_t rows, std::uint64_t seed, double rate_hz = 100.0);
std::vector<Step> SyntheticSteps(std::size_t rows, std::uint64_t seed);
std::vector<RssiPacket> SyntheticRssi(std::size_t rows, std::uint64_t seed);
std::vector<TruthSample> SyntheticTruth(std::size_t rows, std::uint64_t seed);
std::vector<Estimate> SyntheticEstimates(std::size_t rows, std::uint64_t seed);

}  // namespace trailmark

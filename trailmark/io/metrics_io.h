// SPDX-License-Identifier: MIT
#pragma once
/// metrics.json (spec: "Outputs of a pipeline").

#include <filesystem>
#include <string>

#include "trailmark/eval/metrics.h"

namespace trailmark {

/// `max_series` caps the time series written per node (evenly decimated; 0 = all).
std::string MetricsToJson(const Metrics& metrics, std::size_t max_series = 5000);
void WriteMetricsJson(const std::filesystem::path& path, const Metrics& metrics);

}  // namespace trailmark

// SPDX-License-Identifier: MIT
#pragma once
// A progress bar on stderr with rate and ETA, drawn only when stderr is a terminal (logs and CI
// stay clean) and only after the task has run for a second.

#include <algorithm>
#include <chrono>
#include <string>

namespace trailmark::cli {

class ProgressBar {
 public:
  explicit ProgressBar(std::string label, std::string unit = "%");
  ~ProgressBar();
  /// fraction in [0, 1]; `done_units` (e.g. rows) feeds the rate when given.
  void Update(double fraction, double done_units = -1);
  void Finish();

 private:
  std::string label_;
  std::string unit_;
  std::chrono::steady_clock::time_point start_;
  std::chrono::steady_clock::time_point last_draw_;
  bool enabled_;
  bool drawn_ = false;
};

}  // namespace trailmark::cli

// SPDX-License-Identifier: MIT
#pragma once
// Helpers for tests: a temporary directory removed at the end, and file writing.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "trailmark/core/error.h"
#include "trailmark/core/measurements.h"

namespace trailmark::testing {

class TempDir {
 public:
  TempDir() {
    std::random_device rd;
    path_ = std::filesystem::temp_directory_path() /
            ("trailmark-test-" + std::to_string(rd()) + std::to_string(rd()));
    std::filesystem::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  const std::filesystem::path& path() const { return path_; }
  std::string File(const std::string& name, const std::string& content) const {
    const auto p = path_ / name;
    std::ofstream(p, std::ios::binary) << content;
    return p.string();
  }

 private:
  std::filesystem::path path_;
};

}  // namespace trailmark::testing

namespace trailmark::testing {

/// The recorded data folder (../shared/data next to the repository, or $TRAILMARK_SHARED_DATA);
/// empty when absent (tests using it then skip).
inline std::filesystem::path SharedData(const std::string& sub) {
  const char* env = std::getenv("TRAILMARK_SHARED_DATA");
#ifdef TRAILMARK_SHARED_DIR
  const std::filesystem::path base =
      env ? std::filesystem::path(env) : std::filesystem::path(TRAILMARK_SHARED_DIR) / "data";
#else
  const std::filesystem::path base = env ? env : "";
#endif
  const auto p = base / sub;
  return std::filesystem::exists(p) ? p : std::filesystem::path();
}

/// Two runs of one estimator, one with a reported-only error share (a consider parameter) and one
/// without: the same rows and estimates to the bit; with `psd`, every row's covariance grown by
/// a positive semi-definite share (to rounding). Returns the largest growth of the trace.
inline double ExpectSameEstimatesWiderCovariances(const std::vector<Estimate>& with,
                                                  const std::vector<Estimate>& without, bool psd) {
  EXPECT_EQ(with.size(), without.size());
  double grew = 0;
  for (std::size_t i = 0; i < std::min(with.size(), without.size()); ++i) {
    const Estimate& a = with[i];
    const Estimate& b = without[i];
    const double dxx = a.sxx - b.sxx, dyy = a.syy - b.syy, dxy = a.sxy - b.sxy;
    const bool same = a.id == b.id && a.t == b.t && a.position_n == b.position_n;
    const bool wider =
        !psd || (dxx >= -1e-9 && dyy >= -1e-9 && dxx * dyy - dxy * dxy >= -1e-9 * (1 + dxx + dyy));
    if (!same || !wider) {
      ADD_FAILURE() << "row " << i << " " << a.id << " at " << a.t
                    << (same ? ": covariance not wider" : ": another estimate");
      return grew;
    }
    grew = std::max(grew, dxx + dyy);
  }
  return grew;
}

/// Every step of `steps` turned by `deg` degrees (a track's heading offset: a boot's toe-out).
inline void TurnSteps(std::vector<Step>& steps, double deg) {
  const double c = std::cos(deg * M_PI / 180), s = std::sin(deg * M_PI / 180);
  for (Step& st : steps) {
    const double x = st.delta_n.x(), y = st.delta_n.y();
    st.delta_n.x() = c * x - s * y;
    st.delta_n.y() = s * x + c * y;
  }
}

/// Writes `text` to a file named `name` in a fresh directory and expects `read(path)` to throw
/// InputError naming that file at `line` with `problem` in its message.
template <class Read>
void ExpectFileRefused(const std::string& name, const std::string& text, std::size_t line,
                       const std::string& problem, Read&& read) {
  TempDir dir;
  const std::string path = dir.File(name, text);
  try {
    read(path);
    ADD_FAILURE() << "accepted: " << text;
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), path) << e.what();
    EXPECT_EQ(e.line(), line) << e.what();
    EXPECT_NE(std::string(e.what()).find(problem), std::string::npos) << e.what();
  }
}

}  // namespace trailmark::testing

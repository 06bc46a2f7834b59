// SPDX-License-Identifier: MIT
#pragma once
// Helpers for tests: a temporary directory removed at the end, and file writing.

#include <filesystem>
#include <fstream>
#include <cstdlib>
#include <random>
#include <string>

#include <gtest/gtest.h>

#include "trailmark/core/error.h"

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

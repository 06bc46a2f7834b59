// SPDX-License-Identifier: MIT
#include "progress.h"

#include <fmt/format.h>
#include <unistd.h>

#include <cstdio>

namespace trailmark::cli {

ProgressBar::ProgressBar(std::string label, std::string unit)
    : label_(std::move(label)),
      unit_(std::move(unit)),
      start_(std::chrono::steady_clock::now()),
      last_draw_(start_),
      enabled_(isatty(fileno(stderr)) != 0) {}

ProgressBar::~ProgressBar() { Finish(); }

void ProgressBar::Update(double fraction, double done_units) {
  if (!enabled_) return;
  const auto now = std::chrono::steady_clock::now();
  const double elapsed = std::chrono::duration<double>(now - start_).count();
  if (elapsed < 1.0 || std::chrono::duration<double>(now - last_draw_).count() < 0.2) return;
  last_draw_ = now;
  fraction = std::clamp(fraction, 0.0, 1.0);
  constexpr int kWidth = 30;
  const int filled = static_cast<int>(fraction * kWidth);
  const double eta = fraction > 1e-6 ? elapsed * (1.0 - fraction) / fraction : 0.0;
  const std::string rate = done_units >= 0
                               ? fmt::format("{:.0f} {}/s", done_units / elapsed, unit_)
                               : fmt::format("{:.1f} %/s", 100.0 * fraction / elapsed);
  fmt::print(stderr, "\r{} [{}{}] {:5.1f}%  {}  ETA {:.0f}s   ", label_, std::string(filled, '#'),
             std::string(kWidth - filled, '.'), 100.0 * fraction, rate, eta);
  std::fflush(stderr);
  drawn_ = true;
}

void ProgressBar::Finish() {
  if (drawn_) {
    fmt::print(stderr, "\r{}\r", std::string(100, ' '));
    std::fflush(stderr);
    drawn_ = false;
  }
}

}  // namespace trailmark::cli

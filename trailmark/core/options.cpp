// SPDX-License-Identifier: MIT
#include "trailmark/core/options.h"

#include <charconv>

#include <fmt/format.h>

namespace trailmark {

const char* ToString(OptionType type) {
  switch (type) {
    case OptionType::kReal: return "real";
    case OptionType::kInteger: return "integer";
    case OptionType::kBool: return "bool";
    case OptionType::kChoice: return "choice";
  }
  return "?";
}

bool OptionBounds::Contains(double v) const {
  if (min_open ? !(v > min) : !(v >= min)) return false;
  if (max_open ? !(v < max) : !(v <= max)) return false;
  return true;
}

std::string OptionBounds::Describe() const {
  const bool lo = std::isfinite(min), hi = std::isfinite(max);
  if (lo && hi) {
    if (!min_open && !max_open) return fmt::format("within {:g} .. {:g}", min, max);
    return fmt::format("{} {:g} and {} {:g}", min_open ? ">" : ">=", min, max_open ? "<" : "<=",
                       max);
  }
  if (lo) return fmt::format("{} {:g}", min_open ? ">" : ">=", min);
  if (hi) return fmt::format("{} {:g}", max_open ? "<" : "<=", max);
  return "";
}

namespace detail {

std::optional<double> ParseReal(const std::string& text) {
  double v = 0;
  const char* begin = text.data();
  const char* end = begin + text.size();
  if (begin != end && *begin == '+') ++begin;  // from_chars takes no leading '+'
  const auto [ptr, ec] = std::from_chars(begin, end, v);
  if (ec != std::errc() || ptr != end || begin == end || !std::isfinite(v)) return std::nullopt;
  return v;
}

std::optional<bool> ParseBool(const std::string& v) {
  if (v == "1" || v == "true" || v == "on" || v == "yes") return true;
  if (v == "0" || v == "false" || v == "off" || v == "no") return false;
  return std::nullopt;
}

std::string FormatReal(double v) { return fmt::format("{}", v); }

}  // namespace detail
}  // namespace trailmark

// SPDX-License-Identifier: MIT
#include "trailmark/io/json_input.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

#include "trailmark/core/error.h"

namespace trailmark::io_detail {

std::string ReadText(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw InputError(path.string(), 0, "file does not exist");
  const auto size = std::filesystem::file_size(path, ec);
  if (!ec && size > (64u << 20)) {
    throw InputError(path.string(), 0,
                     fmt::format("{} bytes: too large for a JSON description (limit 64 MiB)", size));
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path.string(), 0, "cannot open");
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

namespace {

// Line of a byte offset, for parse errors.
std::size_t LineOf(const std::string& text, std::size_t byte) {
  std::size_t line = 1;
  for (std::size_t i = 0; i < std::min(byte, text.size()); ++i) line += text[i] == '\n';
  return line;
}

}  // namespace

nlohmann::json ParseJson(const std::string& text, const std::string& source) {
  try {
    return nlohmann::json::parse(text);
  } catch (const nlohmann::json::parse_error& e) {
    std::string what = e.what();
    // nlohmann's message starts with "[json.exception.parse_error.101] parse error at ...".
    const auto pos = what.find("] ");
    if (pos != std::string::npos) what = what.substr(pos + 2);
    throw InputError(source, LineOf(text, e.byte), "invalid JSON: " + what);
  } catch (const nlohmann::json::exception& e) {
    // e.g. out_of_range.406 "number overflow parsing '5e500'" (found by the fuzzer)
    std::string what = e.what();
    const auto pos = what.find("] ");
    if (pos != std::string::npos) what = what.substr(pos + 2);
    throw InputError(source, 0, "invalid JSON: " + what);
  }
}

[[noreturn]] void Bad(const std::string& source, const std::string& where,
                      const std::string& problem) {
  throw InputError(source, 0, where + ": " + problem);
}

double Number(const nlohmann::json& j, const std::string& source, const std::string& where) {
  if (!j.is_number()) Bad(source, where, "expected a number");
  const double v = j.get<double>();
  if (!std::isfinite(v)) Bad(source, where, "not a finite number");
  return v;
}

}  // namespace trailmark::io_detail

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

bool ReadBoundedLine(std::istream& in, std::string& line, const std::string& file,
                     std::size_t line_no, std::size_t max_bytes) {
  line.clear();
  std::streambuf* buffer = in.rdbuf();
  for (int c = buffer->sbumpc(); c != std::char_traits<char>::eof(); c = buffer->sbumpc()) {
    if (c == '\n') return true;
    if (line.size() >= max_bytes) {
      throw InputError(file, line_no,
                       fmt::format("line longer than {} bytes: not a text file of this format?",
                                   max_bytes));
    }
    line.push_back(static_cast<char>(c));
  }
  return !line.empty();
}

void WriteFloorPlanMission(const std::filesystem::path& out, const nlohmann::json& mission,
                           const std::string& plan_geojson) {
  std::filesystem::create_directories(out);
  for (const auto& [name, text] : {std::pair<const char*, std::string>{"mission.json", mission.dump(2) + "\n"},
                                   {"floorplan.geojson", plan_geojson}}) {
    std::ofstream f(out / name, std::ios::binary);
    f << text;
    if (!f) throw std::runtime_error((out / name).string() + ": write failed");
  }
}

Vec2 LonLatToMetres(const nlohmann::json& c, const LocalFrame& frame, const std::string& source,
                    const std::string& where, const std::string& origin_name) {
  if (!c.is_array() || c.size() < 2) Bad(source, where, "expected a position [lon, lat]");
  const double lon = Number(c[0], source, where + "/0");
  const double lat = Number(c[1], source, where + "/1");
  if (!IsGeodetic(lat, lon)) {
    Bad(source, where, fmt::format("[{}, {}] is not a WGS84 longitude, latitude", lon, lat));
  }
  const Vec3 enu = frame.ToEnu(lat, lon, frame.origin().height_m);
  const Vec2 p(enu.x(), enu.y());
  if (p.norm() > 50e3) {
    Bad(source, where,
        fmt::format("[{}, {}] is {:.0f} km from {}", lon, lat, p.norm() / 1e3, origin_name));
  }
  return p;
}

std::vector<std::pair<const nlohmann::json*, std::string>> GeoJsonRings(
    const nlohmann::json& g, const std::string& source, const std::string& where) {
  std::vector<std::pair<const nlohmann::json*, std::string>> rings;
  const std::string type = g.contains("type") && g["type"].is_string() ? g["type"].get<std::string>() : "";
  if (!g.contains("coordinates") || !g["coordinates"].is_array()) {
    Bad(source, where + "/coordinates", "expected an array");
  }
  const nlohmann::json& c = g["coordinates"];
  auto polygon = [&](const nlohmann::json& p, const std::string& w) {
    if (!p.is_array()) Bad(source, w, "expected an array of rings");
    for (std::size_t r = 0; r < p.size(); ++r) {
      if (!p[r].is_array()) Bad(source, fmt::format("{}/{}", w, r), "expected a ring");
      rings.emplace_back(&p[r], fmt::format("{}/{}", w, r));
    }
  };
  if (type == "Polygon") {
    polygon(c, where + "/coordinates");
  } else if (type == "MultiPolygon") {
    for (std::size_t k = 0; k < c.size(); ++k) polygon(c[k], fmt::format("{}/coordinates/{}", where, k));
  } else if (type == "LineString") {
    rings.emplace_back(&c, where + "/coordinates");
  }
  return rings;
}

}  // namespace trailmark::io_detail

// SPDX-License-Identifier: MIT
#pragma once
/// Internal to io/: reading JSON input files with errors that name the file, the line (parse
/// errors) or the JSON pointer of the offending value. Not part of the public headers' API
/// (it exposes nlohmann::json).

#include <filesystem>
#include <istream>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include "trailmark/io/geo.h"

namespace trailmark::io_detail {

/// The whole file; InputError when missing, unreadable or above 64 MiB.
std::string ReadText(const std::filesystem::path& path);
/// InputError with the line of a syntax error.
nlohmann::json ParseJson(const std::string& text, const std::string& source);
/// InputError "source: where: problem".
[[noreturn]] void Bad(const std::string& source, const std::string& where,
                      const std::string& problem);
/// A finite number, else InputError naming `where`.
double Number(const nlohmann::json& j, const std::string& source, const std::string& where);

/// The next line of a text file (without its '\n'; a '\r' kept); false at the end. A line
/// longer than `max_bytes` is an InputError naming `file` and `line_no` before it is held in
/// memory (a binary file, or a text file with no line breaks).
bool ReadBoundedLine(std::istream& in, std::string& line, const std::string& file,
                     std::size_t line_no, std::size_t max_bytes = std::size_t{1} << 20);

/// A mission directory of a converted floor plan: `out`/mission.json (`mission`, pretty-printed)
/// and `out`/floorplan.geojson (`plan_geojson`); std::runtime_error when a write fails.
void WriteFloorPlanMission(const std::filesystem::path& out, const nlohmann::json& mission,
                           const std::string& plan_geojson);

/// A GeoJSON position [lon, lat] (WGS 84) as metres east/north of `frame`'s origin. InputError
/// naming `where` for anything but a WGS 84 position, or one more than 50 km from the origin
/// (named `origin_name` in the message): a building is not tens of kilometres across, so it is
/// a wrong location or swapped coordinates.
Vec2 LonLatToMetres(const nlohmann::json& position, const LocalFrame& frame,
                    const std::string& source, const std::string& where,
                    const std::string& origin_name);

/// The rings of a Polygon or MultiPolygon geometry (a LineString as one ring), each with its
/// JSON pointer; none for other types. InputError for coordinates that are not arrays.
std::vector<std::pair<const nlohmann::json*, std::string>> GeoJsonRings(
    const nlohmann::json& geometry, const std::string& source, const std::string& where);

}  // namespace trailmark::io_detail

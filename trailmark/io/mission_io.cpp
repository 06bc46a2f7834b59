// SPDX-License-Identifier: MIT
#include "trailmark/io/mission_io.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>

#include "trailmark/core/error.h"
#include "trailmark/core/random.h"
#include "trailmark/io/json_input.h"

namespace trailmark {
namespace {

using io_detail::Bad;
using io_detail::Number;
using io_detail::ParseJson;
using io_detail::ReadText;
using nlohmann::json;

std::optional<double> OptNumber(const json& obj, const char* key, const std::string& source,
                                const std::string& where) {
  if (!obj.contains(key) || obj[key].is_null()) return std::nullopt;
  return Number(obj[key], source, where + "/" + key);
}

// Plausibility bounds (issue 30): beyond them a value is a wrong unit or a corrupted file, and
// it would only come back as a non-finite estimate. 10,000 km is beyond any incident's frame
// (a local frame in metres; latitude/longitude must be projected first).
constexpr double kMaxCoordinateM = 1e7;
constexpr double kMaxSigmaM = 1e5;       // 100 km: "unknown" is the absent key, not 1e308
constexpr double kMaxHeadingRad = 1e3;   // a few hundred turns: degrees or garbage beyond

Vec3 Position(const json& j, const std::string& source, const std::string& where) {
  if (!j.is_array() || j.size() < 2 || j.size() > 3) {
    Bad(source, where, "expected [x, y] or [x, y, z] in metres");
  }
  Vec3 p = Vec3::Zero();
  for (std::size_t i = 0; i < j.size(); ++i) {
    p[static_cast<int>(i)] = Number(j[i], source, fmt::format("{}/{}", where, i));
    if (std::abs(p[static_cast<int>(i)]) > kMaxCoordinateM) {
      Bad(source, fmt::format("{}/{}", where, i),
          fmt::format("{:g} m is not a position in a local frame (|x| <= {:g} m)",
                      p[static_cast<int>(i)], kMaxCoordinateM));
    }
  }
  return p;
}

std::string String(const json& obj, const char* key, const std::string& source,
                   const std::string& where, bool required) {
  if (!obj.contains(key) || obj[key].is_null()) {
    if (required) Bad(source, where, fmt::format("missing key '{}'", key));
    return {};
  }
  if (!obj[key].is_string()) Bad(source, where + "/" + key, "expected a string");
  return obj[key].get<std::string>();
}

json Pos(const Vec3& p) { return json::array({p.x(), p.y(), p.z()}); }

/// A level: an integer, also when written as a number with nothing after the point (1.0, as
/// Python's json and GeoJSON tools write them); 0.5 or "G" are refused.
int IntegralLevel(const json& j, const std::string& source, const std::string& where) {
  if (!j.is_number()) Bad(source, where, "expected an integer level");
  const double v = j.get<double>();
  if (!(std::abs(v) <= 1000)) Bad(source, where, fmt::format("{:g} is not a plausible level", v));
  if (v != std::floor(v)) Bad(source, where, fmt::format("expected an integer level, not {:g}", v));
  return static_cast<int>(v);
}

}  // namespace

MissionInfo ParseMissionInfo(const std::string& text, const std::string& source) {
  const json root = ParseJson(text, source);
  if (!root.is_object()) Bad(source, "/", "expected a JSON object");
  MissionInfo info;
  info.format = String(root, "format", source, "/", false);
  if (!info.format.empty() && info.format.rfind("trailmark-mission/", 0) != 0) {
    Bad(source, "/format", fmt::format("'{}' is not a trailmark mission", info.format));
  }
  if (!info.format.empty() && info.format != "trailmark-mission/1") {
    Bad(source, "/format", fmt::format("version '{}' is newer than this reader (1)", info.format));
  }
  if (info.format.empty()) info.format = "trailmark-mission/1";
  info.name = String(root, "name", source, "/", false);
  info.description = String(root, "description", source, "/", false);

  if (root.contains("nodes")) {
    const json& nodes = root["nodes"];
    if (!nodes.is_array()) Bad(source, "/nodes", "expected an array");
    std::set<std::string> seen;
    for (std::size_t i = 0; i < nodes.size(); ++i) {
      const std::string where = fmt::format("/nodes/{}", i);
      const json& n = nodes[i];
      if (!n.is_object()) Bad(source, where, "expected an object");
      NodeInfo node;
      node.id = String(n, "id", source, where, true);
      if (!IsValidNodeId(node.id)) {
        Bad(source, where + "/id", fmt::format("'{}' is not a node id ([A-Za-z0-9_.-]+)", node.id));
      }
      if (!seen.insert(node.id).second) {
        Bad(source, where + "/id", fmt::format("node '{}' declared twice", node.id));
      }
      const std::string kind = String(n, "kind", source, where, true);
      const auto parsed = ParseNodeKind(kind);
      if (!parsed) {
        Bad(source, where + "/kind",
            fmt::format("unknown kind '{}' (agent, crumb, landmark, base)", kind));
      }
      node.kind = *parsed;
      if (n.contains("position") && !n["position"].is_null()) {
        node.position = Position(n["position"], source, where + "/position");
      }
      node.position_sigma_m = OptNumber(n, "position_sigma", source, where);
      if (n.contains("start") && !n["start"].is_null()) {
        node.start = Position(n["start"], source, where + "/start");
      }
      node.start_sigma_m = OptNumber(n, "start_sigma", source, where);
      node.start_heading_rad = OptNumber(n, "start_heading", source, where);
      node.start_heading_sigma_rad = OptNumber(n, "start_heading_sigma", source, where);
      for (const auto& [key, sigma] :
           {std::pair{"position_sigma", node.position_sigma_m},
            std::pair{"start_sigma", node.start_sigma_m},
            std::pair{"start_heading_sigma", node.start_heading_sigma_rad}}) {
        if (sigma && *sigma < 0) Bad(source, where + "/" + key, "must not be negative");
        if (sigma && *sigma > kMaxSigmaM) {
          Bad(source, where + "/" + key,
              fmt::format("{:g} is not a plausible sigma (at most {:g}; leave the key out when "
                          "unknown)",
                          *sigma, kMaxSigmaM));
        }
      }
      if (node.start_heading_rad && std::abs(*node.start_heading_rad) > kMaxHeadingRad) {
        Bad(source, where + "/start_heading",
            fmt::format("{:g} is not a heading in radians", *node.start_heading_rad));
      }
      if (node.kind == NodeKind::kBase && !node.position) {
        Bad(source, where, "a base node needs its known 'position'");
      }
      info.nodes.push_back(std::move(node));
    }
  }
  if (root.contains("radio") && !root["radio"].is_null()) {
    const json& r = root["radio"];
    if (!r.is_object()) Bad(source, "/radio", "expected an object");
    RadioCalibration radio;
    radio.model = String(r, "model", source, "/radio", false);
    if (radio.model.empty()) radio.model = "log-distance";
    if (radio.model != "log-distance") {
      Bad(source, "/radio/model", fmt::format("unknown model '{}' (log-distance)", radio.model));
    }
    // Each value is known only where it is given: a partial block (say the shadowing sigma
    // alone) is not a calibration, and the estimators fit the rest (RadioCalibration::Complete).
    const auto alpha = OptNumber(r, "alpha_dbm", source, "/radio");
    const auto exponent = OptNumber(r, "path_loss_exponent", source, "/radio");
    const auto sigma = OptNumber(r, "shadowing_sigma_db", source, "/radio");
    radio.alpha_dbm = alpha.value_or(radio.alpha_dbm);
    radio.path_loss_exponent = exponent.value_or(radio.path_loss_exponent);
    radio.shadowing_sigma_db = sigma.value_or(radio.shadowing_sigma_db);
    radio.alpha_given = alpha.has_value();
    radio.exponent_given = exponent.has_value();
    radio.sigma_given = sigma.has_value();
    if (radio.path_loss_exponent <= 0) Bad(source, "/radio/path_loss_exponent", "must be > 0");
    if (radio.shadowing_sigma_db < 0) Bad(source, "/radio/shadowing_sigma_db", "must be >= 0");
    info.radio = radio;
  }
  if (root.contains("floorplan") && !root["floorplan"].is_null()) {
    info.floorplan = String(root, "floorplan", source, "/", false);
    // A file of the mission directory: never an absolute path or one leading out of it.
    const std::filesystem::path plan(*info.floorplan);
    bool outside = plan.is_absolute() || plan.has_root_name() || info.floorplan->empty();
    for (const auto& part : plan) outside = outside || part == "..";
    if (outside) {
      Bad(source, "/floorplan",
          fmt::format("'{}' is not a file of the mission directory (a relative path without "
                      "'..')",
                      *info.floorplan));
    }
  }
  if (root.contains("floors") && !root["floors"].is_null()) {
    // Spec 1.1 "Floors": each level once, a finite elevation; kept sorted by elevation, which
    // must rise with the level (a level above another cannot lie below it).
    const json& floors = root["floors"];
    if (!floors.is_array()) Bad(source, "/floors", "expected an array of {level, elevation_m}");
    std::set<int> levels;
    for (std::size_t i = 0; i < floors.size(); ++i) {
      const std::string where = fmt::format("/floors/{}", i);
      const json& f = floors[i];
      if (!f.is_object()) Bad(source, where, "expected an object {level, elevation_m}");
      if (!f.contains("level")) Bad(source, where + "/level", "expected an integer level");
      const int level = IntegralLevel(f["level"], source, where + "/level");
      const auto elevation = OptNumber(f, "elevation_m", source, where);
      if (!elevation) Bad(source, where, "missing key 'elevation_m'");
      if (std::abs(*elevation) > 1e4) {
        Bad(source, where + "/elevation_m",
            fmt::format("{:g} m is not a plausible elevation", *elevation));
      }
      if (!levels.insert(static_cast<int>(level)).second) {
        Bad(source, where + "/level", fmt::format("level {} listed twice", level));
      }
      info.floors.push_back({static_cast<int>(level), *elevation});
    }
    std::sort(info.floors.begin(), info.floors.end(),
              [](const FloorLevel& a, const FloorLevel& b) { return a.elevation_m < b.elevation_m; });
    for (std::size_t i = 1; i < info.floors.size(); ++i) {
      const FloorLevel& lo = info.floors[i - 1];
      const FloorLevel& hi = info.floors[i];
      if (!(hi.level > lo.level) || !(hi.elevation_m > lo.elevation_m)) {
        Bad(source, "/floors",
            fmt::format("level {} at {:g} m and level {} at {:g} m: a higher level must lie "
                        "higher",
                        lo.level, lo.elevation_m, hi.level, hi.elevation_m));
      }
    }
  }
  if (root.contains("geo_origin") && !root["geo_origin"].is_null()) {
    const json& g = root["geo_origin"];
    if (!g.is_object()) Bad(source, "/geo_origin", "expected an object {lat_deg, lon_deg, height_m}");
    const auto lat = OptNumber(g, "lat_deg", source, "/geo_origin");
    const auto lon = OptNumber(g, "lon_deg", source, "/geo_origin");
    if (!lat || !lon) Bad(source, "/geo_origin", "missing key 'lat_deg' or 'lon_deg'");
    if (std::abs(*lat) > 90 || std::abs(*lon) > 180) {
      Bad(source, "/geo_origin",
          fmt::format("({:g}, {:g}) is not a WGS 84 latitude, longitude", *lat, *lon));
    }
    const double height = OptNumber(g, "height_m", source, "/geo_origin").value_or(0.0);
    if (std::abs(height) > 1e4) Bad(source, "/geo_origin/height_m", "not a plausible height");
    info.geo_origin = GeoOrigin{*lat, *lon, height};
  }
  return info;
}

MissionInfo ReadMissionInfo(const std::filesystem::path& path) {
  return ParseMissionInfo(ReadText(path), path.string());
}

std::string MissionInfoToJson(const MissionInfo& info) {
  json root;
  root["format"] = info.format;
  root["name"] = info.name;
  if (!info.description.empty()) root["description"] = info.description;
  json nodes = json::array();
  for (const auto& n : info.nodes) {
    json j;
    j["id"] = n.id;
    j["kind"] = std::string(ToString(n.kind));
    if (n.position) j["position"] = Pos(*n.position);
    if (n.position_sigma_m) j["position_sigma"] = *n.position_sigma_m;
    if (n.start) j["start"] = Pos(*n.start);
    if (n.start_sigma_m) j["start_sigma"] = *n.start_sigma_m;
    if (n.start_heading_rad) j["start_heading"] = *n.start_heading_rad;
    if (n.start_heading_sigma_rad) j["start_heading_sigma"] = *n.start_heading_sigma_rad;
    nodes.push_back(j);
  }
  root["nodes"] = nodes;
  if (info.radio) {
    root["radio"] = {{"model", info.radio->model}};
    if (info.radio->alpha_given) root["radio"]["alpha_dbm"] = info.radio->alpha_dbm;
    if (info.radio->exponent_given) {
      root["radio"]["path_loss_exponent"] = info.radio->path_loss_exponent;
    }
    if (info.radio->sigma_given)
      root["radio"]["shadowing_sigma_db"] = info.radio->shadowing_sigma_db;
  }
  if (info.floorplan) root["floorplan"] = *info.floorplan;
  if (!info.floors.empty()) {
    json floors = json::array();
    for (const FloorLevel& f : info.floors) {
      floors.push_back({{"level", f.level}, {"elevation_m", f.elevation_m}});
    }
    root["floors"] = floors;
  }
  if (info.geo_origin) {
    root["geo_origin"] = {{"lat_deg", info.geo_origin->lat_deg},
                          {"lon_deg", info.geo_origin->lon_deg},
                          {"height_m", info.geo_origin->height_m}};
  }
  return root.dump(2) + "\n";
}

void WriteMissionInfo(const std::filesystem::path& path, const MissionInfo& info) {
  std::ofstream out(path, std::ios::binary);
  out << MissionInfoToJson(info);
  if (!out) throw std::runtime_error(path.string() + ": write failed");
}

namespace {
/// An object's string member, "" when absent or not a string (a value of another type is then
/// refused by whoever needs the string, with its path).
std::string StringMember(const nlohmann::json& object, const char* key) {
  const auto it = object.find(key);
  return it != object.end() && it->is_string() ? it->get<std::string>() : std::string();
}
}  // namespace

void RequirePlanInMetres(const std::vector<Segment2>& walls, const std::string& source) {
  // A plan in degrees (longitude/latitude, e.g. an indoor map exported as is) is a building a
  // few ten-thousandths of a unit across: refused, named, instead of an empty search (issue 23).
  Box2 box;
  for (const auto& w : walls) box.Extend(w.a), box.Extend(w.b);
  if (box.Empty()) return;
  const Vec2 size = box.max - box.min;
  if (std::max(size.x(), size.y()) >= 0.05) return;
  const bool lon_lat = std::abs(box.min.x()) <= 180 && std::abs(box.max.x()) <= 180 &&
                       std::abs(box.min.y()) <= 90 && std::abs(box.max.y()) <= 90;
  Bad(source, "/features",
      fmt::format("the walls span {:.3g} x {:.3g} (from ({:.7g}, {:.7g})): {}; the mission "
                  "format's plans are in metres (trailmark convert wrld-indoor converts a WRLD "
                  "indoor map)",
                  size.x(), size.y(), box.min.x(), box.min.y(),
                  lon_lat ? "this looks like longitude/latitude in degrees, not metres"
                          : "far too small for a building in metres"));
}

FloorPlan ParseFloorPlanGeoJson(const std::string& text, const std::string& source,
                                std::optional<int> level, std::vector<int>* levels_present) {
  std::set<int> levels;
  const json root = ParseJson(text, source);
  if (!root.is_object() || StringMember(root, "type") != "FeatureCollection") {
    Bad(source, "/", "expected a GeoJSON FeatureCollection");
  }
  if (!root.contains("features") || !root["features"].is_array()) {
    Bad(source, "/features", "expected an array");
  }
  std::vector<Segment2> walls, doors;
  std::vector<Room> rooms;
  const json& features = root["features"];
  for (std::size_t i = 0; i < features.size(); ++i) {
    const std::string where = fmt::format("/features/{}", i);
    const json& f = features[i];
    if (!f.is_object()) Bad(source, where, "expected a Feature object");
    const json props =
        f.contains("properties") && f["properties"].is_object() ? f["properties"] : json::object();
    // The kind as drawn in any case ("Wall" is a wall); features of other kinds (labels,
    // furniture, ...) are ignored before anything else of theirs is read.
    std::string kind = props.contains("kind") && props["kind"].is_string()
                           ? props["kind"].get<std::string>()
                           : std::string();
    std::transform(kind.begin(), kind.end(), kind.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    if (kind != "wall" && kind != "door" && kind != "room") continue;
    int feature_level = 0;
    if (props.contains("level") && !props["level"].is_null()) {
      feature_level = IntegralLevel(props["level"], source, where + "/properties/level");
    }
    levels.insert(feature_level);
    if (level && feature_level != *level) continue;
    if (!f.contains("geometry") || !f["geometry"].is_object()) {
      Bad(source, where + "/geometry", "missing geometry");
    }
    const json& g = f["geometry"];
    const std::string type = StringMember(g, "type");
    if (!g.contains("coordinates") || !g["coordinates"].is_array()) {
      Bad(source, where + "/geometry/coordinates", "expected an array");
    }
    auto point = [&](const json& c, const std::string& w) {
      if (!c.is_array() || c.size() < 2) Bad(source, w, "expected a position [x, y]");
      return Vec2(Number(c[0], source, w + "/0"), Number(c[1], source, w + "/1"));
    };
    auto line = [&](const json& coords, const std::string& w, std::vector<Segment2>& out) {
      if (coords.size() < 2) Bad(source, w, "a LineString needs at least two positions");
      for (std::size_t k = 0; k + 1 < coords.size(); ++k) {
        out.push_back({point(coords[k], fmt::format("{}/{}", w, k)),
                       point(coords[k + 1], fmt::format("{}/{}", w, k + 1))});
      }
    };
    const json& coords = g["coordinates"];
    const std::string cw = where + "/geometry/coordinates";
    if (kind == "room") {
      if (type != "Polygon") Bad(source, where + "/geometry/type", "a room must be a Polygon");
      if (coords.empty() || !coords[0].is_array()) Bad(source, cw, "expected a ring");
      Room room;
      room.level = feature_level;
      if (props.contains("name") && props["name"].is_string()) room.name = props["name"];
      for (std::size_t k = 0; k < coords[0].size(); ++k) {
        room.ring.push_back(point(coords[0][k], fmt::format("{}/0/{}", cw, k)));
      }
      if (room.ring.size() >= 2 && (room.ring.front() - room.ring.back()).norm() < 1e-12) {
        room.ring.pop_back();
      }
      if (room.ring.size() < 3) Bad(source, cw, "a room needs at least three corners");
      rooms.push_back(std::move(room));
      continue;
    }
    auto& out = kind == "wall" ? walls : doors;
    if (type == "LineString") {
      line(coords, cw, out);
    } else if (type == "MultiLineString") {
      for (std::size_t k = 0; k < coords.size(); ++k) {
        if (!coords[k].is_array()) Bad(source, fmt::format("{}/{}", cw, k), "expected a line");
        line(coords[k], fmt::format("{}/{}", cw, k), out);
      }
    } else {
      Bad(source, where + "/geometry/type",
          fmt::format("a {} must be a LineString or MultiLineString, not '{}'", kind, type));
    }
  }
  if (levels_present) levels_present->assign(levels.begin(), levels.end());
  RequirePlanInMetres(walls, source);
  return FloorPlan(std::move(walls), std::move(doors), std::move(rooms));
}

FloorPlan ReadFloorPlanGeoJson(const std::filesystem::path& path, std::optional<int> level,
                               std::vector<int>* levels_present) {
  return ParseFloorPlanGeoJson(ReadText(path), path.string(), level, levels_present);
}

int DefaultFloorPlanLevel(const std::vector<int>& levels) {
  if (levels.empty() || std::find(levels.begin(), levels.end(), 0) != levels.end()) return 0;
  return *std::min_element(levels.begin(), levels.end());
}

namespace {

// The plan's walls, doors and rooms as GeoJSON features; with `level`, every feature carries it.
void AppendFloorFeatures(json& features, const FloorPlan& plan, std::optional<int> level,
                         bool polyline_walls = false) {
  auto properties = [&](json p) {
    if (level) p["level"] = *level;
    return p;
  };
  auto add_line = [&](const Segment2& s, const char* kind) {
    features.push_back({{"type", "Feature"},
                        {"properties", properties({{"kind", kind}})},
                        {"geometry",
                         {{"type", "LineString"},
                          {"coordinates", json::array({json::array({s.a.x(), s.a.y()}),
                                                       json::array({s.b.x(), s.b.y()})})}}}});
  };
  const auto& walls = plan.walls();
  for (std::size_t i = 0; i < walls.size();) {
    // A run of walls each starting where the previous ended: one LineString when asked.
    std::size_t j = i + 1;
    while (polyline_walls && j < walls.size() && walls[j].a == walls[j - 1].b) ++j;
    if (j == i + 1) {
      add_line(walls[i], "wall");
    } else {
      json coords = json::array({json::array({walls[i].a.x(), walls[i].a.y()})});
      for (std::size_t k = i; k < j; ++k) coords.push_back(json::array({walls[k].b.x(), walls[k].b.y()}));
      features.push_back({{"type", "Feature"},
                          {"properties", properties({{"kind", "wall"}})},
                          {"geometry", {{"type", "LineString"}, {"coordinates", coords}}}});
    }
    i = j;
  }
  for (const auto& d : plan.doors()) add_line(d, "door");
  for (const auto& r : plan.rooms()) {
    json ring = json::array();
    for (const auto& p : r.ring) ring.push_back(json::array({p.x(), p.y()}));
    ring.push_back(json::array({r.ring.front().x(), r.ring.front().y()}));
    features.push_back(
        {{"type", "Feature"},
         {"properties", properties({{"kind", "room"}, {"name", r.name}, {"level", r.level}})},
         {"geometry", {{"type", "Polygon"}, {"coordinates", json::array({ring})}}}});
  }
}

std::string FeatureCollection(json features) {
  return json{{"type", "FeatureCollection"}, {"features", std::move(features)}}.dump() + "\n";
}

}  // namespace

std::string FloorPlanToGeoJson(const FloorPlan& plan, bool polyline_walls) {
  json features = json::array();
  AppendFloorFeatures(features, plan, std::nullopt, polyline_walls);
  return FeatureCollection(std::move(features));
}

std::string FloorPlanToGeoJson(const std::vector<std::pair<int, FloorPlan>>& floors,
                               bool polyline_walls) {
  json features = json::array();
  for (const auto& [level, plan] : floors) AppendFloorFeatures(features, plan, level, polyline_walls);
  return FeatureCollection(std::move(features));
}

std::string RestyleCsv(const std::string& text, const MissionWriteStyle& style,
                       std::uint64_t stream_seed) {
  Random rng(style.seed ^ (stream_seed * 0x9e3779b97f4a7c15ULL));
  std::vector<std::string> lines;
  for (std::size_t at = 0; at < text.size();) {
    std::size_t end = text.find('\n', at);
    if (end == std::string::npos) end = text.size();
    lines.push_back(text.substr(at, end - at));
    at = end + 1;
  }
  if (lines.empty()) return text;
  auto split = [](const std::string& line) {
    std::vector<std::string> cells;
    std::size_t at = 0;
    for (std::size_t comma; (comma = line.find(',', at)) != std::string::npos; at = comma + 1)
      cells.push_back(line.substr(at, comma - at));
    cells.push_back(line.substr(at));
    return cells;
  };
  const std::size_t columns = split(lines.front()).size();
  std::vector<std::size_t> order(columns);
  for (std::size_t i = 0; i < columns; ++i) order[i] = i;
  if (style.csv_shuffled_columns) {
    for (std::size_t i = columns; i > 1; --i)
      std::swap(order[i - 1], order[static_cast<std::size_t>(rng.Uniform() * static_cast<double>(i))]);
  }
  const std::size_t extra_at =
      static_cast<std::size_t>(rng.Uniform() * static_cast<double>(columns + 1));
  std::string out;
  out.reserve(text.size() + text.size() / 8);
  if (style.csv_comments) out += "# written by trailmark simulate --vary: comments, column order and extra columns are allowed\n";
  for (std::size_t li = 0; li < lines.size(); ++li) {
    if (lines[li].empty()) continue;
    if (style.csv_comments && li > 0 && rng.Uniform() < 0.01) out += "# a comment between rows\n";
    const std::vector<std::string> cells = split(lines[li]);
    std::vector<std::string> drawn;
    for (std::size_t i = 0; i < columns; ++i) drawn.push_back(order[i] < cells.size() ? cells[order[i]] : "");
    if (style.csv_extra_column)
      drawn.insert(drawn.begin() + static_cast<std::ptrdiff_t>(extra_at),
                   li == 0 ? "operator_note" : (li % 3 == 0 ? "\"smoke, heavy\"" : ""));
    for (std::size_t i = 0; i < drawn.size(); ++i) {
      if (i > 0) out += ',';
      out += drawn[i];
    }
    out += '\n';
  }
  return out;
}

void WriteMissionDirectory(const std::filesystem::path& dir, const MissionData& data,
                           const FloorPlan* plan, const MissionWriteStyle& style) {
  std::filesystem::create_directories(dir);
  MissionInfo info = data.info;
  if (plan != nullptr && !info.floorplan) info.floorplan = "floorplan.geojson";
  WriteMissionInfo(dir / "mission.json", info);
  const bool restyle = style.csv_comments || style.csv_shuffled_columns || style.csv_extra_column;
  std::uint64_t stream_seed = 0;
  auto write = [&](const auto& rows) {
    using Row = typename std::decay_t<decltype(rows)>::value_type;
    ++stream_seed;
    const std::filesystem::path path = dir / StreamFileName<Row>();
    if (rows.empty()) {
      // The directory holds what was written: a stream file of an earlier mission written
      // there would otherwise be read as this one's.
      std::error_code ignored;
      std::filesystem::remove(path, ignored);
      return;
    }
    WriteAll<Row>(path.string(), rows);
    if (restyle) {
      const std::string text = RestyleCsv(ReadText(path), style, stream_seed);
      std::ofstream out(path, std::ios::binary | std::ios::trunc);
      out << text;
      if (!out) throw std::runtime_error(path.string() + ": write failed");
    }
  };
  write(data.imu);
  write(data.steps);
  write(data.rssi);
  write(data.ranges);
  write(data.bearings);
  write(data.events);
  write(data.baro);
  write(data.truth);
  if (plan != nullptr) {
    std::ofstream out(dir / *info.floorplan, std::ios::binary);
    out << FloorPlanToGeoJson(*plan, style.polyline_walls);
    if (!out) throw std::runtime_error((dir / *info.floorplan).string() + ": write failed");
  }
}

void WriteMissionDirectory(const std::filesystem::path& dir, const MissionData& data,
                           const std::vector<std::pair<int, FloorPlan>>& levels,
                           const MissionWriteStyle& style) {
  MissionData with_plan = data;
  if (!with_plan.info.floorplan) with_plan.info.floorplan = "floorplan.geojson";
  WriteMissionDirectory(dir, with_plan, nullptr, style);
  const std::filesystem::path path = dir / *with_plan.info.floorplan;
  std::ofstream out(path, std::ios::binary);
  out << FloorPlanToGeoJson(levels, style.polyline_walls);
  if (!out) throw std::runtime_error(path.string() + ": write failed");
}

MissionData ReadMissionData(const MissionDirectory& mission) {
  MissionData data;
  data.info = mission.info();
  auto read = [&](auto& rows) {
    using Row = typename std::decay_t<decltype(rows)>::value_type;
    if (!mission.HasStream<Row>()) return;
    auto reader = mission.OpenStream<Row>();
    Row row;
    while (reader.Next(row)) rows.push_back(row);
  };
  read(data.imu);
  read(data.steps);
  read(data.rssi);
  read(data.ranges);
  read(data.bearings);
  read(data.events);
  read(data.baro);
  read(data.truth);
  return data;
}

MissionDirectory::MissionDirectory(std::filesystem::path dir) : dir_(std::move(dir)) {
  std::error_code ec;
  if (!std::filesystem::is_directory(dir_, ec)) {
    throw InputError(dir_.string(), 0, "not a mission directory (does not exist or not a folder)");
  }
  info_ = ReadMissionInfo(dir_ / "mission.json");
  for (const auto& n : info_.nodes) registry_.Add(n.id, n.kind);
  if (Has("events.csv")) {
    // Pass 1 over events: crumbs that drops introduce. Ids are checked for syntax here and
    // against the registry (declared ids + all drops) when the stream is read for real.
    RowReader<MissionEvent> events(Path("events.csv").string());
    MissionEvent e;
    std::set<std::string> seen;
    while (events.Next(e)) {
      if (e.event != "drop") continue;
      // A drop puts a crumb (or beacon) down: an agent or a base is not dropped.
      if (const NodeInfo* n = info_.Find(e.node);
          n != nullptr && (n->kind == NodeKind::kAgent || n->kind == NodeKind::kBase)) {
        throw InputError(Path("events.csv").string(), events.csv().line(),
                         fmt::format("'{}' is {} in mission.json: a 'drop' event's node is the "
                                     "crumb or beacon dropped",
                                     e.node, n->kind == NodeKind::kAgent ? "an agent" : "a base"));
      }
      if (!registry_.Contains(e.node) && seen.insert(e.node).second) {
        dropped_.push_back(e.node);
      }
    }
    for (const auto& id : dropped_) registry_.Add(id, NodeKind::kCrumb);
  }
}

bool MissionDirectory::Has(const std::string& file) const {
  std::error_code ec;
  return std::filesystem::is_regular_file(dir_ / file, ec);
}

void MissionDirectory::Require(const std::string& file, const std::string& needed_by) const {
  if (!Has(file)) {
    throw InputError((dir_ / file).string(), 0,
                     fmt::format("missing: {} needs this file", needed_by));
  }
}

FloorPlan ReadFloorPlanFloor(const std::filesystem::path& path, std::optional<int> level,
                             std::vector<int>* levels_present) {
  const std::string text = ReadText(path);
  std::vector<int> levels;
  FloorPlan all = ParseFloorPlanGeoJson(text, path.string(), std::nullopt, &levels);
  if (levels_present) *levels_present = levels;
  if (level && !levels.empty() && std::find(levels.begin(), levels.end(), *level) == levels.end()) {
    throw InputError(path.string(), 0,
                     fmt::format("the floor plan has no level {} (its levels: {})", *level,
                                 fmt::join(levels, ", ")));
  }
  if (levels.size() <= 1 && !level) return all;
  return ParseFloorPlanGeoJson(text, path.string(), level.value_or(DefaultFloorPlanLevel(levels)));
}

std::optional<FloorPlan> MissionDirectory::LoadFloorPlan(std::optional<int> level,
                                                         std::vector<int>* levels_present) const {
  if (!info_.floorplan) return std::nullopt;
  return ReadFloorPlanFloor(dir_ / *info_.floorplan, level, levels_present);
}

}  // namespace trailmark

// SPDX-License-Identifier: MIT
#include "trailmark/io/convert_imdf.h"

#include <fmt/format.h>
#include <zip.h>

#include <cmath>
#include <fstream>
#include <set>

#include "trailmark/core/error.h"
#include "trailmark/io/geo.h"
#include "trailmark/io/json_input.h"
#include "trailmark/io/mission_io.h"

namespace trailmark {
namespace {

using nlohmann::json;
using io_detail::Bad;

constexpr std::size_t kMaxFileBytes = 64u << 20;
const char* const kFiles[] = {"manifest.json", "venue.geojson", "level.geojson", "unit.geojson",
                              "opening.geojson"};

/// The IMDF files we read, by name, with the name errors give each.
struct ImdfFiles {
  std::map<std::string, std::pair<std::string, std::string>> files;  ///< name -> (source, text)
  const std::pair<std::string, std::string>* Find(const std::string& name) const {
    const auto it = files.find(name);
    return it == files.end() ? nullptr : &it->second;
  }
};

std::string BaseName(const std::string& entry) {
  const auto slash = entry.find_last_of('/');
  return slash == std::string::npos ? entry : entry.substr(slash + 1);
}

ImdfFiles ReadZip(const std::filesystem::path& path) {
  const std::string archive = path.string();
  int error = 0;
  zip_t* za = zip_open(archive.c_str(), ZIP_RDONLY, &error);
  if (za == nullptr) {
    zip_error_t ze;
    zip_error_init_with_code(&ze, error);
    const std::string what = zip_error_strerror(&ze);
    zip_error_fini(&ze);
    throw InputError(archive, 0, "not a readable zip archive: " + what);
  }
  ImdfFiles out;
  try {
    const zip_int64_t n = zip_get_num_entries(za, 0);
    for (zip_int64_t i = 0; i < n; ++i) {
      const char* raw = zip_get_name(za, static_cast<zip_uint64_t>(i), 0);
      if (raw == nullptr) continue;
      const std::string entry = raw, name = BaseName(entry);
      if (std::find(std::begin(kFiles), std::end(kFiles), name) == std::end(kFiles)) continue;
      if (entry.find("__MACOSX") != std::string::npos) continue;  // macOS resource forks
      const std::string source = archive + ":" + entry;
      if (out.files.count(name)) throw InputError(source, 0, "a second " + name + " in the archive");
      zip_stat_t st;
      if (zip_stat_index(za, static_cast<zip_uint64_t>(i), 0, &st) != 0 || !(st.valid & ZIP_STAT_SIZE)) {
        throw InputError(source, 0, "cannot read its size in the archive");
      }
      if (st.size > kMaxFileBytes) throw InputError(source, 0, "larger than 64 MiB");
      zip_file_t* f = zip_fopen_index(za, static_cast<zip_uint64_t>(i), 0);
      if (f == nullptr) throw InputError(source, 0, std::string("cannot open: ") + zip_strerror(za));
      std::string text(static_cast<std::size_t>(st.size), '\0');
      const zip_int64_t got = zip_fread(f, text.data(), st.size);
      zip_fclose(f);
      if (got < 0 || static_cast<zip_uint64_t>(got) != st.size) {
        throw InputError(source, 0, "damaged in the archive (short read or bad checksum)");
      }
      out.files[name] = {source, std::move(text)};
    }
  } catch (...) {
    zip_discard(za);
    throw;
  }
  zip_discard(za);
  return out;
}

ImdfFiles ReadFolder(const std::filesystem::path& dir) {
  ImdfFiles out;
  for (const char* name : kFiles) {
    const auto path = dir / name;
    if (std::filesystem::exists(path)) out.files[name] = {path.string(), io_detail::ReadText(path)};
  }
  return out;
}

/// A FeatureCollection's features array.
const json& Features(const json& root, const std::string& source) {
  if (!root.is_object() || !root.contains("features") || !root["features"].is_array()) {
    Bad(source, "/features", "expected a GeoJSON FeatureCollection with a features array");
  }
  return root["features"];
}

/// An IMDF LABELS object's English text, else its first; empty when absent.
std::string Label(const json& props, const char* key) {
  if (!props.contains(key) || !props[key].is_object() || props[key].empty()) return {};
  const json& labels = props[key];
  if (labels.contains("en") && labels["en"].is_string()) return labels["en"];
  for (const auto& [lang, text] : labels.items()) {
    if (text.is_string()) return text;
  }
  return {};
}

const json& Properties(const json& f, const std::string& source, const std::string& where) {
  if (!f.is_object()) Bad(source, where, "expected a Feature object");
  if (!f.contains("properties") || !f["properties"].is_object()) {
    Bad(source, where + "/properties", "expected an object");
  }
  return f["properties"];
}

std::string LevelId(const json& props, const std::string& source, const std::string& where) {
  if (!props.contains("level_id") || !props["level_id"].is_string()) {
    Bad(source, where + "/properties/level_id", "expected the id of a level");
  }
  return props["level_id"];
}

/// A GeoJSON position [lon, lat] as a frame origin; nullopt for anything else (the fallbacks
/// for a venue without a display point look for one, they do not judge the data).
std::optional<GeoOrigin> OriginAt(const json& c) {
  if (!c.is_array() || c.size() < 2 || !c[0].is_number() || !c[1].is_number()) return std::nullopt;
  const double lon = c[0].get<double>(), lat = c[1].get<double>();
  if (!IsGeodetic(lat, lon)) return std::nullopt;
  return GeoOrigin{lat, lon, 0.0};
}

/// Unit categories that are not rooms: open circulation, solid material, voids, outdoors.
bool IsRoomCategory(const std::string& category) {
  static const std::set<std::string> not_rooms{
      "walkway", "structure", "opentobelow", "brick", "concrete", "drywall", "glass", "wood",
      "column", "road", "parking", "vegetation", "unenclosedarea", "fieldofplay", "footbridge",
      "platform", "ramp", "movingwalkway", "escalator", "steps"};
  return not_rooms.count(category) == 0;
}

/// Undirected edge key, at 1 mm: an edge two units share is one wall.
std::pair<std::pair<long long, long long>, std::pair<long long, long long>> EdgeKey(const Vec2& a,
                                                                                   const Vec2& b) {
  auto q = [](const Vec2& p) {
    return std::make_pair(std::llround(p.x() * 1000), std::llround(p.y() * 1000));
  };
  auto ka = q(a), kb = q(b);
  if (kb < ka) std::swap(ka, kb);
  return {ka, kb};
}

}  // namespace

ImdfVenue ReadImdfVenue(const std::filesystem::path& source, std::optional<GeoOrigin> origin) {
  if (!std::filesystem::exists(source)) throw InputError(source.string(), 0, "does not exist");
  const ImdfFiles files =
      std::filesystem::is_directory(source) ? ReadFolder(source) : ReadZip(source);
  for (const char* required : {"level.geojson", "unit.geojson"}) {
    if (!files.Find(required)) {
      throw InputError(source.string(), 0, std::string("no ") + required + ": not an IMDF venue");
    }
  }
  ImdfVenue venue;
  // The origin: given, else the venue's display point.
  if (const auto* v = files.Find("venue.geojson")) {
    const json root = io_detail::ParseJson(v->second, v->first);
    const json& features = Features(root, v->first);
    if (!features.empty()) {
      const json& props = Properties(features[0], v->first, "/features/0");
      venue.name = Label(props, "name");
      if (!origin && props.contains("display_point") && props["display_point"].is_object()) {
        const json& p = props["display_point"];
        const std::string where = "/features/0/properties/display_point/coordinates";
        if (!p.contains("coordinates") || !p["coordinates"].is_array() || p["coordinates"].size() < 2) {
          Bad(v->first, where, "expected [lon, lat]");
        }
        const double lon = io_detail::Number(p["coordinates"][0], v->first, where + "/0");
        const double lat = io_detail::Number(p["coordinates"][1], v->first, where + "/1");
        if (!IsGeodetic(lat, lon)) Bad(v->first, where, "not a WGS 84 longitude, latitude");
        origin = GeoOrigin{lat, lon, 0.0};
      }
    }
  }
  // Levels by ordinal.
  const auto& [level_source, level_text] = *files.Find("level.geojson");
  const json levels_root = io_detail::ParseJson(level_text, level_source);
  std::map<std::string, int> ordinal_of;
  std::map<int, ImdfLevel> by_ordinal;
  const json& level_features = Features(levels_root, level_source);
  for (std::size_t i = 0; i < level_features.size(); ++i) {
    const std::string where = fmt::format("/features/{}", i);
    const json& f = level_features[i];
    const json& props = Properties(f, level_source, where);
    if (!f.contains("id") || !f["id"].is_string()) Bad(level_source, where + "/id", "expected a feature id");
    if (!props.contains("ordinal") || !props["ordinal"].is_number_integer() ||
        std::abs(props["ordinal"].get<std::int64_t>()) > 1000) {
      Bad(level_source, where + "/properties/ordinal", "expected an integer ordinal");
    }
    const int ordinal = props["ordinal"].get<int>();
    const std::string id = f["id"];
    if (!ordinal_of.emplace(id, ordinal).second) Bad(level_source, where + "/id", "level '" + id + "' twice");
    ImdfLevel& level = by_ordinal[ordinal];
    level.ordinal = ordinal;
    level.ids.push_back(id);
    if (level.name.empty()) level.name = Label(props, "name");
    // Without a venue display point, the first level's.
    if (!origin && props.contains("display_point") && props["display_point"].is_object() &&
        props["display_point"].contains("coordinates")) {
      origin = OriginAt(props["display_point"]["coordinates"]);
    }
  }
  if (by_ordinal.empty()) throw InputError(level_source, 0, "no levels");
  for (const auto& [ordinal, level] : by_ordinal) {
    if (level.ids.size() > 1) {
      venue.notes.push_back(fmt::format("ordinal {}: {} IMDF levels (several buildings) drawn as one level",
                                        ordinal, level.ids.size()));
    }
  }

  const auto& [unit_source, unit_text] = *files.Find("unit.geojson");
  const json units_root = io_detail::ParseJson(unit_text, unit_source);
  const json& units = Features(units_root, unit_source);
  if (!origin) {  // the first unit's first position
    for (const json& f : units) {
      if (f.is_object() && f.contains("geometry") && f["geometry"].is_object()) {
        const auto rings = io_detail::GeoJsonRings(f["geometry"], unit_source, "/features");
        if (!rings.empty() && !rings[0].first->empty()) origin = OriginAt((*rings[0].first)[0]);
        if (origin) break;
      }
    }
  }
  if (!origin) throw InputError(unit_source, 0, "no position to place the venue's frame at");
  venue.origin = *origin;
  const LocalFrame frame(*origin);
  const std::string origin_name = "the venue's origin";
  auto level_for = [&](const json& props, const std::string& src, const std::string& where) -> ImdfLevel& {
    const std::string id = LevelId(props, src, where);
    const auto it = ordinal_of.find(id);
    if (it == ordinal_of.end()) Bad(src, where + "/properties/level_id", "no level '" + id + "' in level.geojson");
    return by_ordinal[it->second];
  };
  std::map<int, std::set<decltype(EdgeKey(Vec2(), Vec2()))>> seen_edges;
  for (std::size_t i = 0; i < units.size(); ++i) {
    const std::string where = fmt::format("/features/{}", i);
    const json& f = units[i];
    const json& props = Properties(f, unit_source, where);
    ImdfLevel& level = level_for(props, unit_source, where);
    if (!f.contains("geometry") || !f["geometry"].is_object()) {
      Bad(unit_source, where + "/geometry", "a unit needs a polygon");
    }
    const std::string category =
        props.contains("category") && props["category"].is_string() ? props["category"].get<std::string>() : "unspecified";
    for (const auto& [ring, w] : io_detail::GeoJsonRings(f["geometry"], unit_source, where + "/geometry")) {
      std::vector<Vec2> pts;
      for (std::size_t k = 0; k < ring->size(); ++k) {
        pts.push_back(io_detail::LonLatToMetres((*ring)[k], frame, unit_source, fmt::format("{}/{}", w, k), origin_name));
      }
      for (std::size_t k = 1; k < pts.size(); ++k) {
        if ((pts[k] - pts[k - 1]).norm() < 1e-3) continue;
        if (seen_edges[level.ordinal].insert(EdgeKey(pts[k - 1], pts[k])).second) {
          level.walls.push_back({pts[k - 1], pts[k]});
        }
      }
      if (w.ends_with("/0") && IsRoomCategory(category)) {
        Room r;
        r.name = category == "stairs" ? "stairs" : Label(props, "name");
        if (r.name.empty()) r.name = category;
        r.level = level.ordinal;
        r.ring = pts;
        if (r.ring.size() > 1 && (r.ring.front() - r.ring.back()).norm() < 1e-9) r.ring.pop_back();
        if (r.ring.size() >= 3) level.rooms.push_back(std::move(r));
      }
    }
  }
  if (const auto* o = files.Find("opening.geojson")) {
    const json root = io_detail::ParseJson(o->second, o->first);
    const json& openings = Features(root, o->first);
    for (std::size_t i = 0; i < openings.size(); ++i) {
      const std::string where = fmt::format("/features/{}", i);
      const json& f = openings[i];
      const json& props = Properties(f, o->first, where);
      ImdfLevel& level = level_for(props, o->first, where);
      if (!f.contains("geometry") || !f["geometry"].is_object() ||
          f["geometry"].value("type", "") != "LineString") {
        Bad(o->first, where + "/geometry", "an opening needs a LineString");
      }
      const auto rings = io_detail::GeoJsonRings(f["geometry"], o->first, where + "/geometry");
      std::vector<Vec2> pts;
      for (std::size_t k = 0; k < rings[0].first->size(); ++k) {
        pts.push_back(io_detail::LonLatToMetres((*rings[0].first)[k], frame, o->first,
                                                fmt::format("{}/{}", rings[0].second, k), origin_name));
      }
      for (std::size_t k = 1; k < pts.size(); ++k) {
        if ((pts[k] - pts[k - 1]).norm() >= 1e-3) level.doors.push_back({pts[k - 1], pts[k]});
      }
    }
  } else {
    venue.notes.push_back("no opening.geojson: no doors (every unit closed)");
  }
  for (auto& [ordinal, level] : by_ordinal) venue.levels.push_back(std::move(level));
  return venue;
}

void WriteImdfMission(const ImdfVenue& venue, const std::filesystem::path& out) {
  std::vector<std::pair<int, FloorPlan>> floors;
  json levels = json::array();
  for (const ImdfLevel& l : venue.levels) {
    floors.emplace_back(l.ordinal, l.Plan());
    levels.push_back({{"level", l.ordinal}, {"imdf_ids", l.ids}, {"name", l.name}});
  }
  const json mission{
      {"format", "trailmark-mission/1"},
      {"name", venue.name.empty() ? std::string("imdf-venue") : venue.name},
      {"description", "floor plan of an IMDF venue, metres east/north of its display point"},
      {"nodes", json::array()},
      {"floorplan", "floorplan.geojson"},
      {"provenance", {{"converted_from", "imdf"}, {"levels", levels}}},
      {"geo_origin",
       {{"lat_deg", venue.origin.lat_deg}, {"lon_deg", venue.origin.lon_deg}, {"height_m", 0.0}}}};
  io_detail::WriteFloorPlanMission(out, mission, FloorPlanToGeoJson(floors));
}

}  // namespace trailmark

// SPDX-License-Identifier: MIT
#include "trailmark/io/convert_wrld.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <numbers>
#include <optional>

#include <Eigen/Eigenvalues>
#include <set>

#include "trailmark/core/error.h"
#include "trailmark/io/json_input.h"
#include "trailmark/io/geo.h"
#include "trailmark/io/mission_io.h"

namespace trailmark {
namespace {

using nlohmann::json;
using io_detail::Bad;
using io_detail::Number;

const std::set<std::string>& BlockingTypes() {
  static const std::set<std::string> types{"wall",   "window",   "building_outline",
                                           "stairs", "elevator", "inaccessible_space",
                                           "floor_opening"};
  return types;
}

/// A door polygon (a thin shape across the gap between two wall polygons) as the segment along
/// its long axis through its centroid: the opening the door gives, drawn across the gap.
std::optional<Segment2> DoorSegment(std::vector<Vec2> pts) {
  if (pts.size() > 2 && (pts.front() - pts.back()).norm() < 1e-9) pts.pop_back();  // closed ring
  if (pts.size() < 2) return std::nullopt;
  Vec2 c = Vec2::Zero();
  for (const Vec2& p : pts) c += p;
  c /= static_cast<double>(pts.size());
  Eigen::Matrix2d scatter = Eigen::Matrix2d::Zero();
  for (const Vec2& p : pts) scatter += (p - c) * (p - c).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(scatter);
  const Vec2 axis = eig.eigenvectors().col(1);  // the larger eigenvalue's
  double lo = 0, hi = 0;
  for (const Vec2& p : pts) {
    lo = std::min(lo, (p - c).dot(axis));
    hi = std::max(hi, (p - c).dot(axis));
  }
  if (hi - lo < 1e-3) return std::nullopt;
  return Segment2{c + lo * axis, c + hi * axis};
}

WrldLevel ReadLevel(const std::filesystem::path& path, const LocalFrame& proj) {
  const std::string source = path.string();
  const json root = io_detail::ParseJson(io_detail::ReadText(path), source);
  if (!root.is_object() || !root.contains("features") || !root["features"].is_array()) {
    Bad(source, "/features", "expected a GeoJSON FeatureCollection with a features array");
  }
  WrldLevel level;
  const json& features = root["features"];
  for (std::size_t i = 0; i < features.size(); ++i) {
    const std::string where = fmt::format("/features/{}", i);
    const json& f = features[i];
    if (!f.is_object()) Bad(source, where, "expected a Feature object");
    if (!f.contains("properties") || !f["properties"].is_object()) continue;
    const json& props = f["properties"];
    const std::string type =
        props.contains("type") && props["type"].is_string() ? props["type"].get<std::string>() : "";
    const bool blocking = BlockingTypes().count(type) > 0;
    const bool room = type == "room" || type == "bathroom";
    const bool door = type == "door";
    if (!blocking && !room && !door) continue;
    if (!f.contains("geometry") || f["geometry"].is_null()) continue;  // "no_geometry" items
    if (!f["geometry"].is_object()) Bad(source, where + "/geometry", "expected an object");
    for (const auto& [ring, w] : io_detail::GeoJsonRings(f["geometry"], source, where + "/geometry")) {
      std::vector<Vec2> pts;
      for (std::size_t k = 0; k < ring->size(); ++k) {
        pts.push_back(io_detail::LonLatToMetres((*ring)[k], proj, source, fmt::format("{}/{}", w, k),
                                                "the building's location in main.json"));
      }
      if (door) {
        if (w.ends_with("/0")) {
          if (const auto d = DoorSegment(pts)) level.doors.push_back(*d);
        }
      } else if (blocking) {
        for (std::size_t k = 1; k < pts.size(); ++k) {
          if ((pts[k] - pts[k - 1]).norm() > 1e-9) level.walls.push_back({pts[k - 1], pts[k]});
        }
      } else if (w.ends_with("/0") && pts.size() >= 3) {  // a room's outer ring
        Room r;
        if (props.contains("name") && props["name"].is_string()) r.name = props["name"];
        r.ring = pts;
        if ((r.ring.front() - r.ring.back()).norm() < 1e-9) r.ring.pop_back();
        if (r.ring.size() >= 3) level.rooms.push_back(std::move(r));
      }
    }
  }
  return level;
}

}  // namespace

const WrldLevel* WrldBuilding::Level(const std::string& id) const {
  for (const auto& l : levels) {
    if (l.id == id) return &l;
  }
  return nullptr;
}

WrldBuilding ReadWrldBuilding(const std::filesystem::path& dir) {
  const std::filesystem::path main_path = dir / "main.json";
  const std::string source = main_path.string();
  const json main = io_detail::ParseJson(io_detail::ReadText(main_path), source);
  if (!main.is_object()) Bad(source, "/", "expected an object");
  WrldBuilding b;
  if (main.contains("id") && main["id"].is_string()) b.id = main["id"];
  if (main.contains("name") && main["name"].is_string()) b.name = main["name"];
  if (!main.contains("location") || !main["location"].is_object() ||
      !main["location"].contains("coordinates")) {
    Bad(source, "/location", "expected a GeoJSON Point with coordinates [lon, lat]");
  }
  const json& loc = main["location"]["coordinates"];
  if (!loc.is_array() || loc.size() < 2) {
    Bad(source, "/location/coordinates", "expected [lon, lat]");
  }
  b.lon0_deg = Number(loc[0], source, "/location/coordinates/0");
  b.lat0_deg = Number(loc[1], source, "/location/coordinates/1");
  if (std::abs(b.lon0_deg) > 180 || std::abs(b.lat0_deg) >= 89) {
    Bad(source, "/location/coordinates", "not a WGS84 longitude, latitude (|lat| < 89)");
  }
  if (!main.contains("levels") || !main["levels"].is_array() || main["levels"].empty()) {
    Bad(source, "/levels", "expected a non-empty array of levels");
  }
  const LocalFrame proj(GeoOrigin{b.lat0_deg, b.lon0_deg, 0.0});
  std::set<int> z_seen;
  const json& levels = main["levels"];
  for (std::size_t i = 0; i < levels.size(); ++i) {
    const std::string where = fmt::format("/levels/{}", i);
    const json& l = levels[i];
    if (!l.is_object() || !l.contains("filename") || !l["filename"].is_string()) {
      Bad(source, where, "expected an object with a \"filename\"");
    }
    const std::string file = l["filename"];
    if (file.empty() || file.find("..") != std::string::npos || file.front() == '/') {
      Bad(source, where + "/filename", "'" + file + "' is not a file name inside the folder");
    }
    const double z = l.contains("z_order") ? Number(l["z_order"], source, where + "/z_order")
                                           : static_cast<double>(i);
    if (z != std::floor(z) || std::abs(z) > 1000) {
      Bad(source, where + "/z_order", "expected a whole number");
    }
    if (!z_seen.insert(static_cast<int>(z)).second) {
      Bad(source, where + "/z_order", fmt::format("z_order {} used by two levels", z));
    }
    WrldLevel level = ReadLevel(dir / file, proj);
    level.z_order = static_cast<int>(z);
    for (auto& r : level.rooms) r.level = level.z_order;
    if (l.contains("id") && l["id"].is_string()) level.id = l["id"];
    if (l.contains("name") && l["name"].is_string()) level.name = l["name"];
    b.levels.push_back(std::move(level));
  }
  std::sort(b.levels.begin(), b.levels.end(),
            [](const WrldLevel& a, const WrldLevel& c) { return a.z_order < c.z_order; });
  return b;
}

std::string WrldFloorPlanGeoJson(const WrldBuilding& b) {
  std::vector<std::pair<int, FloorPlan>> floors;
  std::vector<Segment2> walls;
  for (const auto& l : b.levels) {
    floors.emplace_back(l.z_order, l.Plan());
    walls.insert(walls.end(), floors.back().second.walls().begin(),
                 floors.back().second.walls().end());
  }
  RequirePlanInMetres(walls, b.id.empty() ? std::string("the WRLD building") : b.id);
  return FloorPlanToGeoJson(floors);
}

void WriteWrldMission(const WrldBuilding& b, const std::filesystem::path& out) {
  json levels = json::array();
  for (const auto& l : b.levels) {
    levels.push_back({{"level", l.z_order}, {"wrld_id", l.id}, {"name", l.name}});
  }
  const json mission{
      {"format", "trailmark-mission/1"},
      {"name", b.id.empty() ? std::string("wrld-building") : b.id},
      {"description", fmt::format("floor plan of {} (WRLD Indoor Map Format v1), metres east/"
                                  "north of its location",
                                  b.name.empty() ? b.id : b.name)},
      {"nodes", json::array()},
      {"floorplan", "floorplan.geojson"},
      {"provenance",
       {{"converted_from", "wrld-indoor"}, {"levels", levels}}},
      {"geo_origin", {{"lat_deg", b.lat0_deg}, {"lon_deg", b.lon0_deg}, {"height_m", 0.0}}}};
  io_detail::WriteFloorPlanMission(out, mission, WrldFloorPlanGeoJson(b));
}

}  // namespace trailmark

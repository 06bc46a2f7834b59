// SPDX-License-Identifier: MIT
#include "trailmark/io/geo.h"

#include <GeographicLib/LocalCartesian.hpp>
#include <fmt/format.h>

#include <cmath>
#include <stdexcept>

#include "trailmark/io/json_input.h"

namespace trailmark {

struct LocalFrame::Impl {
  GeographicLib::LocalCartesian frame;
};

bool IsGeodetic(double lat_deg, double lon_deg) {
  return std::isfinite(lat_deg) && std::isfinite(lon_deg) && std::abs(lat_deg) <= 90 &&
         std::abs(lon_deg) <= 180;
}

LocalFrame::LocalFrame(const GeoOrigin& origin) : origin_(origin) {
  if (!IsGeodetic(origin.lat_deg, origin.lon_deg) || !std::isfinite(origin.height_m)) {
    throw std::invalid_argument(fmt::format(
        "({}, {}) is not a WGS 84 latitude, longitude", origin.lat_deg, origin.lon_deg));
  }
  impl_ = std::make_unique<Impl>(
      Impl{GeographicLib::LocalCartesian(origin.lat_deg, origin.lon_deg, origin.height_m)});
}

LocalFrame::~LocalFrame() = default;
LocalFrame::LocalFrame(const LocalFrame& other)
    : origin_(other.origin_), impl_(std::make_unique<Impl>(*other.impl_)) {}
LocalFrame& LocalFrame::operator=(const LocalFrame& other) {
  if (this != &other) {
    origin_ = other.origin_;
    impl_ = std::make_unique<Impl>(*other.impl_);
  }
  return *this;
}

Vec3 LocalFrame::ToEnu(double lat_deg, double lon_deg, double height_m) const {
  double x = 0, y = 0, z = 0;
  impl_->frame.Forward(lat_deg, lon_deg, height_m, x, y, z);
  return Vec3(x, y, z);
}

GeoOrigin LocalFrame::ToGeodetic(const Vec3& enu_m) const {
  GeoOrigin g;
  impl_->frame.Reverse(enu_m.x(), enu_m.y(), enu_m.z(), g.lat_deg, g.lon_deg, g.height_m);
  return g;
}

namespace {

/// Replaces every position [x, y(, z)] under `coords` by [lon, lat]; `depth` levels of arrays
/// above the positions (0: a Point's position).
void ToLonLat(nlohmann::json& coords, int depth, const LocalFrame& frame, const std::string& source,
              const std::string& where) {
  if (!coords.is_array()) io_detail::Bad(source, where, "expected an array");
  if (depth > 0) {
    for (std::size_t k = 0; k < coords.size(); ++k) {
      ToLonLat(coords[k], depth - 1, frame, source, where + "/" + std::to_string(k));
    }
    return;
  }
  if (coords.size() < 2) io_detail::Bad(source, where, "expected a position [x, y]");
  const double x = io_detail::Number(coords[0], source, where + "/0");
  const double y = io_detail::Number(coords[1], source, where + "/1");
  // On the frame's tangent plane (z = 0): within a building its height above the ellipsoid
  // differs by millimetres, which move latitude and longitude by nanometres.
  const GeoOrigin g = frame.ToGeodetic(Vec3(x, y, 0));
  coords = nlohmann::json::array({g.lon_deg, g.lat_deg});
}

int PositionDepth(const std::string& type) {
  if (type == "Point") return 0;
  if (type == "LineString" || type == "MultiPoint") return 1;
  if (type == "Polygon" || type == "MultiLineString") return 2;
  if (type == "MultiPolygon") return 3;
  return -1;
}

}  // namespace

std::string FloorPlanToWgs84GeoJson(const std::string& geojson, const std::string& source,
                                    const GeoOrigin& origin) {
  const LocalFrame frame(origin);
  nlohmann::json root = io_detail::ParseJson(geojson, source);
  if (!root.is_object() || !root.contains("features") || !root["features"].is_array()) {
    io_detail::Bad(source, "/features", "expected a GeoJSON FeatureCollection");
  }
  for (std::size_t i = 0; i < root["features"].size(); ++i) {
    nlohmann::json& f = root["features"][i];
    const std::string where = "/features/" + std::to_string(i) + "/geometry";
    if (!f.is_object() || !f.contains("geometry") || f["geometry"].is_null()) continue;
    nlohmann::json& g = f["geometry"];
    if (!g.is_object() || !g.contains("type") || !g["type"].is_string()) {
      io_detail::Bad(source, where, "expected a geometry with a type");
    }
    const int depth = PositionDepth(g["type"].get<std::string>());
    if (depth < 0) io_detail::Bad(source, where + "/type", "not a geometry this export knows");
    if (!g.contains("coordinates")) io_detail::Bad(source, where, "no coordinates");
    ToLonLat(g["coordinates"], depth, frame, source, where + "/coordinates");
  }
  root.erase("crs");  // RFC 7946: WGS 84 longitude, latitude is the only system
  root["trailmark_geo_origin"] = {{"lat_deg", origin.lat_deg}, {"lon_deg", origin.lon_deg},
                                  {"height_m", origin.height_m}};
  return root.dump() + "\n";
}

}  // namespace trailmark

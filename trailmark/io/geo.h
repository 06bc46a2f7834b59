// SPDX-License-Identifier: MIT
#pragma once
/// WGS 84 latitude, longitude and height <-> metres of the local east-north-up frame at an
/// origin (mission.json's "geo_origin"), through GeographicLib's LocalCartesian: exact on the
/// ellipsoid (a spherical equirectangular formula is 0.34 % short in the east at 56 deg N).
/// x east, y north, z up (ROS REP 103's ENU). Used by every converter of geographic data and by
/// the WGS 84 export of floor plans.

#include <memory>
#include <string>

#include "trailmark/core/mission.h"

namespace trailmark {

class LocalFrame {
 public:
  /// Throws std::invalid_argument for a latitude beyond +-90 deg or a longitude beyond
  /// +-180 deg (e.g. swapped coordinates).
  explicit LocalFrame(const GeoOrigin& origin);
  ~LocalFrame();
  LocalFrame(const LocalFrame&);
  LocalFrame& operator=(const LocalFrame&);

  const GeoOrigin& origin() const { return origin_; }
  /// Metres east, north, up of a geodetic point.
  Vec3 ToEnu(double lat_deg, double lon_deg, double height_m = 0) const;
  /// The geodetic point of a position in the frame.
  GeoOrigin ToGeodetic(const Vec3& enu_m) const;

 private:
  struct Impl;
  GeoOrigin origin_;
  std::unique_ptr<Impl> impl_;
};

/// A floor plan GeoJSON of the mission format (metres of the navigation frame) as WGS 84 GeoJSON
/// (RFC 7946: [longitude, latitude] in degrees) for GIS tools, the frame placed at `origin`;
/// every feature and property kept, a z coordinate left out. Throws InputError naming `source`
/// and the JSON pointer of a position that is not [x, y].
std::string FloorPlanToWgs84GeoJson(const std::string& geojson, const std::string& source,
                                    const GeoOrigin& origin);

/// Whether (lat, lon) are a WGS 84 latitude and longitude (finite, within +-90 / +-180 deg).
bool IsGeodetic(double lat_deg, double lon_deg);

}  // namespace trailmark

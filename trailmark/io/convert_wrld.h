// SPDX-License-Identifier: MIT
#pragma once
/// Converter: a building in the WRLD Indoor Map Format v1 (wrld3d/wrld-indoor-maps-api:
/// main.json naming the levels, one GeoJSON FeatureCollection per level in WGS84 lon/lat) into
/// the mission format's floor plan — metres east/north of the building's location in main.json
/// (the WGS 84 local tangent plane at that point, through GeographicLib: io/geo.h; recorded as
/// mission.json's geo_origin), one `level` per WRLD level (its z_order), walls as LineStrings.
///
/// Walls: the edges of the polygons of the types that cannot be walked through — wall,
/// window, building_outline, stairs, elevator, inaccessible_space, floor_opening (a lift or a
/// stairwell is a block on a floor plan; a search goes round it). Doors: each door polygon (a
/// thin shape across the gap the map leaves between wall polygons) as a door segment along its
/// long axis, drawn across the gap (spec 1.1). Rooms: the outer ring of room and bathroom
/// polygons, with their name. Other types are ignored.

#include <filesystem>
#include <string>
#include <vector>

#include "trailmark/geometry/floor_plan.h"

namespace trailmark {

struct WrldLevel {
  std::string id, name;
  int z_order = 0;  ///< the mission floor plan's `level`
  std::vector<Segment2> walls;
  std::vector<Segment2> doors;
  std::vector<Room> rooms;  ///< level = z_order
  FloorPlan Plan() const { return FloorPlan(walls, doors, rooms); }
};

struct WrldBuilding {
  std::string id, name;
  double lon0_deg = 0, lat0_deg = 0;  ///< origin of the metric frame (main.json location)
  std::vector<WrldLevel> levels;      ///< in z_order
  /// The level with this WRLD id (e.g. "westport-house-floor-1"); nullptr when absent.
  const WrldLevel* Level(const std::string& id) const;
};

/// Reads `dir`/main.json and every level file it names. Throws InputError naming the file and
/// the JSON pointer of a bad value: a missing level file, a position that is not [lon, lat] or
/// lies more than 50 km from main.json's location, two levels with one z_order.
WrldBuilding ReadWrldBuilding(const std::filesystem::path& dir);

/// The building as a mission floor plan (all levels; the spec's "Floor plans").
std::string WrldFloorPlanGeoJson(const WrldBuilding& building);

/// A mission directory holding the floor plan: mission.json (no nodes; name, provenance) and
/// floorplan.geojson — the plan to put next to recorded streams from that building.
void WriteWrldMission(const WrldBuilding& building, const std::filesystem::path& out_dir);

}  // namespace trailmark

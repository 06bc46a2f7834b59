// SPDX-License-Identifier: MIT
#pragma once
/// Converter: an IMDF venue (Indoor Mapping Data Format 1.0, OGC Community Standard 20-094: the
/// archive integrators receive from venue owners, a .zip or its unpacked folder of GeoJSON
/// FeatureCollections in WGS 84) into the mission format's multi-floor floor plan.
///
/// - level.geojson: one mission `level` per IMDF `ordinal` (levels of several buildings with one
///   ordinal become one level, noted); names kept.
/// - unit.geojson: every unit polygon's edges are walls (edges two units share once); units of
///   a room-like category (room, restroom, ...; not walkway, structure, opentobelow) become
///   rooms with their English (else first) name; `stairs` units become rooms named "stairs"
///   (map matching changes level there).
/// - opening.geojson: each opening LineString is a door drawn along the unit edges it opens
///   (spec 1.1: "along a wall").
/// - fixture.geojson (optional): obstruction-like fixtures are not walls (a search goes round
///   furniture without a plan) and are ignored; other files are not read.
/// Metres east/north of the venue's display point (or `origin`) through GeographicLib
/// (io/geo.h), recorded as mission.json's geo_origin.

#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "trailmark/core/mission.h"
#include "trailmark/geometry/floor_plan.h"

namespace trailmark {

struct ImdfLevel {
  int ordinal = 0;
  std::string name;
  std::vector<std::string> ids;  ///< the IMDF level features merged into it
  std::vector<Segment2> walls;
  std::vector<Segment2> doors;
  std::vector<Room> rooms;  ///< level = ordinal
  FloorPlan Plan() const { return FloorPlan(walls, doors, rooms); }
};

struct ImdfVenue {
  std::string name;
  GeoOrigin origin;
  std::vector<ImdfLevel> levels;  ///< by ordinal
  std::vector<std::string> notes;
};

/// Reads `source`: an IMDF .zip archive or the folder it unpacks to (manifest.json optional;
/// level.geojson and unit.geojson required, venue.geojson and opening.geojson read when
/// present). Throws InputError naming the file (inside the archive: "archive.zip:unit.geojson")
/// and the JSON pointer of a bad value: a feature without a geometry or level_id its file
/// needs, a level_id no level has, a position that is not WGS 84 or lies more than 50 km from
/// the origin, a level without an integer ordinal, a damaged archive.
ImdfVenue ReadImdfVenue(const std::filesystem::path& source,
                        std::optional<GeoOrigin> origin = std::nullopt);

/// mission.json (no nodes; geo_origin, the levels' IMDF ids and names under provenance) and
/// floorplan.geojson.
void WriteImdfMission(const ImdfVenue& venue, const std::filesystem::path& out_dir);

}  // namespace trailmark

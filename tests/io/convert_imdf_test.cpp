// SPDX-License-Identifier: MIT
// The IMDF venue converter on a venue written by hand from the format's description (OGC
// 20-094): levels by ordinal, unit edges as walls (a shared edge once), openings as doors along
// them, rooms with their names, metres against the geodesic reference; the same venue as a zip
// archive; bad input named by file and JSON pointer.
#include "trailmark/io/convert_imdf.h"

#include <GeographicLib/Geodesic.hpp>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <zip.h>

#include "test_util.h"
#include "trailmark/core/error.h"
#include "trailmark/io/mission_io.h"

namespace trailmark {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;

// Level 0 at (lon 2.35, lat 48.85): a walkway 2e-4 deg east of a room 1e-4 deg square, sharing
// the edge at lon 2.3501; an opening on that edge; a stairs unit east of the walkway, sharing
// its east edge. Level 1: one room.
constexpr const char* kVenue = R"({"type":"FeatureCollection","features":[{"id":"v1","type":"Feature",
  "feature_type":"venue","geometry":null,"properties":{"category":"businesscampus",
  "name":{"fr":"Campus","en":"Campus"},"display_point":{"type":"Point","coordinates":[2.35,48.85]}}}]})";
constexpr const char* kLevels = R"({"type":"FeatureCollection","features":[
  {"id":"L0","type":"Feature","feature_type":"level","geometry":null,
   "properties":{"category":"unspecified","ordinal":0,"outdoor":false,"name":{"en":"Ground"}}},
  {"id":"L1","type":"Feature","feature_type":"level","geometry":null,
   "properties":{"category":"unspecified","ordinal":1,"outdoor":false,"name":{"en":"First"}}}]})";
constexpr const char* kUnits = R"({"type":"FeatureCollection","features":[
  {"id":"u1","type":"Feature","feature_type":"unit","properties":{"category":"room","level_id":"L0",
   "name":{"de":"Kueche","en":"Kitchen"}},"geometry":{"type":"Polygon","coordinates":
   [[[2.35,48.85],[2.3501,48.85],[2.3501,48.8501],[2.35,48.8501],[2.35,48.85]]]}},
  {"id":"u2","type":"Feature","feature_type":"unit","properties":{"category":"walkway","level_id":"L0",
   "name":null},"geometry":{"type":"Polygon","coordinates":
   [[[2.3501,48.85],[2.3503,48.85],[2.3503,48.8501],[2.3501,48.8501],[2.3501,48.85]]]}},
  {"id":"u3","type":"Feature","feature_type":"unit","properties":{"category":"stairs","level_id":"L0"},
   "geometry":{"type":"Polygon","coordinates":
   [[[2.3503,48.85],[2.3504,48.85],[2.3504,48.8501],[2.3503,48.8501],[2.3503,48.85]]]}},
  {"id":"u4","type":"Feature","feature_type":"unit","properties":{"category":"room","level_id":"L1"},
   "geometry":{"type":"Polygon","coordinates":
   [[[2.35,48.85],[2.3501,48.85],[2.3501,48.8501],[2.35,48.8501],[2.35,48.85]]]}}]})";
constexpr const char* kOpenings = R"({"type":"FeatureCollection","features":[
  {"id":"o1","type":"Feature","feature_type":"opening","properties":{"category":"pedestrian",
   "level_id":"L0","door":{"type":"hinged","automatic":false,"material":"wood"}},
   "geometry":{"type":"LineString","coordinates":[[2.3501,48.85004],[2.3501,48.85006]]}}]})";

double GeodesicM(double lat1, double lon1, double lat2, double lon2) {
  double s12 = 0;
  GeographicLib::Geodesic::WGS84().Inverse(lat1, lon1, lat2, lon2, s12);
  return s12;
}

void WriteVenue(const testing::TempDir& dir, const std::string& units = kUnits,
                const std::string& levels = kLevels) {
  dir.File("manifest.json", R"({"version":"1.0.0","language":"en"})");
  dir.File("venue.geojson", kVenue);
  dir.File("level.geojson", levels);
  dir.File("unit.geojson", units);
  dir.File("opening.geojson", kOpenings);
}

TEST(ImdfConverter, LevelsUnitsAndOpeningsIntoAMultiFloorPlan) {
  testing::TempDir dir;
  WriteVenue(dir);
  const ImdfVenue venue = ReadImdfVenue(dir.path());
  EXPECT_EQ(venue.name, "Campus");
  EXPECT_EQ(venue.origin.lat_deg, 48.85);
  ASSERT_EQ(venue.levels.size(), 2u);
  const ImdfLevel& g = venue.levels[0];
  EXPECT_EQ(g.ordinal, 0);
  EXPECT_EQ(g.name, "Ground");
  // Three rectangles in a row: 12 edges, the two shared ones once: 10 walls.
  EXPECT_EQ(g.walls.size(), 10u);
  ASSERT_EQ(g.doors.size(), 1u);
  // Metres against the geodesic: the room's east edge at 1e-4 deg of longitude.
  const double east_m = GeodesicM(48.85, 2.35, 48.85, 2.3501);
  EXPECT_NEAR(g.doors[0].a.x(), east_m, 1e-3);
  EXPECT_NEAR((g.doors[0].b - g.doors[0].a).norm(), GeodesicM(48.85004, 2.3501, 48.85006, 2.3501), 1e-3);
  ASSERT_EQ(g.rooms.size(), 2u);  // the room and the stairs; the walkway is not a room
  EXPECT_EQ(g.rooms[0].name, "Kitchen");
  EXPECT_EQ(g.rooms[1].name, "stairs");
  EXPECT_EQ(g.rooms[0].ring.size(), 4u);
  const FloorPlan plan = g.Plan();
  const double north_m = GeodesicM(48.85, 2.35, 48.8501, 2.35);  // 11.1 m
  const double door_y = (g.doors[0].a.y() + g.doors[0].b.y()) / 2;
  EXPECT_FALSE(plan.Crosses({east_m - 1, door_y}, {east_m + 1, door_y}));  // through the door
  EXPECT_TRUE(plan.Crosses({east_m - 1, 0.2 * north_m}, {east_m + 1, 0.2 * north_m}));
  EXPECT_EQ(venue.levels[1].walls.size(), 4u);
  EXPECT_TRUE(venue.levels[1].doors.empty());

  // As a mission: both levels, the origin recorded.
  testing::TempDir out;
  WriteImdfMission(venue, out.path());
  const MissionDirectory mission(out.path());
  std::vector<int> levels;
  ASSERT_TRUE(mission.LoadFloorPlan(std::nullopt, &levels));
  EXPECT_EQ(levels, (std::vector<int>{0, 1}));
  EXPECT_EQ(mission.LoadFloorPlan(0)->doors().size(), 1u);
  ASSERT_TRUE(mission.info().geo_origin);
  EXPECT_EQ(mission.info().geo_origin->lon_deg, 2.35);
}

TEST(ImdfConverter, AZipArchiveReadsAsItsFolder) {
  testing::TempDir dir;
  WriteVenue(dir);
  const std::string archive = (dir.path() / "venue.zip").string();
  int error = 0;
  zip_t* za = zip_open(archive.c_str(), ZIP_CREATE | ZIP_TRUNCATE, &error);
  ASSERT_NE(za, nullptr);
  for (const char* name : {"manifest.json", "venue.geojson", "level.geojson", "unit.geojson", "opening.geojson"}) {
    zip_source_t* src = zip_source_file(za, (dir.path() / name).c_str(), 0, -1);
    ASSERT_NE(src, nullptr);
    ASSERT_GE(zip_file_add(za, (std::string("venue/") + name).c_str(), src, ZIP_FL_OVERWRITE), 0);
  }
  ASSERT_EQ(zip_close(za), 0);
  const ImdfVenue from_zip = ReadImdfVenue(archive);
  const ImdfVenue from_folder = ReadImdfVenue(dir.path());
  ASSERT_EQ(from_zip.levels.size(), from_folder.levels.size());
  for (std::size_t k = 0; k < from_zip.levels.size(); ++k) {
    ASSERT_EQ(from_zip.levels[k].walls.size(), from_folder.levels[k].walls.size());
    for (std::size_t w = 0; w < from_zip.levels[k].walls.size(); ++w) {
      EXPECT_EQ(from_zip.levels[k].walls[w].a, from_folder.levels[k].walls[w].a);
      EXPECT_EQ(from_zip.levels[k].walls[w].b, from_folder.levels[k].walls[w].b);
    }
  }
  // Not a zip at all.
  const std::string junk = dir.File("junk.zip", "PK\x03\x04 this is not an archive");
  try {
    ReadImdfVenue(junk);
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_THAT(e.what(), AllOf(HasSubstr("junk.zip"), HasSubstr("not a readable zip archive")));
  }
}

TEST(ImdfConverter, BadInputIsNamed) {
  auto error = [](const std::string& units, const std::string& levels = kLevels) {
    testing::TempDir dir;
    WriteVenue(dir, units, levels);
    try {
      ReadImdfVenue(dir.path());
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_EQ(error(kUnits), "");
  EXPECT_THAT(error(R"({"type":"FeatureCollection","features":[{"id":"u","type":"Feature",
      "properties":{"category":"room","level_id":"L9"},"geometry":{"type":"Polygon","coordinates":[[[2.35,48.85],[2.3501,48.85]]]}}]})"),
              AllOf(HasSubstr("unit.geojson"), HasSubstr("/features/0/properties/level_id"),
                    HasSubstr("no level 'L9'")));
  EXPECT_THAT(error(R"({"type":"FeatureCollection","features":[{"id":"u","type":"Feature",
      "properties":{"category":"room","level_id":"L0"},"geometry":{"type":"Polygon","coordinates":[[[2.35,48.85],[400000,5400000]]]}}]})"),
              AllOf(HasSubstr("/features/0/geometry/coordinates/0/1"), HasSubstr("not a WGS84")));
  EXPECT_THAT(error(R"({"type":"FeatureCollection","features":[{"id":"u","type":"Feature",
      "properties":{"category":"room","level_id":"L0"},"geometry":{"type":"Polygon","coordinates":[[[2.35,48.85],[3.35,48.85]]]}}]})"),
              HasSubstr("km from the venue's origin"));
  EXPECT_THAT(error(kUnits, R"({"type":"FeatureCollection","features":[{"id":"L0","type":"Feature",
      "properties":{"ordinal":"ground"}}]})"),
              AllOf(HasSubstr("level.geojson"), HasSubstr("/features/0/properties/ordinal")));
  EXPECT_THAT(error("{\"type\":\"FeatureCollection\",\n\"features\":[}"),
              AllOf(HasSubstr("unit.geojson:2"), HasSubstr("invalid JSON")));
  testing::TempDir empty;
  empty.File("level.geojson", kLevels);
  try {
    ReadImdfVenue(empty.path());
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_THAT(e.what(), HasSubstr("no unit.geojson: not an IMDF venue"));
  }
}

}  // namespace
}  // namespace trailmark

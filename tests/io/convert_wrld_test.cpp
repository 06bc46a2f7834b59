// SPDX-License-Identifier: MIT
// The WRLD indoor-map converter: exact metres on a hand-made building, named errors, and the
// real Westport House map (../shared/data/floorplan-westport-house, read in place; skipped
// without it) converted into a mission whose floors read back as they were converted.
#include "trailmark/io/convert_wrld.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <GeographicLib/Geodesic.hpp>

#include <cmath>
#include <numbers>

#include "test_util.h"
#include "trailmark/core/error.h"
#include "trailmark/io/geo.h"
#include "trailmark/io/json_input.h"
#include "trailmark/io/mission_io.h"

#include <nlohmann/json.hpp>

namespace trailmark {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;

// The geodesic distance between two WGS 84 points (GeographicLib's geodesic: the reference).
double GeodesicM(double lat1, double lon1, double lat2, double lon2) {
  double s12 = 0;
  GeographicLib::Geodesic::WGS84().Inverse(lat1, lon1, lat2, lon2, s12);
  return s12;
}

// A one-level building at (lon 10, lat 60): a wall rectangle 2e-4 deg east by 1e-4 deg north,
// a room, a door polygon (a thin quadrilateral) and a no_geometry item.
void WriteBuilding(const testing::TempDir& dir, const std::string& level_json) {
  dir.File("main.json", R"({"id":"b","name":"B","location":{"type":"Point","coordinates":[10,60]},
    "levels":[{"id":"b-up","name":"1","z_order":1,"filename":"up.geojson"},
              {"id":"b-g","name":"G","z_order":0,"filename":"g.geojson"}]})");
  dir.File("up.geojson", R"({"type":"FeatureCollection","features":[]})");
  dir.File("g.geojson", level_json);
}

constexpr const char* kGround = R"({"type":"FeatureCollection","features":[
  {"type":"Feature","properties":{"type":"wall"},"geometry":{"type":"Polygon","coordinates":
    [[[10,60],[10.0002,60],[10.0002,60.0001],[10,60.0001],[10,60]]]}},
  {"type":"Feature","properties":{"type":"door"},"geometry":{"type":"Polygon","coordinates":
    [[[10.00005,59.999999],[10.00007,59.999999],[10.00007,60.000001],[10.00005,60.000001],
      [10.00005,59.999999]]]}},
  {"type":"Feature","properties":{"type":"room","name":"office"},"geometry":{"type":"Polygon",
    "coordinates":[[[10,60],[10.0001,60],[10.0001,60.0001],[10,60]]]}},
  {"type":"Feature","properties":{"type":"no_geometry"},"geometry":null}]})";

TEST(WrldConverter, ProjectsLevelsIntoMetresExactly) {
  testing::TempDir dir;
  WriteBuilding(dir, kGround);
  const WrldBuilding b = ReadWrldBuilding(dir.path());
  ASSERT_EQ(b.levels.size(), 2u);
  EXPECT_EQ(b.levels[0].id, "b-g");  // sorted by z_order
  EXPECT_EQ(b.levels[0].z_order, 0);
  const WrldLevel& g = b.levels[0];
  ASSERT_EQ(g.walls.size(), 4u);  // the rectangle's edges; the door polygon is not a wall
  // Metres on the ellipsoid: the geodesic distances (1 mm; a parallel bends off the east axis
  // by d^2 tan(lat) / 2N, 0.07 mm here).
  EXPECT_NEAR(g.walls[0].a.norm(), 0, 1e-9);
  EXPECT_NEAR(g.walls[0].b.x(), GeodesicM(60, 10, 60, 10.0002), 1e-3);  // 11.17 m
  EXPECT_NEAR(g.walls[0].b.y(), 0, 1e-3);
  EXPECT_NEAR(g.walls[1].b.y(), GeodesicM(60, 10.0002, 60.0001, 10.0002), 1e-3);  // 11.13 m
  // The door: along its long axis (east-west, 2e-5 deg = 1.12 m) through its centre, on the
  // south wall.
  ASSERT_EQ(g.doors.size(), 1u);
  EXPECT_NEAR((g.doors[0].b - g.doors[0].a).norm(), GeodesicM(60, 10.00005, 60, 10.00007), 1e-3);
  EXPECT_NEAR(g.doors[0].a.y(), 0, 1e-3);
  EXPECT_NEAR(std::min(g.doors[0].a.x(), g.doors[0].b.x()), GeodesicM(60, 10, 60, 10.00005), 1e-3);
  ASSERT_EQ(g.rooms.size(), 1u);
  EXPECT_EQ(g.rooms[0].name, "office");
  EXPECT_EQ(g.rooms[0].ring.size(), 3u);  // the closing point dropped
  // Written as a mission: the floors read back one at a time.
  testing::TempDir out;
  WriteWrldMission(b, out.path());
  const MissionDirectory mission(out.path());
  std::vector<int> levels;
  const auto plan = mission.LoadFloorPlan(std::nullopt, &levels);
  EXPECT_EQ(levels, (std::vector<int>{0}));  // level 1 has no features
  ASSERT_TRUE(plan.has_value());
  EXPECT_EQ(plan->doors().size(), 1u);
  EXPECT_TRUE(plan->Crosses({1, 1}, {1, -1}));
  EXPECT_FALSE(plan->Crosses({1, 1}, {10, 10}));
  EXPECT_FALSE(plan->Crosses({3.3, 1}, {3.3, -1}));  // through the door, open in the south wall
  ASSERT_TRUE(mission.info().geo_origin.has_value());
  EXPECT_EQ(mission.info().geo_origin->lat_deg, 60);
  // Exported back to WGS 84 for GIS tools: the walls' corners where the WRLD map had them.
  const nlohmann::json wgs = nlohmann::json::parse(FloorPlanToWgs84GeoJson(
      io_detail::ReadText(mission.Path("floorplan.geojson")), "floorplan.geojson",
      *mission.info().geo_origin));
  std::vector<std::pair<double, double>> corners;
  for (const auto& f : wgs["features"]) {
    if (f["properties"]["kind"] != "wall") continue;
    for (const auto& c : f["geometry"]["coordinates"]) corners.emplace_back(c[0], c[1]);
  }
  ASSERT_FALSE(corners.empty());
  for (const auto& [lon, lat] : corners) {
    const double lon_corner = lon < 10.0001 ? 10.0 : 10.0002, lat_corner = lat < 60.00005 ? 60.0 : 60.0001;
    EXPECT_NEAR(lon, lon_corner, 1e-10);
    EXPECT_NEAR(lat, lat_corner, 1e-10);
  }
}

TEST(WrldConverter, BadInputIsNamed) {
  auto error = [](const std::string& level_json, const std::string& main_json = "") {
    testing::TempDir dir;
    WriteBuilding(dir, level_json);
    if (!main_json.empty()) dir.File("main.json", main_json);
    try {
      ReadWrldBuilding(dir.path());
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_EQ(error(kGround), "");
  EXPECT_THAT(error(R"({"type":"FeatureCollection","features":[{"type":"Feature",
      "properties":{"type":"wall"},"geometry":{"type":"Polygon","coordinates":[[[10,60],[10]]]}}]})"),
              AllOf(HasSubstr("g.geojson"), HasSubstr("/features/0/geometry/coordinates/0/1"),
                    HasSubstr("[lon, lat]")));
  // Projected coordinates instead of lon/lat, or a map of another place.
  EXPECT_THAT(error(R"({"type":"FeatureCollection","features":[{"type":"Feature",
      "properties":{"type":"wall"},"geometry":{"type":"Polygon","coordinates":[[[10,60],[11,60]]]}}]})"),
              AllOf(HasSubstr("g.geojson"), HasSubstr("km from the building's location")));
  EXPECT_THAT(error(R"({"type":"FeatureCollection","features":[{"type":"Feature",
      "properties":{"type":"wall"},"geometry":{"type":"Polygon","coordinates":[[[350000,6200000],[1,1]]]}}]})"),
              HasSubstr("not a WGS84"));
  EXPECT_THAT(error("{\"type\":\"FeatureCollection\",\n\"features\":[}"),
              AllOf(HasSubstr("g.geojson:2"), HasSubstr("invalid JSON")));
  EXPECT_THAT(error(kGround, R"({"location":{"coordinates":[10,60]},"levels":[
      {"filename":"g.geojson","z_order":0},{"filename":"up.geojson","z_order":0}]})"),
              AllOf(HasSubstr("main.json"), HasSubstr("/levels/1/z_order"), HasSubstr("two levels")));
  EXPECT_THAT(error(kGround, R"({"location":{"coordinates":[10,60]},"levels":[
      {"filename":"missing.geojson"}]})"),
              AllOf(HasSubstr("missing.geojson"), HasSubstr("does not exist")));
  EXPECT_THAT(error(kGround, R"({"location":{"coordinates":[10,60]},"levels":[
      {"filename":"../g.geojson"}]})"),
              AllOf(HasSubstr("/levels/0/filename"), HasSubstr("inside the folder")));
  EXPECT_THAT(error(kGround, R"({"levels":[]})"), HasSubstr("/location"));
  testing::TempDir empty;
  try {
    ReadWrldBuilding(empty.path());
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_THAT(e.what(), AllOf(HasSubstr("main.json"), HasSubstr("does not exist")));
  }
}

TEST(WrldConverter, WestportHouseConvertsIntoAMultiFloorMission) {
  const auto dir = testing::SharedData("floorplan-westport-house");
  if (dir.empty()) GTEST_SKIP() << "../shared/data/floorplan-westport-house not found";
  const WrldBuilding b = ReadWrldBuilding(dir);
  ASSERT_EQ(b.levels.size(), 7u);  // G, 1..6
  testing::TempDir out;
  WriteWrldMission(b, out.path());
  const MissionDirectory mission(out.path());
  std::vector<int> levels;
  mission.LoadFloorPlan(std::nullopt, &levels);
  EXPECT_EQ(levels, (std::vector<int>{0, 1, 2, 3, 4, 5, 6}));
  for (const auto& l : b.levels) {
    const auto plan = mission.LoadFloorPlan(l.z_order);
    ASSERT_EQ(plan->walls().size(), l.walls.size()) << l.id;
    for (std::size_t k = 0; k < l.walls.size(); ++k) {
      ASSERT_LT((plan->walls()[k].a - l.walls[k].a).norm(), 1e-9);
      ASSERT_LT((plan->walls()[k].b - l.walls[k].b).norm(), 1e-9);
    }
    // Every floor of an office building is tens of metres across, about its location.
    const Box2 box = plan->Bounds();
    EXPECT_GT((box.max - box.min).norm(), 20.0) << l.id;
    EXPECT_LT(box.max.cwiseAbs().maxCoeff(), 200.0) << l.id;
  }
}

}  // namespace
}  // namespace trailmark

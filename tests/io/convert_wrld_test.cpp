// SPDX-License-Identifier: MIT
// The WRLD indoor-map converter: exact metres on a hand-made building, named errors, and the
// real Westport House map (../shared/data/floorplan-westport-house, read in place; skipped
// without it) converted into a mission whose floors read back as they were converted.
#include "trailmark/io/convert_wrld.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "test_util.h"
#include "trailmark/core/error.h"
#include "trailmark/io/mission_io.h"

namespace trailmark {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;

// 1e-4 degrees of latitude in metres on the mean-radius sphere.
constexpr double kDegLatM = 6371008.8 * std::numbers::pi / 180;

// A one-level building at (lon 10, lat 60): a wall square 1e-4 deg on a side, a room, a
// door polygon (ignored) and a no_geometry item. At lat 60 a degree of longitude is half a
// degree of latitude long.
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
    [[[10,60],[10.00001,60],[10.00001,60.00001],[10,60]]]}},
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
  ASSERT_EQ(g.walls.size(), 4u);  // the square's edges; the door polygon is not a wall
  const double side_m = 1e-4 * kDegLatM;  // 11.12 m
  EXPECT_NEAR(g.walls[0].a.norm(), 0, 1e-9);
  EXPECT_NEAR(g.walls[0].b.x(), 2 * side_m * 0.5, 1e-9);  // cos 60 = 0.5
  EXPECT_NEAR(g.walls[0].b.y(), 0, 1e-9);
  EXPECT_NEAR(g.walls[1].b.y(), side_m, 1e-9);
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
  EXPECT_EQ(plan->walls().size(), 4u);
  EXPECT_TRUE(plan->Crosses({1, 1}, {1, -1}));
  EXPECT_FALSE(plan->Crosses({1, 1}, {10, 10}));
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

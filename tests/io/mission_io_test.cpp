// SPDX-License-Identifier: MIT
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "test_util.h"
#include "trailmark/core/error.h"
#include "trailmark/io/mission_io.h"

namespace trailmark {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;
using testing::TempDir;

std::string ErrorOfMission(const std::string& text) {
  try {
    ParseMissionInfo(text, "mission.json");
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

// The example of the spec, verbatim in content (extra keys allowed).
constexpr const char* kSpecExample = R"({
  "format": "trailmark-mission/1",
  "name": "office-loop-400m",
  "description": "free text",
  "provenance": {"recorded_by": "someone else"},
  "nodes": [
    {"id": "base", "kind": "base", "position": [0, 0, 0]},
    {"id": "ff1", "kind": "agent", "start": [0, 0, 0], "start_heading": 1.5708},
    {"id": "lm3", "kind": "landmark", "position": [4.0, 2.5, 0], "position_sigma": 0.5}
  ],
  "radio": {"model": "log-distance", "alpha_dbm": -40.0, "path_loss_exponent": 2.3,
            "shadowing_sigma_db": 4.0},
  "floorplan": "floorplan.geojson"
})";

TEST(MissionJson, ParsesTheSpecExample) {
  const MissionInfo info = ParseMissionInfo(kSpecExample, "mission.json");
  ASSERT_EQ(info.nodes.size(), 3u);
  EXPECT_EQ(info.nodes[1].kind, NodeKind::kAgent);
  EXPECT_NEAR(*info.nodes[1].start_heading_rad, 1.5708, 1e-12);
  EXPECT_EQ(info.nodes[2].position->y(), 2.5);
  EXPECT_EQ(*info.nodes[2].position_sigma_m, 0.5);
  EXPECT_EQ(info.radio->path_loss_exponent, 2.3);
  EXPECT_EQ(*info.floorplan, "floorplan.geojson");
}

TEST(MissionJson, MinimalMissionAndAgentStartFromBase) {
  const MissionInfo info = ParseMissionInfo(
      R"({"nodes":[{"id":"b","kind":"base","position":[1,2]},{"id":"a","kind":"agent"}]})", "m");
  EXPECT_EQ(*info.AgentStart(info.nodes[1]), Vec3(1, 2, 0));
  EXPECT_EQ(ParseMissionInfo("{}", "m").nodes.size(), 0u);
}

TEST(MissionDirectory, WritingAgainLeavesNoStreamOfTheEarlierMission) {
  testing::TempDir dir;
  MissionData first;
  first.info.nodes.push_back(NodeInfo::Agent("ff1", Vec3::Zero(), 0.1));
  first.steps.push_back(Step{0, 1, "ff1", Vec3(0.7, 0, 0), std::nullopt});
  first.events.push_back({0.5, "ff1", "stop", ""});
  WriteMissionDirectory(dir.path(), first);
  ASSERT_TRUE(std::filesystem::exists(dir.path() / "events.csv"));
  MissionData second = first;
  second.events.clear();  // e.g. a variant without events
  WriteMissionDirectory(dir.path(), second);
  EXPECT_FALSE(std::filesystem::exists(dir.path() / "events.csv"));
  const MissionData back = ReadMissionData(MissionDirectory(dir.path()));
  EXPECT_TRUE(back.events.empty());
  EXPECT_EQ(back.steps.size(), 1u);
}

TEST(MissionJson, RoundTrips) {
  const MissionInfo a = ParseMissionInfo(kSpecExample, "m");
  const MissionInfo b = ParseMissionInfo(MissionInfoToJson(a), "m");
  ASSERT_EQ(a.nodes.size(), b.nodes.size());
  for (std::size_t i = 0; i < a.nodes.size(); ++i) {
    EXPECT_EQ(a.nodes[i].id, b.nodes[i].id);
    EXPECT_EQ(a.nodes[i].position, b.nodes[i].position);
    EXPECT_EQ(a.nodes[i].start_heading_rad, b.nodes[i].start_heading_rad);
  }
  EXPECT_EQ(a.radio->alpha_dbm, b.radio->alpha_dbm);
}

TEST(MissionJson, BadInputNamesTheProblem) {
  EXPECT_THAT(ErrorOfMission("{\n  \"nodes\": [\n    {\"id\": \"a\",, }\n]}"),
              AllOf(HasSubstr("mission.json:3:"), HasSubstr("invalid JSON")));
  EXPECT_THAT(ErrorOfMission(""), HasSubstr("invalid JSON"));
  // A number beyond double range is an error, not a crash (found by the fuzzer).
  EXPECT_THAT(ErrorOfMission(R"({"nodes":[{"id":"b","kind":"base","position":[5e500,0,0]}]})"),
              AllOf(HasSubstr("invalid JSON"), HasSubstr("number overflow")));
  EXPECT_THAT(ErrorOfMission(R"({"nodes":[{"id":"a","kind":"robot"}]})"),
              AllOf(HasSubstr("/nodes/0/kind"), HasSubstr("unknown kind 'robot'")));
  EXPECT_THAT(ErrorOfMission(R"({"nodes":[{"id":"a","kind":"agent"},{"id":"a","kind":"agent"}]})"),
              HasSubstr("declared twice"));
  EXPECT_THAT(ErrorOfMission(R"({"nodes":[{"id":"a b","kind":"agent"}]})"),
              HasSubstr("not a node id"));
  EXPECT_THAT(ErrorOfMission(R"({"nodes":[{"id":"b","kind":"base"}]})"),
              HasSubstr("needs its known 'position'"));
  EXPECT_THAT(ErrorOfMission(R"({"nodes":[{"id":"a","kind":"agent","start":[1,"x"]}]})"),
              AllOf(HasSubstr("/nodes/0/start/1"), HasSubstr("expected a number")));
  EXPECT_THAT(ErrorOfMission(R"({"format":"trailmark-mission/2"})"), HasSubstr("newer"));
  EXPECT_THAT(ErrorOfMission(R"({"radio":{"path_loss_exponent":-1}})"), HasSubstr("must be > 0"));
  EXPECT_THAT(ErrorOfMission("[1,2]"), HasSubstr("expected a JSON object"));
}

TEST(MissionJson, ImplausibleValuesAndPlansOutsideTheMissionAreRefused) {
  // Values that would only come back as non-finite estimates: named at their JSON pointer.
  EXPECT_THAT(ErrorOfMission(R"({"nodes":[{"id":"a","kind":"agent","start":[0,0],"start_sigma":1e308}]})"),
              AllOf(HasSubstr("/nodes/0/start_sigma"), HasSubstr("not a plausible sigma")));
  EXPECT_THAT(ErrorOfMission(R"({"nodes":[{"id":"l","kind":"landmark","position":[-1e308,0]}]})"),
              AllOf(HasSubstr("/nodes/0/position/0"), HasSubstr("not a position in a local frame")));
  EXPECT_THAT(ErrorOfMission(R"({"nodes":[{"id":"l","kind":"landmark","position":[0,0],"position_sigma":1e300}]})"),
              HasSubstr("/nodes/0/position_sigma"));
  EXPECT_THAT(ErrorOfMission(R"({"nodes":[{"id":"a","kind":"agent","start_heading":1e9}]})"),
              HasSubstr("/nodes/0/start_heading"));
  for (const char* plan : {"/etc/passwd", "../other/floorplan.geojson", "a/../../x.geojson"}) {
    EXPECT_THAT(ErrorOfMission(std::string(R"({"floorplan":")") + plan + R"("})"),
                AllOf(HasSubstr("/floorplan"), HasSubstr("not a file of the mission directory")))
        << plan;
  }
  EXPECT_EQ(ErrorOfMission(R"({"floorplan":"plans/level0.geojson"})"), "");
}

TEST(MissionDirectory, DroppedCrumbsJoinTheRegistryAndUnknownIdsFail) {
  TempDir dir;
  dir.File("mission.json", R"({"nodes":[{"id":"base","kind":"base","position":[0,0,0]},
                                         {"id":"ff1","kind":"agent"}]})");
  dir.File("events.csv", "t,agent,event,node\n0,ff1,enter,\n5,ff1,drop,c1\n");
  dir.File("rssi.csv", "t,rx,tx,rssi_dbm\n6,ff1,c1,-50\n7,ff1,c9,-50\n");
  const MissionDirectory mission(dir.path());
  EXPECT_TRUE(mission.registry().Contains("c1"));
  EXPECT_FALSE(mission.registry().Contains("c9"));
  EXPECT_EQ(mission.dropped_crumbs(), std::vector<std::string>{"c1"});
  auto reader = mission.OpenStream<RssiPacket>();
  RssiPacket p;
  EXPECT_TRUE(reader.Next(p));
  try {
    reader.Next(p);
    FAIL() << "expected an error for c9";
  } catch (const InputError& e) {
    EXPECT_THAT(e.what(), AllOf(HasSubstr("rssi.csv:3:"), HasSubstr("'c9'")));
  }
  EXPECT_THAT(
      [&] {
        try {
          mission.Require("steps.csv", "the pdr pipeline");
        } catch (const InputError& e) {
          return std::string(e.what());
        }
        return std::string();
      }(),
      AllOf(HasSubstr("steps.csv"), HasSubstr("pdr pipeline")));
}

TEST(MissionDirectory, AnAgentOrABaseIsNotDropped) {
  // A drop event whose node is an agent or the base would make it a beacon or crumb of the
  // estimators (it did: the agent's id became a beacon of the map): refused with file and line.
  for (const char* node : {"ff1", "base"}) {
    TempDir dir;
    dir.File("mission.json", R"({"nodes":[{"id":"base","kind":"base","position":[0,0,0]},
                                           {"id":"ff1","kind":"agent"}]})");
    dir.File(
        "events.csv",
        std::string("t,agent,event,node\n0,ff1,enter,\n5,ff1,drop,c1\n6,ff1,drop,") + node + "\n");
    try {
      const MissionDirectory mission(dir.path());
      FAIL() << "expected an error for dropping " << node;
    } catch (const InputError& e) {
      EXPECT_THAT(e.what(),
                  AllOf(HasSubstr("events.csv:4:"), HasSubstr(std::string("'") + node + "'"),
                        HasSubstr("'drop' event")));
    }
  }
}

TEST(MissionDirectory, TheAgentColumnNamesAnAgent) {
  // A landmark's barometer, a base that stops, a crumb's steps: the agent column of steps, IMU,
  // barometer and events names a moving person (found by the readers' audit, 2026-12-06: they
  // were read without a word). Refused with the file and line; an agent's rows are read.
  TempDir dir;
  dir.File("mission.json", R"({"nodes":[{"id":"base","kind":"base","position":[0,0,0]},
                                         {"id":"ff1","kind":"agent"},
                                         {"id":"lm1","kind":"landmark","position":[3,0,0]}]})");
  dir.File("events.csv", "t,agent,event,node\n0,ff1,enter,\n5,ff1,drop,c1\n9,base,stop,\n");
  dir.File("baro.csv", "t,agent,pressure_hpa\n0,ff1,1013.2\n0.5,lm1,1013.1\n");
  dir.File("steps.csv",
           "t0,t1,agent,dx,dy,dz,sxx,syy,szz\n0,0.5,ff1,0.7,0,0,,,\n0.5,1,c1,0.7,0,0,,,\n");
  const MissionDirectory mission(dir.path());
  auto error_of = [&](auto reader, auto row) {
    try {
      while (reader.Next(row)) {
      }
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_THAT(error_of(mission.OpenStream<MissionEvent>(), MissionEvent{}),
              AllOf(HasSubstr("events.csv:4:"), HasSubstr("'base' is a base")));
  EXPECT_THAT(error_of(mission.OpenStream<BaroSample>(), BaroSample{}),
              AllOf(HasSubstr("baro.csv:3:"), HasSubstr("'lm1' is a landmark")));
  EXPECT_THAT(error_of(mission.OpenStream<Step>(), Step{}),
              AllOf(HasSubstr("steps.csv:3:"), HasSubstr("'c1' is a crumb")));
}

TEST(MissionDirectory, MissingDirectoryOrMissionJson) {
  TempDir dir;
  EXPECT_THROW(MissionDirectory(dir.path() / "nope"), InputError);
  EXPECT_THROW(MissionDirectory{dir.path()}, InputError);  // no mission.json
}

TEST(FloorPlanGeoJson, ReadsWallsDoorsRoomsAndLevels) {
  const char* text = R"({"type":"FeatureCollection","features":[
    {"type":"Feature","properties":{"kind":"wall"},
     "geometry":{"type":"LineString","coordinates":[[0,0],[10,0],[10,5]]}},
    {"type":"Feature","properties":{"kind":"door"},
     "geometry":{"type":"LineString","coordinates":[[4,0],[5,0]]}},
    {"type":"Feature","properties":{"kind":"room","name":"r1"},
     "geometry":{"type":"Polygon","coordinates":[[[0,0],[10,0],[10,5],[0,5],[0,0]]]}},
    {"type":"Feature","properties":{"kind":"wall","level":1},
     "geometry":{"type":"LineString","coordinates":[[0,0],[0,5]]}},
    {"type":"Feature","properties":{"kind":"stairs"},"geometry":null}]})";
  const FloorPlan all = ParseFloorPlanGeoJson(text, "plan.geojson");
  EXPECT_EQ(all.walls().size(), 3u);
  EXPECT_EQ(all.doors().size(), 1u);
  ASSERT_EQ(all.rooms().size(), 1u);
  EXPECT_EQ(all.rooms()[0].ring.size(), 4u);
  EXPECT_EQ(all.solid_walls().size(), 4u);  // the door splits the first wall in two
  EXPECT_FALSE(all.Crosses({4.5, -1}, {4.5, 1}));  // through the door
  EXPECT_TRUE(all.Crosses({2, -1}, {2, 1}));
  const FloorPlan ground = ParseFloorPlanGeoJson(text, "plan.geojson", 0);
  EXPECT_EQ(ground.walls().size(), 2u);
  // Round trip.
  const FloorPlan back = ParseFloorPlanGeoJson(FloorPlanToGeoJson(all), "x");
  EXPECT_EQ(back.solid_walls().size(), all.solid_walls().size());
}

TEST(FloorPlanGeoJson, APlanInDegreesIsRefusedAndNamed) {
  // Issue 23: a 20 x 12 m building exported in longitude/latitude (Dundee) instead of metres.
  const std::string degrees = R"({"type":"FeatureCollection","features":[
    {"type":"Feature","properties":{"kind":"wall"},
     "geometry":{"type":"LineString","coordinates":[[-2.9701,56.4620],[-2.9698,56.4620],
       [-2.9698,56.4621],[-2.9701,56.4621],[-2.9701,56.4620]]}}]})";
  try {
    ParseFloorPlanGeoJson(degrees, "plan.geojson");
    FAIL() << "a plan in degrees was read";
  } catch (const InputError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("plan.geojson"), std::string::npos) << what;
    EXPECT_NE(what.find("longitude/latitude"), std::string::npos) << what;
  }
  // The same shape in millimetres' worth of metres far from any lon/lat: too small, said so.
  const std::string tiny = R"({"type":"FeatureCollection","features":[
    {"type":"Feature","properties":{"kind":"wall"},
     "geometry":{"type":"LineString","coordinates":[[500,500],[500.02,500],[500.02,500.01]]}}]})";
  try {
    ParseFloorPlanGeoJson(tiny, "plan.geojson");
    FAIL() << "a 2 cm plan was read";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("far too small"), std::string::npos) << e.what();
  }
  // A small real room (a 1 m cupboard) is a plan in metres.
  EXPECT_NO_THROW(ParseFloorPlanGeoJson(R"({"type":"FeatureCollection","features":[
    {"type":"Feature","properties":{"kind":"wall"},
     "geometry":{"type":"LineString","coordinates":[[0,0],[1,0],[1,1]]}}]})",
                                        "plan.geojson"));
}

TEST(FloorPlanGeoJson, AMultiFloorPlanIsReadOneFloorAtATime) {
  // Floor 0 a 10 x 5 m room; floor 1 a wall straight across it (the room above is split).
  TempDir dir;
  dir.File("mission.json", R"({"nodes":[],"floorplan":"plan.geojson"})");
  dir.File("plan.geojson", R"({"type":"FeatureCollection","features":[
    {"type":"Feature","properties":{"kind":"wall"},
     "geometry":{"type":"LineString","coordinates":[[0,0],[10,0],[10,5],[0,5],[0,0]]}},
    {"type":"Feature","properties":{"kind":"wall","level":1},
     "geometry":{"type":"LineString","coordinates":[[5,0],[5,5]]}},
    {"type":"Feature","properties":{"kind":"room","level":-1,"name":"cellar"},
     "geometry":{"type":"Polygon","coordinates":[[[0,0],[4,0],[4,4],[0,0]]]}}]})");
  const MissionDirectory mission(dir.path());
  std::vector<int> levels;
  const auto ground = mission.LoadFloorPlan(std::nullopt, &levels);
  EXPECT_EQ(levels, (std::vector<int>{-1, 0, 1}));
  // Not told which: level 0 (the entry floor), never the floors merged.
  ASSERT_TRUE(ground.has_value());
  EXPECT_EQ(ground->walls().size(), 4u);
  EXPECT_FALSE(ground->Crosses({2, 2}, {8, 2}));
  const auto upstairs = mission.LoadFloorPlan(1);
  EXPECT_EQ(upstairs->walls().size(), 1u);
  EXPECT_TRUE(upstairs->Crosses({2, 2}, {8, 2}));
  // A basement (a negative level) is one floor too: its room, none of the other floors' walls.
  const auto cellar = mission.LoadFloorPlan(-1);
  EXPECT_EQ(cellar->rooms().size(), 1u);
  EXPECT_TRUE(cellar->walls().empty());
  try {
    mission.LoadFloorPlan(2);
    FAIL() << "expected an error for level 2";
  } catch (const InputError& e) {
    EXPECT_THAT(e.what(), AllOf(HasSubstr("plan.geojson"), HasSubstr("no level 2"),
                                HasSubstr("-1, 0, 1")));
  }
  EXPECT_EQ(DefaultFloorPlanLevel({-1, 0, 1}), 0);
  EXPECT_EQ(DefaultFloorPlanLevel({2, 3}), 2);  // no level 0: the lowest
  EXPECT_EQ(DefaultFloorPlanLevel({}), 0);
  // A plan without levels is one floor, level 0.
  std::vector<int> one;
  ParseFloorPlanGeoJson(R"({"type":"FeatureCollection","features":[{"type":"Feature",
      "properties":{"kind":"wall"},"geometry":{"type":"LineString","coordinates":[[0,0],[1,0]]}}]})",
                        "x", std::nullopt, &one);
  EXPECT_EQ(one, std::vector<int>{0});
}

TEST(FloorPlanGeoJson, BadGeometryIsNamed) {
  auto error = [](const std::string& t) {
    try {
      ParseFloorPlanGeoJson(t, "plan.geojson");
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_THAT(error(R"({"type":"Feature"})"), HasSubstr("FeatureCollection"));
  EXPECT_THAT(error(R"({"type":"FeatureCollection","features":[{"type":"Feature",
      "properties":{"kind":"wall"},"geometry":{"type":"LineString","coordinates":[[0,0]]}}]})"),
              AllOf(HasSubstr("/features/0"), HasSubstr("at least two")));
  EXPECT_THAT(error(R"({"type":"FeatureCollection","features":[{"type":"Feature",
      "properties":{"kind":"wall"},"geometry":{"type":"Point","coordinates":[0,0]}}]})"),
              HasSubstr("LineString"));
  // A "type" that is not a string (found by the fuzzer: it escaped as a JSON library error).
  EXPECT_THAT(error(R"({"type":"FeatureCollection","features":[{"type":"Feature",
      "properties":{"kind":"wall"},"geometry":{"type":[[0,0],[1,0]]}}]})"),
              HasSubstr("/features/0/geometry"));
  EXPECT_THAT(error(R"({"type":["FeatureCollection"]})"), HasSubstr("FeatureCollection"));
}

}  // namespace
}  // namespace trailmark

namespace trailmark {
namespace {

TEST(MissionJson, FloorsOfTheSpecRoundTripSortedAndBadOnesAreNamed) {
  const MissionInfo info = ParseMissionInfo(
      R"({"floors": [{"level": 0, "elevation_m": 0.0}, {"level": 1, "elevation_m": 3.5},
                     {"level": -1, "elevation_m": -3.2}]})",
      "mission.json");
  ASSERT_EQ(info.floors.size(), 3u);
  EXPECT_EQ(info.floors.front().level, -1);  // sorted by elevation
  EXPECT_EQ(info.floors.back().level, 1);
  const MissionInfo again = ParseMissionInfo(MissionInfoToJson(info), "again");
  ASSERT_EQ(again.floors.size(), 3u);
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(again.floors[i].level, info.floors[i].level);
    EXPECT_EQ(again.floors[i].elevation_m, info.floors[i].elevation_m);
  }
  EXPECT_TRUE(ParseMissionInfo("{}", "m").floors.empty());
  EXPECT_THAT(ErrorOfMission(R"({"floors": [{"level": 0, "elevation_m": 0}, {"level": 0, "elevation_m": 3}]})"),
              AllOf(HasSubstr("/floors/1/level"), HasSubstr("listed twice")));
  EXPECT_THAT(ErrorOfMission(R"({"floors": [{"level": 0, "elevation_m": 3}, {"level": 1, "elevation_m": 0}]})"),
              HasSubstr("a higher level must lie higher"));
  EXPECT_THAT(ErrorOfMission(R"({"floors": [{"level": 0.5, "elevation_m": 0}]})"),
              AllOf(HasSubstr("/floors/0/level"), HasSubstr("integer")));
  EXPECT_THAT(ErrorOfMission(R"({"floors": [{"level": 2}]})"), HasSubstr("elevation_m"));
  EXPECT_THAT(ErrorOfMission(R"({"floors": {"level": 2}})"), HasSubstr("expected an array"));
}

TEST(Streams, FloorAndVerticalVarianceColumnsOfVersion1Point1) {
  TempDir dir;
  // Truth with levels; a level that is not an integer is refused with its line.
  const std::string truth = dir.File("truth.csv", "t,id,x,y,z,floor\n0,a,1,2,3.5,1\n1,a,1,2,0,\n");
  const auto rows = ReadAll<TruthSample>(truth);
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_EQ(rows[0].floor, 1);
  EXPECT_FALSE(rows[1].floor.has_value());
  const std::string bad = dir.File("t2.csv", "t,id,x,y,z,floor\n0,a,1,2,3.5,1.5\n");
  try {
    ReadAll<TruthSample>(bad);
    FAIL() << "a level of 1.5 was accepted";
  } catch (const InputError& e) {
    EXPECT_THAT(e.what(), AllOf(HasSubstr("t2.csv:2"), HasSubstr("not a level")));
  }
  // Estimates: szz and floor written only when some row has them, read back the same.
  std::vector<Estimate> est{{0, "a", Vec3(1, 2, 3.4), 1, 0, 1, 0.04, 1}, {1, "a", Vec3(1, 2, 0), 1, 0, 1}};
  const auto lines = FormatAll(est);
  EXPECT_EQ(lines.front(), "t,id,x,y,z,sxx,sxy,syy,szz,floor");
  EXPECT_EQ(lines.back(), "1,a,1,2,0,1,0,1,,");
  const std::string path = (dir.path() / "estimates.csv").string();
  WriteAll(path, est);
  const auto back = ReadAll<Estimate>(path);
  ASSERT_EQ(back.size(), 2u);
  EXPECT_EQ(back[0].szz, 0.04);
  EXPECT_EQ(back[0].floor, 1);
  EXPECT_FALSE(back[1].szz.has_value());
  est.pop_back();
  est[0].szz.reset();
  est[0].floor.reset();
  EXPECT_EQ(FormatAll(est).front(), "t,id,x,y,z,sxx,sxy,syy");  // 1.0 columns
  // Barometer in Pa instead of hPa: refused with its line.
  const std::string pa = dir.File("baro.csv", "t,agent,pressure_hpa\n0,a,1013.2\n0.2,a,101320\n");
  try {
    ReadAll<BaroSample>(pa);
    FAIL() << "101320 hPa was accepted";
  } catch (const InputError& e) {
    EXPECT_THAT(e.what(), AllOf(HasSubstr("baro.csv:3"), HasSubstr("Pa or kPa")));
  }
}

TEST(InputAsTheSpecAllows, FeaturesOfOtherKindsKindsInAnyCaseAndWholeLevelsWrittenAsReals) {
  // Found by an audit of the readers against the spec (2026-12-06): a label feature whose
  // `level` is a name refused the whole plan; "Wall" was silently no wall; 1.0 was no level.
  const char* text = R"({"type":"FeatureCollection","features":[
    {"type":"Feature","properties":{"kind":"label","level":"G","text":"lobby"},
     "geometry":{"type":"Point","coordinates":[1,1]}},
    {"type":"Feature","properties":{"kind":"Wall","level":1.0},
     "geometry":{"type":"LineString","coordinates":[[0,0],[10,0]]}},
    {"type":"Feature","properties":{"kind":"DOOR","level":1},
     "geometry":{"type":"LineString","coordinates":[[4,0],[5,0]]}}]})";
  std::vector<int> levels;
  const FloorPlan plan = ParseFloorPlanGeoJson(text, "plan.geojson", std::nullopt, &levels);
  EXPECT_EQ(plan.walls().size(), 1u);
  EXPECT_EQ(plan.doors().size(), 1u);
  EXPECT_EQ(levels, std::vector<int>{1});
  const std::string half = R"({"type":"FeatureCollection","features":[
    {"type":"Feature","properties":{"kind":"wall","level":0.5},
     "geometry":{"type":"LineString","coordinates":[[0,0],[10,0]]}}]})";
  try {
    ParseFloorPlanGeoJson(half, "plan.geojson");
    FAIL() << "level 0.5 was accepted";
  } catch (const InputError& e) {
    EXPECT_THAT(e.what(), AllOf(HasSubstr("/features/0/properties/level"), HasSubstr("integer")));
  }
  const MissionInfo info = ParseMissionInfo(
      R"({"floors": [{"level": 1.0, "elevation_m": 3}, {"level": 0, "elevation_m": 0}]})", "m");
  ASSERT_EQ(info.floors.size(), 2u);
  EXPECT_EQ(info.floors.back().level, 1);
}

TEST(InputAsTheSpecAllows, APartialRadioBlockIsNotACalibration) {
  // "radio holds calibration if known": a sigma alone is not one; alpha and the exponent are not
  // invented from defaults (they were, and the landmark filter then took itself as calibrated).
  const MissionInfo sigma_only =
      ParseMissionInfo(R"({"radio": {"shadowing_sigma_db": 6}})", "mission.json");
  ASSERT_TRUE(sigma_only.radio.has_value());
  EXPECT_FALSE(sigma_only.radio->Complete());
  EXPECT_TRUE(sigma_only.radio->sigma_given);
  EXPECT_EQ(sigma_only.radio->shadowing_sigma_db, 6.0);
  // Written back as it was given.
  EXPECT_THAT(MissionInfoToJson(sigma_only), ::testing::Not(HasSubstr("alpha_dbm")));
  const MissionInfo again = ParseMissionInfo(MissionInfoToJson(sigma_only), "again");
  EXPECT_FALSE(again.radio->Complete());
  EXPECT_EQ(again.radio->shadowing_sigma_db, 6.0);
  // The spec's example is a calibration; without a sigma it still is (the default sigma).
  EXPECT_TRUE(ParseMissionInfo(kSpecExample, "m").radio->Complete());
  const MissionInfo no_sigma =
      ParseMissionInfo(R"({"radio": {"alpha_dbm": -60, "path_loss_exponent": 2}})", "m");
  EXPECT_TRUE(no_sigma.radio->Complete());
  EXPECT_FALSE(no_sigma.radio->sigma_given);
}

TEST(InputAsTheSpecAllows, EmptyCellsAreUnknownNotZeroAndExtraColumnsMayRepeatAName) {
  TempDir dir;
  // A step with sxx given and syy empty: the given variance for both horizontal axes (both
  // were dropped for the pipeline's default).
  const auto steps = ReadAll<Step>(
      dir.File("steps.csv",
               "t0,t1,agent,dx,dy,dz,sxx,syy,szz\n0,0.5,a,0.7,0,0,0.01,,\n0.5,1,a,0.7,0,0,,,\n"));
  ASSERT_EQ(steps.size(), 2u);
  ASSERT_TRUE(steps[0].variance_m2.has_value());
  EXPECT_EQ(steps[0].variance_m2->x(), 0.01);
  EXPECT_EQ(steps[0].variance_m2->y(), 0.01);
  EXPECT_FALSE(steps[1].variance_m2.has_value());
  // Estimates without a covariance (another method's): unknown, written back empty.
  const auto est = ReadAll<Estimate>(
      dir.File("estimates.csv", "t,id,x,y,z,sxx,sxy,syy\n0,a,1,2,0,,,\n1,a,1,2,0,0.5,0,0.5\n"));
  ASSERT_EQ(est.size(), 2u);
  EXPECT_FALSE(est[0].covariance_known);
  EXPECT_TRUE(est[1].covariance_known);
  EXPECT_EQ(FormatAll(est)[1], "0,a,1,2,0,,,");
  // Two extra columns of one name are ignored like any extra column (a column that is read may
  // still not appear twice: CsvReader.DuplicateHeaderColumn).
  const auto truth =
      ReadAll<TruthSample>(dir.File("truth.csv", "t,id,note,x,y,z,note\n0,a,p,1,2,0,q\n"));
  ASSERT_EQ(truth.size(), 1u);
  EXPECT_EQ(truth[0].position_n, Vec3(1, 2, 0));
}

}  // namespace
}  // namespace trailmark

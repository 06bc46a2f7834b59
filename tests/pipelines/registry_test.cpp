// SPDX-License-Identifier: MIT
// The pipeline registry: one table that the CLI, the server and the docs read.
#include "trailmark/pipelines/registry.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>

#include "test_util.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/pipelines/batch_run.h"
#include "trailmark/sim/scenarios.h"

namespace trailmark {
namespace {

using ::testing::HasSubstr;

TEST(Registry, NinePipelinesEachWithItsSchemaAndFactory) {
  std::set<std::string> names;
  for (const auto& p : Pipelines()) {
    names.insert(p.name);
    EXPECT_FALSE(p.description.empty()) << p.name;
    EXPECT_FALSE(p.needs.empty()) << p.name;
    EXPECT_FALSE(p.options.empty()) << p.name;
    EXPECT_TRUE(p.make) << p.name;
    EXPECT_TRUE(p.floor_level) << p.name;
    for (const StreamSet& need : p.needs) {
      for (Stream s : need.List()) EXPECT_TRUE(p.uses.Has(s)) << p.name << " needs what it uses";
    }
    std::set<std::string> keys;
    for (const auto& o : p.options) {
      EXPECT_TRUE(keys.insert(o.key).second) << p.name << ": key " << o.key << " twice";
      EXPECT_FALSE(o.description.empty()) << p.name << " " << o.key;
    }
  }
  EXPECT_EQ(names,
            (std::set<std::string>{"pdr", "ins", "breadcrumb", "landmarks-stopgo", "landmarks-ukf",
                                   "beacons-mds", "beacons-ekf", "mapmatch", "fusion"}));
  EXPECT_EQ(FindPipeline("nope"), nullptr);
  EXPECT_THAT([] { RequirePipeline("nope"); },
              ::testing::ThrowsMessage<std::invalid_argument>(HasSubstr("known: pdr, ")));
}

TEST(Registry, EveryDefaultIsAValueItsParserAccepts) {
  // The schema is generated from the Options structs: each key given its documented default
  // builds the same estimator as no option at all.
  const SimulatedMission house = SimulateScenario("house1-search", 1);
  const SimulatedMission corridor = SimulateScenario("landmark-corridor", 1);
  for (const auto& p : Pipelines()) {
    const SimulatedMission& sim = p.min_landmarks > 0 ? corridor : house;
    for (const auto& o : p.options) {
      // (unset optional settings: their default is a word, e.g. "auto (per detector)")
      if (o.default_value.rfind("auto", 0) == 0 || o.default_value.rfind("every level", 0) == 0)
        continue;
      const OptionValues one{{o.key, o.default_value}};
      EXPECT_NO_THROW(p.make({sim.data.info, &sim.plan}, one, Feed::kTimeOrdered))
          << p.name << " " << o.key << "=" << o.default_value;
    }
  }
}

/// The error of making a pipeline with these options ("" when it is made).
std::string MakeError(const std::string& name, const EstimatorInputs& in, const OptionValues& o) {
  try {
    RequirePipeline(name).make(in, o, Feed::kTimeOrdered);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

TEST(Registry, OutOfRangeAndUnknownOptionsAreErrorsNamingTheKey) {
  const SimulatedMission sim = SimulateScenario("house1-search", 1);
  const EstimatorInputs in{sim.data.info, &sim.plan};
  const std::string particles = MakeError("mapmatch", in, {{"particles", "3"}});
  EXPECT_THAT(particles, HasSubstr("pipeline mapmatch: option particles='3'"));
  EXPECT_THAT(particles, HasSubstr("within 10 .. 1e+06"));
  const std::string unknown = MakeError("ins", in, {{"zupt_sigma_mps", "1"}});
  EXPECT_THAT(unknown, HasSubstr("unknown option 'zupt_sigma_mps'"));
  EXPECT_THAT(unknown, HasSubstr("zupt_sigma"));
  EXPECT_THROW(RequirePipeline("pdr").make(in, {{"ins.window", "0"}}, Feed::kTimeOrdered),
               std::invalid_argument);
}

// A run refused (here: a bad option) leaves the output folder's earlier estimates.csv as it was
// (not truncated beside the diagnostics.json of the run that wrote it), and no partial file.
TEST(Registry, ARefusedRunLeavesTheEarlierEstimatesAsTheyWere) {
  testing::TempDir dir;
  const SimulatedMission sim = SimulateScenario("office-loop-1lap", 1);
  WriteMissionDirectory(dir.path(), sim.data);
  const MissionDirectory mission(dir.path());
  const auto out = dir.path() / "run";
  const RunResult first = RunPipeline(RequirePipeline("pdr"), {mission, {}}, out);
  ASSERT_GT(first.estimates, 0u);
  auto read = [&] {
    std::ifstream in(out / "estimates.csv");
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
  };
  const std::string before = read();
  EXPECT_THROW(RunPipeline(RequirePipeline("breadcrumb"), {mission, {{"fixed_lag_s", "-1"}}}, out),
               std::invalid_argument);
  EXPECT_EQ(read(), before);
  EXPECT_FALSE(std::filesystem::exists(out / "estimates.csv.partial"));
}

// landmarks-stopgo has no continuous tracker: its options do not list the tracker's, and a
// tracker key given to it is refused instead of being ignored.
TEST(Registry, EachLandmarkPipelineListsAndTakesOnlyTheOptionsItReads) {
  auto keys = [](const std::string& name) {
    std::set<std::string> k;
    for (const auto& o : RequirePipeline(name).options) k.insert(o.key);
    return k;
  };
  const auto stopgo = keys("landmarks-stopgo"), ukf = keys("landmarks-ukf");
  for (const char* tracker : {"filter", "slam", "adapt_noise", "shadowing_length_m"}) {
    EXPECT_EQ(stopgo.count(tracker), 0u) << tracker;
    EXPECT_EQ(ukf.count(tracker), 1u) << tracker;
  }
  for (const char* both : {"drift_per_m", "loss", "fix_fusion", "gate_other_floors"}) {
    EXPECT_EQ(stopgo.count(both), 1u) << both;
    EXPECT_EQ(ukf.count(both), 1u) << both;
  }
  const SimulatedMission sim = SimulateScenario("landmark-corridor", 1);
  const EstimatorInputs in{sim.data.info, &sim.plan};
  EXPECT_THAT(MakeError("landmarks-stopgo", in, {{"slam", "false"}}),
              HasSubstr("unknown option 'slam'"));
  EXPECT_EQ(MakeError("landmarks-ukf", in, {{"slam", "false"}}), "");
}

// One view between rows for every steps-based pipeline (the step front end's), on by default;
// the views of their own that beacons-ekf and the fusion had are off by default (ablations).
TEST(Registry, EveryStepsBasedPipelineHasTheFrontEndsViewBetweenRows) {
  for (const PipelineSpec& spec : Pipelines()) {
    std::optional<std::string> view, beacons_view, fusion_view;
    for (const auto& o : spec.options) {
      if (o.key == "view_period_s") view = o.default_value;
      if (o.key == "extrapolate") beacons_view = o.default_value;
      if (o.key == "fusion.predict_fraction") fusion_view = o.default_value;
    }
    EXPECT_EQ(view.has_value(), spec.steps_based) << spec.name;
    if (view) EXPECT_EQ(*view, "0.1") << spec.name;
    if (beacons_view) EXPECT_EQ(*beacons_view, "false") << spec.name;
    if (fusion_view) EXPECT_EQ(*fusion_view, "0") << spec.name;
  }
  const SimulatedMission sim = SimulateScenario("beacon-trail", 1);
  const EstimatorInputs in{sim.data.info, &sim.plan};
  EXPECT_EQ(MakeError("pdr", in, {{"view_period_s", "0.2"}}), "");
  EXPECT_THAT(MakeError("pdr", in, {{"view_period_s", "0.001"}}), HasSubstr("view_period_s"));
  EXPECT_THAT(MakeError("ins", in, {{"view_period_s", "0.2"}}),
              HasSubstr("unknown option 'view_period_s'"));
}

TEST(Registry, JsonListsNameNeedsUsesLiveAndOptions) {
  const auto j = nlohmann::json::parse(RegistryJson());
  ASSERT_EQ(j.size(), Pipelines().size());
  for (const auto& p : j) {
    for (const char* key : {"name", "needs", "uses", "live", "options"})
      EXPECT_TRUE(p.contains(key)) << key;
    EXPECT_TRUE(p["live"].get<bool>());
    for (const auto& o : p["options"]) {
      for (const char* key : {"key", "type", "default", "unit", "description"})
        EXPECT_TRUE(o.contains(key)) << p["name"] << " " << key;
    }
  }
  EXPECT_EQ(j[0]["name"], "pdr");
  EXPECT_EQ(j[0]["needs"][0], "steps.csv or imu.csv");
}

TEST(Registry, TheDocsOptionTablesAreTheRegistrysText) {
  std::ifstream in(std::string(TRAILMARK_SOURCE_DIR) + "/docs/pipeline-options.md");
  ASSERT_TRUE(in) << "docs/pipeline-options.md missing";
  std::stringstream text;
  text << in.rdbuf();
  EXPECT_EQ(text.str(), RegistryMarkdown())
      << "docs/pipeline-options.md is stale: regenerate it with `trailmark pipelines --markdown "
         "> docs/pipeline-options.md`";
}

TEST(Registry, RunnableFollowsTheNeeds) {
  testing::TempDir dir;
  dir.File("mission.json", R"({"nodes":[{"id":"ff1","kind":"agent","start":[0,0,0]}]})");
  EXPECT_TRUE(RunnablePipelines(MissionDirectory(dir.path())).empty());
  dir.File("imu.csv", "t,agent,ax,ay,az,gx,gy,gz\n0,ff1,0,0,9.8,0,0,0\n");
  EXPECT_THAT(RunnablePipelines(MissionDirectory(dir.path())),
              ::testing::ElementsAre("pdr", "breadcrumb", "ins", "fusion"));
  dir.File("ranges.csv", "t,a,b,range\n0,ff1,b1,1\n");
  EXPECT_THAT(RunnablePipelines(MissionDirectory(dir.path())),
              ::testing::Contains("beacons-ekf"));
}

}  // namespace
}  // namespace trailmark

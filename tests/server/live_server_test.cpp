// SPDX-License-Identifier: MIT
// The live server runs the batch run's estimators: a mission posted as its devices would (CSV
// bodies, journaled, committed, fed to the estimator) gives the batch estimates, node by node,
// bit for bit — but the last ones, which wait for data after them (the reorder window, a step
// not yet ended) since a live incident has no end of data.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <map>
#include <mutex>
#include <thread>

#include "pipelines/run_named.h"
#include "server/incident_server.h"
#include "test_util.h"
#include "trailmark/eval/metrics.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/io/streams.h"
#include "trailmark/sim/imu_sim.h"
#include "trailmark/sim/scenarios.h"

namespace trailmark::server {
namespace {

using trailmark::testing::TempDir;

template <class Row>
std::string Body(const std::vector<Row>& rows) {
  std::string body;
  for (const auto& line : FormatAll(rows)) body += line + "\n";
  return body;
}

/// Each device's rows of a stream, in 1 s batches, the batches of a second in turn.
template <class Row>
void Post(IncidentServer& server, const std::string& stream, const std::vector<Row>& rows,
          double from, double to) {
  std::map<std::string, std::vector<Row>> by_device;
  for (const Row& r : rows) {
    const TimeS t = RowTime(MissionRow(r));
    if (t >= from && t < to) by_device[RowNode(MissionRow(r))].push_back(r);
  }
  for (const auto& [device, batch] : by_device) server.Ingest(stream, Body(batch));
}

/// Each device's rows of a second in one bundle (POST /api/ingest): its streams in the order
/// Post sends them, header lines included.
struct Bundles {
  std::map<std::string, nlohmann::ordered_json> by_device;
  template <class Row>
  void Add(const std::string& stream, const std::vector<Row>& rows, double from, double to) {
    std::map<std::string, std::vector<Row>> by;
    for (const Row& r : rows) {
      const TimeS t = RowTime(MissionRow(r));
      if (t >= from && t < to) by[RowNode(MissionRow(r))].push_back(r);
    }
    for (const auto& [device, batch] : by) by_device[device][stream] = Body(batch);
  }
  void Send(IncidentServer& server) {
    for (const auto& [device, bundle] : by_device) {
      const nlohmann::json answer = server.IngestBundle(bundle.dump());
      EXPECT_FALSE(answer.contains("error")) << answer.dump();
    }
    by_device.clear();
  }
};

std::map<std::string, std::vector<Estimate>> ByNode(const std::vector<Estimate>& rows) {
  std::map<std::string, std::vector<Estimate>> by;
  for (const auto& e : rows) by[e.id].push_back(e);
  return by;
}

/// The mission written into `dir`/mission (every level's plan of a multi-floor building).
MissionDirectory WriteMission(const TempDir& dir, const SimulatedMission& sim) {
  if (sim.levels.empty()) {
    WriteMissionDirectory(dir.path() / "mission", sim.data, &sim.plan);
  } else {
    WriteMissionDirectory(dir.path() / "mission", sim.data, sim.levels);
  }
  return MissionDirectory(dir.path() / "mission");
}

/// A live server on the mission in `dir` (WriteMission), its journal beside it, token "t", quiet.
ServerOptions LiveOptions(const TempDir& dir, const std::string& pipeline) {
  ServerOptions o;
  o.live_dir = dir.path() / "mission";
  o.journal_file = dir.path() / "journal.db";
  o.pipeline = pipeline;
  o.port = 0;
  o.token = "t";
  o.log = [](const std::string&) {};
  return o;
}

/// What a live server running `pipeline` on the mission in `dir` estimated from the mission's
/// streams posted as its devices would (each device's rows of a second in one body), once every
/// row was estimated (or a minute passed); `rows_estimated`/`refusals` get the server's counts.
std::vector<Estimate> RunLive(const TempDir& dir, const std::string& pipeline,
                              const SimulatedMission& sim, std::size_t* rows_posted,
                              std::size_t* rows_estimated, std::size_t* refusals,
                              bool bundled = false, nlohmann::json* final_state = nullptr,
                              double estimator_pass_s = ServerOptions{}.estimator_pass_s) {
  ServerOptions o = LiveOptions(dir, pipeline);
  o.estimator_pass_s = estimator_pass_s;
  if (!sim.levels.empty()) {
    o.floor_plan = sim.plan;  // the ground floor's
    o.floor_levels = sim.levels;
  } else if (RequirePipeline(pipeline).uses_floor_plan) {
    o.floor_plan = sim.plan;  // as `trailmark serve --live` gives the mission's plan
  }
  std::mutex m;
  std::vector<Estimate> live;
  o.on_estimate = [&](const Estimate& e) {
    std::lock_guard<std::mutex> lock(m);
    live.push_back(e);
  };
  IncidentServer server(sim.data.info, {}, o);
  server.Start();
  const MissionData& d = sim.data;
  const TimeS end = d.truth.back().t + 1;
  for (TimeS t = -5; t < end && bundled; t += 1.0) {
    Bundles b;
    b.Add("events.csv", d.events, t, t + 1);
    b.Add("steps.csv", d.steps, t, t + 1);
    b.Add("imu.csv", d.imu, t, t + 1);
    b.Add("ranges.csv", d.ranges, t, t + 1);
    b.Add("bearings.csv", d.bearings, t, t + 1);
    b.Add("rssi.csv", d.rssi, t, t + 1);
    b.Add("baro.csv", d.baro, t, t + 1);
    b.Send(server);
  }
  for (TimeS t = -5; t < end && !bundled; t += 1.0) {
    Post(server, "events.csv", d.events, t, t + 1);
    Post(server, "steps.csv", d.steps, t, t + 1);
    Post(server, "imu.csv", d.imu, t, t + 1);
    Post(server, "ranges.csv", d.ranges, t, t + 1);
    Post(server, "bearings.csv", d.bearings, t, t + 1);
    Post(server, "rssi.csv", d.rssi, t, t + 1);
    Post(server, "baro.csv", d.baro, t, t + 1);
  }
  const std::size_t rows = d.events.size() + d.steps.size() + d.imu.size() + d.ranges.size() +
                           d.bearings.size() + d.rssi.size() + d.baro.size();
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (server.stats().estimated_rows.load() < rows && std::chrono::steady_clock::now() < give_up)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  if (final_state) *final_state = server.StateJson();
  server.Stop();
  *rows_posted = rows;
  *rows_estimated = server.stats().estimated_rows.load();
  *refusals = server.stats().estimator_refusals.load();
  return live;
}

/// `exact_height`: z, szz and floor bit for bit too. A per-agent pipeline (pdr, ins) gets a
/// device's steps and barometer readings as they arrive, not merged in time order: an estimate's
/// height then uses the readings received so far, and only its horizontal part is the batch
/// run's bit for bit.
void ExpectLiveIsTheBatchPrefix(const std::string& pipeline, const SimulatedMission& sim,
                                bool exact_height = true, bool bundled = false,
                                double estimator_pass_s = ServerOptions{}.estimator_pass_s) {
  SCOPED_TRACE(pipeline + (bundled ? " (bundles)" : ""));
  TempDir dir;
  const MissionDirectory mission = WriteMission(dir, sim);
  VectorSink batch;
  trailmark::testing::RunNamed(pipeline, mission, {}, batch);
  std::size_t rows = 0, estimated = 0, refusals = 0;
  const std::vector<Estimate> live =
      RunLive(dir, pipeline, sim, &rows, &estimated, &refusals, bundled, nullptr, estimator_pass_s);
  EXPECT_EQ(estimated, rows);
  EXPECT_EQ(refusals, 0u);

  const auto a = ByNode(batch.rows), b = ByNode(live);
  std::size_t compared = 0, held = 0, floors_differ = 0;
  double max_dz = 0;
  for (const auto& [id, rows_of] : a) {
    const auto it = b.find(id);
    const std::size_t n = it == b.end() ? 0 : it->second.size();
    ASSERT_LE(n, rows_of.size()) << id;
    for (std::size_t i = 0; i < n; ++i) {
      ASSERT_EQ(rows_of[i].t, it->second[i].t) << id << " " << i;
      ASSERT_EQ(rows_of[i].position_n.head<2>(), it->second[i].position_n.head<2>())
          << id << " " << i;
      ASSERT_EQ(rows_of[i].sxx, it->second[i].sxx) << id << " " << i;
      ASSERT_EQ(rows_of[i].floor.has_value(), it->second[i].floor.has_value()) << id << " " << i;
      if (exact_height) {
        ASSERT_EQ(rows_of[i].position_n.z(), it->second[i].position_n.z()) << id << " " << i;
        ASSERT_EQ(rows_of[i].szz, it->second[i].szz) << id << " " << i;
        ASSERT_EQ(rows_of[i].floor, it->second[i].floor) << id << " " << i;
      } else {
        floors_differ += rows_of[i].floor != it->second[i].floor;
        max_dz = std::max(max_dz, std::abs(rows_of[i].position_n.z() - it->second[i].position_n.z()));
      }
    }
    compared += n;
    held += rows_of.size() - n;
    // What live still holds at the end: estimates of the last seconds, and the end-of-data
    // rows of the batch run (every static node's final row).
    for (std::size_t i = n; i < rows_of.size(); ++i) {
      EXPECT_GE(rows_of[i].t, rows_of.back().t - 3.0) << id << " " << i;
    }
  }
  EXPECT_GT(compared, 10 * held);
  // Heights from readings a second late at most: the same floor nearly always (at a landing
  // the level may change one estimate earlier or later), never far apart.
  EXPECT_LE(floors_differ, compared / 100) << "of " << compared;
  EXPECT_LT(max_dz, 1.5);
}

TEST(LiveServer, BeaconsEkfOnTheJournalIsTheBatchRun) {
  ExpectLiveIsTheBatchPrefix("beacons-ekf", testing::WithFootImuOnly(SimulateScenario("beacon-trail", 4), 3));
}

// The fusion live is its batch run, and the state says which members each firefighter's
// estimate uses (issue 27).
TEST(LiveServer, FusionOnTheJournalIsTheBatchRunAndNamesItsSources) {
  const SimulatedMission sim = SimulateScenario("beacon-trail", 4);
  ExpectLiveIsTheBatchPrefix("fusion", sim);
  TempDir dir;
  WriteMission(dir, sim);
  std::size_t rows = 0, estimated = 0, refusals = 0;
  nlohmann::json state;
  RunLive(dir, "fusion", sim, &rows, &estimated, &refusals, false, &state);
  bool any = false;
  for (const auto& n : state.at("nodes")) {
    if (n.at("kind") != "agent") continue;
    ASSERT_TRUE(n.contains("sources")) << n.dump();
    double sum = 0;
    for (const auto& s : n.at("sources")) {
      sum += s.at("weight").get<double>();
      any = any || s.at("source") == "beacons-ekf";
    }
    EXPECT_NEAR(sum, 1.0, 1e-9);
  }
  EXPECT_TRUE(any) << state.dump();  // the trail's ranges reached the beacon filter
}

// With a backlog the estimator works in passes (ServerOptions::estimator_pass_s) and the state
// is published between them; passes of one row each still give the batch run: no row lost,
// repeated or reordered at a pass's end.
TEST(LiveServer, AnEstimatorWorkingInShortPassesGivesTheBatchRunToo) {
  ExpectLiveIsTheBatchPrefix("breadcrumb", SimulateScenario("training-building", 2), true, false,
                             0.0);
}

TEST(LiveServer, BundlesOfADevicesStreamsGiveTheBatchRunToo) {
  // POST /api/ingest: each device's streams of a second in one request, one transaction.
  ExpectLiveIsTheBatchPrefix("beacons-ekf",
                             testing::WithFootImuOnly(SimulateScenario("beacon-trail", 4), 3),
                             /*exact_height=*/true, /*bundled=*/true);
  SimulatedMission sim = SimulateScenario("multi-floor", 3);
  sim.data.imu.clear();
  ExpectLiveIsTheBatchPrefix("pdr", sim, /*exact_height=*/false, /*bundled=*/true);
}

TEST(LiveServer, ABundleIsCheckedWholeBeforeAnyOfItIsJournaled) {
  TempDir dir;
  const SimulatedMission sim = SimulateScenario("beacon-trail", 4);
  WriteMission(dir, sim);
  IncidentServer server(sim.data.info, {}, LiveOptions(dir, "pdr"));
  server.Start();
  const std::string agent = sim.data.steps.front().agent;
  std::vector<Step> steps;
  for (const Step& st : sim.data.steps)
    if (st.agent == agent && steps.size() < 4) steps.push_back(st);
  const std::string good = Body(std::vector<Step>(steps.begin() + 2, steps.end()));
  const auto refused = [&](const std::string& body, const std::string& why) {
    try {
      server.IngestBundle(body);
      ADD_FAILURE() << "accepted: " << body;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(why), std::string::npos) << e.what();
    }
  };
  refused("{\"steps.csv\": ", "not JSON");
  refused("[1, 2]", "a bundle is a JSON object");
  refused("{}", "a bundle is a JSON object");
  refused(nlohmann::json{{"steps.csv", good}, {"rssi.csv", 5}}.dump(), "'rssi.csv' must be");
  // A bad row in the second section: the first is not journaled either; the error names the
  // section and the line.
  std::string bad_rssi = "t,rx,tx,rssi_dbm\n0.5," + agent + ",b1,-60\n0.6," + agent + ",b1,loud\n";
  refused(nlohmann::ordered_json{{"steps.csv", good}, {"rssi.csv", bad_rssi}}.dump(),
          "request body rssi.csv:3");
  refused(nlohmann::json{{"nope.csv", "t\n1\n"}}.dump(), "nope.csv");
  EXPECT_EQ(server.stats().ingested_rows.load(), 0u);
  // Accepted: both sections, one answer per stream.
  const nlohmann::json ok = server.IngestBundle(nlohmann::ordered_json{{"steps.csv", good}}.dump());
  EXPECT_EQ(ok["accepted"], 2u);
  EXPECT_EQ(ok["streams"]["steps.csv"]["accepted"], 2u);
  EXPECT_FALSE(ok.contains("error"));
  // A section out of time order is refused alone: the others of the bundle are committed, and
  // the answer says which (a resend is idempotent: its rows come back as duplicates).
  const std::string late = Body(std::vector<Step>(steps.begin(), steps.begin() + 1));
  const std::string baro = "t,agent,pressure_hpa\n" + std::to_string(steps.back().t1 + 1) + "," + agent + ",1013.0\n";
  const nlohmann::json partly =
      server.IngestBundle(nlohmann::ordered_json{{"steps.csv", late}, {"baro.csv", baro}}.dump());
  ASSERT_TRUE(partly.contains("error")) << partly.dump();
  EXPECT_NE(partly["streams"]["steps.csv"]["error"].get<std::string>().find("time order"),
            std::string::npos);
  EXPECT_EQ(partly["streams"]["baro.csv"]["accepted"], 1u);
  EXPECT_EQ(server.stats().ingested_rows.load(), 3u);
  server.Stop();
}

TEST(LiveServer, LandmarksUkfOnTheJournalIsTheBatchRun) {
  ExpectLiveIsTheBatchPrefix("landmarks-ukf", SimulateScenario("landmark-corridor", 4));
}

TEST(LiveServer, PdrWithABarometerOnTheJournalIsTheBatchRunFloorsIncluded) {
  // The multi-floor building: phone steps and barometers posted live give the batch run's
  // heights and floors (issue 26).
  SimulatedMission sim = SimulateScenario("multi-floor", 3);
  sim.data.imu.clear();  // the phone's steps only (the batch run would shadow the IMU with them)
  ExpectLiveIsTheBatchPrefix("pdr", sim, /*exact_height=*/false);
}

TEST(LiveServer, BreadcrumbAcrossFloorsOnTheJournalIsTheBatchRun) {
  // The multi-floor building's crumbs on every level, radio gated by floor (issue 26): a
  // pipeline in global time order gets the batch run's heights, so the same packets are gated
  // and the estimates are the batch run's bit for bit, floors included.
  SimulatedMission sim = SimulateScenario("multi-floor", 5);
  sim.data.imu.clear();
  ExpectLiveIsTheBatchPrefix("breadcrumb", sim);
}

TEST(LiveServer, MapMatchingFollowsTheFloorsLive) {
  // `trailmark serve --pipeline mapmatch` on a multi-floor building: every level's plan, each
  // agent's filter changing level in the stairwell as its barometer readings arrive. A
  // per-agent pipeline gets a device's steps and readings as they come, so a level may change
  // a step earlier or later than in the batch run and the particles differ: the live estimates
  // are as good as the batch run's, not equal to them.
  SimulatedMission sim = SimulateScenario("multi-floor", 13);
  sim.data.imu.clear();
  TempDir dir;
  const MissionDirectory mission = WriteMission(dir, sim);
  VectorSink batch;
  trailmark::testing::RunNamed("mapmatch", mission, {}, batch);
  std::size_t rows = 0, estimated = 0, refusals = 0;
  const std::vector<Estimate> live = RunLive(dir, "mapmatch", sim, &rows, &estimated, &refusals);
  ASSERT_EQ(estimated, rows);
  const MissionData& d = sim.data;
  auto sorted = [](std::vector<Estimate> v) {
    std::stable_sort(v.begin(), v.end(), [](const Estimate& a, const Estimate& b) { return a.t < b.t; });
    return v;
  };
  const Metrics mb = Evaluate(sim.data.info, d.truth, sorted(batch.rows));
  const Metrics ml = Evaluate(sim.data.info, d.truth, sorted(live));
  ASSERT_TRUE(mb.floors && ml.floors);
  EXPECT_GE(ml.floors->floor_hit_rate, mb.floors->floor_hit_rate - 0.01);
  EXPECT_LT(ml.agents.stats.mean_m, mb.agents.stats.mean_m + 0.5);
  EXPECT_LT(ml.agents.stats.mean_m, 2.0);
  std::printf("mapmatch live: mean %.2f m (batch %.2f m), right floor %.1f %% (batch %.1f %%)\n",
              ml.agents.stats.mean_m, mb.agents.stats.mean_m, 100 * ml.floors->floor_hit_rate,
              100 * mb.floors->floor_hit_rate);
  // Every live estimate of an agent carries its level.
  for (const Estimate& e : live) {
    if (e.id == "ff1" || e.id == "ff2") ASSERT_TRUE(e.floor.has_value()) << e.id << " " << e.t;
  }
}

TEST(LiveServer, BreadcrumbOnTheJournalIsTheBatchRun) {
  TrainingBuildingOptions o;
  o.rooms_per_side = 2;
  ExpectLiveIsTheBatchPrefix("breadcrumb", SimulateTrainingBuilding(o, 6));
}

}  // namespace
}  // namespace trailmark::server

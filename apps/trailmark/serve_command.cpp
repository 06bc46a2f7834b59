// SPDX-License-Identifier: MIT
// `trailmark serve --replay MISSION`: the incident server on a recorded or simulated mission.
#include <fmt/format.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <fstream>
#include <random>
#include <thread>

#include "commands.h"
#include "server/incident_server.h"
#include "server/journal.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/pipelines/batch_run.h"
#include "trailmark/pipelines/registry.h"

namespace trailmark::cli {

namespace {

std::atomic<bool> g_stop{false};
void OnSignal(int) { g_stop = true; }

std::string RandomToken() {
  std::random_device rd;
  return fmt::format("{:016x}{:016x}", (static_cast<unsigned long long>(rd()) << 32) ^ rd(),
                     (static_cast<unsigned long long>(rd()) << 32) ^ rd());
}

std::atomic<bool>& StopFlag() { return g_stop; }

// The floor the incident is tracked and drawn on: a floor-plan pipeline's `level` option when
// given (a level the plan lacks is an error naming its levels), else the plan's default floor;
// `levels` gets every level of a multi-level plan (the floor selector, mapmatch's levels).
std::optional<FloorPlan> ServedFloorPlan(const MissionDirectory& mission,
                                         const PipelineSpec& pipeline,
                                         const std::map<std::string, std::string>& options,
                                         LevelPlans* levels) {
  return LoadPipelineFloor(pipeline, mission, options, nullptr, levels);
}

}  // namespace

int ServeLive(const ServeOptions& o) {
  if (o.journal.empty()) throw std::invalid_argument("serve --live needs --journal FILE");
  const MissionDirectory mission(o.live);  // mission.json of the incident (nodes, floor plan)
  server::ServerOptions so;
  so.live_dir = o.live;
  so.journal_file = o.journal;
  // Without --pipeline: of the pipelines every incident can feed (steps or a foot IMU is all
  // they need), the one of lowest serve rank — the fusion, whose members join as their
  // evidence arrives.
  const PipelineSpec* chosen = nullptr;
  for (const auto& p : Pipelines()) {
    if (!o.pipeline.empty()) {
      if (p.name == o.pipeline) chosen = &p;
      continue;
    }
    const bool any_incident = !p.needs_floor_plan && p.min_landmarks == 0 && p.needs.size() == 1 &&
                              p.needs.front() == kStepOrImuStreams;
    if (any_incident && p.serve_rank && (!chosen || *p.serve_rank < *chosen->serve_rank))
      chosen = &p;
  }
  const PipelineSpec& spec = chosen ? *chosen : RequirePipeline(o.pipeline);
  so.pipeline = spec.name;
  so.pipeline_options = o.options;
  so.mqtt.uri = o.mqtt_uri;
  so.mqtt.incident = o.incident;
  so.mqtt.username = o.mqtt_user;
  so.mqtt.password = o.mqtt_password;
  so.mqtt.ca_file = o.mqtt_ca;
  so.tls_cert_file = o.tls_cert;
  so.tls_key_file = o.tls_key;
  so.bind = o.bind;
  so.header_deadline_s = o.header_deadline_s;
  so.max_connections_per_address = o.max_connections_per_address;
  so.request_deadline_s = o.request_deadline_s;
  so.port = o.port;
  so.token = o.token.empty() ? RandomToken() : o.token;
  so.alerts.map_error = spec.raises_map_alerts;
  std::vector<Segment2> walls;
  if (mission.info().floorplan && !mission.Has(*mission.info().floorplan)) {
    fmt::print(
        "note: mission.json names the floor plan '{}', which {} does not hold: the "
        "dashboard shows no walls\n",
        *mission.info().floorplan, o.live.string());
  } else if (auto plan = ServedFloorPlan(mission, spec, so.pipeline_options, &so.floor_levels)) {
    walls = plan->solid_walls();
    so.floor_plan = std::move(*plan);
  }
  server::IncidentServer srv(mission.info(), {}, so, {}, std::move(walls));
  srv.Start();
  fmt::print(
      "trailmark serve: live incident '{}', journal {}, pipeline {} (incremental), listening on "
      "{}://{}:{}/\n",
      mission.info().name, o.journal.string(), so.pipeline, srv.scheme(), o.bind, srv.port());
  fmt::print("dashboard: {}://{}:{}/?token={}\n", srv.scheme(), o.bind, srv.port(), so.token);
  if (!o.mqtt_uri.empty())
    fmt::print("mqtt: {}, topics trailmark/{}/<node>/<stream>\n", o.mqtt_uri, o.incident);
  std::fflush(stdout);
  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  while (!StopFlag()) std::this_thread::sleep_for(std::chrono::milliseconds(100));
  srv.Stop();
  fmt::print(
      "trailmark serve: stopped after {} requests ({} refused without the token, {} rejected), {} "
      "rows "
      "journaled, {} duplicates dropped\n",
      srv.stats().requests.load(), srv.stats().unauthorized.load(),
      srv.stats().rejected_requests.load(), srv.stats().ingested_rows.load(),
      srv.stats().duplicate_rows.load());
  if (const auto* m = srv.mqtt_stats()) {
    fmt::print("mqtt: {} messages received, {} ingested, {} rejected, {} estimates published\n",
               m->received.load(), m->ingested.load(), m->rejected.load(), m->published.load());
  }
  return 0;
}

int JournalExport(const std::filesystem::path& journal, const std::filesystem::path& mission,
                  const std::filesystem::path& out, bool salvage) {
  if (!std::filesystem::exists(journal))
    throw std::invalid_argument(journal.string() + ": no such journal");
  server::Journal j(journal, salvage ? server::Journal::Open::kSalvage : server::Journal::Open::kNormal);
  const std::size_t rows = j.Export(out, mission / "mission.json");
  if (j.problems().empty()) {
    fmt::print("exported {} rows from {} into {}\n", rows, journal.string(), out.string());
    return 0;
  }
  fmt::print("salvaged {} rows from {} into {}; the journal is damaged:\n", rows,
             journal.string(), out.string());
  for (const auto& p : j.problems()) fmt::print("  {}\n", p);
  return 3;
}

int Serve(const ServeOptions& o) {
  if (!o.live.empty()) return ServeLive(o);
  const MissionDirectory mission(o.replay);
  const PipelineSpec* p = nullptr;
  if (o.pipeline.empty()) {
    // The most capable pipeline the mission can feed (the registry's serve ranks).
    for (const auto& spec : Pipelines()) {
      if (spec.serve_rank && CanRun(spec, mission) && (!p || *spec.serve_rank < *p->serve_rank))
        p = &spec;
    }
    if (p == nullptr)
      throw std::invalid_argument("serve: no pipeline can run on " + o.replay.string());
  } else {
    p = &RequirePipeline(o.pipeline);
  }
  const std::string pipeline = p->name;
  VectorSink sink;
  const EstimatorSummary summary = RunBatch(*p, {mission, o.options}, sink);
  sink.rows = sink.TakeSortedByTime();
  server::ServerOptions so;
  so.bind = o.bind;
  so.header_deadline_s = o.header_deadline_s;
  so.max_connections_per_address = o.max_connections_per_address;
  so.request_deadline_s = o.request_deadline_s;
  so.port = o.port;
  so.tls_cert_file = o.tls_cert;
  so.tls_key_file = o.tls_key;
  so.speed = o.speed;
  so.token = o.token.empty() ? RandomToken() : o.token;
  so.alerts.map_error = p->raises_map_alerts;
  // When each node was heard (for the link-lost alert): every row of the measurement streams.
  const MissionData data = ReadMissionData(mission);
  std::vector<std::pair<TimeS, std::string>> heard;
  for (const auto& r : data.steps) heard.emplace_back(r.t1, r.agent);
  for (const auto& r : data.rssi) heard.emplace_back(r.t, r.rx), heard.emplace_back(r.t, r.tx);
  for (const auto& r : data.ranges) heard.emplace_back(r.t, r.a), heard.emplace_back(r.t, r.b);
  for (std::size_t k = 0; k < data.imu.size(); k += 10)
    heard.emplace_back(data.imu[k].t, data.imu[k].agent);
  std::stable_sort(heard.begin(), heard.end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<Segment2> walls;
  if (const auto plan = ServedFloorPlan(mission, *p, o.options, &so.floor_levels)) {
    walls = plan->solid_walls();
  }
  server::IncidentServer srv(mission.info(), std::move(sink.rows), so, std::move(heard),
                             std::move(walls));
  srv.SetIntegrityNotes(summary.integrity);
  srv.Start();
  fmt::print("trailmark serve: {} on '{}' at {}x, listening on {}://{}:{}/\n", pipeline,
             mission.info().name, o.speed, srv.scheme(), o.bind, srv.port());
  fmt::print("dashboard: {}://{}:{}/?token={}\n", srv.scheme(), o.bind, srv.port(), so.token);
  std::fflush(stdout);
  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  while (!g_stop) {
    if (o.exit_after_replay && srv.replay_done()) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  srv.Stop();
  fmt::print(
      "trailmark serve: stopped after {} requests ({} refused without the token), {} estimates "
      "released\n",
      srv.stats().requests.load(), srv.stats().unauthorized.load(),
      srv.stats().released_estimates.load());
  return 0;
}

int BenchLoad(const server::LoadTestOptions& options, const std::filesystem::path& json_out) {
  const std::string what =
      !options.mission.empty()
          ? fmt::format("the mission {} replayed (its agents as the devices)",
                        options.mission.string())
          : fmt::format("{} firefighters x {:g} min of {:g} Hz IMU + radio{}", options.firefighters,
                        options.minutes, options.imu_hz,
                        options.stagger_s > 0
                            ? fmt::format(" (starts {:g} s apart)", options.stagger_s)
                            : std::string(" (all in step)"));
  fmt::print(
      "bench load: {}, {:g} s per request{}, "
      "pipeline {}, {}, journal under {}\n",
      what, options.batch_s,
      options.speed > 0 ? fmt::format(" at {:g}x real time", options.speed) : std::string(),
      options.pipeline,
      !options.mqtt_uri.empty() ? "MQTT QoS 1 via " + options.mqtt_uri
      : options.bundle          ? std::string("HTTP POST, a window's streams in one request")
                                : std::string("HTTP POST, one request per stream"),
      std::filesystem::absolute(options.work_dir).string());
  std::fflush(stdout);
  const nlohmann::json r = server::RunLoadTest(options);
  fmt::print(
      "rows sent and journaled   {} ({} IMU, {} steps, {} of the other streams) in {} requests "
      "({}, {} devices, {:.1f} min)\n",
      r["rows"].get<std::size_t>(), r["imu_rows"].get<std::size_t>(),
      r["step_rows"].get<std::size_t>(),
      r["other_rows"].get<std::size_t>() - r["step_rows"].get<std::size_t>(),
      r["requests"].get<std::size_t>(), r["scenario"].get<std::string>(),
      r["firefighters"].get<std::size_t>(), r["incident_minutes"].get<double>());
  fmt::print(
      "sustained                 {:.0f} rows/s, {:.0f} requests/s ({:.0f}x real time per "
      "firefighter)\n",
      r["rows_per_s"].get<double>(), r["requests_per_s"].get<double>(),
      r["real_time_factor"].get<double>());
  fmt::print("group commits             {} ({:.0f} rows per fsync)\n",
             r["journal_commits"].get<std::size_t>(), r["rows_per_commit"].get<double>());
  fmt::print("latency POST -> event     p50 {:.1f} ms, p99 {:.1f} ms, max {:.1f} ms ({} batches)\n",
             r["latency_ms_p50"].get<double>(), r["latency_ms_p99"].get<double>(),
             r["latency_ms_max"].get<double>(), r["latency_samples"].get<std::size_t>());
  fmt::print("latency data -> estimate  p50 {:.1f} ms, p99 {:.1f} ms, max {:.1f} ms ({} estimates)\n",
             r["data_to_estimate_ms_p50"].get<double>(), r["data_to_estimate_ms_p99"].get<double>(),
             r["data_to_estimate_ms_max"].get<double>(),
             r["data_to_estimate_samples"].get<std::size_t>());
  if (const auto late = r["estimator"].find("rows_late"); late != r["estimator"].end()) {
    fmt::print("rows late at the estimator {:.0f} (after its reorder window)\n",
               late->get<double>());
  }
  fmt::print(
      "CPU                       {:.1f} s, {:.2f} cores busy (server and clients, one "
      "process)\n",
      r["cpu_s"].get<double>(), r["cpu_cores_busy"].get<double>());
  fmt::print("peak memory               {:.0f} MB resident\n", r["peak_rss_mb"].get<double>());
  if (!json_out.empty()) std::ofstream(json_out) << r.dump(2) << "\n";
  return 0;
}

}  // namespace trailmark::cli

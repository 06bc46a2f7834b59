// SPDX-License-Identifier: MIT
// trailmark: the command-line contract (docs/cli.md).
//   trailmark simulate SCENARIO --seed N --out DIR
//   trailmark run --pipeline NAME MISSION --out DIR
//   trailmark eval MISSION ESTIMATES.csv
//   trailmark report RUN_DIR... --out report.html
//   trailmark reproduce breadcrumb|ins [--seeds N]
//   trailmark energy [--battery-mah Q --sleep-ua I ...]
//   trailmark wayout MISSION [--agent A] [--at T]
//   trailmark patterns MISSION --out FILE [--level N] [--grid-m S] [--map-axes]
//   trailmark serve --replay MISSION [--speed S] [--port P] [--token T]
//   trailmark validate MISSION | pipelines | scenarios | demo | bench

#include <fmt/format.h>
#include <glog/logging.h>

#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <map>

#include "commands.h"
#include "experiments/experiments.h"
#include "trailmark/core/error.h"
#include "trailmark/io/convert_foot_imu.h"
#include "trailmark/io/convert_imdf.h"
#include "trailmark/io/convert_ipin.h"
#include "trailmark/io/convert_pyshoe.h"
#include "trailmark/io/convert_wrld.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/io/trajectory_formats.h"
#include "trailmark/landmarks/energy.h"
#include "trailmark/pipelines/batch_run.h"
#include "trailmark/pipelines/registry.h"
#include "trailmark/sim/scenarios.h"
#include "trailmark_generated/version.h"

namespace fs = std::filesystem;
using namespace trailmark;

std::map<std::string, std::string> ParseKeyValues(const std::vector<std::string>& items) {
  std::map<std::string, std::string> options;
  for (const auto& kv : items) {
    const auto eq = kv.find('=');
    if (eq == std::string::npos || eq == 0) {
      throw std::invalid_argument("--option wants key=value, got '" + kv + "'");
    }
    options[kv.substr(0, eq)] = kv.substr(eq + 1);
  }
  return options;
}

int main(int argc, char** argv) {
  // Ceres (the beacon map's least squares) reports a linear solve that Levenberg-Marquardt then
  // damps and retries as a glog warning on stderr, before glog is even initialized: not a
  // user's business. glog writes to stderr only (no log files), errors only.
  FLAGS_logtostderr = true;
  FLAGS_minloglevel = google::GLOG_ERROR;
  google::InitGoogleLogging(argv[0]);
  CLI::App app{"trailmark: where every firefighter is, without GPS or infrastructure"};
  // An unsigned option would take "-3" as 2^64 - 3: say so instead.
  const CLI::Validator kWholeNonNegative(
      [](std::string& text) {
        return !text.empty() && text.front() == '-'
                   ? "must be a whole number >= 0, not '" + text + "'"
                   : std::string();
      },
      "INT >= 0");
  app.require_subcommand(1);
  app.set_version_flag("--version", std::string("trailmark ") + TRAILMARK_VERSION);

  std::string scenario = "office-loop";
  std::uint64_t seed = 1;
  std::string out;
  auto* simulate = app.add_subcommand("simulate", "simulate a scenario into a mission directory");
  simulate->add_option("scenario", scenario, "scenario name (see 'trailmark scenarios')")
      ->required();
  simulate->add_option("--seed", seed, "random seed; the same seed gives the same mission")
      ->check(kWholeNonNegative);
  simulate->add_option("--out", out, "mission directory to write")->required();
  cli::SimulateImu sim_imu;
  simulate
      ->add_option("--imu-rate", sim_imu.rate_hz, "also write imu.csv: foot IMU at this rate (Hz)")
      ->check(CLI::Range(0.0, 2000.0));
  simulate->add_option("--imu-grade", sim_imu.grade,
                       "perfect, tactical, industrial (default), consumer");
  simulate->add_option("--imu-motion", sim_imu.motion, "walk (default), crawl, stairs");
  simulate->add_flag("--imu-only", sim_imu.drop_steps,
                     "no steps.csv: pipelines run the INS on imu.csv");
  simulate->add_option("--imu-mount", sim_imu.mount,
                       "the foot IMU mounted another way: YAW[,ROLL[,PITCH]] in degrees (e.g. 90: "
                       "y forward; 0,180: upside down)");
  cli::SimulateSearchArgs sim_search;
  simulate->add_option("--floorplan", sim_search.floorplan,
                       "search: the floor plan (GeoJSON) to search, e.g. from 'trailmark convert'");
  simulate->add_option("--level", sim_search.level,
                       "search: which floor (default level 0, else the lowest)");
  simulate->add_option("--entry", sim_search.entry, "search: where the team enters, X,Y in metres");
  simulate->add_option("--heading", sim_search.heading_deg,
                       "search: walking-in direction in degrees (0 = +x, 90 = +y; default: "
                       "away from the door nearest the entry)");
  simulate->add_option("--hand", sim_search.hand, "search: left (default) or right");
  simulate
      ->add_option("--firefighters", sim_search.firefighters,
                   "all-sources-4h: firefighters (default 20)")
      ->check(CLI::Range(1, 1000));
  simulate
      ->add_option("--minutes", sim_search.minutes,
                   "search: duration (default 10); all-sources-4h: length (default 240)")
      ->check(CLI::Range(0.1, 1440.0));

  cli::SimulateVary sim_vary;
  simulate
      ->add_option("--vary", sim_vary.k,
                   "draw variant K of the scenario: another frame, radio, ranges, surveys, PDR "
                   "errors, phone steps, events, start, CSV style (docs/simulator.md)")
      ->check(kWholeNonNegative);
  simulate->add_option("--family", sim_vary.family,
                       "with --vary: only this family (frame, radio, ranges, nodes, pdr, phone, "
                       "events, start, csv; default all)");

  app.add_subcommand("scenarios", "list the simulator's scenarios");

  std::string pipeline, mission;
  std::vector<std::string> run_options;
  auto* run = app.add_subcommand("run", "run a pipeline on a mission: DIR/estimates.csv");
  run->add_option("--pipeline", pipeline, "pipeline name (see 'trailmark pipelines')")->required();
  run->add_option("mission", mission, "mission directory")
      ->required()
      ->check(CLI::ExistingDirectory);
  run->add_option("--out", out, "output directory")->required();
  run->add_option("--option", run_options, "pipeline option key=value (repeatable)");

  auto* pipelines = app.add_subcommand("pipelines", "list pipelines, the files each needs and its options");
  bool pipelines_json = false, pipelines_markdown = false;
  pipelines->add_flag("--json", pipelines_json,
                      "the registry as JSON: name, needs, uses, live, capabilities, options");
  pipelines->add_flag("--markdown", pipelines_markdown,
                      "the option tables in Markdown (docs/pipeline-options.md)");

  auto* validate =
      app.add_subcommand("validate", "check every file of a mission (all reader checks)");
  validate->add_option("mission", mission, "mission directory")->required();

  std::string estimates, metrics_out;
  auto* eval = app.add_subcommand("eval", "score estimates against the mission's truth");
  eval->add_option("mission", mission, "mission directory with truth.csv")->required();
  eval->add_option("estimates", estimates, "estimates.csv")->required()->check(CLI::ExistingFile);
  eval->add_option("--out", metrics_out, "metrics.json path (default: next to the estimates)");

  std::vector<std::string> run_dirs;
  auto* report = app.add_subcommand("report", "write one self-contained HTML report");
  report->add_option("runs", run_dirs, "run directories (written by 'trailmark run')")
      ->required()
      ->check(CLI::ExistingDirectory);
  report->add_option("--mission", mission, "mission directory (default: from the runs)");
  report->add_option("--out", out, "HTML file")->required();

  std::string demo_out = "out/demo";
  auto* demo = app.add_subcommand("demo",
                                  "the main job: simulate the default mission, run every "
                                  "pipeline, print the summary and write the report");
  demo->add_option("--scenario", scenario, "scenario");
  demo->add_option("--seed", seed, "random seed");
  demo->add_option("--out", demo_out, "output directory");

  std::size_t bench_rows = 1'000'000;
  std::string bench_json;
  auto* bench = app.add_subcommand("bench", "I/O throughput per stream and pipeline speed");
  bench->add_option("--rows", bench_rows, "rows per stream");
  bench->add_option("--json", bench_json, "write the results as JSON");
  std::string bench_what;
  bench->add_option("what", bench_what,
                    "empty: I/O and pdr; 'breadcrumb': the large-incident benchmark (issue 8); "
                    "'load': the live server under load on loopback (issue 7); 'ins': the foot "
                    "INS on a mission's imu.csv, core and end to end (--mission); 'landmarks': "
                    "landmarks-ukf on a 4-hour 20-firefighter landmark incident (issue 24)");
  std::string bench_mission;
  int bench_runs = 7;
  bench
      ->add_option("--mission", bench_mission,
                   "ins: the mission directory whose imu.csv is run; load: the mission replayed "
                   "(its agents as the devices) instead of a simulation")
      ->check(CLI::ExistingDirectory);
  bench->add_option("--runs", bench_runs, "ins: runs of each measurement (the best is reported)")
      ->check(CLI::Range(1, 1000000));
  std::vector<std::string> bench_options;
  bench->add_option(
      "--option", bench_options,
      "ins, load, breadcrumb, landmarks: an option of the pipeline key=value (ins: for both "
      "measurements; breadcrumb: on top of the benchmark's; repeatable)");
  server::LoadTestOptions load;
  bench->add_option("--firefighters", load.firefighters, "load: firefighters sending at once");
  bench->add_option("--minutes", load.minutes, "load: incident minutes each one sends");
  bench->add_option("--batch", load.batch_s, "load: seconds of IMU per request");
  bench->add_option("--pipeline", load.pipeline, "load: the live pipeline (ins, pdr, ...)");
  bench
      ->add_option("--speed", load.speed,
                   "load: send at this multiple of real time (0: as fast as acknowledged)")
      ->check(CLI::Range(0.0, 1e9));
  bench->add_option("--max-skew", load.max_skew_s,
                    "load: devices keep within this many mission seconds of each other (0: free)");
  bench->add_option("--stagger", load.stagger_s,
                    "load: firefighter k starts (k-1) x this many seconds later (0: all in step)")
      ->check(CLI::Range(0.0, 3600.0));
  bool load_per_stream = false;
  bench->add_flag("--per-stream", load_per_stream,
                  "load: one request per stream (POST /api/ingest/<stream>) instead of each "
                  "window's streams in one (POST /api/ingest)");
  std::string load_dir = ".";
  bench->add_option("--dir", load_dir, "load: where the journal goes (a real disk)");
  bench->add_option(
      "--mqtt", load.mqtt_uri,
      "load: devices publish to this MQTT broker instead of POSTing (tcp://host:port)");
  IncidentOptions incident;
  double solve_period = 1.0, covariance_period = 5.0;
  bench->add_option("--agents", incident.agents, "breadcrumb, landmarks: firefighters");
  bench->add_option("--crumbs", incident.crumbs, "breadcrumb: breadcrumbs");
  bench->add_option("--hours", incident.duration_s, "breadcrumb, landmarks: incident length (h)")
      ->transform([](std::string v) {
        // Hours to seconds; anything that is no positive number is refused with the option's name.
        double h = 0;
        try {
          h = std::stod(v);
        } catch (const std::exception&) {
          throw CLI::ValidationError("'" + v + "' is not a number of hours");
        }
        if (!(h > 0) || !std::isfinite(h)) {
          throw CLI::ValidationError("'" + v + "' must be a positive number of hours");
        }
        return std::to_string(h * 3600.0);
      });
  bench->add_option("--measurements", incident.measurements, "breadcrumb: total measurements");
  bench->add_option("--solve-period", solve_period, "breadcrumb: re-solve at most every S s");
  bench->add_option("--covariance-period", covariance_period,
                    "breadcrumb: refresh marginal covariances every S s");

  std::string reproduce_name;
  int reproduce_seeds = 8;
  std::string reproduce_out = "out/reproduce";
  auto* reproduce = app.add_subcommand(
      "reproduce", "a paper's experiment on simulated equivalents, side by side with the paper");
  std::string reproduction_names;  // from the reproductions' registry: never out of date
  for (const auto& r : experiments::Reproductions())
    reproduction_names += (reproduction_names.empty() ? "" : " | ") + r.name;
  reproduce->add_option("name", reproduce_name, reproduction_names)->required();
  reproduce->add_option("--seeds", reproduce_seeds, "number of simulated runs (seeds 1..N)")
      ->check(CLI::Range(1, 1000));
  int reproduce_first_seed = 1;
  reproduce
      ->add_option("--first-seed", reproduce_first_seed,
                   "mapmatch: seed of the first run (runs first..first+N-1)")
      ->check(CLI::Range(1, 1000000));
  reproduce->add_option("--out", reproduce_out, "output directory (missions, runs, results.md)");
  std::string reproduce_data = std::getenv("TRAILMARK_SHARED_DATA")
                                   ? std::getenv("TRAILMARK_SHARED_DATA")
                                   : "../shared/data";
  reproduce->add_option("--data", reproduce_data,
                        "recorded data folder (ins: holds pyshoe-vicon/; default ../shared/data "
                        "or $TRAILMARK_SHARED_DATA)");
  std::vector<std::string> reproduce_options;
  reproduce->add_option("--option", reproduce_options,
                        "key=value passed to the reproduced pipeline (ablations)");
  std::vector<std::string> reproduce_pipelines;
  reproduce->add_option("--pipeline", reproduce_pipelines,
                        "robustness: only this pipeline (repeatable; needed with --option)");
  std::vector<std::string> reproduce_families;
  reproduce->add_option("--family", reproduce_families,
                        "robustness: only this variation family (repeatable)");

  std::string convert_format, convert_src, convert_out;
  auto* convert =
      app.add_subcommand("convert",
                         "convert recorded data into a mission directory (formats: pyshoe-vicon, "
                         "openshoe-figure8, llio-gcp-walk, zupt-dualfoot, wrld-indoor, euroc, ipin-logfile, imdf)");
  convert
      ->add_option("format", convert_format,
                   "pyshoe-vicon (TRIAL.csv) | openshoe-figure8 (imu_820hz.txt) | llio-gcp-walk "
                   "(WALK_imu.csv) | zupt-dualfoot (the folder) | wrld-indoor (the folder "
                   "holding main.json: a WRLD indoor map as a multi-floor floor plan) | euroc "
                   "(a EuRoC mav0 folder or its state_groundtruth_estimate0/data.csv: ground "
                   "truth, and imu0 when present) | ipin-logfile (an IPIN competition "
                   "GetSensorData logfile: IMU, barometer, POSI truth with floors, BLE, WiFi) | "
                   "imdf (an IMDF venue .zip or its folder: levels, units, openings as doors)")
      ->required();
  convert->add_option("source", convert_src, "source file or folder")
      ->required()
      ->check(CLI::ExistingPath);
  convert->add_option("--out", convert_out, "mission directory to write")->required();
  IpinOptions ipin_options;
  std::string convert_origin;
  convert->add_option("--agent", ipin_options.agent, "ipin-logfile: the phone's node id (default phone)");
  convert->add_option("--origin", convert_origin,
                      "ipin-logfile, imdf: LAT,LON[,HEIGHT] of the frame's origin (default: the "
                      "first POSI; the venue's display point)");
  convert->add_option("--max-venue-m", ipin_options.max_venue_m,
                      "ipin-logfile: a POSI farther from the origin is refused (default 2000 m)")
      ->check(CLI::PositiveNumber);

  std::string export_format, export_source, export_id, export_out;
  auto* export_cmd = app.add_subcommand(
      "export",
      "write estimates or truth in a standard trajectory format (tum: for evo_ape / evo_rpe), or "
      "a mission's floor plan as WGS 84 GeoJSON for GIS tools (geojson-wgs84)");
  export_cmd->add_option("format", export_format, "tum | geojson-wgs84")->required();
  export_cmd
      ->add_option("source", export_source,
                   "tum: estimates.csv or truth.csv; geojson-wgs84: the mission directory (its "
                   "floor plan and geo_origin)")
      ->required()
      ->check(CLI::ExistingPath);
  export_cmd->add_option("--id", export_id, "tum: the node whose trajectory to write");
  export_cmd->add_option("--out", export_out, "file to write")->required();

  landmarks::EnergyModel energy_model;
  std::vector<double> energy_after_years{0, 1, 2, 5};
  std::vector<double> energy_periods{0.5, 1, 3, 10, 60};
  auto* energy = app.add_subcommand(
      "energy", "landmark battery lifetime (radio-landmarks paper, eqs. 1-2, Fig. 5)");
  energy->add_option("--battery-mah", energy_model.battery_mAh, "battery capacity (mAh)")
      ->check(CLI::PositiveNumber);
  energy->add_option("--sleep-ua", energy_model.sleep_current_uA, "sleep current (uA)")
      ->check(CLI::PositiveNumber);
  energy->add_option("--send-ma", energy_model.send_current_mA, "current while sending (mA)")
      ->check(CLI::NonNegativeNumber);
  energy->add_option("--send-ms", energy_model.send_time_ms, "time of one send (ms)")
      ->check(CLI::NonNegativeNumber);
  energy->add_option("--after-years", energy_after_years, "years asleep before the emergency")
      ->check(CLI::NonNegativeNumber);
  energy->add_option("--periods", energy_periods, "wake-up periods (s)")
      ->check(CLI::PositiveNumber);

  std::string wayout_mission, wayout_agent = "ff1";
  double wayout_at = std::numeric_limits<double>::quiet_NaN();
  auto* wayout = app.add_subcommand(
      "wayout",
      "the way back out along an ultrasound beacon trail: walk to the smallest beacon id "
      "you hear (ultrasound-beacons paper, sec. 4)");
  wayout->add_option("mission", wayout_mission, "mission directory with ranges.csv")->required();
  wayout->add_option("--agent", wayout_agent, "the firefighter (default ff1)");
  wayout->add_option("--at", wayout_at, "mission time (s); default: the end of the mission");

  std::string patterns_mission, patterns_out;
  int patterns_level = 0;
  double patterns_grid_m = 1.0;
  bool patterns_map_axes = false;
  auto* patterns = app.add_subcommand(
      "patterns",
      "map matching's search grid and directional-search sequences of a mission's floor plan, "
      "as GeoJSON, and the doors no sequence passes (issue 23)");
  patterns->add_option("mission", patterns_mission, "mission directory with a floor plan")
      ->required();
  patterns->add_option("--out", patterns_out, "GeoJSON file to write")->required();
  auto* patterns_level_opt = patterns->add_option("--level", patterns_level,
                                                  "which floor (default level 0, else the lowest)");
  patterns->add_option("--grid-m", patterns_grid_m, "grid spacing (m; default 1)");
  patterns->add_flag("--map-axes", patterns_map_axes,
                     "the grid along the map's x/y axes (the paper) instead of the walls");

  cli::ServeOptions serve_options;
  std::string serve_replay;
  std::vector<std::string> serve_kv;
  auto* serve =
      app.add_subcommand("serve",
                         "the incident server: replays a mission's online estimates at a speed "
                         "and serves the state and the dashboard over HTTP (docs/server.md)");
  std::string serve_live, serve_journal;
  auto* replay_opt = serve->add_option("--replay", serve_replay, "mission directory to replay");
  auto* live_opt = serve->add_option("--live", serve_live,
                                     "live incident: directory with its mission.json; "
                                     "measurements are POSTed to /api/ingest/<stream> (or a "
                                     "device's streams together to /api/ingest)");
  serve->add_option("--journal", serve_journal,
                    "live mode: the SQLite journal file (created or resumed)");
  serve->add_option("--mqtt", serve_options.mqtt_uri,
                    "live mode: also ingest from this MQTT broker (tcp://host:port)");
  serve->add_option("--incident", serve_options.incident,
                    "MQTT topic tree trailmark/<incident>/... (default incident)");
  serve->add_option("--mqtt-user", serve_options.mqtt_user, "MQTT user name");
  serve->add_option("--mqtt-password", serve_options.mqtt_password,
                    "MQTT password (also $TRAILMARK_MQTT_PASSWORD)");
  serve->add_option("--mqtt-ca", serve_options.mqtt_ca,
                    "ssl:// brokers: the CA certificate (PEM) to trust");
  serve->add_option("--tls-cert", serve_options.tls_cert,
                    "serve HTTPS with this certificate chain (PEM)");
  serve->add_option("--tls-key", serve_options.tls_key, "the private key (PEM) of --tls-cert");
  replay_opt->excludes(live_opt);
  serve->add_option("--pipeline", serve_options.pipeline,
                    "pipeline (default: the most capable runnable one)");
  serve->add_option("--option", serve_kv, "pipeline option key=value (repeatable)");
  serve->add_option("--speed", serve_options.speed, "mission seconds per wall second")
      ->check(CLI::PositiveNumber);
  serve->add_option("--port", serve_options.port, "TCP port (0: any free port)")
      ->check(CLI::Range(0, 65535));
  serve->add_option("--bind", serve_options.bind,
                    "address to listen on (default 127.0.0.1, loopback only)");
  serve->add_option("--token", serve_options.token,
                    "access token (default: $TRAILMARK_TOKEN, else a random one)");
  serve->add_option("--header-deadline", serve_options.header_deadline_s,
                    "seconds a request's line and headers (and a TLS handshake) may take (default 10)")
      ->check(CLI::PositiveNumber);
  serve->add_option("--request-deadline", serve_options.request_deadline_s,
                    "seconds a whole request, body included, may take (default 60)")
      ->check(CLI::PositiveNumber);
  serve->add_option("--max-connections-per-address", serve_options.max_connections_per_address,
                    "connections one client address may hold (default 32; 0: no cap)")
      ->check(CLI::Range(0, 1000000));
  serve->add_flag("--exit-after-replay", serve_options.exit_after_replay,
                  "stop when the replay has ended");

  std::string journal_file, journal_mission, journal_out;
  auto* journal = app.add_subcommand("journal", "the incident journal of `trailmark serve --live`");
  auto* journal_export =
      journal->add_subcommand("export", "write the journal as a mission directory");
  journal_export->add_option("journal", journal_file, "journal file")->required();
  journal_export
      ->add_option("--mission", journal_mission, "directory with the incident's mission.json")
      ->required();
  journal_export->add_option("--out", journal_out, "mission directory to write")->required();
  bool journal_salvage = false;
  journal_export->add_flag("--salvage", journal_salvage,
                           "a damaged journal: write what is readable and say what is not (exit 3)");
  journal->require_subcommand(1);

  CLI11_PARSE(app, argc, argv);
  try {
    if (*simulate) {
      cli::Simulate(scenario, seed, out, sim_imu, sim_search, sim_vary);
    } else if (app.got_subcommand("scenarios")) {
      for (const auto& s : Scenarios()) fmt::print("{:<18} {}\n", s.name, s.description);
      fmt::print("{:<18} {}\n", "search",
                 "a left- or right-hand directional search on your own floor plan: --floorplan "
                 "F [--level N] --entry X,Y [--heading DEG] [--hand left|right] [--minutes M]");
    } else if (*run) {
      const RunResult r = cli::Run(pipeline, mission, out, ParseKeyValues(run_options));
      fmt::print("{}: {} estimates in {:.3f} s -> {}\n", r.pipeline, r.estimates, r.wall_time_s,
                 (fs::path(out) / "estimates.csv").string());
    } else if (*pipelines) {
      if (pipelines_json) {
        fmt::print("{}\n", RegistryJson());
      } else if (pipelines_markdown) {
        fmt::print("{}", RegistryMarkdown());
      } else {
        for (const auto& p : Pipelines()) {
          std::string needs, uses;
          for (const auto& f : p.NeedsText()) needs += (needs.empty() ? "" : ", ") + f;
          for (Stream s : p.uses.List()) uses += (uses.empty() ? "" : ", ") + std::string(StreamFileName(s));
          fmt::print("{:<16} {}\n{:<16} needs: mission.json, {}; uses if present: {}; {} options "
                     "(--json lists them)\n",
                     p.name, p.description, "", needs, uses, p.options.size());
        }
      }
    } else if (*validate) {
      cli::Validate(mission);
    } else if (*eval) {
      const fs::path m = metrics_out.empty() ? fs::path(estimates).parent_path() / "metrics.json"
                                             : fs::path(metrics_out);
      cli::Eval(mission, estimates, m, true);
    } else if (*report) {
      std::vector<fs::path> dirs(run_dirs.begin(), run_dirs.end());
      cli::Report(dirs, mission, out);
    } else if (*demo) {
      return cli::Demo(scenario, seed, demo_out);
    } else if (*bench) {
      if (bench_what == "breadcrumb") {
        return cli::BenchBreadcrumb(incident, solve_period, covariance_period, bench_json,
                                    ParseKeyValues(bench_options));
      }
      if (bench_what == "landmarks") {
        LandmarkIncidentOptions o;
        o.agents = incident.agents;
        o.duration_s = incident.duration_s;
        return cli::BenchLandmarks(o, ParseKeyValues(bench_options), bench_json);
      }
      if (bench_what == "ins") {
        if (bench_mission.empty()) throw std::invalid_argument("bench ins needs --mission DIR");
        return cli::BenchIns(bench_mission, bench_runs, ParseKeyValues(bench_options), bench_json);
      }
      if (bench_what == "load") {
        load.work_dir = load_dir;
        load.mission = bench_mission;
        load.pipeline_options = ParseKeyValues(bench_options);
        load.bundle = !load_per_stream;
        return cli::BenchLoad(load, bench_json);
      }
      if (!bench_what.empty())
        throw std::invalid_argument("unknown benchmark '" + bench_what + "'");
      return cli::Bench(bench_rows, bench_json);
    } else if (*convert) {
      std::size_t samples = 0;
      if (convert_format == "wrld-indoor") {
        const WrldBuilding building = ReadWrldBuilding(convert_src);
        WriteWrldMission(building, convert_out);
        for (const auto& l : building.levels) {
          fmt::print("level {:>3} ({}): {} walls, {} rooms\n", l.z_order,
                     l.name.empty() ? l.id : l.name, l.walls.size(), l.rooms.size());
        }
        fmt::print("converted {} ({} levels) into {} (floorplan.geojson, mission.json)\n",
                   convert_src, building.levels.size(), convert_out);
        return 0;
      }
      if (convert_format == "imdf") {
        const ImdfVenue venue = ReadImdfVenue(
            convert_src, convert_origin.empty() ? std::nullopt
                                             : std::optional<GeoOrigin>(cli::ParseGeoOrigin(convert_origin)));
        WriteImdfMission(venue, convert_out);
        for (const auto& l : venue.levels) {
          fmt::print("level {:>3} ({}): {} walls, {} doors, {} rooms\n", l.ordinal,
                     l.name.empty() ? l.ids.front() : l.name, l.walls.size(), l.doors.size(), l.rooms.size());
        }
        for (const auto& note : venue.notes) fmt::print("note: {}\n", note);
        fmt::print("converted {} ({} levels) into {} (floorplan.geojson, mission.json)\n",
                   convert_src, venue.levels.size(), convert_out);
        return 0;
      }
      if (convert_format == "ipin-logfile") {
        if (!convert_origin.empty()) ipin_options.origin = cli::ParseGeoOrigin(convert_origin);
        const IpinLogfile log = ReadIpinLogfile(convert_src, ipin_options);
        WriteIpinMission(log, convert_out);
        for (const auto& [type, count] : log.records) fmt::print("{:>6} {}\n", type, count);
        for (const auto& note : log.notes) fmt::print("note: {}\n", note);
        fmt::print("converted {} into {} ({} IMU samples, {} truth positions, {} BLE packets)\n",
                   convert_src, convert_out, log.mission.imu.size(), log.mission.truth.size(),
                   log.mission.rssi.size());
        return 0;
      }
      if (convert_format == "pyshoe-vicon") {
        const PyShoeTrial trial = ReadPyShoeTrial(convert_src);
        WritePyShoeMission(trial, convert_out);
        samples = trial.imu.size();
      } else {
        MissionData m;
        if (convert_format == "openshoe-figure8")
          m = ReadOpenShoeFigure8(convert_src);
        else if (convert_format == "llio-gcp-walk")
          m = ReadLlioWalk(convert_src);
        else if (convert_format == "zupt-dualfoot")
          m = ReadDualFoot(convert_src);
        else if (convert_format == "euroc")
          m = ReadEuroc(convert_src);
        else
          throw std::invalid_argument("unknown format '" + convert_format + "'");
        WriteMissionDirectory(convert_out, m, nullptr);
        samples = m.imu.size();
      }
      fmt::print("converted {} ({} IMU samples) into {}\n", convert_src, samples, convert_out);
    } else if (*export_cmd) {
      if (export_format == "geojson-wgs84") {
        cli::ExportFloorPlanWgs84(export_source, export_out);
        fmt::print("wrote the floor plan of {} as WGS 84 GeoJSON to {}\n", export_source, export_out);
        return 0;
      }
      if (export_format != "tum") {
        throw std::invalid_argument("unknown export format '" + export_format +
                                    "' (tum, geojson-wgs84)");
      }
      if (export_id.empty()) throw std::invalid_argument("export tum needs --id ID");
      const std::size_t poses = cli::ExportTum(export_source, export_id, export_out);
      fmt::print("wrote {} poses of {} to {}\n", poses, export_id, export_out);
    } else if (*energy) {
      const auto& e = energy_model;
      fmt::print("landmark: {} mAh, sleep {} uA, send {} mA for {} ms\n", e.battery_mAh,
                 e.sleep_current_uA, e.send_current_mA, e.send_time_ms);
      fmt::print("sleep-only lifetime: {:.2f} years (eq. 1 with Q_left = 0)\n\n",
                 e.SleepLifetimeS() / landmarks::kSecondsPerYear);
      fmt::print("operating time when woken every T_wakeup, after sleeping (eq. 2):\n");
      fmt::print("{:>12}", "T_wakeup s");
      for (double y : energy_after_years) fmt::print(" {:>14}", fmt::format("after {:g} y", y));
      fmt::print("\n");
      for (double p : energy_periods) {
        fmt::print("{:>12g}", p);
        for (double y : energy_after_years) {
          const double t = e.MaxOperatingTimeS(y * landmarks::kSecondsPerYear, p);
          fmt::print(" {:>14}", t >= 86400 * 2 ? fmt::format("{:.1f} d", t / 86400)
                                               : fmt::format("{:.1f} h", t / 3600));
        }
        fmt::print("\n");
      }
    } else if (*serve) {
      if (serve_replay.empty() && serve_live.empty())
        throw std::invalid_argument("serve needs --replay MISSION or --live DIR");
      serve_options.live = serve_live;
      if (serve_options.mqtt_password.empty() && std::getenv("TRAILMARK_MQTT_PASSWORD")) {
        serve_options.mqtt_password = std::getenv("TRAILMARK_MQTT_PASSWORD");
      }
      serve_options.journal = serve_journal;
      serve_options.replay = serve_replay;
      serve_options.options = ParseKeyValues(serve_kv);
      if (serve_options.token.empty() && std::getenv("TRAILMARK_TOKEN"))
        serve_options.token = std::getenv("TRAILMARK_TOKEN");
      return cli::Serve(serve_options);
    } else if (*journal_export) {
      return cli::JournalExport(journal_file, journal_mission, journal_out, journal_salvage);
    } else if (*patterns) {
      return cli::WriteSearchPatterns(
          patterns_mission, patterns_out,
          patterns_level_opt->count() > 0 ? std::optional<int>(patterns_level) : std::nullopt,
          patterns_grid_m, patterns_map_axes);
    } else if (*wayout) {
      const MissionDirectory m(wayout_mission);
      const beacons::WayOutReport w = ComputeWayOut(
          m, wayout_agent, std::isnan(wayout_at) ? std::nullopt : std::optional<double>(wayout_at));
      std::string heard;
      for (const auto& h : w.heard) heard += (heard.empty() ? "" : ", ") + h;
      fmt::print("{} hears: {}\n", wayout_agent, heard.empty() ? "no beacon" : heard);
      for (std::size_t k = 0; k < w.route.size(); ++k) {
        const auto& p = w.route_positions_n[k];
        fmt::print("{:>3}. {:<10} {}\n", k + 1, w.route[k],
                   p ? fmt::format("at ({:.1f}, {:.1f}) m", p->x(), p->y()) : "position unknown");
      }
      if (w.broken) fmt::print("warning: {}\n", *w.broken);
      if (!w.route.empty() && !w.broken) fmt::print("then out through the entry\n");
      return w.route.empty() || w.broken ? 3 : 0;
    } else if (*reproduce) {
      experiments::ReproductionArgs args;
      args.seeds = reproduce_seeds;
      args.out = reproduce_out;
      args.options = ParseKeyValues(reproduce_options);
      args.data_dir = reproduce_data;
      args.first_seed = reproduce_first_seed;
      args.pipelines = reproduce_pipelines;
      args.families = reproduce_families;
      return experiments::Reproduce(reproduce_name, args);
    }
  } catch (const InputError& e) {
    fmt::print(stderr, "error: {}\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    fmt::print(stderr, "error: {}\n", e.what());
    return 1;
  }
  return 0;
}

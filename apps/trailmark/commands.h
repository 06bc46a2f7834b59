// SPDX-License-Identifier: MIT
#pragma once
// The CLI's commands. Each is a plain function so tests and the demo can call them.

#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "server/load_test.h"
#include "trailmark/eval/metrics.h"
#include "trailmark/pipelines/batch_run.h"
#include "trailmark/sim/synthetic_incident.h"

namespace trailmark::cli {

/// Foot-IMU options of `trailmark simulate` (rate 0: no imu.csv).
struct SimulateImu {
  double rate_hz = 0;
  std::string grade = "industrial";
  std::string motion = "walk";
  bool drop_steps = false;  ///< write imu.csv only (no steps.csv): pipelines then run the INS
  /// "YAW[,ROLL[,PITCH]]" in degrees: the IMU mounted another way (MountImu); given empty: refused
  std::optional<std::string> mount;
};
/// The `search` scenario of `trailmark simulate`: a directional search on the user's floor plan
/// (one floor of it), entering at `entry` ("X,Y" in the plan's metres).
struct SimulateSearchArgs {
  std::string floorplan;              ///< floor-plan GeoJSON file (spec: "Floor plans")
  std::optional<int> level;           ///< default: level 0, else the lowest
  std::string entry;                  ///< "X,Y"
  std::optional<double> heading_deg;  ///< walking in; default: away from the nearest door
  std::string hand = "left";
  std::optional<double> minutes;    ///< search: default 10; all-sources-4h: default 240
  std::optional<int> firefighters;  ///< all-sources-4h: default 20
  bool Given() const {
    return !floorplan.empty() || level || !entry.empty() || heading_deg || hand != "left";
  }
};
/// `--vary K [--family F]`: a variant of the scenario (sim/variation.h, docs/simulator.md).
struct SimulateVary {
  std::optional<std::uint64_t> k;
  std::string family = "all";
};
void Simulate(const std::string& scenario, std::uint64_t seed, const std::filesystem::path& out,
              const SimulateImu& imu = {}, const SimulateSearchArgs& search = {},
              const SimulateVary& vary = {});
RunResult Run(const std::string& pipeline, const std::filesystem::path& mission,
              const std::filesystem::path& out, const std::map<std::string, std::string>& options);
/// Evaluates, prints the per-node table, writes metrics.json next to the estimates (or `out`).
Metrics Eval(const std::filesystem::path& mission, const std::filesystem::path& estimates,
             const std::filesystem::path& metrics_out, bool print);
void Report(const std::vector<std::filesystem::path>& run_dirs,
            const std::filesystem::path& mission, const std::filesystem::path& out);
/// The main job: simulate the default mission and run every pipeline it has the inputs for;
/// the other pipelines run on the simulated experiment of their paper (landmark corridor,
/// beacon trail, each with dead reckoning for comparison); print the summary table and write
/// one HTML report per mission.
int Demo(const std::string& scenario, std::uint64_t seed, const std::filesystem::path& out);
/// "LAT,LON[,HEIGHT]" (degrees, metres); std::invalid_argument naming the text otherwise.
GeoOrigin ParseGeoOrigin(const std::string& text);
/// `trailmark export tum FILE --id ID --out OUT`: the node's rows of an estimates.csv or a
/// truth.csv (told apart by their header) as a TUM trajectory; returns the number of poses.
/// Throws InputError naming the ids the file has when `id` is not among them.
std::size_t ExportTum(const std::filesystem::path& source, const std::string& id,
                      const std::filesystem::path& out);
/// `trailmark export geojson-wgs84 MISSION --out FILE`: the mission's floor plan (every level)
/// in WGS 84 longitude/latitude at its geo_origin. InputError when it has neither.
void ExportFloorPlanWgs84(const std::filesystem::path& mission, const std::filesystem::path& out);

/// `trailmark patterns MISSION --out FILE`: map matching's search grid and directional-search
/// sequences of the mission's floor plan, written as GeoJSON (the plan, every sequence, the
/// inside nodes, the inner doors no sequence passes), with a summary printed (issue 23). The
/// entry is the first agent's start (else the inside node nearest the plan's corner). Returns
/// 0, or 3 when an inner door is not traversed.
int WriteSearchPatterns(const std::filesystem::path& mission, const std::filesystem::path& out,
                        std::optional<int> level, double grid_m, bool map_axes);

/// Reads every file of a mission with all checks; prints rows and time span per stream.
void Validate(const std::filesystem::path& mission);
int Bench(std::size_t rows, const std::filesystem::path& json_out);
/// `trailmark bench breadcrumb`: the large-incident benchmark of the breadcrumb localizer;
/// `localizer_options`: breadcrumb pipeline options (key=value) on top of the benchmark's own.
int BenchBreadcrumb(const IncidentOptions& options, double solve_period_s,
                    double covariance_period_s, const std::filesystem::path& json_out,
                    const std::map<std::string, std::string>& localizer_options = {});
/// `trailmark bench landmarks`: landmarks-ukf on a synthetic landmark incident (issue 24), rows
/// in memory: the pipeline as `run` builds it and the estimator alone; `options`: the pipeline's.
int BenchLandmarks(const LandmarkIncidentOptions& options,
                   const std::map<std::string, std::string>& pipeline_options,
                   const std::filesystem::path& json_out);
/// `trailmark bench ins --mission DIR`: the INS core on the samples in memory and the whole
/// `run --pipeline ins`, samples/s, best of `runs`.
int BenchIns(const std::filesystem::path& mission_dir, int runs,
             const std::map<std::string, std::string>& options,
             const std::filesystem::path& json_out);
/// `trailmark bench load`: the live server under load on loopback (server/load_test.h).
int BenchLoad(const server::LoadTestOptions& options, const std::filesystem::path& json_out);
/// `trailmark serve`: replay a mission's online estimates into the incident server.
struct ServeOptions {
  std::filesystem::path replay;
  std::string pipeline;  ///< empty: the most capable runnable one
  std::map<std::string, std::string> options;
  double speed = 10;
  int port = 8080;
  std::string bind = "127.0.0.1";
  std::string token;  ///< empty: a random one is made and printed
  bool exit_after_replay = false;
  std::filesystem::path live, journal;  ///< live mode: mission.json directory and journal file
  std::string mqtt_uri, incident = "incident", mqtt_user, mqtt_password;  ///< live mode over MQTT
  std::string mqtt_ca;            ///< CA certificate (PEM) that signed the broker's (ssl://)
  std::string tls_cert, tls_key;  ///< HTTPS: the server's certificate chain and key (PEM)
  double header_deadline_s = 10.0;               ///< see server::ServerOptions
  std::size_t max_connections_per_address = 32;  ///< 0: no cap
  double request_deadline_s = 60.0;
};
int Serve(const ServeOptions& options);
int ServeLive(const ServeOptions& options);
/// `trailmark journal export JOURNAL --mission DIR --out OUT [--salvage]`: exit 3 when salvaging
/// found the journal damaged (what was readable is written).
int JournalExport(const std::filesystem::path& journal, const std::filesystem::path& mission,
                  const std::filesystem::path& out, bool salvage = false);

void PrintSummaryTable(const std::vector<std::pair<RunResult, Metrics>>& rows,
                       const std::vector<std::string>& missions);

}  // namespace trailmark::cli

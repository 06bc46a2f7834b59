#pragma once
/// `trailmark serve`: the incident server (issue 7, first part). Replays a mission's online
/// estimates at a chosen speed into an IncidentState and serves it over HTTP (cpp-httplib):
///   GET /api/state   (Authorization: Bearer TOKEN)  -> the state JSON, 401 without the token
///   GET /?token=TOKEN                                -> the dashboard page
///   GET /api/health                                  -> {"ok": true} (no token)
///   GET /api/floorplan (bearer token)                -> {"walls": [[x0, y0, x1, y1], ...]}
///   POST /api/ingest/<stream> (bearer token; live mode) -> rows journaled, then acknowledged
/// Binds to 127.0.0.1 unless told otherwise. Every request without the right token is refused
/// and counted. See docs/server.md.

#include <atomic>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "server/incident_state.h"
#include "server/mqtt_bridge.h"
#include "trailmark/geometry/segment.h"

namespace trailmark::server {

struct ServerOptions {
  /// Live mode (instead of a replay): a directory with the incident's mission.json, and the
  /// journal file; measurements are POSTed to /api/ingest/<stream>, journaled, and the pipeline
  /// re-run on the journal at most every `live_period_s`.
  std::filesystem::path live_dir, journal_file;
  std::string pipeline = "pdr";
  std::map<std::string, std::string> pipeline_options;
  double live_period_s = 1.0;
  MqttOptions mqtt;  ///< live mode: also ingest from an MQTT broker when `mqtt.uri` is set
  std::string bind = "127.0.0.1";
  int port = 8080;      ///< 0: any free port (see IncidentServer::port())
  std::string token;    ///< required; never empty
  double speed = 10.0;  ///< mission seconds per wall second
  AlertOptions alerts;
  std::size_t max_request_bytes = 1 << 20;
};

struct ServerStats {
  std::atomic<std::size_t> requests{0}, unauthorized{0}, released_estimates{0};
  std::atomic<std::size_t> ingested_rows{0}, duplicate_rows{0}, rejected_requests{0},
      pipeline_runs{0};
};

class IncidentServer {
 public:
  /// `estimates` in non-decreasing time (a pipeline's online output); `heard`: (time, node) of
  /// every measurement, released with the replay for the link-lost alert; `walls`: the floor
  /// plan's solid walls for the dashboard (may be empty).
  IncidentServer(const MissionInfo& info, std::vector<Estimate> estimates, ServerOptions options,
                 std::vector<std::pair<TimeS, std::string>> heard = {},
                 std::vector<Segment2> walls = {});
  ~IncidentServer();
  IncidentServer(const IncidentServer&) = delete;
  IncidentServer& operator=(const IncidentServer&) = delete;

  /// Binds and starts serving and replaying; throws std::runtime_error when it cannot bind.
  void Start();
  void Stop();
  int port() const { return port_; }
  bool replay_done() const { return replay_done_; }
  const ServerStats& stats() const { return stats_; }
  const MqttStats* mqtt_stats() const { return mqtt_ ? &mqtt_->stats() : nullptr; }
  /// The state JSON as GET /api/state returns it.
  nlohmann::json StateJson();

 private:
  void ReplayLoop();
  void LiveLoop();
  /// Parses one POSTed CSV document of `stream`, journals its rows; returns the JSON answer.
  nlohmann::json Ingest(const std::string& stream, const std::string& body);

  MissionInfo info_;
  std::vector<Estimate> estimates_;
  ServerOptions options_;
  std::vector<std::pair<TimeS, std::string>> heard_;
  std::vector<Segment2> walls_;
  std::mutex mutex_;
  IncidentState state_;
  struct Http;
  std::unique_ptr<Http> http_;
  std::thread http_thread_, replay_thread_;
  std::atomic<bool> stop_{false}, replay_done_{false}, dirty_{false};
  struct Live;
  std::unique_ptr<Live> live_;
  std::mutex ingest_mutex_;
  std::unique_ptr<MqttBridge> mqtt_;
  std::map<std::string, std::string> device_status_;
  int port_ = 0;
  ServerStats stats_;
};

/// The dashboard page served at / (self-contained, no network beyond this server).
const char* DashboardHtml();

}  // namespace trailmark::server

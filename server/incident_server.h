// SPDX-License-Identifier: MIT
#pragma once
/// `trailmark serve`: the incident server (issue 7). Replays a mission's online estimates at a
/// chosen speed, or runs live on measurements POSTed over HTTP or received over MQTT (journaled
/// first, then estimated incrementally), into an IncidentState that it serves over HTTP
/// (cpp-httplib):
///   GET /api/state   (Authorization: Bearer TOKEN)  -> the state JSON, 401 without the token
///   GET /api/events  (bearer token or ?token=)      -> server-sent events: the state JSON on change
///   GET /api/history (bearer token)                  -> trails and alert log for the timeline
///   GET /?token=TOKEN                                -> the dashboard (web/, built with Vite)
///   GET /api/health                                  -> {"ok": true} (no token)
///   GET /api/floorplan (bearer token)                -> {"walls": [[x0, y0, x1, y1], ...],
///                                                        "nodes": [...], and with several levels
///                                                        "level": the walls' level, "levels":
///                                                        [{"level": L, "walls": [...]}, ...]}
///   GET /api/stats (bearer token)                    -> counters and the latest rejection reasons
///   POST /api/ingest/<stream> (bearer token; live mode) -> rows journaled, then acknowledged
///   POST /api/ingest (bearer token; live mode; {"<stream>": "<CSV>", ...}) -> the same, a
///                                                        device's streams in one transaction
/// Binds to 127.0.0.1 unless told otherwise. Every request without the right token is refused
/// and counted; every rejection is counted and logged with its reason. See docs/server.md.

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <string_view>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "server/incident_state.h"
#include "server/mqtt_bridge.h"
#include "trailmark/geometry/floor_plan.h"
#include "trailmark/geometry/segment.h"

namespace trailmark::server {

struct ServerOptions {
  /// Live mode (instead of a replay): a directory with the incident's mission.json, and the
  /// journal file; measurements are POSTed to /api/ingest/<stream> (or received over MQTT),
  /// journaled, then fed to the pipeline's online estimator as each commit lands — the same
  /// estimator a batch run uses (pipelines/registry.h), with rows that need global time order
  /// put in it by its reorder buffer (option reorder_s).
  std::filesystem::path live_dir, journal_file;
  std::string pipeline = "pdr";  ///< a name of the registry
  std::map<std::string, std::string> pipeline_options;
  /// The floor the pipeline works on (those that need a floor plan).
  std::optional<FloorPlan> floor_plan;
  /// Every level of a multi-level plan (empty for one level): a pipeline that follows the
  /// floors (mapmatch) uses them, and the dashboard's floor selector draws each.
  LevelPlans floor_levels;
  MqttOptions mqtt;  ///< live mode: also ingest from an MQTT broker when `mqtt.uri` is set
  /// HTTPS when both are set: the certificate chain and private key files (PEM).
  std::string tls_cert_file, tls_key_file;
  std::string bind = "127.0.0.1";
  int port = 8080;      ///< 0: any free port (see IncidentServer::port())
  std::string token;    ///< required; never empty
  double speed = 10.0;  ///< mission seconds per wall second
  AlertOptions alerts;
  std::size_t max_request_bytes = 1 << 20;
  /// Server-sent events: at most one state message per client this often (coalescing).
  double events_min_interval_s = 0.01;
  /// The estimator takes the rows committed since its last pass, but at most this long of
  /// them per pass (wall time, s): the state and the event streams are updated between
  /// passes, so that a backlog (an estimator slower than the devices) shows its progress
  /// instead of freezing the dashboard until all of it is done. 0: one row per pass.
  double estimator_pass_s = 0.05;
  std::size_t http_threads = 64;  ///< each connected device and dashboard holds one
  /// Plain HTTP: a request's line and headers must arrive within this (s) of its first byte,
  /// and one client address may hold at most this many connections at once (0: no cap; a
  /// gateway relaying many devices from one address needs more). With TLS too (the handshake
  /// within the header deadline).
  double header_deadline_s = 10.0;
  std::size_t max_connections_per_address = 32;  ///< half the default http_threads
  /// The whole request (its body too) within this (s) of its first byte, and at most this
  /// many connections waiting for a worker (more are answered 503 at once).
  double request_deadline_s = 60.0;
  std::size_t max_waiting_connections = 256;
  /// Receives every rejection reason (also counted; the latest are in /api/stats); default:
  /// a line on stderr.
  std::function<void(const std::string&)> log;
  /// Live mode: receives every estimate the estimator produces, in order (from the live loop's
  /// thread), e.g. to forward them or to compare them with a batch run; may be empty.
  std::function<void(const Estimate&)> on_estimate;
};

struct ServerStats {
  std::atomic<std::size_t> requests{0}, unauthorized{0}, released_estimates{0};
  std::atomic<std::size_t> ingested_rows{0}, duplicate_rows{0}, rejected_requests{0},
      estimated_rows{0}, estimator_refusals{0}, commits{0}, events_sent{0};
};

/// Whether `given` equals `secret`, in time that depends on the secret's length only (not on
/// where the first difference is): a token is not guessable byte by byte from response times.
bool SameSecret(std::string_view given, std::string_view secret);

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

  /// Replay: the integrity notes of the run that made the estimates (raised as `integrity`
  /// alerts as the replay reaches their time). Live mode takes them from its estimator.
  void SetIntegrityNotes(std::vector<IntegrityNote> notes);
  /// Binds and starts serving and replaying; throws std::runtime_error when it cannot bind.
  void Start();
  void Stop();
  int port() const { return port_; }
  const char* scheme() const { return options_.tls_cert_file.empty() ? "http" : "https"; }
  bool replay_done() const { return replay_done_; }
  const ServerStats& stats() const { return stats_; }
  const MqttStats* mqtt_stats() const { return mqtt_ ? &mqtt_->stats() : nullptr; }
  /// The state JSON as GET /api/state returns it.
  nlohmann::json StateJson();
  /// Parses one CSV document of `stream` (an HTTP body, an MQTT payload), journals its rows
  /// (group commit) and returns {"accepted", "duplicates"} once committed. Throws
  /// std::invalid_argument for bad input (nothing journaled; the message names the line),
  /// std::runtime_error when the journal cannot commit.
  nlohmann::json Ingest(const std::string& stream, const std::string& body);
  /// Several streams of one device in one request (POST /api/ingest): a JSON object
  /// {"imu.csv": "<CSV text>", "ranges.csv": "...", ...}. Every section is checked before any
  /// is journaled (bad input: std::invalid_argument, nothing journaled); then all are committed
  /// in one transaction, each as Ingest would (a section refused for time order journals
  /// nothing of itself: its "error" in the answer). Returns {"accepted", "duplicates",
  /// "streams": {stream: {"accepted", "duplicates"[, "error"]}}[, "error"]}.
  nlohmann::json IngestBundle(const std::string& body);
  /// GET /api/stats: counters, the latest rejections, the live estimator's summary numbers.
  nlohmann::json StatsJson();

 private:
  void ReplayLoop();
  void LiveLoop();
  void CommitLoop();
  /// Counts and logs a rejection.
  void Reject(const std::string& reason);
  /// Group commit: a request's rows wait for the committer (defined in the .cpp).
  struct Pending;
  /// Parses and checks one stream's CSV (`source` names it in errors) into `pending`.
  void Prepare(const std::string& stream, const std::string& source, const std::string& body,
               Pending& pending);
  /// Queues them together (one transaction), waits, counts; each gets its `result`.
  void Commit(const std::vector<Pending*>& pending);
  /// The state changed: wake the event streams.
  void Changed();
  /// The event-stream message of the state at `version` (or later): written once per version
  /// and shared by every client.
  std::shared_ptr<const std::string> EventMessage(std::uint64_t version);

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
  std::atomic<bool> stop_{false}, replay_done_{false};
  struct Live;
  std::unique_ptr<Live> live_;
  std::unique_ptr<MqttBridge> mqtt_;
  std::map<std::string, std::string> device_status_;
  int port_ = 0;
  ServerStats stats_;
  std::mutex event_mutex_;
  std::condition_variable event_cv_;
  std::uint64_t version_ = 0;
  std::shared_ptr<const std::string> event_message_;  ///< guarded by mutex_
  std::uint64_t event_message_version_ = 0;
  std::mutex log_mutex_;
  std::deque<std::pair<double, std::string>> recent_rejections_;
};

/// A file of the dashboard (web/ built by Vite, embedded at build time): null when absent.
struct WebAsset {
  std::string_view content, mime;
};
const WebAsset* FindWebAsset(const std::string& path);

}  // namespace trailmark::server

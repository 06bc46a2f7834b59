// SPDX-License-Identifier: MIT
#include "server/incident_server.h"

#include <httplib.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <future>
#include <optional>
#include <sstream>
#include <stdexcept>

#include "server/compressed_asset.h"
#include "server/gated_http_server.h"
#include "server/journal.h"
#include "trailmark_generated/version.h"
#include "trailmark/core/error.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/io/streams.h"
#include "trailmark/pipelines/registry.h"

namespace trailmark::server {

struct IncidentServer::Http {
  std::unique_ptr<httplib::Server> server;  ///< an httplib::SSLServer for HTTPS
  GateCore* gate = nullptr;                 ///< the server's connection gate
};

struct IncidentServer::Pending {
  Journal::Batch batch;
  std::vector<MissionRow> rows;
  std::promise<Journal::AppendResult> done;
  Journal::AppendResult result;  ///< once committed (Commit)
};

struct IncidentServer::Live {
  std::unique_ptr<Journal> journal;
  std::filesystem::path work;  ///< the MQTT client's persistence
  /// The pipeline's online estimator (the registry's, as in a batch run), fed committed rows.
  std::unique_ptr<OnlineEstimator> estimator;
  std::mutex estimator_mutex;  ///< the live loop feeds it; /api/stats reads its summary
  /// Group commit: requests wait here until the committer has journaled them.
  using Pending = IncidentServer::Pending;
  std::mutex queue_mutex;
  std::condition_variable queue_cv;
  std::vector<Pending*> queue;
  std::thread committer;
  /// Committed rows, in commit order, for the estimator.
  std::mutex feed_mutex;
  std::condition_variable feed_cv;
  std::vector<MissionRow> feed;
};

namespace {

/// The type of every JSON reply (why the charset: where the replies are made).
constexpr const char* kJsonType = "application/json; charset=utf-8";

// An embedded asset in an encoding, compressed at its first request and kept.
const std::string& CompressedAsset(const std::string& path, const WebAsset& asset,
                                   ContentEncoding encoding) {
  static std::mutex mutex;
  static std::map<std::pair<std::string, ContentEncoding>, std::string> cache;
  std::lock_guard<std::mutex> lock(mutex);
  auto it = cache.find({path, encoding});
  if (it == cache.end()) it = cache.emplace(std::pair{path, encoding}, Compress(asset.content, encoding)).first;
  return it->second;
}

/// Parses a CSV document of one stream into typed rows and its journal batch (canonical text,
/// times, nodes, lines). Throws InputError naming `name` and the line.
template <class Row>
void Parse(const std::string& name, const std::string& body, Journal::Batch& batch,
           std::vector<MissionRow>& typed) {
  const std::vector<Row> rows = ParseAll<Row>(name, body, nullptr, &batch.lines);
  std::vector<std::string> lines = FormatAll(rows);
  batch.header = lines.front();
  batch.rows.assign(std::make_move_iterator(lines.begin() + 1),
                    std::make_move_iterator(lines.end()));
  typed.reserve(rows.size());
  for (const Row& r : rows) {
    typed.emplace_back(r);
    batch.t.push_back(RowTime(typed.back()));
    batch.node.push_back(RowNode(typed.back()));
  }
}

void ParseStream(const std::string& stream, const std::string& name, const std::string& body,
                 Journal::Batch& batch, std::vector<MissionRow>& typed) {
  batch.stream = stream;
  WithStreamRowType(stream, [&]<class Row>(std::type_identity<Row>) {
    Parse<Row>(name, body, batch, typed);
  });
}

/// (id, node JSON) of every agent: what is published to MQTT as its retained estimate.
std::vector<std::pair<std::string, std::string>> AgentJson(const IncidentState& state) {
  std::vector<std::pair<std::string, std::string>> out;
  const nlohmann::json j = state.ToJson();  // (a temporary would dangle in the loop)
  for (const auto& n : j.at("nodes")) {
    if (n.at("kind") == "agent") out.emplace_back(n.at("id"), n.dump());
  }
  return out;
}

}  // namespace

bool SameSecret(std::string_view given, std::string_view secret) {
  // Every byte of the secret is compared, whatever the given text; lengths last.
  unsigned char diff = 0;
  for (std::size_t i = 0; i < secret.size(); ++i) {
    const unsigned char g = i < given.size() ? static_cast<unsigned char>(given[i]) : 0;
    diff |= static_cast<unsigned char>(g ^ static_cast<unsigned char>(secret[i]));
  }
  return (diff == 0) & (given.size() == secret.size());
}

IncidentServer::IncidentServer(const MissionInfo& info, std::vector<Estimate> estimates,
                               ServerOptions options,
                               std::vector<std::pair<TimeS, std::string>> heard,
                               std::vector<Segment2> walls)
    : info_(info),
      estimates_(std::move(estimates)),
      options_(std::move(options)),
      heard_(std::move(heard)),
      walls_(std::move(walls)),
      state_(info_, options_.alerts),
      http_(new Http) {
  if (options_.token.empty()) throw std::invalid_argument("serve: a token is required");
  if (!(options_.speed > 0)) throw std::invalid_argument("serve: speed must be > 0");
  if (!options_.log) {
    options_.log = [](const std::string& line) { spdlog::warn("{}", line); };
  }
  if (!options_.journal_file.empty()) {
    const PipelineSpec& pipeline = RequirePipeline(options_.pipeline);
    live_ = std::make_unique<Live>();
    // The estimator first: bad options fail before the journal is touched.
    live_->estimator = pipeline.make(
        {info_, options_.floor_plan ? &*options_.floor_plan : nullptr, "the floor plan",
         options_.floor_levels.empty() ? nullptr : &options_.floor_levels},
        options_.pipeline_options, Feed::kLive);
    live_->journal = std::make_unique<Journal>(options_.journal_file);
    live_->work = std::filesystem::path(options_.journal_file.string() + ".work");
    // A restart: the journal's rows through the estimator again, in arrival order.
    live_->journal->ForEach(
        [this](const std::string& stream, const std::string& header, const std::string& row) {
          Journal::Batch batch;
          try {
            ParseStream(stream, "journal", header + "\n" + row + "\n", batch, live_->feed);
          } catch (const std::exception& e) {
            Reject(std::string("journal row not re-read: ") + e.what());
          }
        });
  }
}

IncidentServer::~IncidentServer() { Stop(); }

nlohmann::json IncidentServer::StateJson() {
  std::lock_guard<std::mutex> lock(mutex_);
  return state_.ToJson();
}

std::shared_ptr<const std::string> IncidentServer::EventMessage(std::uint64_t version) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (!event_message_ || event_message_version_ != version) {
    event_message_ = std::make_shared<const std::string>("data: " + state_.ToJsonText() + "\n\n");
    event_message_version_ = version;
  }
  return event_message_;
}

void IncidentServer::Reject(const std::string& reason) {
  ++stats_.rejected_requests;
  {
    std::lock_guard<std::mutex> lock(log_mutex_);
    const double now = std::chrono::duration<double>(
                           std::chrono::system_clock::now().time_since_epoch())
                           .count();
    recent_rejections_.emplace_back(now, reason);
    while (recent_rejections_.size() > 100) recent_rejections_.pop_front();
  }
  options_.log("rejected: " + reason);
}

void IncidentServer::Changed() {
  {
    std::lock_guard<std::mutex> lock(event_mutex_);
    ++version_;
  }
  event_cv_.notify_all();
}

nlohmann::json IncidentServer::StatsJson() {
  nlohmann::json j = {{"requests", stats_.requests.load()},
                      {"unauthorized", stats_.unauthorized.load()},
                      {"rejected", stats_.rejected_requests.load()},
                      {"released_estimates", stats_.released_estimates.load()},
                      {"ingested_rows", stats_.ingested_rows.load()},
                      {"duplicate_rows", stats_.duplicate_rows.load()},
                      {"journal_commits", stats_.commits.load()},
                      {"estimated_rows", stats_.estimated_rows.load()},
                      {"estimator_refusals", stats_.estimator_refusals.load()},
                      {"events_sent", stats_.events_sent.load()}};
  if (http_ && http_->gate != nullptr) {
    const GateStats& g = http_->gate->gate_stats();
    j["connections_refused_per_address"] = g.refused_per_address.load();
    j["header_deadlines_missed"] = g.header_deadlines.load();
    j["request_deadlines_missed"] = g.request_deadlines.load();
    j["connections_refused_waiting"] = g.refused_waiting.load();
    j["tls_handshakes_failed"] = g.handshakes_failed.load();
  }
  if (const MqttStats* m = mqtt_stats()) {
    j["mqtt"] = {{"received", m->received.load()},
                 {"ingested", m->ingested.load()},
                 {"rejected", m->rejected.load()},
                 {"published", m->published.load()}};
  }
  nlohmann::json recent = nlohmann::json::array();
  {
    std::lock_guard<std::mutex> lock(log_mutex_);
    for (const auto& [t, why] : recent_rejections_) recent.push_back({{"unix_time", t}, {"reason", why}});
  }
  j["recent_rejections"] = recent;
  if (live_) {
    // The estimator's own counters (rows used, ignored, late, waiting in its reorder buffer).
    std::lock_guard<std::mutex> lock(live_->estimator_mutex);
    j["estimator"] = live_->estimator->Summary().numbers;
  }
  return j;
}

void IncidentServer::Start() {
  if (options_.tls_cert_file.empty() != options_.tls_key_file.empty())
    throw std::invalid_argument("serve: HTTPS needs both a certificate and its key");
  ConnectionLimits limits;
  limits.header_deadline_s = options_.header_deadline_s;
  limits.max_per_address = options_.max_connections_per_address;
  limits.request_deadline_s = options_.request_deadline_s;
  limits.max_waiting = options_.max_waiting_connections;
  std::string why;
  if (!limits.IsValid(&why)) throw std::invalid_argument("serve: " + why);
  auto log = [log = options_.log](const std::string& line) {
    if (log) log(line);
  };
  if (options_.tls_cert_file.empty()) {
    auto gated = std::make_unique<GatedHttpServer>(limits, log);
    http_->gate = gated.get();
    http_->server = std::move(gated);
  } else {
    for (const auto& f : {options_.tls_cert_file, options_.tls_key_file}) {
      if (!std::filesystem::exists(f)) throw std::invalid_argument("serve: " + f + ": no such file");
    }
    auto ssl = std::make_unique<GatedHttpsServer>(limits, log, options_.tls_cert_file.c_str(),
                                                  options_.tls_key_file.c_str());
    if (!ssl->is_valid()) {
      throw std::invalid_argument("serve: " + options_.tls_cert_file + " / " +
                                  options_.tls_key_file +
                                  ": not a PEM certificate chain and its private key");
    }
    http_->gate = ssl.get();
    http_->server = std::move(ssl);
  }
  httplib::Server& svr = *http_->server;
  svr.set_payload_max_length(options_.max_request_bytes);
  svr.set_tcp_nodelay(true);  // small requests and events: no Nagle delay
  // A device keeps its connection (cpp-httplib closes one after 5 requests by default, and a
  // reconnect storm meets its listen backlog of 5: 1 s SYN retransmits).
  svr.set_keep_alive_max_count(1u << 30);
  svr.set_keep_alive_timeout(10);
  const std::size_t threads = std::max<std::size_t>(4, options_.http_threads);
  svr.new_task_queue = [gate = http_->gate, threads] { return gate->NewTaskQueue(threads); };
  // Counts the request; true when it carries the token (the API: Authorization: Bearer; the
  // dashboard and its event stream may also take it as ?token=, the link a commander opens).
  auto authorized = [this](const httplib::Request& req, bool query_token_too) {
    ++stats_.requests;
    const bool ok = SameSecret(req.get_header_value("Authorization"), "Bearer " + options_.token) ||
                    (query_token_too && req.has_param("token") &&
                     SameSecret(req.get_param_value("token"), options_.token));
    if (!ok) ++stats_.unauthorized;
    return ok;
  };
  // JSON replies say their charset: Debian's cpp-httplib (0.11, built with brotli) compresses a
  // reply typed exactly "application/json" with brotli at quality 11 whenever the client accepts
  // "br", as every browser does: 15 s of CPU for the 5.4 MB history of a 4-hour incident, which
  // starved the dashboard's own rendering on a 2-core machine (CI stop 42). A reply with the
  // charset is sent as it is; /api/history?since= keeps the periodic refresh small instead.
  auto refuse = [](httplib::Response& res) {
    res.status = 401;
    res.set_header("WWW-Authenticate", "Bearer");
    res.set_content(R"({"error": "missing or wrong token"})", kJsonType);
  };
  auto json = [](httplib::Response& res, const nlohmann::json& j) {
    res.set_content(j.dump(), kJsonType);
  };
  // Errors raised by the HTTP layer itself (413 oversized body, 404, 400): counted, explained.
  svr.set_error_handler([this](const httplib::Request& req, httplib::Response& res) {
    if (res.status == 401) return;  // refused for the token: counted as unauthorized
    if (res.body.empty()) {
      const std::string why = res.status == 413 ? "request body too large (at most " +
                                                      std::to_string(options_.max_request_bytes) +
                                                      " bytes; send CSV as Content-Type: text/csv)"
                                                : "HTTP " + std::to_string(res.status);
      Reject(req.method + " " + req.path + ": " + why);
      res.set_content(nlohmann::json{{"error", why}}.dump(), kJsonType);
    }
  });
  svr.Get("/api/health", [](const httplib::Request&, httplib::Response& res) {
    res.set_content(nlohmann::json{{"ok", true}, {"version", TRAILMARK_VERSION}}.dump(),
                    kJsonType);
  });
  svr.Get("/api/state", [this, authorized, refuse, json](const httplib::Request& req,
                                                          httplib::Response& res) {
    if (!authorized(req, false)) return refuse(res);
    json(res, StateJson());
  });
  svr.Get("/api/history", [this, authorized, refuse, json](const httplib::Request& req,
                                                            httplib::Response& res) {
    if (!authorized(req, false)) return refuse(res);
    std::optional<double> since;
    if (req.has_param("since")) {
      const std::string text = req.get_param_value("since");
      char* end = nullptr;
      const double v = std::strtod(text.c_str(), &end);
      if (text.empty() || end != text.c_str() + text.size() || !std::isfinite(v)) {
        res.status = 400;
        json(res, {{"error", "since: expected a mission time in seconds, not '" + text + "'"}});
        return;
      }
      since = v;
    }
    std::size_t max_rows = IncidentState::kHistoryMaxRows;
    if (req.has_param("max_rows")) {
      const std::string text = req.get_param_value("max_rows");
      char* end = nullptr;
      const long long v = std::strtoll(text.c_str(), &end, 10);
      if (text.empty() || end != text.c_str() + text.size() || v < 2 || v > 10'000'000) {
        res.status = 400;
        json(res, {{"error", "max_rows: expected a whole number from 2 to 10000000, not '" + text + "'"}});
        return;
      }
      max_rows = static_cast<std::size_t>(v);
    }
    nlohmann::json h;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      h = state_.HistoryJson(since, max_rows);
    }
    json(res, h);
  });
  svr.Get("/api/stats", [this, authorized, refuse, json](const httplib::Request& req,
                                                          httplib::Response& res) {
    if (!authorized(req, false)) return refuse(res);
    json(res, StatsJson());
  });
  svr.Get("/api/events", [this, authorized, refuse](const httplib::Request& req,
                                                    httplib::Response& res) {
    if (!authorized(req, true)) return refuse(res);
    res.set_header("Cache-Control", "no-store");
    auto last = std::make_shared<std::uint64_t>(~std::uint64_t{0});
    res.set_chunked_content_provider(
        "text/event-stream", [this, last](std::size_t, httplib::DataSink& sink) {
          {
            std::unique_lock<std::mutex> lock(event_mutex_);
            event_cv_.wait_for(lock, std::chrono::seconds(5),
                               [&] { return stop_.load() || version_ != *last; });
            if (stop_) return false;
            if (version_ == *last) {
              const std::string keepalive = ": keep-alive\n\n";
              return sink.write(keepalive.data(), keepalive.size());
            }
            *last = version_;
          }
          const auto message = EventMessage(*last);
          if (!sink.write(message->data(), message->size())) return false;
          ++stats_.events_sent;
          // Coalesce: a client gets at most one message per interval, the latest state.
          std::this_thread::sleep_for(std::chrono::duration<double>(options_.events_min_interval_s));
          return !stop_.load();
        });
  });
  if (live_) {
    // The token is checked on the headers, before a byte of the body is read (a stranger's
    // 200 MB is not read to be refused), and the size limit holds for chunked bodies too
    // (cpp-httplib checks Content-Length only): the body is read here, counted as it comes.
    // One stream per request (POST /api/ingest/<stream>) or a device's streams bundled in one
    // (POST /api/ingest: a JSON object of CSV texts, IngestBundle).
    auto ingest = [this, authorized, refuse, json](auto handle) {
      return [this, authorized, refuse, json, handle](const httplib::Request& req,
                                                      httplib::Response& res,
                                                      const httplib::ContentReader& content_reader) {
        if (!authorized(req, false)) {
          res.set_header("Connection", "close");  // its unread body is not a next request
          return refuse(res);
        }
        std::string body;
        bool too_large = false;
        const bool read = content_reader([&](const char* data, std::size_t n) {
          if (body.size() + n > options_.max_request_bytes) {
            too_large = true;
            return false;
          }
          body.append(data, n);
          return true;
        });
        if (too_large || !read) {
          res.status = too_large ? 413 : 400;
          res.set_header("Connection", "close");
          const std::string why =
              too_large ? "request body too large (at most " +
                              std::to_string(options_.max_request_bytes) + " bytes)"
                        : "request body could not be read";
          Reject(req.method + " " + req.path + ": " + why);
          json(res, {{"error", why}});
          return;
        }
        try {
          nlohmann::json answer = handle(req, body);
          // A bundle with a section refused for time order: the others are committed.
          if (answer.contains("error")) res.status = 400;
          json(res, answer);
        } catch (const std::invalid_argument& e) {
          res.status = 400;
          json(res, {{"error", e.what()}});
        } catch (const std::exception& e) {
          res.status = 503;  // the journal could not commit: not acknowledged, retry
          json(res, {{"error", e.what()}});
        }
      };
    };
    svr.Post(R"(/api/ingest/([a-z]+\.csv))",
             ingest([this](const httplib::Request& req, const std::string& body) {
               return Ingest(req.matches[1], body);
             }));
    svr.Post("/api/ingest", ingest([this](const httplib::Request&, const std::string& body) {
               return IngestBundle(body);
             }));
  }
  svr.Get("/api/floorplan", [this, authorized, refuse, json](const httplib::Request& req,
                                                              httplib::Response& res) {
    if (!authorized(req, false)) return refuse(res);
    nlohmann::json walls = nlohmann::json::array();
    for (const auto& w : walls_) walls.push_back({w.a.x(), w.a.y(), w.b.x(), w.b.y()});
    // Nodes known a priori (the base, surveyed landmarks): drawn even before any estimate.
    nlohmann::json known = nlohmann::json::array();
    for (const NodeInfo& n : info_.nodes) {
      if (n.position) {
        known.push_back({{"id", n.id},
                         {"kind", std::string(ToString(n.kind))},
                         {"x", n.position->x()},
                         {"y", n.position->y()}});
      }
    }
    nlohmann::json body{{"walls", walls}, {"nodes", known}};
    if (!options_.floor_levels.empty()) {
      // The dashboard's floor selector: every level's solid walls; "walls" is the default
      // level's (the one a single-floor client draws).
      nlohmann::json levels = nlohmann::json::array();
      std::vector<int> numbers;
      for (const auto& [level, plan] : options_.floor_levels) {
        numbers.push_back(level);
        nlohmann::json lw = nlohmann::json::array();
        for (const auto& w : plan.solid_walls()) lw.push_back({w.a.x(), w.a.y(), w.b.x(), w.b.y()});
        levels.push_back({{"level", level}, {"walls", lw}});
      }
      body["levels"] = levels;
      body["level"] = DefaultFloorPlanLevel(numbers);
    }
    json(res, body);
  });
  // The dashboard: index.html needs the token; its scripts and styles are public code.
  svr.Get("/", [authorized, refuse](const httplib::Request& req, httplib::Response& res) {
    if (!authorized(req, true)) return refuse(res);
    const WebAsset* index = FindWebAsset("/index.html");
    res.set_header("Cache-Control", "no-store");
    res.set_content(std::string(index->content), std::string(index->mime));
  });
  svr.Get(R"(/assets/[A-Za-z0-9_.-]+)", [](const httplib::Request& req, httplib::Response& res) {
    const WebAsset* a = FindWebAsset(req.path);
    if (a == nullptr) {
      res.status = 404;
      return;
    }
    if (a->mime.rfind("text/javascript", 0) == 0) {
      // The script (most of the page's bytes) compressed once, in the encoding the browser
      // takes, under a type the HTTP library does not compress again (compressed_asset.h).
      const ContentEncoding e = PreferredEncoding(req.get_header_value("Accept-Encoding"));
      res.set_header("Vary", "Accept-Encoding");
      if (e != ContentEncoding::kIdentity) res.set_header("Content-Encoding", ContentEncodingName(e));
      res.set_content(CompressedAsset(req.path, *a, e), "application/javascript; charset=utf-8");
      return;
    }
    res.set_content(std::string(a->content), std::string(a->mime));
  });
  port_ = options_.port == 0
              ? svr.bind_to_any_port(options_.bind)
              : (svr.bind_to_port(options_.bind, options_.port) ? options_.port : -1);
  if (port_ <= 0) {
    throw std::runtime_error("serve: cannot listen on " + options_.bind + ":" +
                             std::to_string(options_.port) + " (port in use?)");
  }
  if (live_) live_->committer = std::thread([this] { CommitLoop(); });
  if (live_ && !options_.mqtt.uri.empty()) {
    MqttOptions mo = options_.mqtt;
    if (mo.persist_dir.empty()) mo.persist_dir = (live_->work / "mqtt").string();
    mqtt_ = std::make_unique<MqttBridge>(
        mo,
        [this](const std::string& stream, const std::string& body) { return Ingest(stream, body); },
        [this](const std::string& node, const std::string& status) {
          {
            std::lock_guard<std::mutex> lock(mutex_);
            device_status_[node] = status;
            state_.SetDeviceStatus(node, status);
            state_.Advance(state_.now());
          }
          Changed();
        },
        [this](const std::string& reason) { Reject("mqtt: " + reason); });
    mqtt_->Start();
  }
  http_thread_ = std::thread([this] { http_->server->listen_after_bind(); });
  // Until its accept loop runs, the library's stop() does nothing (it only stops a running
  // server): a Stop() right after Start() would wait for ever on the HTTP thread.
  for (int i = 0; i < 10000 && !http_->server->is_running(); ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  replay_thread_ = std::thread([this] { live_ ? LiveLoop() : ReplayLoop(); });
}

void IncidentServer::Stop() {
  stop_ = true;
  event_cv_.notify_all();
  if (mqtt_) mqtt_->Stop();
  if (http_ && http_->server) http_->server->stop();
  if (http_thread_.joinable()) http_thread_.join();
  if (live_) {
    live_->queue_cv.notify_all();
    if (live_->committer.joinable()) live_->committer.join();
    live_->feed_cv.notify_all();
  }
  if (replay_thread_.joinable()) replay_thread_.join();
}

void IncidentServer::SetIntegrityNotes(std::vector<IntegrityNote> notes) {
  std::lock_guard<std::mutex> lock(mutex_);
  state_.SetIntegrity(std::move(notes));
}

void IncidentServer::ReplayLoop() {
  const auto wall0 = std::chrono::steady_clock::now();
  const TimeS t0 = estimates_.empty() ? 0.0 : estimates_.front().t;
  std::size_t next = 0, next_heard = 0;
  while (!stop_) {
    const double elapsed =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
    const TimeS now = t0 + elapsed * options_.speed;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      while (next_heard < heard_.size() && heard_[next_heard].first <= now) {
        state_.Heard(heard_[next_heard].second, heard_[next_heard].first);
        ++next_heard;
      }
      while (next < estimates_.size() && estimates_[next].t <= now) {
        state_.Apply(estimates_[next++]);
        ++stats_.released_estimates;
      }
      state_.Advance(now);
    }
    Changed();
    if (next >= estimates_.size()) replay_done_ = true;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
}

void IncidentServer::Prepare(const std::string& stream, const std::string& source,
                             const std::string& body, Pending& pending) {
  try {
    ParseStream(stream, source, body, pending.batch, pending.rows);
    // IMU, steps and events come from an agent's own device: it must be one of the incident's
    // agents (radio rows may name crumbs that a later drop event introduces).
    if (stream == "imu.csv" || stream == "steps.csv" || stream == "events.csv") {
      for (std::size_t i = 0; i < pending.rows.size(); ++i) {
        const NodeInfo* n = info_.Find(pending.batch.node[i]);
        if (n == nullptr || n->kind != NodeKind::kAgent) {
          throw std::invalid_argument(source + ":" + std::to_string(pending.batch.lines[i]) +
                                      ": '" + pending.batch.node[i] +
                                      "' is not an agent of this incident (mission.json)");
        }
      }
    }
  } catch (const std::exception& e) {
    Reject(stream + ": " + e.what());
    throw std::invalid_argument(e.what());
  }
}

void IncidentServer::Commit(const std::vector<Pending*>& pending) {
  std::vector<std::future<Journal::AppendResult>> done;
  for (Pending* p : pending) done.push_back(p->done.get_future());
  {
    // Queued together: the commit loop takes them in one group (one transaction).
    std::lock_guard<std::mutex> lock(live_->queue_mutex);
    if (stop_) throw std::runtime_error("the server is stopping");
    live_->queue.insert(live_->queue.end(), pending.begin(), pending.end());
  }
  live_->queue_cv.notify_one();
  for (std::size_t k = 0; k < pending.size(); ++k) {
    const Journal::AppendResult& r = pending[k]->result = done[k].get();  // rethrows a failure
    if (!r.error.empty()) Reject(pending[k]->batch.stream + ": " + r.error);
    stats_.ingested_rows += r.accepted;
    stats_.duplicate_rows += r.duplicates;
  }
}

nlohmann::json IncidentServer::Ingest(const std::string& stream, const std::string& body) {
  if (!live_) throw std::invalid_argument("not a live server");
  Pending pending;
  Prepare(stream, "request body", body, pending);
  Commit({&pending});
  const Journal::AppendResult& r = pending.result;
  if (!r.error.empty()) throw std::invalid_argument(r.error);
  return {{"accepted", r.accepted}, {"duplicates", r.duplicates}};
}

nlohmann::json IncidentServer::IngestBundle(const std::string& body) {
  if (!live_) throw std::invalid_argument("not a live server");
  // {"imu.csv": "t,agent,...\n...", "ranges.csv": "..."}: the sections in the body's order.
  nlohmann::ordered_json sections;
  try {
    sections = nlohmann::ordered_json::parse(body);
  } catch (const nlohmann::json::parse_error& e) {
    Reject(std::string("bundle: ") + e.what());
    throw std::invalid_argument(std::string("request body: not JSON (") + e.what() + ")");
  }
  if (!sections.is_object() || sections.empty()) {
    Reject("bundle: not an object of streams");
    throw std::invalid_argument(
        "request body: a bundle is a JSON object {\"<stream>.csv\": \"<CSV text>\", ...} with "
        "at least one stream");
  }
  std::vector<Pending> pending(sections.size());  // not resized: Commit holds their addresses
  std::vector<Pending*> queued;
  for (const auto& [stream, text] : sections.items()) {
    if (!text.is_string()) {
      Reject("bundle: " + stream + " is not a string");
      throw std::invalid_argument("request body: section '" + stream +
                                  "' must be the stream's CSV text as a JSON string");
    }
    // Every section checked before any is queued: bad input journals nothing.
    queued.push_back(&pending[queued.size()]);
    Prepare(stream, "request body " + stream, text.get_ref<const std::string&>(), *queued.back());
  }
  Commit(queued);
  nlohmann::json streams = nlohmann::json::object();
  std::string errors;
  std::size_t accepted = 0, duplicates = 0;
  for (const Pending& p : pending) {
    const Journal::AppendResult& r = p.result;
    nlohmann::json& one = streams[p.batch.stream] = {{"accepted", r.accepted},
                                                     {"duplicates", r.duplicates}};
    if (!r.error.empty()) {
      one["error"] = r.error;
      errors += (errors.empty() ? "" : "; ") + r.error;
    }
    accepted += r.accepted;
    duplicates += r.duplicates;
  }
  nlohmann::json out = {{"accepted", accepted}, {"duplicates", duplicates}, {"streams", streams}};
  if (!errors.empty()) out["error"] = errors;
  return out;
}

void IncidentServer::CommitLoop() {
  while (true) {
    std::vector<Live::Pending*> group;
    {
      std::unique_lock<std::mutex> lock(live_->queue_mutex);
      live_->queue_cv.wait(lock, [&] { return stop_.load() || !live_->queue.empty(); });
      group.swap(live_->queue);
      if (group.empty() && stop_) return;
    }
    std::vector<const Journal::Batch*> batches;
    for (auto* p : group) batches.push_back(&p->batch);
    std::vector<Journal::AppendResult> results;
    try {
      results = live_->journal->AppendGroup(batches);  // one transaction, one disk flush
      ++stats_.commits;
    } catch (...) {
      for (auto* p : group) p->done.set_exception(std::current_exception());
      continue;
    }
    // Committed: hand the new rows to the estimator (in commit order), then acknowledge.
    bool any = false;
    {
      std::lock_guard<std::mutex> lock(live_->feed_mutex);
      for (std::size_t g = 0; g < group.size(); ++g) {
        const auto& fresh = results[g].fresh;
        for (std::size_t i = 0; i < fresh.size(); ++i) {
          if (fresh[i]) live_->feed.push_back(std::move(group[g]->rows[i])), any = true;
        }
      }
    }
    if (any) live_->feed_cv.notify_one();
    for (std::size_t g = 0; g < group.size(); ++g) group[g]->done.set_value(std::move(results[g]));
  }
}

void IncidentServer::LiveLoop() {
  auto last_publish = std::chrono::steady_clock::now() - std::chrono::hours(1);
  auto last_integrity = last_publish;
  VectorSink sink;
  // The rows committed and not yet estimated, in commit order; [next, end) are left.
  std::vector<MissionRow> rows;
  std::size_t next = 0;
  std::map<std::string, std::string> refusals;  // node -> last reason logged
  const auto pass_limit = std::chrono::duration_cast<std::chrono::steady_clock::duration>(
      std::chrono::duration<double>(std::max(options_.estimator_pass_s, 0.0)));
  while (!stop_) {
    {
      std::unique_lock<std::mutex> lock(live_->feed_mutex);
      if (next == rows.size()) {
        live_->feed_cv.wait_for(lock, std::chrono::milliseconds(100),
                                [&] { return stop_.load() || !live_->feed.empty(); });
        rows.clear();
        next = 0;
        rows.swap(live_->feed);
      } else if (!live_->feed.empty()) {
        rows.insert(rows.end(), std::make_move_iterator(live_->feed.begin()),
                    std::make_move_iterator(live_->feed.end()));
        live_->feed.clear();
      }
    }
    if (next == rows.size()) continue;
    TimeS newest = -1e300;
    sink.rows.clear();
    std::vector<std::pair<std::string, TimeS>> heard;
    std::unique_lock<std::mutex> estimator_lock(live_->estimator_mutex);
    const auto pass_end = std::chrono::steady_clock::now() + pass_limit;
    const std::size_t pass_first = next;
    for (; next < rows.size(); ++next) {
      // The clock is read every 64 rows: a pass ends within 64 rows of its limit (0: a pass
      // is one row).
      if (next > pass_first &&
          (options_.estimator_pass_s <= 0 ||
           ((next - pass_first) % 64 == 0 && std::chrono::steady_clock::now() > pass_end)))
        break;
      const MissionRow& row = rows[next];
      heard.emplace_back(RowNode(row), RowTime(row));
      newest = std::max(newest, RowTime(row));
      try {
        live_->estimator->Add(row, sink);
      } catch (const std::invalid_argument& e) {
        // Valid mission rows the estimator cannot use (e.g. steps of a non-agent): journaled,
        // counted, logged once per node and reason.
        ++stats_.estimator_refusals;
        std::string& logged = refusals[RowNode(row)];
        if (logged != e.what()) {
          logged = e.what();
          options_.log(options_.pipeline + ": " + e.what());
        }
      }
    }
    // The estimator's integrity notes, at most once a second (its summary is not free).
    std::optional<std::vector<IntegrityNote>> integrity;
    if (std::chrono::steady_clock::now() - last_integrity > std::chrono::seconds(1)) {
      last_integrity = std::chrono::steady_clock::now();
      integrity = live_->estimator->Summary().integrity;
    }
    // Which sources each agent's estimate uses (the fusion's members; cheap: a lookup).
    std::vector<std::pair<std::string, std::vector<SourceShare>>> sources;
    for (const NodeInfo& n : info_.nodes) {
      if (n.kind == NodeKind::kAgent) sources.emplace_back(n.id, live_->estimator->Sources(n.id));
    }
    estimator_lock.unlock();
    stats_.estimated_rows += next - pass_first;
    if (next > 4096 && 2 * next > rows.size()) {  // drop the rows done (amortized)
      rows.erase(rows.begin(), rows.begin() + static_cast<std::ptrdiff_t>(next));
      next = 0;
    }
    std::vector<std::pair<std::string, std::string>> to_publish;
    const bool publish = mqtt_ && std::chrono::steady_clock::now() - last_publish >
                                      std::chrono::milliseconds(500);
    {
      std::lock_guard<std::mutex> lock(mutex_);
      for (const auto& [id, t] : heard) state_.Heard(id, t);
      for (const auto& e : sink.rows) state_.Apply(e);
      if (integrity) state_.SetIntegrity(std::move(*integrity));
      for (auto& [id, shares] : sources) state_.SetSources(id, std::move(shares));
      state_.Advance(newest);
      if (publish) to_publish = AgentJson(state_);
    }
    Changed();
    if (options_.on_estimate) {
      for (const auto& e : sink.rows) options_.on_estimate(e);
    }
    if (publish) {
      last_publish = std::chrono::steady_clock::now();
      for (const auto& [node, j] : to_publish) mqtt_->PublishEstimate(node, j);
    }
  }
}

}  // namespace trailmark::server

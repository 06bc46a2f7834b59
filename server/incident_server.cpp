#include "server/incident_server.h"

#include <httplib.h>

#include <algorithm>
#include <chrono>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "server/journal.h"
#include "trailmark/core/error.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/io/streams.h"
#include "trailmark/pipelines/pipeline.h"

namespace trailmark::server {

struct IncidentServer::Http {
  httplib::Server server;
};

struct IncidentServer::Live {
  std::unique_ptr<Journal> journal;
  std::filesystem::path work;  ///< scratch: POST bodies, the exported journal
  std::size_t posts = 0;
};

namespace {

std::vector<std::string> Lines(const std::filesystem::path& file) {
  std::ifstream in(file);
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

// The rows of a CSV document of one stream, checked by the mission readers, in canonical form.
template <class Row>
std::pair<std::string, std::vector<std::string>> Canonical(const std::filesystem::path& in,
                                                           const std::filesystem::path& out) {
  const std::vector<Row> rows = ReadAll<Row>(in.string());
  WriteAll<Row>(out.string(), rows);
  std::vector<std::string> lines = Lines(out);
  if (lines.empty()) return {"", {}};
  const std::string header = lines.front();
  lines.erase(lines.begin());
  return {header, lines};
}

}  // namespace

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
  if (!options_.journal_file.empty()) {
    live_ = std::make_unique<Live>();
    live_->journal = std::make_unique<Journal>(options_.journal_file);
    live_->work = std::filesystem::path(options_.journal_file.string() + ".work");
    std::filesystem::create_directories(live_->work);
    dirty_ = live_->journal->size() > 0;  // a restart: rebuild the state from the journal
  }
}

IncidentServer::~IncidentServer() { Stop(); }

nlohmann::json IncidentServer::StateJson() {
  std::lock_guard<std::mutex> lock(mutex_);
  return state_.ToJson();
}

void IncidentServer::Start() {
  httplib::Server& svr = http_->server;
  svr.set_payload_max_length(options_.max_request_bytes);
  // Counts the request; true when it carries the token (the API: Authorization: Bearer; the
  // dashboard page may also take it as ?token=, the link a commander opens).
  auto authorized = [this](const httplib::Request& req, bool query_token_too) {
    ++stats_.requests;
    const bool ok = req.get_header_value("Authorization") == "Bearer " + options_.token ||
                    (query_token_too && req.has_param("token") &&
                     req.get_param_value("token") == options_.token);
    if (!ok) ++stats_.unauthorized;
    return ok;
  };
  auto refuse = [](httplib::Response& res) {
    res.status = 401;
    res.set_header("WWW-Authenticate", "Bearer");
    res.set_content(R"({"error": "missing or wrong token"})", "application/json");
  };
  // Errors raised by the HTTP layer itself (413 oversized body, 404, 400): counted, explained.
  svr.set_error_handler([this](const httplib::Request&, httplib::Response& res) {
    ++stats_.rejected_requests;
    if (res.body.empty()) {
      const std::string why = res.status == 413 ? "request body too large (at most " +
                                                      std::to_string(options_.max_request_bytes) +
                                                      " bytes; send CSV as Content-Type: text/csv)"
                                                : "HTTP " + std::to_string(res.status);
      res.set_content(nlohmann::json{{"error", why}}.dump(), "application/json");
    }
  });
  svr.Get("/api/health", [](const httplib::Request&, httplib::Response& res) {
    res.set_content(R"({"ok": true})", "application/json");
  });
  svr.Get("/api/state",
          [this, authorized, refuse](const httplib::Request& req, httplib::Response& res) {
            if (!authorized(req, false)) return refuse(res);
            res.set_content(StateJson().dump(), "application/json");
          });
  if (live_) {
    svr.Post(R"(/api/ingest/([a-z]+\.csv))",
             [this, authorized, refuse](const httplib::Request& req, httplib::Response& res) {
               if (!authorized(req, false)) return refuse(res);
               try {
                 res.set_content(Ingest(req.matches[1], req.body).dump(), "application/json");
               } catch (const std::exception& e) {
                 ++stats_.rejected_requests;
                 res.status = 400;
                 res.set_content(nlohmann::json{{"error", e.what()}}.dump(), "application/json");
               }
             });
  }
  svr.Get("/api/floorplan",
          [this, authorized, refuse](const httplib::Request& req, httplib::Response& res) {
            if (!authorized(req, false)) return refuse(res);
            nlohmann::json walls = nlohmann::json::array();
            for (const auto& w : walls_) walls.push_back({w.a.x(), w.a.y(), w.b.x(), w.b.y()});
            res.set_content(nlohmann::json{{"walls", walls}}.dump(), "application/json");
          });
  svr.Get("/", [authorized, refuse](const httplib::Request& req, httplib::Response& res) {
    if (!authorized(req, true)) return refuse(res);
    res.set_content(DashboardHtml(), "text/html; charset=utf-8");
  });
  port_ = options_.port == 0
              ? svr.bind_to_any_port(options_.bind)
              : (svr.bind_to_port(options_.bind, options_.port) ? options_.port : -1);
  if (port_ <= 0) {
    throw std::runtime_error("serve: cannot listen on " + options_.bind + ":" +
                             std::to_string(options_.port) + " (port in use?)");
  }
  if (live_ && !options_.mqtt.uri.empty()) {
    MqttOptions mo = options_.mqtt;
    if (mo.persist_dir.empty()) mo.persist_dir = (live_->work / "mqtt").string();
    mqtt_ = std::make_unique<MqttBridge>(
        mo,
        [this](const std::string& stream, const std::string& body) { return Ingest(stream, body); },
        [this](const std::string& node, const std::string& status) {
          std::lock_guard<std::mutex> lock(mutex_);
          device_status_[node] = status;
          state_.SetDeviceStatus(node, status);
          state_.Advance(state_.now());
        });
    mqtt_->Start();
  }
  http_thread_ = std::thread([this] { http_->server.listen_after_bind(); });
  replay_thread_ = std::thread([this] { live_ ? LiveLoop() : ReplayLoop(); });
}

void IncidentServer::Stop() {
  stop_ = true;
  if (mqtt_) mqtt_->Stop();
  if (http_) http_->server.stop();
  if (http_thread_.joinable()) http_thread_.join();
  if (replay_thread_.joinable()) replay_thread_.join();
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
    if (next >= estimates_.size()) replay_done_ = true;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
}

nlohmann::json IncidentServer::Ingest(const std::string& stream, const std::string& body) {
  std::lock_guard<std::mutex> lock(ingest_mutex_);
  const std::filesystem::path in = live_->work / ("post-" + stream);
  const std::filesystem::path out = live_->work / ("canonical-" + stream);
  {
    std::ofstream f(in, std::ios::binary);
    f << body;
  }
  std::pair<std::string, std::vector<std::string>> rows;
  try {
    if (stream == "steps.csv")
      rows = Canonical<Step>(in, out);
    else if (stream == "rssi.csv")
      rows = Canonical<RssiPacket>(in, out);
    else if (stream == "ranges.csv")
      rows = Canonical<RangeMeasurement>(in, out);
    else if (stream == "bearings.csv")
      rows = Canonical<BearingMeasurement>(in, out);
    else if (stream == "events.csv")
      rows = Canonical<MissionEvent>(in, out);
    else if (stream == "imu.csv")
      rows = Canonical<ImuSample>(in, out);
    else
      throw std::invalid_argument("unknown stream '" + stream + "'");
  } catch (const InputError& e) {
    // Name the request, not the scratch file.
    std::string what = e.what();
    const std::string scratch = in.string();
    if (what.rfind(scratch, 0) == 0) what = "request body" + what.substr(scratch.size());
    throw std::invalid_argument(what);
  }
  const Journal::AppendResult r = live_->journal->Append(stream, rows.first, rows.second);
  stats_.ingested_rows += r.accepted;
  stats_.duplicate_rows += r.duplicates;
  dirty_ = dirty_ || r.accepted > 0;
  return {{"accepted", r.accepted}, {"duplicates", r.duplicates}};
}

void IncidentServer::LiveLoop() {
  const std::filesystem::path mission_json = options_.live_dir / "mission.json";
  auto last = std::chrono::steady_clock::now() - std::chrono::hours(1);
  while (!stop_) {
    const auto now = std::chrono::steady_clock::now();
    if (dirty_ && std::chrono::duration<double>(now - last).count() >= options_.live_period_s) {
      dirty_ = false;
      last = now;
      try {
        const std::filesystem::path dir = live_->work / "mission";
        std::filesystem::remove_all(dir);
        {
          std::lock_guard<std::mutex> lock(ingest_mutex_);
          live_->journal->Export(dir, mission_json);
        }
        if (info_.floorplan && std::filesystem::exists(options_.live_dir / *info_.floorplan)) {
          std::filesystem::copy_file(options_.live_dir / *info_.floorplan, dir / *info_.floorplan,
                                     std::filesystem::copy_options::overwrite_existing);
        }
        const MissionDirectory mission(dir);
        const Pipeline* p = FindPipeline(options_.pipeline);
        VectorSink sink;
        if (p && p->CanRun(mission)) p->Run({mission, options_.pipeline_options}, sink);
        ++stats_.pipeline_runs;
        sink.rows = sink.TakeSortedByTime();
        IncidentState fresh(info_, options_.alerts);
        for (const auto& e : sink.rows) fresh.Apply(e);
        std::vector<std::pair<std::string, std::string>> to_publish;
        {
          std::lock_guard<std::mutex> lock(mutex_);
          for (const auto& [node, status] : device_status_) fresh.SetDeviceStatus(node, status);
          if (!sink.rows.empty()) fresh.Advance(sink.rows.back().t);
          state_ = std::move(fresh);
          const nlohmann::json state = state_.ToJson();  // (a temporary would dangle in the loop)
          for (const auto& n : state.at("nodes")) {
            if (n.at("kind") == "agent") to_publish.emplace_back(n.at("id"), n.dump());
          }
        }
        if (mqtt_) {
          for (const auto& [node, json] : to_publish) mqtt_->PublishEstimate(node, json);
        }
      } catch (const std::exception&) {
        ++stats_.rejected_requests;  // the journal holds rows the pipeline refuses; keep serving
      }
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
}

const char* DashboardHtml() {
  return R"HTML(<!doctype html>
<html lang="en"><head><meta charset="utf-8"><meta name="viewport" content="width=device-width, initial-scale=1">
<title>trailmark — incident</title>
<style>
body{margin:0;font:14px system-ui,sans-serif;display:flex;flex-wrap:wrap;height:100vh}
#map{flex:3 1 480px;min-height:60vh;background:#111}#side{flex:1 1 240px;padding:8px;overflow:auto}
.alert{background:#fee;border-left:4px solid #c00;margin:4px 0;padding:4px}.node{cursor:pointer;padding:2px}
.node.sel{background:#def}
</style></head><body>
<canvas id="map"></canvas>
<div id="side"><h3>Firefighters</h3><div id="list"></div><h3>Alerts</h3><div id="alerts"></div>
<p id="clock"></p></div>
<script>
const token = new URLSearchParams(location.search).get('token') || '';
const canvas = document.getElementById('map'), ctx = canvas.getContext('2d');
let selected = null, trails = {}, walls = [];
fetch('/api/floorplan', {headers: {Authorization: 'Bearer ' + token}}).then(r => r.ok ? r.json() : {walls: []}).then(j => { walls = j.walls; });
function ellipse(n, s, ox, oy) {
  const a = (n.sxx + n.syy) / 2, d = Math.sqrt(Math.max(0, (n.sxx - n.syy) ** 2 / 4 + n.sxy ** 2));
  const l1 = a + d, l2 = Math.max(0, a - d), ang = 0.5 * Math.atan2(2 * n.sxy, n.sxx - n.syy);
  ctx.beginPath(); ctx.ellipse(ox + n.x * s, oy - n.y * s, Math.sqrt(5.991 * l1) * s, Math.sqrt(5.991 * l2) * s, -ang, 0, 2 * Math.PI);
  ctx.stroke();
}
async function tick() {
  const r = await fetch('/api/state', {headers: {Authorization: 'Bearer ' + token}});
  if (!r.ok) { document.getElementById('clock').textContent = 'not authorized'; return; }
  const st = await r.json();
  canvas.width = canvas.clientWidth; canvas.height = canvas.clientHeight;
  const xs = st.nodes.map(n => n.x), ys = st.nodes.map(n => n.y);
  for (const w of walls) { xs.push(w[0], w[2]); ys.push(w[1], w[3]); }
  for (const t of Object.values(trails)) for (const [x, y] of t) { xs.push(x); ys.push(y); }
  const minx = Math.min(...xs, 0) - 2, maxx = Math.max(...xs, 0) + 2, miny = Math.min(...ys, 0) - 2, maxy = Math.max(...ys, 0) + 2;
  const s = Math.min(canvas.width / (maxx - minx), canvas.height / (maxy - miny));
  const ox = -minx * s, oy = canvas.height + miny * s;
  ctx.strokeStyle = '#889'; ctx.lineWidth = 2;
  for (const w of walls) { ctx.beginPath(); ctx.moveTo(ox + w[0] * s, oy - w[1] * s); ctx.lineTo(ox + w[2] * s, oy - w[3] * s); ctx.stroke(); }
  ctx.lineWidth = 1;
  const list = document.getElementById('list'); list.innerHTML = '';
  for (const n of st.nodes) {
    if (n.kind === 'agent') {
      (trails[n.id] = trails[n.id] || []).push([n.x, n.y]);
      ctx.strokeStyle = '#555'; ctx.beginPath();
      trails[n.id].forEach(([x, y], i) => i ? ctx.lineTo(ox + x * s, oy - y * s) : ctx.moveTo(ox + x * s, oy - y * s));
      ctx.stroke();
      ctx.strokeStyle = n.id === selected ? '#ff0' : '#f80'; ellipse(n, s, ox, oy);
      ctx.fillStyle = '#f33'; ctx.beginPath(); ctx.arc(ox + n.x * s, oy - n.y * s, 6, 0, 2 * Math.PI); ctx.fill();
      ctx.fillStyle = '#fff'; ctx.fillText(n.id, ox + n.x * s + 8, oy - n.y * s - 8);
      const div = document.createElement('div'); div.className = 'node' + (n.id === selected ? ' sel' : '');
      div.dataset.id = n.id; div.textContent = `${n.id}: (${n.x.toFixed(1)}, ${n.y.toFixed(1)}) m`;
      div.onclick = () => { selected = n.id; }; list.appendChild(div);
    } else {
      ctx.fillStyle = n.kind === 'base' ? '#4af' : '#8c8';
      ctx.fillRect(ox + n.x * s - 3, oy - n.y * s - 3, 6, 6);
    }
  }
  document.getElementById('alerts').innerHTML = st.alerts.map(a => `<div class="alert">${a.message}</div>`).join('');
  document.getElementById('clock').textContent = st.t === null ? '' : `mission time ${st.t.toFixed(1)} s`;
}
setInterval(tick, 500); tick();
</script></body></html>
)HTML";
}

}  // namespace trailmark::server

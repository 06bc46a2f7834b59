// SPDX-License-Identifier: MIT
#include "server/load_test.h"

#include <fmt/format.h>
#include <sys/resource.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <fstream>
#include <limits>
#include <mutex>
#include <set>
#include <thread>
#include <type_traits>

#include "server/incident_server.h"
#include "server/journal.h"
#include "trailmark/eval/metrics.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/io/streams.h"
#include "trailmark/pipelines/batch_run.h"
#include "trailmark/pipelines/registry.h"
#include "trailmark/sim/imu_sim.h"
#include "trailmark/sim/scenarios.h"

// After Eigen: <resolv.h>, which httplib includes, defines a macro `_res` that Eigen uses as a name.
#include <httplib.h>
#include <mqtt/async_client.h>

namespace trailmark::server {

namespace {

using Clock = std::chrono::steady_clock;

struct Request {
  std::string stream, body;  ///< stream empty: a bundle of the device's streams (JSON)
  double t_last = 0;   ///< a clock batch (IMU, else steps): its last row's time (latency matching)
  double t_first = 0;  ///< its first row's time
  bool has_clock = false;  ///< holds a batch of the device's clock stream
  double t_window = 0;     ///< the start of its window (pacing: every request, clock or not)
};

/// One firefighter's rows (its own ids), each stream in time order.
struct DeviceRows {
  std::vector<ImuSample> imu;
  std::vector<Step> steps;
  std::vector<RssiPacket> rssi;
  std::vector<RangeMeasurement> ranges;
  std::vector<BearingMeasurement> bearings;
  std::vector<MissionEvent> events;
  std::vector<BaroSample> baro;
  std::size_t other_rows() const {
    return rssi.size() + ranges.size() + bearings.size() + events.size() + baro.size();
  }
};

template <class Row>
void AddBody(const std::vector<Row>& rows, std::size_t& next, double until,
             std::vector<Request>& out) {
  std::vector<Row> window;
  for (; next < rows.size() && RowTime(MissionRow(rows[next])) <= until; ++next)
    window.push_back(rows[next]);
  if (window.empty()) return;
  std::string body;
  for (const auto& line : FormatAll(window)) body += line + "\n";
  out.push_back({StreamFileName<Row>(), std::move(body)});
}

template <class Row>
double NextTime(const std::vector<Row>& rows, std::size_t next) {
  return next < rows.size() ? RowTime(MissionRow(rows[next]))
                            : std::numeric_limits<double>::infinity();
}

/// One firefighter's requests in send order, one per window of batch_s from its next row: the
/// window's rows of its clock stream (`clock`: the foot IMU, or the steps of a device without
/// one), then those of the other streams — one request per stream, or (`bundle`) the window's
/// streams in one request (POST /api/ingest). A window without a clock row (a firefighter
/// standing still sends no steps, but still hears packets) is sent all the same.
template <class ClockRow>
std::vector<Request> Batches(const std::vector<ClockRow>& clock, const DeviceRows& d,
                             double batch_s, bool bundle) {
  std::vector<Request> out;
  std::size_t c = 0, r = 0, g = 0, b = 0, e = 0, p = 0, s = 0;
  constexpr bool kImuClock = std::is_same_v<ClockRow, ImuSample>;
  for (;;) {
    double start = std::min({NextTime(clock, c), NextTime(d.events, e), NextTime(d.ranges, g),
                             NextTime(d.bearings, b), NextTime(d.baro, p), NextTime(d.rssi, r)});
    if constexpr (kImuClock) start = std::min(start, NextTime(d.steps, s));
    if (!std::isfinite(start)) break;
    const double end = start + batch_s - 1e-9;
    const std::size_t first = out.size();
    std::vector<ClockRow> batch;
    for (; c < clock.size() && RowTime(MissionRow(clock[c])) <= end; ++c) batch.push_back(clock[c]);
    if (!batch.empty()) {
      std::string body;
      for (const auto& line : FormatAll(batch)) body += line + "\n";
      out.push_back({StreamFileName<ClockRow>(), std::move(body), RowTime(MissionRow(batch.back())),
                     RowTime(MissionRow(batch.front())), true});
    }
    AddBody(d.events, e, end, out);
    if constexpr (kImuClock) AddBody(d.steps, s, end, out);
    AddBody(d.ranges, g, end, out);
    AddBody(d.bearings, b, end, out);
    AddBody(d.baro, p, end, out);
    AddBody(d.rssi, r, end, out);
    for (std::size_t k = first; k < out.size(); ++k) out[k].t_window = start;
    if (bundle && out.size() > first) {
      nlohmann::ordered_json sections;
      for (std::size_t k = first; k < out.size(); ++k) sections[out[k].stream] = out[k].body;
      Request one{"",   sections.dump(), out[first].t_last, out[first].t_first, !batch.empty(),
                  start};
      out.resize(first);
      out.push_back(std::move(one));
    }
  }
  return out;
}

std::vector<Request> Requests(const DeviceRows& d, double batch_s, bool bundle) {
  return d.imu.empty() ? Batches(d.steps, d, batch_s, bundle) : Batches(d.imu, d, batch_s, bundle);
}

/// What the devices send: the incident's nodes, each firefighter's requests in send order.
struct LoadPlan {
  MissionInfo info;
  std::vector<std::string> ids;
  std::vector<std::vector<Request>> requests;
  std::size_t imu_rows = 0, step_rows = 0, other_rows = 0;
  std::optional<FloorPlan> plan;
  LevelPlans levels;
  std::string scenario;
  double duration_s = 0;
};

void Count(const DeviceRows& d, LoadPlan& plan) {
  plan.imu_rows += d.imu.size();
  plan.step_rows += d.steps.size();
  plan.other_rows += d.other_rows();
}

/// A recorded or simulated mission replayed as it is: each agent with a motion stream (IMU or
/// steps) is a device sending its own rows (RowNode: its IMU and steps, its events, what it
/// receives, its barometer); the rows of the other nodes' devices (crumb-to-crumb packets,
/// beacon ranges) go with the first device's.
LoadPlan ReplayedLoad(const LoadTestOptions& o, const PipelineSpec& spec) {
  const MissionDirectory mission(o.mission);
  MissionData data = ReadMissionData(mission);
  LoadPlan plan;
  plan.info = data.info;
  plan.scenario = o.mission.string();
  std::map<std::string, DeviceRows> devices;
  for (const auto& s : data.imu) devices[s.agent];
  for (const auto& s : data.steps) devices[s.agent];
  if (devices.empty())
    throw std::invalid_argument("bench load: " + o.mission.string() +
                                " has no imu.csv or steps.csv rows: no device to replay");
  for (const auto& [id, rows] : devices) plan.ids.push_back(id);
  double t0 = std::numeric_limits<double>::infinity(), t1 = -t0;
  auto device = [&](const auto& row) -> DeviceRows& {
    const MissionRow r(row);
    t0 = std::min(t0, RowTime(r)), t1 = std::max(t1, RowTime(r));
    const auto it = devices.find(RowNode(r));
    return it != devices.end() ? it->second : devices.at(plan.ids.front());
  };
  // Moved, not copied: a 4-hour mission's rows are held once (the device is found first).
  for (auto& x : data.imu) device(x).imu.push_back(std::move(x));
  for (auto& x : data.steps) device(x).steps.push_back(std::move(x));
  for (auto& x : data.rssi) device(x).rssi.push_back(std::move(x));
  for (auto& x : data.ranges) device(x).ranges.push_back(std::move(x));
  for (auto& x : data.bearings) device(x).bearings.push_back(std::move(x));
  for (auto& x : data.events) device(x).events.push_back(std::move(x));
  for (auto& x : data.baro) device(x).baro.push_back(std::move(x));
  plan.duration_s = std::max(t1 - t0, 1e-9);
  for (const auto& id : plan.ids) {
    const DeviceRows& d = devices.at(id);
    plan.requests.push_back(Requests(d, o.batch_s, o.bundle && o.mqtt_uri.empty()));
    Count(d, plan);
  }
  plan.plan = LoadPipelineFloor(spec, mission, o.pipeline_options, nullptr, &plan.levels);
  return plan;
}

double CpuSeconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_utime.tv_sec + u.ru_utime.tv_usec * 1e-6 + u.ru_stime.tv_sec +
         u.ru_stime.tv_usec * 1e-6;
}

double PeakRssMb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss / 1024.0;
}

/// The simulated load (see RunLoadTest's comment below).
LoadPlan SimulatedLoad(const LoadTestOptions& o, const PipelineSpec& spec) {
  // The scenario: the simulated experiment of the pipeline's paper, else the office loop (it
  // ends where it began), with a foot IMU; one walk repeated until the incident time is covered;
  // every firefighter sends it under its own id.
  //  - the office loop (as measured since issue 7): the firefighters share the base and the
  //    crumbs, and each sends its IMU and the packets it receives;
  //  - a paper's experiment: the building's landmarks and base are shared, while each
  //    firefighter drops its own crumbs (its own beacon trail: "ff3-b01"); each device sends
  //    the rows it is the device of (RowNode: its IMU, its events, what it receives) and those
  //    of its crumbs (ranges between its beacons, bearings from them); rows of the shared nodes'
  //    own devices go once, with the first firefighter's. Each repetition of the walk drops
  //    new crumbs ("ff3-r2-b01" in the third): a longer incident has more of them, as a real
  //    one would; the same crumbs dropped again where the dead reckoning has drifted to would
  //    be a contradiction no incident has.
  const bool paper = !spec.paper_scenarios.empty();
  SimulatedMission sim = paper ? SimulateScenario(spec.paper_scenarios.front(), o.seed)
                               : SimulateOfficeLoop(OfficeLoopOptions{}, o.seed);
  ImuSimOptions imu_options;
  imu_options.rate_hz = o.imu_hz;
  AddFootImu(sim, imu_options, o.seed);
  const std::string agent = sim.walks.begin()->first;
  const NodeInfo* original = sim.data.info.Find(agent);
  const double duration_s = o.minutes * 60.0;
  double t0 = 1e300, t_end = -1e300;
  for (const auto& s : sim.data.imu) {
    if (s.agent == agent) t0 = std::min(t0, s.t), t_end = std::max(t_end, s.t);
  }
  const double span = t_end - t0 + 1.0 / o.imu_hz;
  std::set<std::string> crumbs;  // the nodes each firefighter has its own copy of
  if (paper) {
    for (const NodeInfo& n : sim.data.info.nodes) {
      if (n.kind == NodeKind::kCrumb) crumbs.insert(n.id);
    }
    for (const auto& e : sim.data.events) {
      if (e.event == "drop" && !e.node.empty()) crumbs.insert(e.node);
    }
  }
  LoadPlan plan;
  MissionInfo& info = plan.info;
  info.name = "load test";
  info.radio = sim.data.info.radio;
  std::vector<std::string>& ids = plan.ids;
  for (int k = 1; k <= o.firefighters; ++k) {
    const std::string ff = fmt::format("ff{}", k);
    ids.push_back(ff);
    const int repetitions = static_cast<int>(std::ceil(duration_s / span));
    auto id = [&](const std::string& node, int rep) {
      if (node == agent) return ff;
      if (!crumbs.count(node)) return node;
      return rep == 0 ? ff + "-" + node : fmt::format("{}-r{}-{}", ff, rep, node);
    };
    // Whether this firefighter's device sends a row whose device is `node` (and, on the
    // office loop, which it receives).
    auto sends = [&](const std::string& node) {
      return node == agent || crumbs.count(node) || (paper && k == 1);
    };
    NodeInfo n = *original;
    n.id = ff;
    info.nodes.push_back(n);
    for (int rep = 0; rep < repetitions; ++rep) {
      for (const NodeInfo& s : sim.data.info.nodes) {
        if (s.kind == NodeKind::kAgent || (!crumbs.count(s.id) && (k > 1 || rep > 0))) continue;
        NodeInfo copy = s;
        copy.id = id(s.id, rep);
        info.nodes.push_back(copy);
      }
    }
    DeviceRows d;
    for (int rep = 0; rep < repetitions; ++rep) {
      const double shift = rep * span + (k - 1) * o.stagger_s;
      auto keep = [&](double t) { return t + shift - t0 < duration_s; };
      for (auto s : sim.data.imu) {
        if (s.agent != agent || !keep(s.t)) continue;
        s.t += shift, s.agent = ff;
        d.imu.push_back(s);
      }
      // The rows this device sends, shifted and renamed (`a`, `b`: the row's two nodes, the
      // first its device).
      auto copy = [&](const auto& rows, auto& out, auto a, auto b) {
        for (auto r : rows) {
          if (!keep(RowTime(MissionRow(r))) || !sends(r.*a)) continue;
          r.t += shift;
          r.*a = id(r.*a, rep), r.*b = id(r.*b, rep);
          out.push_back(r);
        }
      };
      copy(sim.data.rssi, d.rssi, &RssiPacket::rx, &RssiPacket::tx);
      copy(sim.data.ranges, d.ranges, &RangeMeasurement::a, &RangeMeasurement::b);
      copy(sim.data.bearings, d.bearings, &BearingMeasurement::a, &BearingMeasurement::b);
      for (auto e : sim.data.events) {
        if (!paper || !keep(e.t) || e.agent != agent) continue;
        e.t += shift, e.agent = ff, e.node = id(e.node, rep);
        d.events.push_back(e);
      }
    }
    // The requests now: the rows themselves are not kept (peak memory).
    plan.requests.push_back(Requests(d, o.batch_s, o.bundle && o.mqtt_uri.empty()));
    Count(d, plan);
  }
  if (spec.needs_floor_plan) plan.plan = sim.plan;
  plan.scenario = paper ? spec.paper_scenarios.front() : std::string("office-loop");
  plan.duration_s = duration_s;
  return plan;
}

}  // namespace

nlohmann::json RunLoadTest(const LoadTestOptions& o) {
  if (!(o.batch_s > 0) || !(o.speed >= 0) || !std::isfinite(o.speed) ||
      (o.mission.empty() && (o.firefighters < 1 || !(o.minutes > 0) || !(o.imu_hz > 0) ||
                             !(o.stagger_s >= 0) || !std::isfinite(o.stagger_s))))
    throw std::invalid_argument(
        "bench load: firefighters >= 1; minutes, batch, rate > 0; stagger, speed >= 0");
  const PipelineSpec& spec = RequirePipeline(o.pipeline);
  const LoadPlan load = o.mission.empty() ? SimulatedLoad(o, spec) : ReplayedLoad(o, spec);
  const MissionInfo& info = load.info;
  const std::vector<std::string>& ids = load.ids;
  const std::vector<std::vector<Request>>& requests = load.requests;
  // Steps count among the other streams' rows where a device has a foot IMU too.
  const std::size_t imu_rows = load.imu_rows, other_rows = load.other_rows + load.step_rows;
  const double duration_s = load.duration_s;
  const std::filesystem::path dir = o.work_dir / "load-test";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir / "incident");
  WriteMissionInfo(dir / "incident" / "mission.json", info);

  std::size_t rows_total = imu_rows + other_rows, requests_total = 0, clock_batches = 0;
  for (const auto& device : requests) {
    requests_total += device.size();
    for (const auto& r : device) clock_batches += r.has_clock;
  }

  ServerOptions so;
  so.live_dir = dir / "incident";
  so.journal_file = dir / "journal.db";
  so.pipeline = o.pipeline;
  so.pipeline_options = o.pipeline_options;
  so.floor_plan = load.plan;
  so.floor_levels = load.levels;
  so.port = 0;
  if (!o.mqtt_uri.empty()) {
    so.mqtt.uri = o.mqtt_uri;
    so.mqtt.incident = "load";
    // A fresh session per run: a broker keeps a persistent session's queue between runs.
    so.mqtt.client_id = fmt::format(
        "trailmark-load-{}", std::chrono::steady_clock::now().time_since_epoch().count());
  }
  so.token = "load-test";
  so.http_threads = static_cast<std::size_t>(o.firefighters) + 8;
  // Every simulated device connects from loopback: one address for all of them.
  so.max_connections_per_address = 0;
  std::atomic<std::size_t> logged{0};
  so.log = [&logged](const std::string&) { ++logged; };
  IncidentServer server(info, {}, so);
  server.Start();

  // The dashboard client: every event's agent times, matched against the batches in flight.
  struct InFlight {
    double t_first, t_last;
    Clock::time_point sent;
  };
  std::mutex flight_mutex;
  std::map<std::string, std::deque<InFlight>> in_flight;
  // Data -> estimate: for each new estimate, from the POST of the batch holding its time (a
  // step-based estimate of a firefighter standing still has nothing new to show; the batches
  // of a stance are not waiting for one).
  std::map<std::string, std::deque<InFlight>> holding;
  std::map<std::string, double> shown;
  std::vector<double> data_latencies_ms;
  std::vector<double> latencies_ms;
  double worst_ms = 0;
  std::pair<std::string, double> worst_at;  ///< firefighter and batch time of the worst latency
  latencies_ms.reserve(requests_total);
  std::atomic<bool> done{false};
  std::atomic<std::size_t> events{0};
  std::thread dashboard([&] {
    httplib::Client client("127.0.0.1", server.port());
    std::string buffer;
    client.set_read_timeout(std::chrono::seconds(60));  // events may pause while devices connect
    client.Get("/api/events?token=load-test", [&](const char* data, std::size_t n) {
      buffer.append(data, n);
      for (std::size_t end; (end = buffer.find("\n\n")) != std::string::npos;) {
        const std::string message = buffer.substr(0, end);
        buffer.erase(0, end + 2);
        if (message.rfind("data: ", 0) != 0) continue;
        const auto now = Clock::now();
        ++events;
        const auto state = nlohmann::json::parse(message.substr(6));
        std::lock_guard<std::mutex> lock(flight_mutex);
        for (const auto& node : state.at("nodes")) {
          auto it = in_flight.find(node.at("id").get<std::string>());
          if (it == in_flight.end()) continue;
          const double t = node.at("t").get<double>();
          auto& hold = holding[it->first];
          if (auto [s, fresh] = shown.emplace(it->first, t); fresh || t > s->second) {
            s->second = t;
            while (!hold.empty() && hold.front().t_last < t - 1e-9) hold.pop_front();
            if (!hold.empty() && hold.front().t_first <= t + 1e-9)
              data_latencies_ms.push_back(
                  std::chrono::duration<double, std::milli>(now - hold.front().sent).count());
          }
          while (!it->second.empty() && it->second.front().t_last <= t + 1e-9) {
            latencies_ms.push_back(
                std::chrono::duration<double, std::milli>(now - it->second.front().sent).count());
            if (latencies_ms.back() > worst_ms) {
              worst_ms = latencies_ms.back();
              worst_at = {it->first, it->second.front().t_last};
            }
            it->second.pop_front();
          }
        }
      }
      return !done.load();
    });
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(200));  // the stream is open

  std::atomic<std::size_t> accepted{0}, refused{0};
  std::string first_refusal;
  auto refuse = [&](const std::string& why) {
    if (refused++ == 0) {
      std::lock_guard<std::mutex> lock(flight_mutex);
      first_refusal = why;
    }
  };
  auto sent = [&](std::size_t k, const Request& r) {
    if (r.has_clock) {
      std::lock_guard<std::mutex> lock(flight_mutex);
      in_flight[ids[k]].push_back({r.t_first, r.t_last, Clock::now()});
      holding[ids[k]].push_back({r.t_first, r.t_last, Clock::now()});
    }
  };
  // Every device connects first, one after the other (cpp-httplib listens with a backlog of 5:
  // a storm of simultaneous connects waits for SYN retransmission, 1 s), then all send at once.
  std::vector<std::unique_ptr<httplib::Client>> clients;
  std::vector<std::unique_ptr<mqtt::async_client>> publishers;
  const auto connect0 = Clock::now();
  for (std::size_t k = 0; k < ids.size(); ++k) {
    if (o.mqtt_uri.empty()) {
      clients.push_back(std::make_unique<httplib::Client>("127.0.0.1", server.port()));
      clients.back()->set_keep_alive(true);
      clients.back()->set_tcp_nodelay(true);
      if (!clients.back()->Get("/api/health"))
        throw std::runtime_error("bench load: a device could not connect");
    } else {
      publishers.push_back(std::make_unique<mqtt::async_client>(o.mqtt_uri, "load-" + ids[k],
                                                                mqtt::create_options()));
      publishers.back()
          ->connect(mqtt::connect_options_builder().clean_session(true).max_inflight(64).finalize())
          ->wait();
    }
  }
  const double connect_s = std::chrono::duration<double>(Clock::now() - connect0).count();
  const double cpu0 = CpuSeconds();
  const auto wall0 = Clock::now();
  // Devices keep within max_skew_s of mission time of each other, as in real time (a device
  // that ran ahead by more than an estimator's reorder window would make the others' rows late).
  std::mutex pace_mutex;
  std::condition_variable pace_cv;
  // The window of the last request sent; before the first, the device's start (a team not yet
  // entered is not behind the others). Every request counts, with or without a clock batch: a
  // device whose firefighter stands still (no steps) still sends the packets it hears, and
  // paced on its steps alone it ran minutes of mission time ahead of the others (most rows then
  // reached the estimator late).
  std::vector<double> progress(ids.size(), -1e300);
  for (std::size_t k = 0; k < ids.size(); ++k) {
    if (!requests[k].empty()) progress[k] = requests[k].front().t_window - o.batch_s;
  }
  double t_start = std::numeric_limits<double>::infinity();
  for (const auto& device : requests) {
    if (!device.empty()) t_start = std::min(t_start, device.front().t_window);
  }
  auto pace = [&](std::size_t k, const Request& r) {
    if (o.speed > 0) {  // the wall clock's schedule
      std::this_thread::sleep_until(
          wall0 + std::chrono::duration_cast<Clock::duration>(
                      std::chrono::duration<double>((r.t_window - t_start) / o.speed)));
    }
    if (!(o.max_skew_s > 0)) return;
    std::unique_lock<std::mutex> lock(pace_mutex);
    pace_cv.wait(lock, [&] {
      return *std::min_element(progress.begin(), progress.end()) >= r.t_window - o.max_skew_s ||
             progress[k] <= *std::min_element(progress.begin(), progress.end());
    });
  };
  auto paced = [&](std::size_t k, const Request& r) {
    if (!(o.max_skew_s > 0)) return;
    {
      std::lock_guard<std::mutex> lock(pace_mutex);
      progress[k] = r.t_window;
    }
    pace_cv.notify_all();
  };
  // A device that has sent everything holds no one back (a replayed mission's devices end at
  // different times).
  auto finished = [&](std::size_t k) {
    {
      std::lock_guard<std::mutex> lock(pace_mutex);
      progress[k] = std::numeric_limits<double>::infinity();
    }
    pace_cv.notify_all();
  };
  std::vector<std::thread> devices;
  for (std::size_t k = 0; k < ids.size(); ++k) {
    devices.emplace_back([&, k] {
      if (!o.mqtt_uri.empty()) {
        // QoS 1 through the broker; the device's PUBACK comes from the broker (the server's own
        // PUBACK to the broker follows its journal commit). A window of 32 messages in flight.
        std::deque<mqtt::delivery_token_ptr> window;
        for (const Request& r : requests[k]) {
          pace(k, r);
          sent(k, r);
          paced(k, r);
          try {
            window.push_back(publishers[k]->publish(
                mqtt::make_message("trailmark/load/" + ids[k] + "/" + r.stream, r.body, 1, false)));
            if (window.size() >= 32) {
              window.front()->wait();
              window.pop_front();
            }
          } catch (const mqtt::exception& e) {
            refuse(e.what());
          }
        }
        finished(k);
        for (auto& t : window) t->wait();
        return;
      }
      httplib::Client& client = *clients[k];
      const httplib::Headers auth{{"Authorization", "Bearer load-test"}};
      for (const Request& r : requests[k]) {
        pace(k, r);
        sent(k, r);
        const auto res =
            r.stream.empty() ? client.Post("/api/ingest", auth, r.body, "application/json")
                             : client.Post("/api/ingest/" + r.stream, auth, r.body, "text/csv");
        paced(k, r);
        if (!res || res->status != 200) {
          refuse(fmt::format("{} ({} bytes of {} at t {:.2f} s)",
                             res ? fmt::format("HTTP {} {}", res->status, res->body)
                                 : httplib::to_string(res.error()),
                             r.body.size(), ids[k], r.t_last));
          continue;
        }
        accepted += nlohmann::json::parse(res->body).at("accepted").get<std::size_t>();
      }
      finished(k);
    });
  }
  for (auto& d : devices) d.join();
  if (!o.mqtt_uri.empty()) {
    // Devices are done when the broker has their messages; the rows are in when the server has
    // journaled them all (at most 120 s more).
    const auto give_up = Clock::now() + std::chrono::seconds(120);
    while (server.stats().ingested_rows.load() < rows_total && Clock::now() < give_up)
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    accepted = server.stats().ingested_rows.load();
    for (auto& p : publishers) p->disconnect()->wait();
  }
  const double ingest_s = std::chrono::duration<double>(Clock::now() - wall0).count();
  // Until the estimator has caught up: every batch's event, or nothing new for a second (the
  // INS holds its last samples until the detector window after them arrives: a device's final
  // batch waits for data that never comes).
  std::size_t seen = 0;
  auto last_change = Clock::now();
  while (Clock::now() - last_change < std::chrono::seconds(1)) {
    std::size_t now_seen;
    {
      std::lock_guard<std::mutex> lock(flight_mutex);
      now_seen = latencies_ms.size();
    }
    if (now_seen >= clock_batches) break;
    if (now_seen != seen) seen = now_seen, last_change = Clock::now();
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  const double total_s = std::chrono::duration<double>(last_change - wall0).count();
  const double cpu_s = CpuSeconds() - cpu0;
  done = true;
  const std::size_t estimated = server.stats().estimated_rows.load();
  const std::size_t commits = server.stats().commits.load();
  const std::size_t events_sent = server.stats().events_sent.load();
  const nlohmann::json estimator = server.StatsJson().value("estimator", nlohmann::json::object());
  server.Stop();
  dashboard.join();
  const std::size_t journaled = Journal(so.journal_file).size();
  std::size_t unmatched = 0;
  for (const auto& [id, q] : in_flight) unmatched += q.size();
  if (refused > 0 || journaled != rows_total || accepted != rows_total) {
    throw std::runtime_error(fmt::format(
        "bench load: {} requests refused (first: {}), {} rows accepted, {} journaled of {} sent",
        refused.load(), first_refusal, accepted.load(), journaled, rows_total));
  }
  return {{"firefighters", ids.size()},
          {"incident_minutes", duration_s / 60.0},
          {"mission", o.mission.string()},
          {"imu_hz", o.imu_hz},
          {"batch_s", o.batch_s},
          {"pipeline", o.pipeline},
          {"max_skew_s", o.max_skew_s},
          {"speed", o.speed},
          {"stagger_s", o.stagger_s},
          {"bundled", o.bundle && o.mqtt_uri.empty()},
          {"transport", o.mqtt_uri.empty() ? "http" : "mqtt"},
          {"devices_connect_s", connect_s},
          {"requests", requests_total},
          {"rows", rows_total},
          {"scenario", load.scenario},
          {"imu_rows", imu_rows},
          {"step_rows", load.step_rows},
          {"other_rows", other_rows},
          {"ingest_wall_s", ingest_s},
          {"rows_per_s", rows_total / ingest_s},
          {"requests_per_s", requests_total / ingest_s},
          {"real_time_factor", duration_s / ingest_s},
          {"estimated_rows", estimated},
          {"journal_commits", commits},
          {"rows_per_commit", static_cast<double>(rows_total) / std::max<std::size_t>(1, commits)},
          {"latency_ms_p50", Percentile(latencies_ms, 50)},
          {"latency_ms_p99", Percentile(latencies_ms, 99)},
          {"latency_ms_max", Percentile(latencies_ms, 100)},
          {"latency_samples", latencies_ms.size()},
          {"latency_max_batch", {{"firefighter", worst_at.first}, {"t_last", worst_at.second}}},
          {"data_to_estimate_ms_p50", Percentile(data_latencies_ms, 50)},
          {"data_to_estimate_ms_p99", Percentile(data_latencies_ms, 99)},
          {"data_to_estimate_ms_max", Percentile(data_latencies_ms, 100)},
          {"data_to_estimate_samples", data_latencies_ms.size()},
          {"batches_without_event", unmatched},
          {"events", events.load()},
          {"events_sent_by_server", events_sent},
          {"cpu_s", cpu_s},
          {"cpu_cores_busy", cpu_s / std::max(total_s, ingest_s)},
          {"peak_rss_mb", PeakRssMb()},
          {"rejections_logged", logged.load()},
          {"estimator", estimator}};
}

}  // namespace trailmark::server

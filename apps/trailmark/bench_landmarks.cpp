// SPDX-License-Identifier: MIT
// `trailmark bench landmarks`: issue 24's large landmark incident — 20 firefighters for 4 hours
// under a ceiling grid of radio landmarks (a share of them unknown) — through landmarks-ukf, two
// ways, the rows already in memory (no CSV):
//  - the pipeline as `trailmark run` builds it (step front end, stream checks, dead-reckoning
//    guard, the estimator), with per-row latency;
//  - the estimator alone (landmarks::LandmarkEstimator with the pipeline's options).
// Also the agents' error at their step ends against the generator's truth, and dead reckoning's
// (the pdr pipeline) on the same steps, so that a faster version that estimates something else
// shows.

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <fstream>
#include <nlohmann/json.hpp>
#include <unordered_map>

#include "commands.h"
#include "trailmark/eval/metrics.h"  // Percentile
#include "trailmark/landmarks/landmark_estimator.h"
#include "trailmark/pipelines/registry.h"

namespace trailmark::cli {

namespace {

using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point a) {
  return std::chrono::duration<double>(Clock::now() - a).count();
}

/// The agents' estimates at their step ends, against the truth there.
class ErrorSink : public EstimateSink {
 public:
  explicit ErrorSink(const std::vector<TruthSample>& truth) {
    for (const TruthSample& s : truth) truth_[s.id].push_back(&s);
  }
  void Add(const Estimate& e) override {
    ++rows_;
    const auto it = truth_.find(e.id);
    if (it == truth_.end()) {
      last_[e.id] = e.position_n.head<2>();  // a landmark's latest estimate
      return;
    }
    const auto& v = it->second;
    const auto s = std::lower_bound(v.begin(), v.end(), e.t - 1e-9,
                                    [](const TruthSample* a, double t) { return a->t < t; });
    if (s == v.end() || std::abs((*s)->t - e.t) > 1e-9) return;
    errors_.push_back((e.position_n.head<2>() - (*s)->position_n.head<2>()).norm());
  }
  std::size_t rows() const { return rows_; }
  const std::unordered_map<std::string, Vec2>& last() const { return last_; }
  const std::vector<double>& errors() const { return errors_; }

 private:
  std::unordered_map<std::string, std::vector<const TruthSample*>> truth_;
  std::vector<double> errors_;
  std::unordered_map<std::string, Vec2> last_;
  std::size_t rows_ = 0;
};

struct Measured {
  double wall_s = 0;
  std::vector<double> latency_us;
  std::size_t estimates = 0;
  double mean_m = 0, p95_m = 0;
  std::size_t placed = 0;  ///< landmarks declared without a position that were estimated
  double placed_mean_m = 0;
};

Measured Feed(OnlineEstimator& estimator, const LandmarkIncident& inc, bool latencies) {
  ErrorSink sink(inc.truth);
  Measured m;
  if (latencies) m.latency_us.reserve(inc.rows.size());
  const auto start = Clock::now();
  for (const MissionRow& row : inc.rows) {
    if (latencies) {
      const auto t0 = Clock::now();
      estimator.Add(row, sink);
      m.latency_us.push_back(std::chrono::duration<double, std::micro>(Clock::now() - t0).count());
    } else {
      estimator.Add(row, sink);
    }
  }
  estimator.Finish(sink);
  m.wall_s = Seconds(start);
  m.estimates = sink.rows();
  const auto& e = sink.errors();
  if (!e.empty()) {
    double sum = 0;
    for (double x : e) sum += x;
    m.mean_m = sum / static_cast<double>(e.size());
    m.p95_m = Percentile(e, 95);
  }
  for (const TruthSample& l : inc.landmark_truth) {
    const NodeInfo* node = inc.info.Find(l.id);
    const auto it = sink.last().find(l.id);
    if (node == nullptr || node->position || it == sink.last().end()) continue;
    ++m.placed;
    m.placed_mean_m += (it->second - l.position_n.head<2>()).norm();
  }
  if (m.placed > 0) m.placed_mean_m /= static_cast<double>(m.placed);
  return m;
}

}  // namespace

int BenchLandmarks(const LandmarkIncidentOptions& o, const OptionValues& options,
                   const std::filesystem::path& json_out) {
  const PipelineSpec& spec = RequirePipeline("landmarks-ukf");
  // The estimator alone takes the pipeline's options that are its own (not the front end's).
  landmarks::LandmarkEstimatorOptions core_options;
  core_options.tracking = landmarks::Tracking::kUkf;
  core_options.fix_fusion = landmarks::FixFusion::kIndependent;  // as the pipeline's defaults
  const auto& table = landmarks::LandmarkOptionTable(core_options.tracking);
  const std::vector<std::string> own = table.Keys();
  OptionValues core_values;
  for (const auto& [key, value] : options) {
    if (std::find(own.begin(), own.end(), key) != own.end()) core_values[key] = value;
  }
  std::string why;
  if (!table.Apply(core_values, &core_options, &why)) {
    throw std::invalid_argument("bench landmarks: " + why);
  }
  auto t0 = Clock::now();
  const LandmarkIncident inc = MakeLandmarkIncident(o, 1);
  const double gen_s = Seconds(t0);
  fmt::print(
      "synthetic landmark incident: {} firefighters, {:.1f} h, {} landmarks ({} without a "
      "position), {} steps + {} RSSI packets = {} rows (generated in {:.1f} s)\n",
      o.agents, o.duration_s / 3600, inc.landmarks, inc.unknown, inc.steps, inc.packets,
      inc.rows.size(), gen_s);
  for (const auto& [key, value] : options) fmt::print("option {}={}\n", key, value);

  const EstimatorInputs in{inc.info};
  auto pipeline = spec.make(in, options, Feed::kTimeOrdered);
  const Measured whole = Feed(*pipeline, inc, true);

  landmarks::LandmarkEstimator core(inc.info, core_options);
  const Measured alone = Feed(core, inc, false);

  // Dead reckoning on the same steps (the pdr pipeline): the reference the tracker must beat.
  auto dr = RequirePipeline("pdr").make(in, {}, Feed::kTimeOrdered);
  const Measured dead_reckoning = Feed(*dr, inc, false);

  const double rows = static_cast<double>(inc.rows.size());
  fmt::print(
      "\n| figure | pipeline (as `run`, rows in memory) | estimator alone |\n|---|---|---|\n");
  fmt::print("| wall time (one core) | {:.2f} s | {:.2f} s |\n", whole.wall_s, alone.wall_s);
  fmt::print("| x real time (the incident's {:.0f} s) | {:.0f}x | {:.0f}x |\n", o.duration_s,
             o.duration_s / whole.wall_s, o.duration_s / alone.wall_s);
  fmt::print("| rows/s | {:.0f} | {:.0f} |\n", rows / whole.wall_s, rows / alone.wall_s);
  fmt::print("| per-row latency p50 / p99 / max | {:.2f} / {:.1f} / {:.0f} us | |\n",
             Percentile(whole.latency_us, 50), Percentile(whole.latency_us, 99),
             *std::max_element(whole.latency_us.begin(), whole.latency_us.end()));
  fmt::print("| estimates written | {} | {} |\n", whole.estimates, alone.estimates);
  fmt::print(
      "| agents at their step ends: mean / p95 error | {:.2f} / {:.2f} m | {:.2f} / {:.2f} m |\n",
      whole.mean_m, whole.p95_m, alone.mean_m, alone.p95_m);
  fmt::print(
      "| dead reckoning (pdr) at the same step ends: mean / p95 error | {:.2f} / {:.2f} m | |\n",
      dead_reckoning.mean_m, dead_reckoning.p95_m);
  fmt::print(
      "| landmarks without a position placed (of {}): count, mean error | {}, {:.2f} m | {}, "
      "{:.2f} m |\n",
      inc.unknown, whole.placed, whole.placed_mean_m, alone.placed, alone.placed_mean_m);
  if (!json_out.empty()) {
    nlohmann::json j;
    j["firefighters"] = o.agents;
    j["duration_s"] = o.duration_s;
    j["landmarks"] = inc.landmarks;
    j["unknown_landmarks"] = inc.unknown;
    j["steps"] = inc.steps;
    j["packets"] = inc.packets;
    j["options"] = options;
    j["pipeline"] = {{"wall_s", whole.wall_s},
                     {"x_real_time", o.duration_s / whole.wall_s},
                     {"latency_p50_us", Percentile(whole.latency_us, 50)},
                     {"latency_p99_us", Percentile(whole.latency_us, 99)},
                     {"mean_error_m", whole.mean_m},
                     {"p95_error_m", whole.p95_m},
                     {"unknown_placed", whole.placed},
                     {"unknown_mean_error_m", whole.placed_mean_m}};
    j["dead_reckoning"] = {{"mean_error_m", dead_reckoning.mean_m},
                           {"p95_error_m", dead_reckoning.p95_m}};
    j["estimator"] = {{"wall_s", alone.wall_s},
                      {"x_real_time", o.duration_s / alone.wall_s},
                      {"mean_error_m", alone.mean_m},
                      {"p95_error_m", alone.p95_m}};
    std::ofstream(json_out) << j.dump(2) << "\n";
  }
  return 0;
}

}  // namespace trailmark::cli

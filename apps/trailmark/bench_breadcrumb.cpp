// SPDX-License-Identifier: MIT
// `trailmark bench breadcrumb`: the issue-8 incident benchmark — many firefighters, hundreds of
// breadcrumbs, a million measurements over hours — through the incremental GEN localizer, with
// per-update latency, memory over time, and the reference costs of re-solving the batch problem
// and of the paper's dense inverse.

#include <fmt/format.h>

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <fstream>
#include <nlohmann/json.hpp>
#include <unistd.h>

#include "commands.h"
#include "trailmark/breadcrumb/batch_reference.h"
#include "trailmark/breadcrumb/breadcrumb_estimator.h"
#include "trailmark/breadcrumb/localizer.h"
#include "trailmark/sim/synthetic_incident.h"

namespace trailmark::cli {

namespace {

using Clock = std::chrono::steady_clock;

double ResidentMb() {
  std::ifstream statm("/proc/self/statm");
  long pages = 0, resident = 0;
  statm >> pages >> resident;
  return resident * static_cast<double>(sysconf(_SC_PAGESIZE)) / 1e6;
}

struct IncidentRun {
  double wall_s = 0;
  std::vector<double> latency_us;
  std::vector<std::pair<double, double>> memory;  // (fraction done, resident MB)
  std::size_t factorizations = 0, analyses = 0, agent_states = 0, active_nodes = 0, blocks = 0;
  std::size_t sensitivity_solves = 0;
  double final_mean_error_m = 0;
};

IncidentRun RunIncident(const SyntheticIncident& inc, const breadcrumb::LocalizerOptions& options) {
  breadcrumb::BreadcrumbLocalizer loc(options);
  for (const auto& n : inc.info.nodes) {
    if (n.kind == NodeKind::kAgent) loc.AddAgent(n.id, n.start->head<2>(), 0.1);
    if (n.kind == NodeKind::kBase) loc.AddKnownNode(n.id, n.position->head<2>(), 0.0);
  }
  IncidentRun run;
  run.latency_us.reserve(inc.events.size());
  const auto start = Clock::now();
  std::size_t next_mark = inc.events.size() / 4;
  for (std::size_t k = 0; k < inc.events.size(); ++k) {
    const auto& e = inc.events[k];
    const auto t0 = Clock::now();
    switch (e.kind) {
      case IncidentEvent::Kind::kStep:
        loc.AddStep(e.step);
        loc.Estimate(e.step.agent);  // the online output of the pipeline, at every step
        break;
      case IncidentEvent::Kind::kRssi:
        loc.AddRssi(e.rssi);
        break;
      case IncidentEvent::Kind::kDrop:
        loc.AddEvent(e.drop);
        break;
    }
    run.latency_us.push_back(std::chrono::duration<double, std::micro>(Clock::now() - t0).count());
    if ((k + 1 == next_mark && run.memory.size() < 3) || k + 1 == inc.events.size()) {
      run.memory.emplace_back(static_cast<double>(k + 1) / inc.events.size(), ResidentMb());
      next_mark += inc.events.size() / 4;
    }
  }
  loc.Finish();
  run.wall_s = std::chrono::duration<double>(Clock::now() - start).count();
  run.factorizations = loc.summary().factorizations;
  run.analyses = loc.network().symbolic_analyses();
  run.sensitivity_solves = loc.network().sensitivity_solves();
  run.agent_states = loc.summary().agent_states;
  run.active_nodes = static_cast<std::size_t>(loc.network().active_nodes());
  run.blocks = loc.network().off_diagonal_blocks();
  return run;
}

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  const auto k = static_cast<std::size_t>(q / 100.0 * (v.size() - 1));
  std::nth_element(v.begin(), v.begin() + k, v.end());
  return v[k];
}

/// The cost of re-solving everything at an update: the batch problem (every agent state kept,
/// dense Gauss-Newton) for the first `steps` steps of one agent of a small incident.
double BatchSolveSeconds(int steps, std::uint64_t seed) {
  IncidentOptions o;
  o.agents = 1;
  o.crumbs = 10;
  o.duration_s = steps * o.step_period_s;
  o.measurements = static_cast<std::size_t>(steps * 2);
  o.crumb_drop_period_s = 20;
  const SyntheticIncident inc = MakeSyntheticIncident(o, seed);
  breadcrumb::BatchProblem p;
  std::map<std::string, int> crumb;
  int state = p.num_nodes++;
  Eigen::VectorXd x0 = Eigen::VectorXd::Zero(2 * (steps + 20));
  const Vec2 start = inc.info.nodes[1].start->head<2>();
  p.relative.push_back({state, -1, Vec2::Zero(), start, Mat2::Identity() * 0.01});
  Vec2 pos = start;
  x0.segment<2>(0) = pos;
  breadcrumb::ScalarModel rssi;
  rssi.kind = breadcrumb::ScalarModel::Kind::kRssiDb;
  for (const auto& e : inc.events) {
    if (e.kind == IncidentEvent::Kind::kStep) {
      const int next = p.num_nodes++;
      p.relative.push_back({next, state, Vec2::Zero(), e.step.delta_n.head<2>(), Mat2::Identity() * 1e-3});
      pos += e.step.delta_n.head<2>();
      x0.segment<2>(2 * next) = pos;
      state = next;
    } else if (e.kind == IncidentEvent::Kind::kDrop) {
      const int c = crumb[e.drop.node] = p.num_nodes++;
      p.relative.push_back({c, state, Vec2::Zero(), Vec2::Zero(), Mat2::Identity() * 0.25});
      x0.segment<2>(2 * c) = pos;
    } else if (crumb.count(e.rssi.tx)) {
      p.scalar.push_back({state, crumb[e.rssi.tx], Vec2::Zero(), Vec2::Zero(), e.rssi.rssi_dbm, 16.0, rssi});
    }
  }
  x0.conservativeResize(2 * p.num_nodes);
  const auto t0 = Clock::now();
  breadcrumb::SolveNonlinear(p, x0, 3, 1e-6);
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

}  // namespace

int BenchBreadcrumb(const IncidentOptions& o, double solve_period_s, double covariance_period_s,
                    const std::filesystem::path& json_out,
                    const std::map<std::string, std::string>& localizer_options) {
  breadcrumb::LocalizerOptions options;
  options.calibrate_online = false;  // the synthetic channel is the log-distance model itself
  options.radio = {o.alpha_dbm, o.path_loss_exponent, o.sigma_db, 0.0};
  options.solve_period_s = solve_period_s;
  options.covariance_period_s = covariance_period_s;
  if (!localizer_options.empty()) {  // the pipeline's keys, e.g. heading_rate=1 (an ablation)
    breadcrumb::BreadcrumbEstimatorOptions e;
    e.localizer = options;
    std::string why;
    if (!breadcrumb::BreadcrumbOptionTable().Apply(localizer_options, &e, &why)) {
      throw std::invalid_argument("bench breadcrumb: " + why);
    }
    options = e.localizer;
  }
  auto t0 = Clock::now();
  const SyntheticIncident inc = MakeSyntheticIncident(o, 1);
  const double gen_s = std::chrono::duration<double>(Clock::now() - t0).count();
  fmt::print("synthetic incident: {} firefighters, {} breadcrumbs, {:.1f} h, {} steps + {} RSSI "
             "packets + {} drops = {} measurements (generated in {:.1f} s, {:.0f} MB resident)\n",
             o.agents, inc.drops, o.duration_s / 3600, inc.steps, inc.packets, inc.drops,
             inc.events.size(), gen_s, ResidentMb());
  for (const auto& [key, value] : localizer_options) fmt::print("option {}={}\n", key, value);
  const IncidentRun run = RunIncident(inc, options);
  const double p50 = Percentile(run.latency_us, 50), p99 = Percentile(run.latency_us, 99);
  const double max = *std::max_element(run.latency_us.begin(), run.latency_us.end());
  fmt::print("\n| figure | value |\n|---|---|\n");
  fmt::print("| solve period / covariance period (mission s) | {} / {} |\n", solve_period_s,
             covariance_period_s);
  fmt::print("| total time (one core) | {:.2f} s ({:.0f}x real time) |\n", run.wall_s,
             o.duration_s / run.wall_s);
  fmt::print("| throughput | {:.0f} measurements/s |\n", inc.events.size() / run.wall_s);
  fmt::print("| per-update latency p50 / p99 / max | {:.1f} / {:.1f} / {:.0f} us |\n", p50, p99, max);
  fmt::print("| factorizations (symbolic analyses) / agent states created | {} ({}) / {} |\n",
             run.factorizations, run.analyses, run.agent_states);
  fmt::print("| heading-offset sensitivity solves (one right-hand side per firefighter) | {} |\n",
             run.sensitivity_solves);
  fmt::print("| network at the end: nodes / off-diagonal blocks | {} / {} |\n", run.active_nodes,
             run.blocks);
  std::string mem;
  for (const auto& [f, mb] : run.memory) mem += fmt::format("{:.0f}%: {:.0f} MB  ", 100 * f, mb);
  fmt::print("| resident memory over the run (incl. the {} generated events) | {}|\n",
             inc.events.size(), mem);

  // The paper's dense method: invert L (2 x nodes) at every update, at the final network size.
  const int n = 2 * static_cast<int>(run.active_nodes);
  Eigen::MatrixXd L = Eigen::MatrixXd::Random(n, n);
  L = L * L.transpose() + Eigen::MatrixXd::Identity(n, n) * n;
  t0 = Clock::now();
  const Eigen::MatrixXd inv = L.inverse();
  const double dense_s = std::chrono::duration<double>(Clock::now() - t0).count();
  fmt::print("| paper's dense inverse of L ({}x{}) per update | {:.1f} ms -> {:.0f} s for {} "
             "updates (extrapolated) |\n",
             n, n, 1e3 * dense_s, dense_s * inc.events.size(), inc.events.size());
  // Re-solving the batch problem (nothing marginalized) at an update, vs the incremental p50.
  nlohmann::json batch = nlohmann::json::array();
  for (int steps : {100, 200, 400, 800}) {
    const double s = BatchSolveSeconds(steps, 2);
    fmt::print("| batch re-solve after {} steps of one firefighter (dense GN, 3 it.) | {:.1f} ms "
               "= {:.0f}x the incremental p50 update |\n",
               steps, 1e3 * s, 1e6 * s / std::max(p50, 1e-3));
    batch.push_back({{"steps", steps}, {"seconds", s}});
  }
  (void)inv;
  if (!json_out.empty()) {
    nlohmann::json j = {{"agents", o.agents},
                        {"crumbs", inc.drops},
                        {"duration_s", o.duration_s},
                        {"measurements", inc.events.size()},
                        {"solve_period_s", solve_period_s},
                        {"covariance_period_s", covariance_period_s},
                        {"wall_s", run.wall_s},
                        {"latency_us_p50", p50},
                        {"latency_us_p99", p99},
                        {"latency_us_max", max},
                        {"memory_mb", run.memory},
                        {"dense_inverse_s", dense_s},
                        {"batch", batch}};
    std::ofstream(json_out) << j.dump(2) << "\n";
  }
  return 0;
}

}  // namespace trailmark::cli

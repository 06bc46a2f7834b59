// SPDX-License-Identifier: MIT
// Google Benchmark: I/O throughput per stream kind (rows/s), the wall index, and the pdr
// pipeline on the default mission. `trailmark bench` prints the same figures as a table.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <nanoflann.hpp>

#include "server/journal.h"
#include "trailmark/beacons/beacon_map.h"
#include "trailmark/beacons/map_least_squares.h"
#include "trailmark/beacons/mds.h"
#include "trailmark/beacons/scaat_ekf.h"
#include "trailmark/breadcrumb/gen_network.h"
#include "trailmark/breadcrumb/localizer.h"
#include "trailmark/core/random.h"
#include "trailmark/core/time_order_buffer.h"
#include "trailmark/geometry/rigid_fit.h"
#include "trailmark/ins/zupt_ins.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/landmarks/landmark_estimator.h"
#include "trailmark/landmarks/landmark_ukf.h"
#include "trailmark/mapmatch/particle_filter.h"
#include "trailmark/mapmatch/pattern_comparison.h"
#include "trailmark/mapmatch/search_map.h"
#include "trailmark/pipelines/batch_run.h"
#include "trailmark/sim/beacon_lab.h"
#include "trailmark/sim/house_search.h"
#include "trailmark/sim/imu_sim.h"
#include "trailmark/sim/scenarios.h"
#include "trailmark/sim/synthetic_incident.h"
#include "trailmark/sim/synthetic_streams.h"

namespace {

using namespace trailmark;
namespace fs = std::filesystem;

fs::path BenchDir() {
  static const fs::path dir = [] {
    auto d = fs::temp_directory_path() / "trailmark-gbench";
    fs::create_directories(d);
    return d;
  }();
  return dir;
}

template <class Row>
void BM_Write(benchmark::State& state, std::vector<Row> (*make)(std::size_t, std::uint64_t)) {
  const auto rows = make(static_cast<std::size_t>(state.range(0)), 1);
  const auto path = (BenchDir() / StreamFileName<Row>()).string();
  for (auto _ : state) WriteAll(path, rows);
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(rows.size()));
}

template <class Row>
void BM_Read(benchmark::State& state, std::vector<Row> (*make)(std::size_t, std::uint64_t)) {
  const auto rows = make(static_cast<std::size_t>(state.range(0)), 1);
  const auto path = (BenchDir() / StreamFileName<Row>()).string();
  WriteAll(path, rows);
  for (auto _ : state) {
    RowReader<Row> reader(path);
    Row row;
    std::size_t n = 0;
    while (reader.Next(row)) ++n;
    benchmark::DoNotOptimize(n);
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(rows.size()));
}

std::vector<ImuSample> Imu(std::size_t n, std::uint64_t s) { return SyntheticImu(n, s); }

BENCHMARK_CAPTURE(BM_Write, imu, &Imu)->Arg(200000)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Read, imu, &Imu)->Arg(200000)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Write, steps, &SyntheticSteps)->Arg(200000)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Read, steps, &SyntheticSteps)->Arg(200000)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Write, rssi, &SyntheticRssi)->Arg(200000)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Read, rssi, &SyntheticRssi)->Arg(200000)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Write, truth, &SyntheticTruth)->Arg(200000)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Read, truth, &SyntheticTruth)->Arg(200000)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Write, estimates, &SyntheticEstimates)->Arg(200000)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Read, estimates, &SyntheticEstimates)->Arg(200000)->Unit(benchmark::kMillisecond);

void BM_WallCrossingQuery(benchmark::State& state) {
  const FloorPlan plan = BuildOfficeFloor({});
  Random rng(1);
  std::vector<Segment2> queries;
  for (int i = 0; i < 4096; ++i) {
    const Vec2 a(rng.Uniform(-37, 7), rng.Uniform(-27, 7));
    queries.push_back({a, a + Vec2(rng.Normal(0, 0.5), rng.Normal(0, 0.5))});
  }
  std::size_t i = 0, hits = 0;
  for (auto _ : state) hits += plan.Crosses(queries[i++ & 4095].a, queries[i & 4095].b);
  benchmark::DoNotOptimize(hits);
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_WallCrossingQuery);

/// A floor of n x n cells of 1.5 m: the outline and 2 (n - 1) n partition pieces with door gaps
/// (n = 100: 19,804 walls, a 150 m square floor).
FloorPlan CellularFloor(int n) {
  std::vector<Segment2> walls;
  const double cell = 1.5, side = n * cell;
  AddRectangle(walls, {0, 0}, {side, side});
  for (int i = 1; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      walls.push_back({{i * cell, j * cell}, {i * cell, j * cell + 0.6 * cell}});
      walls.push_back({{j * cell, i * cell}, {j * cell + 0.6 * cell, i * cell}});
    }
  }
  return FloorPlan(std::move(walls), {}, {});
}

// Issue 30, item 5: the map matcher's set-up on a large plan (the floor-plan checks, the wall
// graph, the search sequences) — every wall against every wall before 2026-12-02 (session 7):
// 19.9 s for `trailmark run --pipeline mapmatch` on 19,804 walls, 2.6 s after, the same output;
// the search sequences' own loops made linear on 2026-12-03 (/225: 100,804 walls).
void BM_MapMatchSetUpLargePlan(benchmark::State& state) {
  const FloorPlan plan = CellularFloor(static_cast<int>(state.range(0)));
  for (auto _ : state) {
    benchmark::DoNotOptimize(mapmatch::CheckFloorPlan(plan));
    benchmark::DoNotOptimize(mapmatch::ExtractSearchSequences(plan, {0.7, 0.7}));
  }
  state.counters["walls"] = static_cast<double>(plan.walls().size());
}
BENCHMARK(BM_MapMatchSetUpLargePlan)->Arg(30)->Arg(100)->Arg(225)->Unit(benchmark::kMillisecond);

void BM_PdrPipelineOfficeLoop(benchmark::State& state) {
  const fs::path dir = BenchDir() / "mission";
  const SimulatedMission sim = SimulateScenario("office-loop", 1);
  WriteMissionDirectory(dir, sim.data, &sim.plan);
  const MissionDirectory mission(dir);
  const double duration = sim.data.truth.back().t - sim.data.truth.front().t;
  for (auto _ : state) {
    RunPipeline(RequirePipeline("pdr"), {mission, {}}, BenchDir() / "run");
  }
  state.counters["x_real_time"] = benchmark::Counter(duration * state.iterations(),
                                                     benchmark::Counter::kIsRate);
}
BENCHMARK(BM_PdrPipelineOfficeLoop)->Unit(benchmark::kMillisecond);

void BM_SimulateOfficeLoop(benchmark::State& state) {
  for (auto _ : state) benchmark::DoNotOptimize(SimulateScenario("office-loop", 1));
}
BENCHMARK(BM_SimulateOfficeLoop)->Unit(benchmark::kMillisecond);

void BM_BreadcrumbPipelineOfficeLoop(benchmark::State& state) {
  const fs::path dir = BenchDir() / "mission-bc";
  const SimulatedMission sim = SimulateScenario("office-loop", 1);
  WriteMissionDirectory(dir, sim.data, &sim.plan);
  const MissionDirectory mission(dir);
  const double duration = sim.data.truth.back().t - sim.data.truth.front().t;
  for (auto _ : state) {
    RunPipeline(RequirePipeline("breadcrumb"), {mission, {}}, BenchDir() / "run-bc");
  }
  state.counters["x_real_time"] = benchmark::Counter(duration * state.iterations(),
                                                     benchmark::Counter::kIsRate);
}
BENCHMARK(BM_BreadcrumbPipelineOfficeLoop)->Unit(benchmark::kMillisecond);

// The incremental GEN localizer on a synthetic incident (arg: firefighters; 25 crumbs each,
// 30 min, ~2,000 measurements per firefighter-minute), exact online solves at every output.
void BM_BreadcrumbIncident(benchmark::State& state) {
  IncidentOptions o;
  o.agents = static_cast<int>(state.range(0));
  o.crumbs = 25 * o.agents;
  o.duration_s = 1800;
  o.measurements = static_cast<std::size_t>(o.agents) * 6000;
  const SyntheticIncident inc = MakeSyntheticIncident(o, 1);
  for (auto _ : state) {
    breadcrumb::LocalizerOptions lo;
    lo.calibrate_online = false;
    breadcrumb::BreadcrumbLocalizer loc(lo);
    for (const auto& n : inc.info.nodes) {
      if (n.kind == NodeKind::kAgent) loc.AddAgent(n.id, n.start->head<2>(), 0.1);
    }
    for (const auto& e : inc.events) {
      if (e.kind == IncidentEvent::Kind::kStep) {
        loc.AddStep(e.step);
        benchmark::DoNotOptimize(loc.Estimate(e.step.agent));
      } else if (e.kind == IncidentEvent::Kind::kRssi) {
        loc.AddRssi(e.rssi);
      } else {
        loc.AddEvent(e.drop);
      }
    }
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(inc.events.size()));
  state.counters["x_real_time"] =
      benchmark::Counter(o.duration_s * state.iterations(), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_BreadcrumbIncident)->Arg(1)->Arg(4)->Unit(benchmark::kMillisecond);

// The GEN network once it fills (arg 0: sparse LDL^T always, dense_fill_share 1; arg 1: the
// dense factor, the default 0.5): 60 crumbs ranging to each other, 8 walkers whose old states
// are marginalized at every step (the fill that links every crumb they heard), a solve and the
// walker's marginal at every step, as the localizer does with 20 firefighters.
void BM_GenNetworkFilled(benchmark::State& state) {
  for (auto _ : state) {
    breadcrumb::GenOptions go;
    go.dense_fill_share = state.range(0) == 0 ? 1.0 : 0.5;
    breadcrumb::GenNetwork gen(go);
    Random rng(7);
    constexpr int kCrumbs = 60, kWalkers = 8, kSteps = 150;
    std::vector<Vec2> crumb;
    for (int c = 0; c < kCrumbs; ++c) {
      crumb.emplace_back(rng.Uniform(0, 60), rng.Uniform(0, 30));
      gen.AddPrior(gen.AddNode(crumb.back()), crumb.back(), Mat2::Identity() * 4.0);
    }
    breadcrumb::ScalarModel range;
    std::vector<breadcrumb::NodeIndex> state_of;
    std::vector<Vec2> pos;
    for (int w = 0; w < kWalkers; ++w) {
      pos.emplace_back(rng.Uniform(0, 60), rng.Uniform(0, 30));
      state_of.push_back(gen.AddNode(pos.back()));
      gen.AddPrior(state_of.back(), pos.back(), Mat2::Identity() * 0.01);
    }
    for (int k = 0; k < kSteps; ++k) {
      for (int w = 0; w < kWalkers; ++w) {
        const Vec2 step(0.7 * std::cos(0.05 * k + w), 0.7 * std::sin(0.05 * k + w));
        pos[w] += step;
        const breadcrumb::NodeIndex next = gen.AddNode(gen.Estimate(state_of[w]) + step);
        gen.AddRelative(next, state_of[w], step, Mat2::Identity() * 0.01);
        gen.DeleteNode(state_of[w]);
        gen.MoveNode(next, state_of[w]);
        for (int h = 0; h < 3; ++h) {
          const int c = static_cast<int>(rng.Uniform(0, kCrumbs - 1e-9));
          gen.AddScalar(state_of[w], c, (pos[w] - crumb[c]).norm() + rng.Normal(0, 0.3), 0.09,
                        range);
        }
        gen.Solve();
        benchmark::DoNotOptimize(gen.Covariance(state_of[w]));
      }
    }
    state.counters["dense_factorizations"] = static_cast<double>(gen.dense_factorizations());
  }
}
BENCHMARK(BM_GenNetworkFilled)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

// The time-order buffer as a batch run drives it: 60 simultaneous RSSI packets per instant (20
// firefighters heard by 3 nodes), each pushed and the earlier instants released.
void BM_TimeOrderBuffer(benchmark::State& state) {
  std::vector<MissionRow> rows;
  for (int i = 0; i < 60000; ++i) {
    rows.emplace_back(RssiPacket{0.5 * (i / 60), "ff" + std::to_string(i % 20 + 1),
                                 "b" + std::to_string(i % 3), -60.0});
  }
  std::size_t released = 0;
  for (auto _ : state) {
    TimeOrderBuffer buffer;
    for (const MissionRow& r : rows) {
      buffer.Push(r);
      buffer.ReleaseBefore(RowTime(r), [&](const MissionRow&) { ++released; });
    }
    buffer.ReleaseAll([&](const MissionRow&) { ++released; });
  }
  benchmark::DoNotOptimize(released);
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(rows.size()));
}
BENCHMARK(BM_TimeOrderBuffer)->Unit(benchmark::kMillisecond);

// The full ZUPT INS (15-state error-state KF, adaptive SHOE detector, step output) on a
// synthetic gait at 200 Hz: samples per second.
void BM_ZuptIns(benchmark::State& state) {
  Random rng(1);
  std::vector<ImuSample> imu;
  for (int k = 0; k < 200000; ++k) {
    const double t = 0.005 * k, ph = std::fmod(t, 1.0);
    const bool swing = ph > 0.4;
    const double e = swing ? std::sin(3.14159265 * (ph - 0.4) / 0.6) : 0.0;
    imu.push_back({t, "foot",
                   Vec3(15 * e + rng.Normal(0, 0.02), rng.Normal(0, 0.02), 9.81 + 10 * e),
                   Vec3(rng.Normal(0, 0.002), 6 * e, rng.Normal(0, 0.002))});
  }
  for (auto _ : state) {
    ins::ZuptIns ins;
    std::size_t steps = 0;
    ins.on_step = [&](const Step&) { ++steps; };
    for (const auto& s : imu) ins.Add(s);
    ins.Finish();
    benchmark::DoNotOptimize(steps);
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(imu.size()));
}
BENCHMARK(BM_ZuptIns)->Unit(benchmark::kMillisecond);

// The landmark UKF at 50 Hz (prediction + acceleration update) with 5 RSSI updates every 3 s:
// one item = one 50 Hz sample.
void BM_LandmarkUkf(benchmark::State& state) {
  const radio::LogDistanceModel radio{-30, 7.1, 3};
  const std::vector<Vec2> lm = {{0, 1}, {5, -1}, {10, 1}, {15, -1}, {20, 1}};
  Random rng(2);
  std::size_t items = 0;
  for (auto _ : state) {
    landmarks::LandmarkUkf ukf(Vec2::Zero(), radio);
    for (int k = 0; k < 9000; ++k) {  // 3 minutes
      ukf.Predict(0.02);
      ukf.UpdateAcceleration(Vec2(rng.Normal(0, 0.5), rng.Normal(0, 0.5)));
      if (k % 150 == 0) {
        for (const auto& l : lm) ukf.UpdateRssi(l, Mat2::Zero(), -30 - 71 * std::log10(1 + (l - ukf.position()).norm()));
      }
    }
    benchmark::DoNotOptimize(ukf.position());
    items += 9000;
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(items));
  state.counters["x_real_time"] = benchmark::Counter(items * 0.02, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_LandmarkUkf)->Unit(benchmark::kMillisecond);

// landmarks-ukf's default tracker (landmark_tracker.h) on the simulated office of issue 24: two
// phones, 16 ceiling landmarks (6 unknown, placed by the trackers), every step and packet in time
// order through LandmarkEstimator, without file reading. x_real_time: mission seconds per wall
// second (per incident, both firefighters at once; target >= 10,000x). Arg: the motion models
// of the tracker bank (1: the typical device's tracker alone; 2: the default, tracker_bank.h).
void BM_LandmarkTrackerOffice(benchmark::State& state) {
  const SimulatedMission sim = SimulateScenario("landmark-office", 1);
  std::vector<MissionRow> rows;
  for (const Step& s : sim.data.steps) rows.emplace_back(s);
  for (const RssiPacket& p : sim.data.rssi) rows.emplace_back(p);
  std::stable_sort(rows.begin(), rows.end(),
                   [](const MissionRow& a, const MissionRow& b) { return RowTime(a) < RowTime(b); });
  const double duration = RowTime(rows.back()) - RowTime(rows.front());
  std::size_t items = 0;
  double seconds = 0;
  for (auto _ : state) {
    landmarks::LandmarkEstimatorOptions o;
    o.tracking = landmarks::Tracking::kUkf;
    o.fix_fusion = landmarks::FixFusion::kIndependent;  // continuous tracking: no stop fixes
    o.bank.models = static_cast<int>(state.range(0));
    landmarks::LandmarkEstimator estimator(sim.data.info, o);
    NullSink sink;
    for (const MissionRow& r : rows) estimator.Add(r, sink);
    estimator.Finish(sink);
    benchmark::DoNotOptimize(estimator.Current("ff1"));
    items += rows.size();
    seconds += duration;
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(items));
  state.counters["x_real_time"] = benchmark::Counter(seconds, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_LandmarkTrackerOffice)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);

// landmarks-ukf's estimator on the synthetic landmark incident of `trailmark bench landmarks`
// (issue 24): 20 firefighters under a ceiling grid of 208 landmarks, a quarter unknown, rows in
// memory (arg: minutes of the incident; the CLI runs the 4 hours). x_real_time: incident seconds
// per wall second, all 20 at once.
void BM_LandmarkIncident(benchmark::State& state) {
  LandmarkIncidentOptions o;
  o.duration_s = 60.0 * static_cast<double>(state.range(0));
  const LandmarkIncident inc = MakeLandmarkIncident(o, 1);
  double seconds = 0;
  for (auto _ : state) {
    landmarks::LandmarkEstimatorOptions e;
    e.tracking = landmarks::Tracking::kUkf;
    e.fix_fusion = landmarks::FixFusion::kIndependent;  // the pipeline's defaults
    landmarks::LandmarkEstimator estimator(inc.info, e);
    NullSink sink;
    for (const MissionRow& r : inc.rows) estimator.Add(r, sink);
    estimator.Finish(sink);
    benchmark::DoNotOptimize(estimator.Current("ff1"));
    seconds += o.duration_s;
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(inc.rows.size()));
  state.counters["x_real_time"] = benchmark::Counter(seconds, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_LandmarkIncident)->Arg(10)->Unit(benchmark::kMillisecond)->Iterations(3);

// The SCAAT EKF on the simulated lab trace e (8 min): every step and every ultrasound range and
// bearing, as the beacons-ekf pipeline feeds it, without file reading. x_real_time = mission
// seconds per wall second (issue 4: >= 10,000x).
void BM_ScaatEkfLabTrace(benchmark::State& state) {
  BeaconLabOptions o;
  o.trace = LabTrace::kE;
  const SimulatedMission sim = SimulateBeaconLab(o, 1);
  std::map<std::string, beacons::BeaconPosition> beacon;
  for (const auto& n : sim.data.info.nodes) {
    if (n.position) beacon[n.id] = {n.position->head<2>(), Mat2::Identity() * 1e-4};
  }
  struct Event {
    double t;
    int kind;  // 0 step, 1 range, 2 bearing
    std::size_t index;
  };
  std::vector<Event> events;
  for (std::size_t i = 0; i < sim.data.steps.size(); ++i) events.push_back({sim.data.steps[i].t1, 0, i});
  for (std::size_t i = 0; i < sim.data.ranges.size(); ++i) {
    if (sim.data.ranges[i].b == "ff1") events.push_back({sim.data.ranges[i].t, 1, i});
  }
  for (std::size_t i = 0; i < sim.data.bearings.size(); ++i) events.push_back({sim.data.bearings[i].t, 2, i});
  std::stable_sort(events.begin(), events.end(), [](const Event& a, const Event& b) { return a.t < b.t; });
  const double duration = sim.data.truth.back().t - sim.data.truth.front().t;
  for (auto _ : state) {
    beacons::ScaatEkf ekf(sim.data.info.nodes[0].start->head<2>());
    for (const Event& e : events) {
      if (e.kind == 0) {
        const Step& st = sim.data.steps[e.index];
        ekf.PredictStep(st.delta_n.head<2>(), Mat2::Identity() * st.variance_m2->x());
      } else if (e.kind == 1) {
        const auto& r = sim.data.ranges[e.index];
        ekf.UpdateRange(beacon[r.a], r.range_m, *r.sigma_m);
      } else {
        const auto& b = sim.data.bearings[e.index];
        ekf.UpdateBearing(beacon[b.a], b.bearing_rad, *b.sigma_rad);
      }
    }
    benchmark::DoNotOptimize(ekf.position());
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(events.size()));
  state.counters["x_real_time"] = benchmark::Counter(state.iterations() * duration, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_ScaatEkfLabTrace)->Unit(benchmark::kMillisecond);

// Shortest paths + MDS + SMACOF for n beacons on a 5 m-range trail-like layout (issue 4: 1,000
// beacons < 1 s).
/// n beacons at the lab's density (~21 in 15 x 9 m), ranges measured within 8 m (0.1 m noise).
beacons::RangeMatrix BeaconLinks(int n) {
  Random rng(7);
  const double side = std::sqrt(n * 13.5);
  std::vector<Vec2> p;
  for (int i = 0; i < n; ++i) p.emplace_back(rng.Uniform(0, side), rng.Uniform(0, side));
  beacons::RangeMatrix m(n, std::vector<std::optional<double>>(n));
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j < n; ++j) {
      const double d = (p[i] - p[j]).norm();
      if (d < 8.0) m[i][j] = m[j][i] = d + rng.Normal(0, 0.1);
    }
  }
  return m;
}

void BM_BeaconMds(benchmark::State& state) {
  const beacons::RangeMatrix m = BeaconLinks(static_cast<int>(state.range(0)));
  for (auto _ : state) {
    std::vector<std::vector<double>> full;
    beacons::FillShortestPaths(m, &full);
    benchmark::DoNotOptimize(beacons::RefineSmacof(m, beacons::ClassicalMds(full)));
  }
}
BENCHMARK(BM_BeaconMds)->Arg(21)->Arg(200)->Arg(1000)->Unit(benchmark::kMillisecond);

// The least-squares beacon map (issue 22: 1,000 beacons with 20,000 links in < 1 s): 1,000
// beacons uniform on a 66 x 66 m floor, every pair within 8 m linked (0.1 m noise: ~20,000
// links), a drop prior of 1 m on each beacon and three surveys; solved from the priors with
// marginal covariances (arg 1: ours, sparse LDL^T + Takahashi; arg 2: ceres::Covariance, the
// tests' reference) or without (arg 0). Counters: links, mean error (m).
void BM_BeaconMapLeastSquares(benchmark::State& state) {
  Random rng(11);
  const int n = 1000;
  const double side = 66.0;
  std::vector<Vec2> truth;
  for (int i = 0; i < n; ++i) truth.emplace_back(rng.Uniform(0, side), rng.Uniform(0, side));
  beacons::MapProblem problem;
  problem.beacons = n;
  for (int i = 0; i < n; ++i)
    for (int j = i + 1; j < n; ++j)
      if (const double d = (truth[i] - truth[j]).norm(); d < 8.0)
        problem.links.push_back({i, j, std::abs(d + rng.Normal(0, 0.1)), 0.1});
  std::vector<Vec2> start;
  for (int i = 0; i < n; ++i) {
    const bool surveyed = i < 3;
    const double sigma = surveyed ? 0.05 : 1.0;
    const Vec2 mu = truth[i] + sigma * Vec2(rng.Normal(), rng.Normal());
    problem.priors.push_back({i, mu, Mat2::Identity() * sigma * sigma});
    start.push_back(mu);
  }
  double error = 0;
  int ceres_iterations = 0, newton_steps = 0;
  for (auto _ : state) {
    beacons::MapLeastSquaresOptions options;
    options.covariances = state.range(0) >= 1;
    options.reference_covariance = state.range(0) == 2;
    const beacons::MapSolution s = beacons::SolveMapLeastSquares(problem, {start}, options);
    if (!s.ok) state.SkipWithError(s.why.c_str());
    ceres_iterations = s.iterations;
    newton_steps = s.newton_iterations;
    error = 0;
    for (int i = 0; i < n; ++i) error += (s.position_n[i] - truth[i]).norm() / n;
    benchmark::DoNotOptimize(s.cov.data());
  }
  state.counters["links"] = static_cast<double>(problem.links.size());
  state.counters["mean_error_m"] = error;
  state.counters["ceres_iterations"] = ceres_iterations;
  state.counters["newton_steps"] = newton_steps;
}
BENCHMARK(BM_BeaconMapLeastSquares)->Arg(0)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->Iterations(3);

// Classical MDS alone (double centring + the two leading eigenpairs) on 1,000 beacons'
// shortest-path distances: arg 0 the dense eigensolver, 1 the partial one (issue 31: < 0.2 s).
void BM_ClassicalMds(benchmark::State& state) {
  const beacons::RangeMatrix m = BeaconLinks(1000);
  std::vector<std::vector<double>> full;
  beacons::FillShortestPaths(m, &full);
  const auto solver = state.range(0) == 0 ? beacons::MdsEigensolver::kDense
                                          : beacons::MdsEigensolver::kPartial;
  for (auto _ : state) benchmark::DoNotOptimize(beacons::ClassicalMds(full, solver));
}
BENCHMARK(BM_ClassicalMds)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

// ICP closest points for one pattern comparison (issue 5, item 2: a library or our own "if
// measured faster on these tiny point sets"): 40 odometry points against a 20-node pattern.
// Ours: brute force over the pattern's segments (exact). nanoflann: a k-d tree over the
// pattern densified to 5 cm (an approximation), built per pattern as ICP needs.
std::vector<Vec2> IcpPattern() {
  std::vector<Vec2> p;
  for (int k = 0; k <= 8; ++k) p.emplace_back(k, 0);
  for (int k = 1; k <= 5; ++k) p.emplace_back(8, k);
  for (int k = 7; k >= 2; --k) p.emplace_back(k, 5);
  return p;
}
std::vector<Vec2> IcpQueries() {
  Random rng(4);
  std::vector<Vec2> q;
  for (const Vec2& p : mapmatch::ResampleByDistance(IcpPattern(), 0.5)) q.push_back(p + Vec2(rng.Normal(0, 0.3), rng.Normal(0, 0.3)));
  return q;
}
void BM_IcpOwnBruteForce(benchmark::State& state) {
  const auto target = IcpPattern();
  const auto source = IcpQueries();
  for (auto _ : state) {
    benchmark::DoNotOptimize(mapmatch::Icp(source, target, Mat2::Identity(), Vec2::Zero()));
  }
}
BENCHMARK(BM_IcpOwnBruteForce)->Unit(benchmark::kMicrosecond);

// One time update of the map particle filter (N = 500) on a house-1 search, without (0) and
// with (1) the wall-following model: what the model costs per step.
void BM_MapFilterStep(benchmark::State& state) {
  const SimulatedMission sim = SimulateHouseSearch(HouseSearchOptions(), 3);
  const auto seqs = mapmatch::ExtractSearchSequences(sim.plan, HouseEntry(1));
  const mapmatch::SearchGrid grid(sim.plan);
  mapmatch::MapParticleFilterOptions o;
  o.wall_follow = state.range(0) != 0;
  mapmatch::MapParticleFilter pf(grid, seqs, o);
  pf.InitializeUniform();
  std::size_t k = 0;
  for (auto _ : state) {
    pf.Predict(sim.data.steps[k].delta_n.head<2>());
    if (++k == sim.data.steps.size()) {  // the search again, from the start
      state.PauseTiming();
      k = 0;
      pf.InitializeUniform();
      state.ResumeTiming();
    }
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_MapFilterStep)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);

struct Cloud {
  std::vector<Vec2> pts;
  std::size_t kdtree_get_point_count() const { return pts.size(); }
  double kdtree_get_pt(std::size_t i, std::size_t d) const { return pts[i](static_cast<int>(d)); }
  template <class B>
  bool kdtree_get_bbox(B&) const { return false; }
};
void BM_IcpNanoflannTree(benchmark::State& state) {
  const auto target = IcpPattern();
  const auto source = IcpQueries();
  using Tree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, Cloud>, Cloud, 2>;
  for (auto _ : state) {
    Cloud cloud{mapmatch::ResampleByDistance(target, 0.05)};
    Tree tree(2, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
    Mat2 R = Mat2::Identity();
    Vec2 t = Vec2::Zero();
    std::vector<Vec2> from(source.size()), to(source.size());
    for (int it = 0; it < 10; ++it) {  // the iterations our ICP typically needs
      for (std::size_t k = 0; k < source.size(); ++k) {
        const Vec2 p = R * source[k] + t;
        unsigned int idx = 0;
        double d2 = 0;
        const double q[2] = {p.x(), p.y()};
        tree.knnSearch(q, 1, &idx, &d2);
        from[k] = source[k];
        to[k] = cloud.pts[idx];
      }
      const RigidFit2 fit = FitRigid(from, to, false);
      R = fit.rotation;
      t = fit.translation;
    }
    benchmark::DoNotOptimize(t);
  }
}
BENCHMARK(BM_IcpNanoflannTree)->Unit(benchmark::kMicrosecond);


// Every online estimator of the registry fed its paper's simulated experiment (the office loop
// for the others) row by row from memory, as the live server feeds it: foot IMU at 100 Hz
// instead of steps, the other streams as simulated, in time order. Rows/s of the estimator alone
// (no parsing, no journal): the capacity of one server core for that pipeline.
void BM_OnlineEstimator(benchmark::State& state, const char* name) {
  const PipelineSpec& spec = RequirePipeline(name);
  SimulatedMission sim = spec.paper_scenarios.empty()
                             ? SimulateScenario("office-loop", 1)
                             : SimulateScenario(spec.paper_scenarios.front(), 1);
  ImuSimOptions imu;
  imu.rate_hz = 100;
  AddFootImu(sim, imu, 1);
  std::vector<MissionRow> rows;
  for (const auto& r : sim.data.events) rows.emplace_back(r);
  for (const auto& r : sim.data.ranges) rows.emplace_back(r);
  for (const auto& r : sim.data.bearings) rows.emplace_back(r);
  for (const auto& r : sim.data.rssi) rows.emplace_back(r);
  for (const auto& r : sim.data.imu) rows.emplace_back(r);
  std::stable_sort(rows.begin(), rows.end(), [](const MissionRow& a, const MissionRow& b) {
    return RowTime(a) < RowTime(b);
  });
  const double mission_s = RowTime(rows.back()) - RowTime(rows.front());
  for (auto _ : state) {
    auto estimator = spec.make({sim.data.info, &sim.plan}, {}, Feed::kLive);
    NullSink sink;
    for (const MissionRow& r : rows) estimator->Add(r, sink);
    benchmark::DoNotOptimize(estimator->Summary());
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(rows.size()));
  state.counters["x_real_time"] = benchmark::Counter(
      mission_s * static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}
BENCHMARK_CAPTURE(BM_OnlineEstimator, pdr, "pdr")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_OnlineEstimator, ins, "ins")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_OnlineEstimator, breadcrumb, "breadcrumb")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_OnlineEstimator, landmarks_stopgo, "landmarks-stopgo")
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_OnlineEstimator, landmarks_ukf, "landmarks-ukf")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_OnlineEstimator, beacons_mds, "beacons-mds")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_OnlineEstimator, beacons_ekf, "beacons-ekf")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_OnlineEstimator, mapmatch, "mapmatch")->Unit(benchmark::kMillisecond);

// Issue 30, item 5: the breadcrumb estimator on the office loop (steps, RSSI) with N extra
// surveyed landmarks declared in mission.json that no packet ever names (a building's whole
// landmark list): the cost must follow the nodes used. Before, 3,000 declared took 1.7 s and
// 10,000 timed out.
void BM_BreadcrumbDeclaredNodes(benchmark::State& state) {
  SimulatedMission sim = SimulateScenario("office-loop-1lap", 1);
  for (int k = 0; k < state.range(0); ++k) {
    NodeInfo n;
    n.id = "lm" + std::to_string(k);
    n.kind = NodeKind::kLandmark;
    n.position = Vec3(0.5 * (k % 200), 0.5 * (k / 200), 0);
    n.position_sigma_m = 0.1;
    sim.data.info.nodes.push_back(n);
  }
  std::vector<MissionRow> rows;
  for (const auto& r : sim.data.events) rows.emplace_back(r);
  for (const auto& r : sim.data.rssi) rows.emplace_back(r);
  for (const auto& r : sim.data.steps) rows.emplace_back(r);
  std::stable_sort(rows.begin(), rows.end(), [](const MissionRow& a, const MissionRow& b) {
    return RowTime(a) < RowTime(b);
  });
  const PipelineSpec& spec = RequirePipeline("breadcrumb");
  for (auto _ : state) {
    auto estimator = spec.make({sim.data.info, &sim.plan}, {}, Feed::kLive);
    NullSink sink;
    for (const MissionRow& r : rows) estimator->Add(r, sink);
    estimator->Finish(sink);
    benchmark::DoNotOptimize(estimator->Summary());
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(rows.size()));
}
BENCHMARK(BM_BreadcrumbDeclaredNodes)->Arg(0)->Arg(3000)->Arg(10000)->Unit(benchmark::kMillisecond);

// The live server's journal (server/journal.h): group commits of `batches` requests of 10 foot
// IMU rows each from 20 devices, as `bench load` sends them; rows/s and time per commit include
// the disk flushes (WAL and high-water mark) of the machine's temporary directory.
void BM_JournalAppendGroup(benchmark::State& state) {
  const auto batches = static_cast<std::size_t>(state.range(0));
  const fs::path file = BenchDir() / "journal.sqlite";
  fs::remove(file);
  fs::remove(fs::path(file.string() + "-wal"));
  fs::remove(fs::path(file.string() + "-shm"));
  fs::remove(fs::path(file.string() + ".acked"));
  server::Journal journal(file);
  std::vector<server::Journal::Batch> group(batches);
  double t = 0.0;
  std::int64_t rows = 0;
  for (auto _ : state) {
    state.PauseTiming();  // the rows are made outside the measured time
    std::vector<const server::Journal::Batch*> pointers;
    for (std::size_t b = 0; b < batches; ++b) {
      auto& batch = group[b];
      batch = {};
      batch.stream = "imu.csv";
      batch.header = "t,node,ax,ay,az,gx,gy,gz";
      const std::string node = "ff" + std::to_string(b % 20 + 1);
      for (int i = 0; i < 10; ++i) {
        const double ti = t + 0.01 * i;
        char row[160];
        std::snprintf(row, sizeof row, "%.2f,%s,%.6f,%.6f,%.6f,%.6f,%.6f,%.6f", ti, node.c_str(),
                      0.1 * std::sin(ti), 0.2 * std::cos(ti), -9.81 + 0.01 * i, 0.01 * i,
                      0.02 * std::sin(3 * ti), 0.03);
        batch.rows.emplace_back(row);
        batch.t.push_back(ti);
        batch.node.push_back(node);
        batch.lines.push_back(static_cast<std::size_t>(i) + 2);
      }
      pointers.push_back(&batch);
      if (b % 20 == 19) t += 0.1;
    }
    t += 0.1;
    state.ResumeTiming();
    const auto results = journal.AppendGroup(pointers);
    for (const auto& r : results) rows += static_cast<std::int64_t>(r.accepted);
  }
  state.SetItemsProcessed(rows);
}
BENCHMARK(BM_JournalAppendGroup)->Arg(1)->Arg(10)->Arg(40)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();

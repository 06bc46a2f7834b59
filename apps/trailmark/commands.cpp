// SPDX-License-Identifier: MIT
#include "commands.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <numbers>
#include <set>
#include <sstream>

#include "experiments/experiments.h"
#include "progress.h"
#include "trailmark/core/error.h"
#include "trailmark/eval/metrics.h"
#include "trailmark/ins/height.h"
#include "trailmark/io/csv.h"
#include "trailmark/io/geo.h"
#include "trailmark/io/metrics_io.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/io/trajectory_formats.h"
#include "trailmark/mapmatch/search_map.h"
#include "trailmark/report/html_report.h"
#include "trailmark/sim/house_search.h"
#include "trailmark/sim/imu_sim.h"
#include "trailmark/sim/scenarios.h"
#include "trailmark/sim/variation.h"

namespace trailmark::cli {

namespace fs = std::filesystem;

namespace {

// The `search` scenario: one floor of the user's plan, a directional search from the entry.
SimulatedMission SimulateSearchOnFile(const SimulateSearchArgs& a, std::uint64_t seed) {
  if (a.floorplan.empty() || a.entry.empty())
    throw std::invalid_argument("simulate search needs --floorplan FILE and --entry X,Y");
  std::vector<int> levels;
  const FloorPlan floor = ReadFloorPlanFloor(a.floorplan, a.level, &levels);
  const int level = a.level.value_or(DefaultFloorPlanLevel(levels));
  // The mission's plan is that one floor (its rooms on level 0 with the walls, so that the
  // mission's floor plan has one level).
  std::vector<Room> rooms = floor.rooms();
  for (auto& r : rooms) r.level = 0;
  const FloorPlan plan(floor.walls(), floor.doors(), std::move(rooms));
  Vec2 entry;
  char comma = 0;
  std::istringstream in(a.entry);
  if (!(in >> entry.x() >> comma >> entry.y()) || comma != ',' || !(in >> std::ws).eof())
    throw std::invalid_argument("--entry must be X,Y in metres, not '" + a.entry + "'");
  HouseSearchOptions o;
  if (a.hand == "left")
    o.hand = Hand::kLeft;
  else if (a.hand == "right")
    o.hand = Hand::kRight;
  else
    throw std::invalid_argument("--hand must be left or right, not '" + a.hand + "'");
  o.duration_s = a.minutes.value_or(10.0) * 60;
  std::optional<double> heading;
  if (a.heading_deg) heading = *a.heading_deg * std::numbers::pi / 180;
  SimulatedMission sim = SimulateSearchOnPlan(plan, entry, heading, o, seed);
  if (levels.size() > 1)
    sim.data.info.description += fmt::format("; level {} of {}", level, a.floorplan);
  return sim;
}

}  // namespace

void Simulate(const std::string& scenario, std::uint64_t seed, const fs::path& out,
              const SimulateImu& imu, const SimulateSearchArgs& search, const SimulateVary& vary) {
  const VariationFamily family = ParseVariationFamily(vary.family);
  if (!vary.k && vary.family != "all")
    throw std::invalid_argument("--family needs --vary K (the variant to draw)");
  if (scenario != "search" && search.Given())
    throw std::invalid_argument(
        "--floorplan, --level, --entry, --heading and --hand are for the 'search' scenario");
  if (search.minutes && scenario != "search" && scenario != "all-sources-4h")
    throw std::invalid_argument("--minutes is for the 'search' and 'all-sources-4h' scenarios");
  if (search.firefighters && scenario != "all-sources-4h")
    throw std::invalid_argument("--firefighters is for the 'all-sources-4h' scenario");
  SimulatedMission sim = scenario == "search" ? SimulateSearchOnFile(search, seed)
                         : scenario == "all-sources-4h"
                             ? SimulateAllSourcesLoad(seed, search.firefighters.value_or(20),
                                                      search.minutes.value_or(240.0) * 60)
                             : SimulateScenario(scenario, seed);
  if (imu.rate_hz > 0) {
    sim.data.imu.clear();  // a scenario's own foot IMU gives way to the one asked for
    ImuSimOptions o;
    o.rate_hz = imu.rate_hz;
    o.grade = ImuGrade::ByName(imu.grade);
    if (imu.motion == "walk")
      o.motion = FootMotion::kWalk;
    else if (imu.motion == "crawl")
      o.motion = FootMotion::kCrawl;
    else if (imu.motion == "stairs")
      o.motion = FootMotion::kStairs;
    else
      throw std::invalid_argument("unknown --imu-motion '" + imu.motion +
                                  "' (walk, crawl, stairs)");
    AddFootImu(sim, o, seed ^ 0x1e1e1e1eULL);
    sim.data.info.description += ". Foot IMU at " + fmt::format("{:g}", imu.rate_hz) + " Hz, " +
                                 o.grade.name + " grade, " + imu.motion + ".";
    if (imu.drop_steps) sim.data.steps.clear();
    if (imu.mount) {
      std::vector<double> deg;
      std::stringstream in(*imu.mount);
      for (std::string part; std::getline(in, part, ',');) {
        std::size_t used = 0;
        double value = 0;
        try {
          value = std::stod(part, &used);
        } catch (const std::exception&) {
          used = 0;
        }
        if (used == 0 || used != part.size() || !std::isfinite(value))
          throw std::invalid_argument("--imu-mount: '" + part +
                                      "' is not a number (YAW[,ROLL[,PITCH]] in degrees)");
        deg.push_back(value);
      }
      if (deg.empty() || deg.size() > 3)
        throw std::invalid_argument("--imu-mount takes YAW[,ROLL[,PITCH]] in degrees, not '" +
                                    *imu.mount + "'");
      deg.resize(3, 0.0);
      const double rad = std::numbers::pi / 180;
      MountImu(sim.data.imu, ImuMounting(deg[0] * rad, deg[1] * rad, deg[2] * rad));
      sim.data.info.description += fmt::format(
          " Mounted turned {:g} deg, roll {:g} deg, pitch {:g} deg.", deg[0], deg[1], deg[2]);
    }
  } else if (imu.mount) {
    throw std::invalid_argument("--imu-mount needs --imu-rate (a foot IMU to mount)");
  }
  MissionWriteStyle style;
  if (vary.k) {
    // Last, after every sensor: the variant moves what was simulated, never the reverse.
    const Variation v = DrawVariation(family, *vary.k);
    const std::vector<std::string> notes = ApplyVariation(v, sim);
    style = v.write;
    sim.data.info.description += fmt::format(". Variant {} of family {}.", *vary.k, vary.family);
    if (sim.levels.empty()) {
      WriteMissionDirectory(out, sim.data, &sim.plan, style);
    } else {
      WriteMissionDirectory(out, sim.data, sim.levels, style);  // every level, drawn alike
    }
    experiments::WriteVariationJson(out / "variation.json", scenario, seed, v, notes);
    for (const auto& [key, value] : v.Describe()) fmt::print("  {:<26} {}\n", key, value);
  } else if (sim.levels.empty()) {
    // A scenario without a building (the synthetic incident) has no floor plan to write.
    const bool has_plan = !sim.plan.walls().empty();
    WriteMissionDirectory(out, sim.data, has_plan ? &sim.plan : nullptr);
  } else {
    WriteMissionDirectory(out, sim.data, sim.levels);  // every level in one file
  }
  const auto& d = sim.data;
  std::size_t crumbs = 0;
  for (const auto& e : d.events) crumbs += e.event == "drop";
  fmt::print(
      "simulated '{}' (seed {}) into {}: {} steps, {} IMU samples, {} RSSI packets, {} "
      "crumbs dropped, {} truth rows, {:.0f} s\n",
      scenario, seed, out.string(), d.steps.size(), d.imu.size(), d.rssi.size(), crumbs,
      d.truth.size(), d.truth.empty() ? 0.0 : d.truth.back().t - d.truth.front().t);
}

RunResult Run(const std::string& name, const fs::path& mission_dir, const fs::path& out,
              const std::map<std::string, std::string>& options) {
  const PipelineSpec& pipeline = RequirePipeline(name);
  const MissionDirectory mission(mission_dir);
  RequireCanRun(pipeline, mission);
  ProgressBar bar("run " + name);
  PipelineContext context{mission, options, [&](double f) { bar.Update(f); }};
  RunResult result = RunPipeline(pipeline, context, out);
  bar.Finish();
  if (result.estimates == 0) {
    fmt::print(stderr,
               "warning: {} wrote no estimates for {} (diagnostics.json's notes may say why)\n",
               name, mission_dir.string());
  }
  return result;
}

GeoOrigin ParseGeoOrigin(const std::string& text) {
  std::vector<double> v;
  std::size_t start = 0;
  while (start <= text.size()) {
    const std::size_t comma = text.find(',', start);
    const auto x = ParseFiniteDouble(text.substr(start, comma == std::string::npos ? comma : comma - start));
    if (!x) break;
    v.push_back(*x);
    if (comma == std::string::npos) {
      start = text.size() + 1;
      break;
    }
    start = comma + 1;
  }
  if (start != text.size() + 1 || v.size() < 2 || v.size() > 3 || !IsGeodetic(v[0], v[1])) {
    throw std::invalid_argument("--origin '" + text +
                                "': expected LAT,LON[,HEIGHT] (WGS 84 degrees, metres)");
  }
  return GeoOrigin{v[0], v[1], v.size() == 3 ? v[2] : 0.0};
}

void ExportFloorPlanWgs84(const fs::path& mission_dir, const fs::path& out) {
  const MissionDirectory mission(mission_dir);
  const std::string json = mission.Path("mission.json").string();
  if (!mission.info().floorplan) throw InputError(json, 0, "no \"floorplan\" to export");
  if (!mission.info().geo_origin) {
    throw InputError(json, 0,
                     "no \"geo_origin\": where the frame lies on the Earth is not known (the "
                     "converters of geographic data write it)");
  }
  mission.Require(*mission.info().floorplan, "export geojson-wgs84");
  const fs::path plan = mission.Path(*mission.info().floorplan);
  std::ifstream in(plan, std::ios::binary);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::ofstream f(out, std::ios::binary);
  f << FloorPlanToWgs84GeoJson(text, plan.string(), *mission.info().geo_origin);
  if (!f) throw std::runtime_error(out.string() + ": write failed");
}

namespace {
// Where the search patterns start: the first agent with a start (horizontal), if any.
std::optional<Vec2> FirstAgentStart(const MissionInfo& info) {
  for (const auto& n : info.nodes) {
    if (n.kind != NodeKind::kAgent) continue;
    if (const auto start = info.AgentStart(n)) return start->head<2>();
  }
  return std::nullopt;
}

// A grid axis in degrees for people: to 0.1 deg, and a rounding error below 0 reads as 0.
double AxisDegrees(double rad) {
  const double deg = std::round(rad * 1800.0 / std::numbers::pi) / 10.0;
  return deg == 0.0 ? 0.0 : deg;
}
}  // namespace

int WriteSearchPatterns(const fs::path& mission_dir, const fs::path& out, std::optional<int> level,
                        double grid_m, bool map_axes) {
  const MissionDirectory mission(mission_dir);
  const std::string json_path = mission.Path("mission.json").string();
  const std::optional<FloorPlan> plan = mission.LoadFloorPlan(level);
  if (!plan) throw InputError(json_path, 0, "no \"floorplan\" to search");
  std::optional<Vec2> entry = FirstAgentStart(mission.info());
  mapmatch::SearchSequenceOptions options;
  options.grid.spacing_m = grid_m;
  options.grid.align_to_walls = !map_axes;
  std::string why;
  if (!options.grid.IsValid(&why)) throw std::invalid_argument("--grid-m: " + why);
  const std::string plan_source = mission.Path(*mission.info().floorplan).string();
  mapmatch::SearchPatterns patterns;
  try {
    patterns = mapmatch::BuildSearchPatterns(*plan, entry, options);
  } catch (const std::invalid_argument& e) {
    throw InputError(plan_source, 0, e.what());
  }
  const std::vector<mapmatch::NodeSequence>& sequences = patterns.sequences;
  const std::vector<std::size_t>& missed = patterns.doors_not_traversed;
  const bool corner = patterns.entry_is_corner;
  entry = patterns.entry_n;
  nlohmann::json doc = nlohmann::json::parse(FloorPlanToGeoJson(*plan));
  auto position = [](const Vec2& p) { return nlohmann::json::array({p.x(), p.y()}); };
  std::size_t nodes = 0;
  for (std::size_t k = 0; k < sequences.size(); ++k) {
    nlohmann::json line = nlohmann::json::array();
    for (const Vec2& p : sequences[k].nodes) line.push_back(position(p));
    if (!sequences[k].nodes.empty()) line.push_back(position(sequences[k].nodes.front()));
    nodes += sequences[k].nodes.size();
    doc["features"].push_back({{"type", "Feature"},
                               {"properties",
                                {{"kind", "search_sequence"},
                                 {"index", k},
                                 {"around_inner_walls", sequences[k].around_inner_walls}}},
                               {"geometry", {{"type", "LineString"}, {"coordinates", line}}}});
  }
  nlohmann::json inside = nlohmann::json::array();
  for (const Vec2& c : patterns.inside_n) inside.push_back(position(c));
  doc["features"].push_back({{"type", "Feature"},
                             {"properties", {{"kind", "inside_nodes"}}},
                             {"geometry", {{"type", "MultiPoint"}, {"coordinates", inside}}}});
  std::string missed_text;
  for (const std::size_t d : missed) {
    const Segment2& door = plan->doors()[d];
    doc["features"].push_back(
        {{"type", "Feature"},
         {"properties", {{"kind", "door_not_traversed"}, {"door", d}}},
         {"geometry",
          {{"type", "LineString"},
           {"coordinates", nlohmann::json::array({position(door.a), position(door.b)})}}}});
    if (missed_text.size() < 200) {
      missed_text +=
          fmt::format("{}door {} at ({:.2f}, {:.2f})", missed_text.empty() ? "" : ", ", d,
                      0.5 * (door.a.x() + door.b.x()), 0.5 * (door.a.y() + door.b.y()));
    }
  }
  const double axis_deg = AxisDegrees(patterns.grid_axis_rad);
  doc["trailmark_search_map"] = {{"grid_spacing_m", grid_m},
                                 {"grid_axis_deg", axis_deg},
                                 {"entry", position(*entry)},
                                 {"sequences", sequences.size()},
                                 {"doors_not_traversed", missed.size()}};
  std::ofstream f(out, std::ios::binary);
  f << doc.dump() << "\n";
  if (!f) throw std::runtime_error(out.string() + ": write failed");
  fmt::print(
      "{} search sequences ({} nodes), inside {:.0f} m^2 on a {:g} m grid at {:.1f} deg "
      "({}), from ({:.2f}, {:.2f}){}\n",
      sequences.size(), nodes, static_cast<double>(patterns.inside_n.size()) * grid_m * grid_m,
      grid_m, axis_deg, map_axes ? "the map's axes" : "along the walls", entry->x(), entry->y(),
      corner ? " (no agent start: the inside node nearest the plan's corner)" : "");
  fmt::print("inner doors no sequence passes: {}\n",
             missed.empty()
                 ? std::string("none")
                 : fmt::format("{} of {}: {}", missed.size(), plan->doors().size(), missed_text));
  fmt::print("written: {}\n", out.string());
  return missed.empty() ? 0 : 3;
}

std::size_t ExportTum(const fs::path& source, const std::string& id, const fs::path& out) {
  // estimates.csv has the covariance columns; truth.csv does not.
  bool estimates = false;
  {
    CsvReader header(source.string());
    estimates = header.Column("sxx") >= 0;
  }
  std::string text;
  std::set<std::string> ids;
  auto collect = [&](const auto& rows) {
    for (const auto& r : rows) ids.insert(r.id);
    text = TumTrajectory(rows, id);
  };
  if (estimates) {
    collect(ReadAll<Estimate>(source.string()));
  } else {
    collect(ReadAll<TruthSample>(source.string()));
  }
  if (ids.count(id) == 0) {
    throw InputError(source.string(), 0,
                     fmt::format("no rows of '{}' (ids: {})", id, fmt::join(ids, ", ")));
  }
  std::ofstream f(out, std::ios::binary);
  f << text;
  if (!f) throw std::runtime_error(out.string() + ": write failed");
  return static_cast<std::size_t>(std::count(text.begin(), text.end(), '\n')) - 1;
}

Metrics Eval(const fs::path& mission_dir, const fs::path& estimates_path,
             const fs::path& metrics_out, bool print) {
  const MissionDirectory mission(mission_dir);
  mission.Require("truth.csv", "evaluation");
  const auto truth = ReadAll<TruthSample>(mission.Path("truth.csv").string(), &mission.registry());
  const auto estimates = ReadAll<Estimate>(estimates_path.string(), &mission.registry());
  const Metrics metrics = Evaluate(mission.info(), truth, estimates);
  WriteMetricsJson(metrics_out, metrics);
  if (print) {
    // in95 %: truth inside the ellipse of the estimate in force at each truth instant; own %: at
    // each estimate's own instant (metrics.h).
    fmt::print("{:<10} {:<8} {:>7} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>9} {:>6} {:>6}\n",
               "node", "kind", "samples", "mean m", "median", "p95 m", "max m", "final m",
               "dist m", "mean %dist", "in95 %", "own %");
    // A share as a whole percentage; "-" where it is not known (no covariance given).
    auto Percent = [](double share) {
      return std::isfinite(share) ? fmt::format("{:.0f}", 100.0 * share) : std::string("-");
    };
    auto row = [&Percent](const NodeMetrics& m) {
      // A node never scored (no estimate, or no truth at its estimates' times) has no error.
      const bool scored = m.stats.samples > 0;
      auto metres = [scored](double v) { return scored ? fmt::format("{:.2f}", v) : "-"; };
      fmt::print("{:<10} {:<8} {:>7} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8.1f} {:>9} {:>6} {:>6}\n",
                 m.id, ToString(m.kind), m.stats.samples, metres(m.stats.mean_m),
                 metres(m.stats.median_m), metres(m.stats.p95_m), metres(m.stats.max_m),
                 metres(m.stats.final_m), m.distance_m,
                 m.mean_pct_of_distance ? fmt::format("{:.2f}", *m.mean_pct_of_distance) : "-",
                 scored ? Percent(m.stats.in95) : std::string("-"),
                 m.at_estimates.samples > 0 ? Percent(m.at_estimates.in95) : std::string("-"));
    };
    for (const auto& m : metrics.nodes) row(m);
    row(metrics.agents);
    if (metrics.static_nodes.stats.samples > 0) row(metrics.static_nodes);
    if (metrics.floors) {
      const FloorMetrics& f = *metrics.floors;
      std::string by_agent;
      for (const auto& [id, rate] : f.hit_rate_by_agent) {
        by_agent += fmt::format("{}{} {:.1f} %", by_agent.empty() ? "" : ", ", id, 100 * rate);
      }
      const std::string vertical =
          f.vertical_checked > 0
              ? fmt::format(", vertical in95 {:.0f} % (NEES {:.2f})", 100 * f.vertical_in95,
                            f.vertical_mean_nees)
              : std::string();
      fmt::print(
          "floors: right floor {:.1f} % ({}), CE95 {:.2f} m, VE95 {:.2f} m, SE95 {:.2f} m, "
          "vertical mean {:.2f} m, IPIN score {:.2f} m{}\n",
          100 * f.floor_hit_rate, by_agent, f.ce95_m, f.ve95_m, f.se95_m, f.vertical_mean_m,
          f.ipin_score_m, vertical);
    }
    fmt::print("metrics written to {}\n", metrics_out.string());
  }
  return metrics;
}

namespace {

fs::path MissionOfRun(const fs::path& run_dir) {
  std::ifstream in(run_dir / "diagnostics.json");
  if (!in)
    throw InputError((run_dir / "diagnostics.json").string(), 0,
                     "missing: pass --mission or a directory written by 'trailmark run'");
  nlohmann::json j;
  try {
    in >> j;
  } catch (const std::exception& e) {
    throw InputError((run_dir / "diagnostics.json").string(), 0, e.what());
  }
  return fs::path(j.value("mission", std::string()));
}

std::string PipelineOfRun(const fs::path& run_dir) {
  std::ifstream in(run_dir / "diagnostics.json");
  nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
  if (j.is_object() && j.contains("pipeline")) return j["pipeline"].get<std::string>();
  return run_dir.filename().string();
}

double WallTimeOfRun(const fs::path& run_dir) {
  std::ifstream in(run_dir / "diagnostics.json");
  nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
  if (j.is_object() && j.contains("wall_time_s")) return j["wall_time_s"].get<double>();
  return 0.0;
}

// A run's pipeline (from the registry) and the options it ran with, from its diagnostics.json;
// nullopt when either is missing.
std::optional<std::pair<const PipelineSpec*, OptionValues>> SpecOfRun(const fs::path& run_dir) {
  std::ifstream in(run_dir / "diagnostics.json");
  nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
  if (!j.is_object() || !j.contains("options") || !j["options"].is_object()) return std::nullopt;
  const PipelineSpec* pipeline = FindPipeline(j.value("pipeline", std::string()));
  if (pipeline == nullptr) return std::nullopt;
  OptionValues options;
  for (const auto& [k, v] : j["options"].items()) {
    if (v.is_string()) options[k] = v.get<std::string>();
  }
  return std::make_pair(pipeline, std::move(options));
}

// The floor a run of a floor-plan pipeline was matched on (its `level` option), for the report
// to draw; nullopt for other pipelines or the default floor.
std::optional<int> LevelOfRun(const fs::path& run_dir) {
  const auto run = SpecOfRun(run_dir);
  if (!run || !run->first->needs_floor_plan) return std::nullopt;
  return run->first->floor_level(run->second);
}

// The search patterns of the first map-matching run (its grid options), from the first agent's
// start, as report layers: the sequences, the inside grid nodes (both hidden until ticked) and
// the inner doors no sequence passes (shown). Empty (with a note) when they cannot be built.
std::vector<ReportLayer> SearchPatternLayers(const std::vector<fs::path>& run_dirs,
                                             const MissionInfo& info, const FloorPlan& plan) {
  for (const auto& dir : run_dirs) {
    const auto run = SpecOfRun(dir);
    if (!run || !run->first->search_patterns) continue;
    const std::optional<Vec2> entry = FirstAgentStart(info);
    mapmatch::SearchPatterns patterns;
    try {
      patterns =
          mapmatch::BuildSearchPatterns(plan, entry, run->first->search_patterns(run->second));
    } catch (const std::invalid_argument& e) {
      fmt::print(stderr, "report: the search patterns are not drawn: {}\n", e.what());
      return {};
    }
    std::vector<ReportLayer> layers(3);
    layers[0].label =
        fmt::format("search sequences ({}, {} m grid at {:.1f} deg)", run->first->name,
                    patterns.grid_spacing_m, AxisDegrees(patterns.grid_axis_rad));
    layers[0].colour = "#2e8b57";
    for (const auto& s : patterns.sequences) {
      std::vector<Vec2> line = s.nodes;
      if (!line.empty()) line.push_back(line.front());
      layers[0].lines.push_back(std::move(line));
    }
    layers[1].label = "search grid: inside nodes";
    layers[1].colour = "#9acd32";
    layers[1].points = patterns.inside_n;
    layers[2].label =
        fmt::format("doors no search sequence passes ({})", patterns.doors_not_traversed.size());
    layers[2].colour = "#d62728";
    layers[2].dashed = true;
    layers[2].visible = true;
    for (const std::size_t d : patterns.doors_not_traversed) {
      layers[2].lines.push_back({plan.doors()[d].a, plan.doors()[d].b});
    }
    if (layers[2].lines.empty()) layers.pop_back();
    return layers;
  }
  return {};
}

}  // namespace

void Report(const std::vector<fs::path>& run_dirs, const fs::path& mission_arg,
            const fs::path& out) {
  if (run_dirs.empty()) throw std::invalid_argument("report: give at least one run directory");
  const fs::path mission_dir = mission_arg.empty() ? MissionOfRun(run_dirs.front()) : mission_arg;
  const MissionDirectory mission(mission_dir);
  ReportInput input;
  input.info = mission.info();
  // The floor the first mapmatch run with a `level` was matched on, else the default floor.
  std::optional<int> level;
  for (const auto& run : run_dirs) {
    if ((level = LevelOfRun(run))) break;
  }
  input.plan = mission.LoadFloorPlan(level);
  if (input.plan) input.layers = SearchPatternLayers(run_dirs, input.info, *input.plan);
  if (mission.Has("truth.csv")) {
    input.truth = ReadAll<TruthSample>(mission.Path("truth.csv").string(), &mission.registry());
  }
  for (const auto& dir : run_dirs) {
    ReportRun run;
    run.pipeline = PipelineOfRun(dir);
    run.wall_time_s = WallTimeOfRun(dir);
    run.estimates = ReadAll<Estimate>((dir / "estimates.csv").string(), &mission.registry());
    run.metrics = Evaluate(input.info, input.truth, run.estimates);
    input.runs.push_back(std::move(run));
  }
  std::ofstream(out, std::ios::binary) << BuildHtmlReport(input);
  fmt::print("report written to {}\n", out.string());
}

void PrintSummaryTable(const std::vector<std::pair<RunResult, Metrics>>& rows,
                       const std::vector<std::string>& missions) {
  std::size_t width = 14;  // the pipeline column fits the longest name (landmarks-stopgo)
  for (const auto& [run, m] : rows) width = std::max(width, run.pipeline.size());
  fmt::print("\n{:<18} {:<{}} {:>8} {:>8} {:>8} {:>8} {:>10} {:>10} {:>11} {:>7} {:>10}\n",
             "mission", "pipeline", width, "mean m", "p95 m", "max m", "final m", "mean %dist",
             "max %dist", "static m", "in95 %", "run time s");
  for (std::size_t k = 0; k < rows.size(); ++k) {
    const auto& [run, m] = rows[k];
    const auto& a = m.agents;
    const bool agents = a.stats.samples > 0;
    auto num = [&](double v) { return agents ? fmt::format("{:.2f}", v) : std::string("-"); };
    fmt::print(
        "{:<18} {:<{}} {:>8} {:>8} {:>8} {:>8} {:>10} {:>10} {:>11} {:>7} {:>10.3f}\n",
        k < missions.size() ? missions[k] : "", run.pipeline, width, num(a.stats.mean_m),
        num(a.stats.p95_m), num(a.stats.max_m), num(a.stats.final_m),
        a.mean_pct_of_distance ? fmt::format("{:.2f}", *a.mean_pct_of_distance) : "-",
        a.max_pct_of_distance ? fmt::format("{:.2f}", *a.max_pct_of_distance) : "-",
        m.static_nodes.stats.samples > 0 ? fmt::format("{:.2f}", m.static_nodes.stats.mean_m) : "-",
        agents ? fmt::format("{:.0f}", 100.0 * a.stats.in95) : std::string("-"), run.wall_time_s);
  }
}

namespace {

template <class Row>
void ValidateStream(const MissionDirectory& mission, double (*time)(const Row&)) {
  if (!mission.HasStream<Row>()) return;
  auto reader = mission.OpenStream<Row>();
  Row row;
  double first = 0, last = 0;
  while (reader.Next(row)) {
    if (reader.rows() == 1) first = time(row);
    last = time(row);
  }
  fmt::print("{:<14} {:>10} rows  t {:.3f} .. {:.3f}\n", StreamFileName<Row>(), reader.rows(),
             first, last);
}

}  // namespace

void Validate(const fs::path& mission_dir) {
  const MissionDirectory mission(mission_dir);
  fmt::print("mission.json   {} nodes, {} crumbs dropped in events.csv\n",
             mission.info().nodes.size(), mission.dropped_crumbs().size());
  ValidateStream<ImuSample>(mission, [](const ImuSample& r) { return r.t; });
  ValidateStream<Step>(mission, [](const Step& r) { return r.t1; });
  ValidateStream<RssiPacket>(mission, [](const RssiPacket& r) { return r.t; });
  ValidateStream<RangeMeasurement>(mission, [](const RangeMeasurement& r) { return r.t; });
  ValidateStream<BearingMeasurement>(mission, [](const BearingMeasurement& r) { return r.t; });
  ValidateStream<MissionEvent>(mission, [](const MissionEvent& r) { return r.t; });
  ValidateStream<BaroSample>(mission, [](const BaroSample& r) { return r.t; });
  ValidateStream<TruthSample>(mission, [](const TruthSample& r) { return r.t; });
  // The 1.1 additions: the building's levels, each barometer's range, the truth's levels.
  if (!mission.info().floors.empty()) {
    std::string list;
    for (const FloorLevel& f : mission.info().floors) {
      list += fmt::format("{}{} at {:.2f} m", list.empty() ? "" : ", ", f.level, f.elevation_m);
    }
    fmt::print("{:<14} {} levels: {}\n", "floors", mission.info().floors.size(), list);
  }
  if (mission.HasStream<BaroSample>()) {
    // Each barometer's range without its spikes: the 1st to 99th percentile of its readings,
    // and the extremes beside them.
    std::map<std::string, std::vector<double>> readings;
    auto reader = mission.OpenStream<BaroSample>();
    for (BaroSample b; reader.Next(b);) readings[b.agent].push_back(b.pressure_hpa);
    for (auto& [agent, v] : readings) {
      const double lo = Percentile(v, 1), hi = Percentile(v, 99);
      const auto [mn, mx] = std::minmax_element(v.begin(), v.end());
      fmt::print("{:<14} {}: {:.2f} .. {:.2f} hPa (1st-99th percentile; {:.1f} m of pressure "
                 "altitude), extremes {:.2f} .. {:.2f} hPa\n",
                 "barometer", agent, lo, hi, PressureAltitudeM(lo) - PressureAltitudeM(hi), *mn,
                 *mx);
    }
  }
  if (mission.HasStream<TruthSample>()) {
    std::set<int> truth_levels;
    auto reader = mission.OpenStream<TruthSample>();
    for (TruthSample s; reader.Next(s);) {
      if (s.floor) truth_levels.insert(*s.floor);
    }
    if (!truth_levels.empty()) {
      fmt::print("{:<14} levels in truth: {}\n", "truth.csv", fmt::join(truth_levels, ", "));
    }
  }
  std::vector<int> levels;
  if (const auto plan = mission.LoadFloorPlan(std::nullopt, &levels)) {
    if (levels.size() > 1) {
      // One line per floor: a single-floor pipeline uses one of them (mapmatch: level=N).
      for (const int level : levels) {
        const auto floor = mission.LoadFloorPlan(level);
        fmt::print("{:<14} level {}: {} walls, {} doors, {} rooms{}\n", *mission.info().floorplan,
                   level, floor->walls().size(), floor->doors().size(), floor->rooms().size(),
                   level == DefaultFloorPlanLevel(levels) ? " (the default floor)" : "");
      }
    } else {
      fmt::print("{:<14} {} walls, {} doors, {} rooms\n", *mission.info().floorplan,
                 plan->walls().size(), plan->doors().size(), plan->rooms().size());
    }
  }
  fmt::print("valid; runnable pipelines:");
  for (const auto& name : RunnablePipelines(mission)) fmt::print(" {}", name);
  fmt::print("\n");
}

int Demo(const std::string& scenario, std::uint64_t seed, const fs::path& out) {
  const fs::path mission_dir = out / "mission";
  // The default mission carries both PDR steps and a simulated foot IMU (industrial grade,
  // 100 Hz), so that every pipeline runs: the steps-based ones on steps.csv, ins on imu.csv.
  SimulateImu imu;
  imu.rate_hz = 100;
  imu.grade = "industrial";
  Simulate(scenario, seed, mission_dir, imu);
  std::vector<std::pair<RunResult, Metrics>> rows;
  std::vector<std::string> missions;
  std::set<std::string> done;
  auto run_all = [&](const std::string& label, const fs::path& mdir, const fs::path& runs,
                     const fs::path& report) {
    const MissionDirectory mission(mdir);
    std::vector<fs::path> run_dirs;
    for (const auto& name : RunnablePipelines(mission)) {
      if (done.count(name)) continue;
      const fs::path run_dir = runs / name;
      RunResult r = Run(name, mdir, run_dir, RequirePipeline(name).report_options);
      Metrics m = Eval(mdir, run_dir / "estimates.csv", run_dir / "metrics.json", false);
      rows.emplace_back(std::move(r), std::move(m));
      missions.push_back(label);
      run_dirs.push_back(run_dir);
      done.insert(name);
    }
    if (!run_dirs.empty()) Report(run_dirs, mdir, report);
  };
  run_all(scenario, mission_dir, out / "runs", out / "report.html");
  // Pipelines that need other sensors run on the simulated experiment of their paper (also
  // when they ran on the default mission), with the baseline (dead reckoning) on the same
  // mission for comparison.
  std::vector<std::string> extras;
  for (const auto& p : Pipelines()) {
    for (const auto& s : p.paper_scenarios) {
      if (std::find(extras.begin(), extras.end(), s) == extras.end()) extras.push_back(s);
    }
  }
  std::vector<std::string> reports{(out / "report.html").string()};
  std::vector<std::string> floor_lines;
  for (const std::string& extra : extras) {
    const fs::path mdir = out / "missions" / extra;
    Simulate(extra, seed, mdir);
    for (const auto& p : Pipelines()) {
      const auto& s = p.paper_scenarios;
      if (p.baseline || std::find(s.begin(), s.end(), extra) != s.end()) done.erase(p.name);
    }
    run_all(extra, mdir, out / "runs" / extra, out / ("report-" + extra + ".html"));
    reports.push_back((out / ("report-" + extra + ".html")).string());
  }
  {
    // Every source at once (issue 27): the multi-floor building with two firefighters, their
    // breadcrumbs, radio landmarks on every level, an ultrasound exit trail, foot IMUs, phone
    // steps, barometers and every level's plan; every pipeline that can run on it, the fusion
    // among them. Its report has the Floors table.
    const std::string extra = "all-sources";
    const fs::path mdir = out / "missions" / extra;
    Simulate(extra, seed, mdir);
    for (const auto& p : Pipelines()) done.erase(p.name);
    const std::size_t first = rows.size();
    run_all(extra, mdir, out / "runs" / extra, out / ("report-" + extra + ".html"));
    reports.push_back((out / ("report-" + extra + ".html")).string());
    for (std::size_t i = first; i < rows.size(); ++i) {
      if (const auto& f = rows[i].second.floors; f && rows[i].second.agents.stats.samples > 0) {
        floor_lines.push_back(fmt::format(
            "{:<18} {:<18} right floor {:.1f} %, VE95 {:.2f} m, IPIN score {:.2f} m", extra,
            rows[i].first.pipeline, 100 * f->floor_hit_rate, f->ve95_m, f->ipin_score_m));
      }
    }
  }
  PrintSummaryTable(rows, missions);
  for (const auto& line : floor_lines) fmt::print("{}\n", line);
  for (const auto& p : Pipelines()) {
    if (!done.count(p.name) && !p.baseline)
      fmt::print("not run (no mission with its inputs): {}\n", p.name);
  }
  fmt::print("\nreports: {}\n", fmt::join(reports, ", "));
  return 0;
}

}  // namespace trailmark::cli

#include "trailmark/pipelines/mapmatch_pipeline.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cmath>
#include <deque>
#include <map>
#include <memory>

#include "trailmark/core/error.h"
#include "trailmark/mapmatch/particle_filter.h"
#include "trailmark/pipelines/pipeline_options.h"
#include "trailmark/pipelines/step_source.h"

namespace trailmark {

bool MapMatchPipeline::CanRun(const MissionDirectory& mission) const {
  return HasSteps(mission) && mission.info().floorplan.has_value() &&
         mission.Has(*mission.info().floorplan);
}

namespace {

constexpr int kDefaultMapMatchParticles = 2000;

struct AgentTrack {
  std::unique_ptr<mapmatch::MapParticleFilter> filter;
  Vec2 odometry_n = Vec2::Zero();
  double walked_m = 0, since_compare_m = 0;
  std::deque<std::pair<double, Vec2>> history;  ///< (distance walked, odometry position)
  bool alarm = false;
  TimeS alarm_since = 0;
  std::vector<std::pair<TimeS, TimeS>> alarms;
  std::vector<std::string> wall_alarms;  ///< when and where the walk crossed the map's walls
  std::size_t comparisons = 0, skipped_comparisons = 0;
};

}  // namespace

struct MapMatchSession::Impl {
  std::string init;
  mapmatch::MapParticleFilterOptions fo;
  mapmatch::SearchSequenceOptions so;
  mapmatch::PatternComparisonOptions co;
  double compare_every_m = 2.0, alarm_m2 = 3.0, alarm_min_s = 10.0;
  int map_error_wall_alarms = 5;
  FloorPlan plan;
  std::vector<mapmatch::NodeSequence> sequences;
  std::unique_ptr<mapmatch::SearchGrid> grid;
  std::shared_ptr<const DistanceField> wall_distance;  ///< shared by the agents' filters
  std::map<std::string, AgentTrack> agents;
  std::size_t icp_runs = 0, icp_abandoned = 0;
  TimeS t_last = 0;
};

MapMatchSession::MapMatchSession(const MissionInfo& info, FloorPlan plan,
                                 const std::string& plan_file,
                                 const std::map<std::string, std::string>& options,
                                 PipelineSummary& summary)
    : info_(info), impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  PipelineOptions po(options, "mapmatch");
  m.init = po.String("init", "auto");
  if (m.init != "auto" && m.init != "known" && m.init != "uniform") {
    throw std::invalid_argument("pipeline mapmatch: init must be auto, known or uniform, not '" +
                                m.init + "'");
  }
  auto& fo = m.fo;
  auto& so = m.so;
  auto& co = m.co;
  // Ours: 2,000 particles by default (the paper: N = 500, `particles=500`); with the
  // wall-following model the belief stays sharp, and more particles keep the second
  // hypotheses alive through furniture (docs/mapmatch.md: measured on held-out searches).
  fo.particles = kDefaultMapMatchParticles;
  fo.particles = static_cast<int>(po.Whole("particles", fo.particles, 10, 1000000));
  fo.recover_pattern_updates =
      static_cast<int>(po.Whole("recover_pattern_updates", fo.recover_pattern_updates, 0, 1000000));
  fo.confirm_pattern_updates =
      static_cast<int>(po.Whole("confirm_pattern_updates", fo.confirm_pattern_updates, 0, 1000000));
  // 2^53: every whole number up to it is exact in the option's double.
  fo.seed = static_cast<std::uint64_t>(po.Whole("seed", 1, 0, std::int64_t{1} << 53));
  m.map_error_wall_alarms =
      static_cast<int>(po.Whole("map_error_wall_alarms", m.map_error_wall_alarms, 1, 1000000));
  // Option key -> the setting it overrides (the default is the setting's value).
  for (const auto& [key, field] : std::initializer_list<std::pair<const char*, double*>>{
           {"sigma", &fo.likelihood_sigma},
           {"tracking_sigma", &fo.tracking_likelihood_sigma},
           {"outlier_weight", &fo.outlier_weight},
           {"new_particle_weight", &fo.new_particle_weight},
           {"max_match_rmse_m", &fo.max_match_rmse_m},
           {"patterns_above_variance_m2", &fo.use_patterns_above_variance_m2},
           {"relocalize_above_variance_m2", &fo.relocalize_above_variance_m2},
           {"known_start_relocalize_above_variance_m2",
            &fo.known_start_relocalize_above_variance_m2},
           {"wall_alarm_k", &fo.wall_alarm_k},
           {"wall_alarm_h", &fo.wall_alarm_h},
           {"recover_position_sigma_m", &fo.recover_position_sigma_m},
           {"recover_heading_sigma_rad", &fo.recover_heading_sigma_rad},
           {"position_noise_m", &fo.position_noise_m},
           {"heading_noise_rad_per_m", &fo.heading_noise_rad_per_m},
           {"wall_follow_offset_m", &fo.wall_follow_offset_m},
           {"wall_follow_sigma_m", &fo.wall_follow_sigma_m},
           {"wall_follow_leave", &fo.wall_follow_leave},
           {"wall_follow_return", &fo.wall_follow_return},
           {"wall_follow_off_likelihood", &fo.wall_follow_off_likelihood},
           {"wall_follow_converged_power", &fo.wall_follow_converged_power},
           {"grid_m", &so.grid.spacing_m},
           {"pattern_length_m", &co.pattern_length_m},
           {"point_spacing_m", &co.point_spacing_m},
           {"icp_trim", &co.icp.trim_fraction},
           {"compare_every_m", &m.compare_every_m},
           {"variance_alarm_m2", &m.alarm_m2},
           {"variance_alarm_min_s", &m.alarm_min_s}}) {
    *field = po.Double(key, *field);
  }
  for (const auto& [key, field] : std::initializer_list<std::pair<const char*, bool*>>{
           {"pseudo", &fo.pseudo_observations},
           {"resample", &fo.resample_from_patterns},
           {"recover", &fo.recover_on_wall_alarm},
           {"recover_reweight_converged", &fo.recover_reweight_converged},
           {"stay_inside", &fo.stay_inside},
           {"wall_follow", &fo.wall_follow},
       }) {
    *field = po.Bool(key, *field);
  }
  po.RejectUnknown();
  std::string why;
  if (!fo.IsValid(&why) || !so.grid.IsValid(&why) || !co.IsValid(&why) ||
      !(m.compare_every_m > 0) || !(m.alarm_m2 > 0) || !(m.alarm_min_s >= 0)) {
    throw std::invalid_argument(
        "pipeline mapmatch: " +
        (why.empty()
             ? "compare_every_m and variance_alarm_m2 must be > 0, variance_alarm_min_s >= 0"
             : why));
  }

  m.plan = std::move(plan);
  for (const auto& p : mapmatch::CheckFloorPlan(m.plan, so.wall_snap_m)) {
    if (p.fatal) throw InputError(plan_file, 0, p.message);
    summary.notes.push_back("floor plan: " + p.message);
  }
  // The entry: the first agent's start, else the single base, else a corner of the building.
  std::optional<Vec2> entry;
  for (const NodeInfo& n : info.nodes) {
    if (n.kind != NodeKind::kAgent) continue;
    if (const auto s = info.AgentStart(n)) {
      entry = s->head<2>();
      break;
    }
  }
  if (!entry) {
    entry = m.plan.Bounds().min;
    summary.notes.push_back(
        "no agent start or base: the search sequence starts at the building's corner");
  }
  try {
    m.sequences = mapmatch::ExtractSearchSequences(m.plan, *entry, so);
  } catch (const std::invalid_argument& e) {
    throw InputError(plan_file, 0, e.what());
  }
  m.grid = std::make_unique<mapmatch::SearchGrid>(m.plan, so.grid);
  if (fo.wall_follow) {
    try {
      m.wall_distance = mapmatch::MakeWallDistanceField(m.plan);
    } catch (const std::invalid_argument& e) {
      throw InputError(plan_file, 0, e.what());
    }
  }
  std::size_t nodes = 0;
  for (const auto& s : m.sequences) nodes += s.nodes.size();
  summary.numbers["search_sequences"] = static_cast<double>(m.sequences.size());
  summary.numbers["search_nodes"] = static_cast<double>(nodes);
  summary.numbers["inside_area_m2"] =
      m.grid->inside_count() * so.grid.spacing_m * so.grid.spacing_m;
}

MapMatchSession::~MapMatchSession() = default;

void MapMatchSession::AddStep(const Step& step, EstimateSink& sink, PipelineSummary& summary) {
  Impl& m = *impl_;
  auto emit = [&](TimeS t, const std::string& id, const AgentTrack& a) {
    const Vec2 mean = a.filter->Mean();
    const Mat2 c = a.filter->Covariance();
    sink.Add({t, id, Vec3(mean.x(), mean.y(), 0), c(0, 0), c(0, 1), c(1, 1)});
  };
  auto it = m.agents.find(step.agent);
  if (it == m.agents.end()) {
    const NodeInfo* node = info_.Find(step.agent);
    if (node == nullptr || node->kind != NodeKind::kAgent) {
      throw std::invalid_argument(
          fmt::format("'{}' has steps but is not an agent in mission.json", step.agent));
    }
    const auto start = info_.AgentStart(*node);
    const bool known = m.init == "known" || (m.init == "auto" && start.has_value());
    if (known && !start) {
      throw std::invalid_argument(
          fmt::format("init=known but agent '{}' has no start in mission.json", step.agent));
    }
    AgentTrack a;
    mapmatch::MapParticleFilterOptions o = m.fo;
    o.seed = m.fo.seed + m.agents.size();
    a.filter =
        std::make_unique<mapmatch::MapParticleFilter>(*m.grid, m.sequences, o, m.wall_distance);
    if (known) {
      a.filter->InitializeKnown(start->head<2>(), 0.0,
                                std::max(node->start_sigma_m.value_or(0.2), 0.05),
                                std::max(node->start_heading_sigma_rad.value_or(0.09), 0.01));
    } else {
      a.filter->InitializeUniform();
    }
    summary.notes.push_back(
        fmt::format("{}: initial state {}", step.agent, known ? "known" : "unknown (uniform)"));
    it = m.agents.emplace(step.agent, std::move(a)).first;
    emit(step.t0, step.agent, it->second);
  }
  AgentTrack& a = it->second;
  const Vec2 d = step.delta_n.head<2>();
  a.filter->Predict(d);
  a.odometry_n += d;
  a.walked_m += d.norm();
  a.since_compare_m += d.norm();
  a.history.emplace_back(a.walked_m, a.odometry_n);
  while (a.history.size() > 2 && a.history[1].first <= a.walked_m - m.co.pattern_length_m)
    a.history.pop_front();
  if (m.fo.pseudo_observations && a.since_compare_m >= m.compare_every_m &&
      a.walked_m >= m.co.pattern_length_m) {
    a.since_compare_m = 0;
    if (!a.filter->WantsPatterns()) {
      ++a.skipped_comparisons;  // converged: the comparison would not be used
    } else {
      std::vector<Vec2> trajectory;
      for (const auto& h : a.history) trajectory.push_back(h.second);
      const mapmatch::PatternComparison pc =
          mapmatch::ComparePatterns(trajectory, m.sequences, m.co);
      m.icp_runs += pc.icp_runs;
      m.icp_abandoned += pc.icp_abandoned;
      // The odometry's walking direction over its last metre.
      Vec2 dir = Vec2::Zero();
      for (auto h = a.history.rbegin(); h != a.history.rend(); ++h) {
        dir = a.odometry_n - h->second;
        if (a.walked_m - h->first >= 1.0) break;
      }
      a.filter->UpdatePatterns(pc, std::atan2(dir.y(), dir.x()));
      ++a.comparisons;
    }
  }
  emit(step.t1, step.agent, a);
  // Map-error evidence (ours): the walk keeps crossing the map's walls (the filter's CUSUM
  // of the blocked share of the belief).
  if (a.filter->LastStepRaisedWallAlarm()) {
    const Vec2 where = a.filter->Mean();
    a.wall_alarms.push_back(
        fmt::format("t={:.1f} s near ({:.1f}, {:.1f})", step.t1, where.x(), where.y()));
  }
  // Map-error indicator (sec. V-E): the estimated variance above the alarm level.
  const double variance = a.filter->Covariance().trace();
  if (!a.alarm && variance > m.alarm_m2) a.alarm = true, a.alarm_since = step.t1;
  if (a.alarm && variance <= m.alarm_m2) {
    a.alarm = false;
    if (step.t1 - a.alarm_since >= m.alarm_min_s) a.alarms.emplace_back(a.alarm_since, step.t1);
  }
  m.t_last = step.t1;
}

void MapMatchSession::Summarize(PipelineSummary& summary) {
  Impl& m = *impl_;
  for (auto& [id, a] : m.agents) {
    auto alarms = a.alarms;
    if (a.alarm && m.t_last - a.alarm_since >= m.alarm_min_s)
      alarms.emplace_back(a.alarm_since, m.t_last);
    summary.notes.push_back(id + ": " + a.filter->summary().BriefReport());
    std::string periods;
    for (const auto& [t0, t1] : alarms)
      periods += fmt::format("{}{:.1f}-{:.1f} s", periods.empty() ? "" : ", ", t0, t1);
    summary.notes.push_back(
        fmt::format("{}: variance above {:.1f} m^2 for {:.0f} s or more (map error, or not yet "
                    "converged): {}",
                    id, m.alarm_m2, m.alarm_min_s, periods.empty() ? "never" : periods));
    summary.numbers[id + ".variance_alarms"] = static_cast<double>(alarms.size());
    summary.numbers[id + ".wall_alarms"] = static_cast<double>(a.wall_alarms.size());
    std::string crossings;
    for (const auto& w : a.wall_alarms) crossings += (crossings.empty() ? "" : "; ") + w;
    summary.notes.push_back(
        fmt::format("{}: wall alarms (the walk kept crossing walls of the map): {}", id,
                    crossings.empty() ? "never" : crossings));
    // The map-error verdict: the paper's variance indicator, or wall alarms repeated (one alarm
    // can also be a cloud that drifted off at a narrow door; a moved door makes the walk cross
    // the map's walls on every pass).
    const bool suspected =
        !alarms.empty() || static_cast<int>(a.wall_alarms.size()) >= m.map_error_wall_alarms;
    summary.numbers[id + ".map_error_suspected"] = suspected ? 1.0 : 0.0;
    if (suspected) {
      summary.notes.push_back(fmt::format(
          "{}: map error suspected ({})", id,
          !alarms.empty() ? "the variance stayed high" : "the walk kept crossing the map's walls"));
    }
    summary.numbers[id + ".pattern_comparisons"] = static_cast<double>(a.comparisons);
    summary.numbers[id + ".comparisons_skipped_converged"] =
        static_cast<double>(a.skipped_comparisons);
    summary.numbers[id + ".wall_eliminations"] =
        static_cast<double>(a.filter->summary().wall_eliminations);
    summary.numbers[id + ".restarts"] = static_cast<double>(a.filter->summary().restarts);
  }
  summary.numbers["icp_runs"] = static_cast<double>(m.icp_runs);
  summary.numbers["icp_abandoned"] = static_cast<double>(m.icp_abandoned);
}

std::optional<int> TakeMapMatchLevel(std::map<std::string, std::string>& options) {
  const auto it = options.find("level");
  if (it == options.end()) return std::nullopt;
  PipelineOptions lo({{"level", it->second}}, "mapmatch");
  const int level = static_cast<int>(lo.Whole("level", 0, -1000000, 1000000));
  options.erase(it);
  return level;
}

PipelineSummary MapMatchPipeline::Run(const PipelineContext& context, EstimateSink& sink) const {
  const MissionDirectory& mission = context.mission;
  auto [ins_options, rest] = SplitInsOptions(context.options);
  PipelineSummary summary;
  if (!mission.info().floorplan) {
    throw InputError(mission.Path("mission.json").string(), 0,
                     "the mapmatch pipeline needs a floor plan: mission.json has no \"floorplan\"");
  }
  mission.Require(*mission.info().floorplan, "the mapmatch pipeline");
  const std::string plan_file = mission.Path(*mission.info().floorplan).string();
  // One floor of a multi-floor plan (the paper's filter is 2-D): `level`, else level 0 (the
  // entry floor) or the lowest.
  const std::optional<int> level = TakeMapMatchLevel(rest);
  std::vector<int> levels;
  FloorPlan plan = *mission.LoadFloorPlan(level, &levels);
  if (levels.size() > 1) {
    summary.notes.push_back(fmt::format("floor plan: {} levels ({}); the filter uses level {}{}",
                                        levels.size(), fmt::join(levels, ", "),
                                        level.value_or(DefaultFloorPlanLevel(levels)),
                                        level ? "" : " (option level=N for another)"));
  }
  MapMatchSession session(mission.info(), std::move(plan), plan_file, rest, summary);
  StepSource steps(mission, ins_options, "the mapmatch pipeline", &summary);
  Step step;
  std::size_t rows = 0;
  while (steps.Next(step)) {
    try {
      session.AddStep(step, sink, summary);
    } catch (const std::invalid_argument& e) {
      steps.Fail(e.what());
    }
    if (++rows % 1024 == 0) context.progress(steps.Progress());
  }
  session.Summarize(summary);
  context.progress(1.0);
  return summary;
}

}  // namespace trailmark

// SPDX-License-Identifier: MIT
#include "trailmark/mapmatch/map_match_estimator.h"

#include <fmt/format.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <deque>
#include <map>
#include <stdexcept>

#include "trailmark/core/error.h"
#include "trailmark/ins/dead_reckoning.h"

namespace trailmark::mapmatch {

bool MapMatchEstimatorOptions::IsValid(std::string* why) const {
  if (!filter.IsValid(why) || !sequences.grid.IsValid(why) || !comparison.IsValid(why) ||
      !dr_test.IsValid(why))
    return false;
  if (!(compare_every_m > 0) || !(variance_alarm_m2 > 0) || !(variance_alarm_min_s >= 0) ||
      map_error_wall_alarms < 1 || !(walking_direction_m > 0) ||
      !(stairwell_veto_variance_m2 >= 0)) {
    if (why)
      *why = "compare_every_m and variance_alarm_m2 must be > 0, variance_alarm_min_s >= 0, "
             "stairwell_veto_variance_m2 >= 0";
    return false;
  }
  return true;
}

const OptionTable<MapMatchEstimatorOptions>& MapMatchOptionTable() {
  static const OptionTable<MapMatchEstimatorOptions> table = [] {
    using O = MapMatchEstimatorOptions;
    OptionTable<O> t;
    const auto any = OptionBounds::Any();
    t.Choice("init", &O::init,
             std::vector<std::pair<std::string, StartMode>>{{"auto", StartMode::kAuto},
                                                            {"known", StartMode::kKnown},
                                                            {"uniform", StartMode::kUniform}},
             "initial state: known start, uniform over the building, or auto (known if given)");
    t.Integer("particles", [](O& o) -> int& { return o.filter.particles; },
              OptionBounds::Between(10, 1000000), "particles per agent (the paper: 500)");
    t.Integer(
        "kld_min_particles", [](O& o) -> int& { return o.filter.kld_min_particles; },
        OptionBounds::Between(10, 1000000),
        "KLD-sampling: the fewest particles (at most `particles`)");
    t.Integer("recover_pattern_updates",
              [](O& o) -> int& { return o.filter.recover_pattern_updates; },
              OptionBounds::Between(0, 1000000), "forced comparisons after a wall alarm");
    t.Integer("confirm_pattern_updates",
              [](O& o) -> int& { return o.filter.confirm_pattern_updates; },
              OptionBounds::Between(0, 1000000), "comparisons that confirm a recovery");
    t.Integer("seed", [](O& o) -> std::uint64_t& { return o.filter.seed; },
              OptionBounds::NonNegative(), "the particle filter's random stream");
    t.Integer("map_error_wall_alarms", &O::map_error_wall_alarms,
              OptionBounds::Between(1, 1000000), "wall alarms that make the map-error verdict");
    auto real = [&](const char* key, auto field, const char* unit, OptionBounds b,
                    const char* description) { t.Real(key, field, unit, b, description); };
    real("sigma", [](O& o) -> double& { return o.filter.likelihood_sigma; }, "", any,
         "sigma of eq. (2), the pattern likelihood");
    real("tracking_sigma", [](O& o) -> double& { return o.filter.tracking_likelihood_sigma; }, "",
         any, "sigma of eq. (2) once the track is found (0: sigma throughout)");
    real("outlier_weight", [](O& o) -> double& { return o.filter.outlier_weight; }, "", any,
         "alpha of the likelihood alpha + (1 - alpha) exp(-E / sigma^2)");
    real("new_particle_weight", [](O& o) -> double& { return o.filter.new_particle_weight; }, "",
         any, "weight of particles drawn from a pattern observation");
    real("max_match_rmse_m", [](O& o) -> double& { return o.filter.max_match_rmse_m; }, "m", any,
         "worse ICP matches are not used");
    real("patterns_above_variance_m2",
         [](O& o) -> double& { return o.filter.use_patterns_above_variance_m2; }, "m^2", any,
         "comparisons only while the variance is above this (0: always)");
    real("relocalize_above_variance_m2",
         [](O& o) -> double& { return o.filter.relocalize_above_variance_m2; }, "m^2", any,
         "hysteresis level for comparisons once on track (0: off)");
    real("known_start_relocalize_above_variance_m2",
         [](O& o) -> double& { return o.filter.known_start_relocalize_above_variance_m2; }, "m^2",
         any, "a known start compares again only above this variance");
    real("wall_alarm_k", [](O& o) -> double& { return o.filter.wall_alarm_k; }, "", any,
         "CUSUM allowance of the blocked share of the belief");
    real("wall_alarm_h", [](O& o) -> double& { return o.filter.wall_alarm_h; }, "", any,
         "CUSUM threshold of the wall alarm");
    real("recover_position_sigma_m",
         [](O& o) -> double& { return o.filter.recover_position_sigma_m; }, "m", any,
         "spread of a recovery's draws");
    real("recover_heading_sigma_rad",
         [](O& o) -> double& { return o.filter.recover_heading_sigma_rad; }, "rad", any,
         "heading spread of a recovery's draws");
    real("position_noise_m", [](O& o) -> double& { return o.filter.position_noise_m; }, "m", any,
         "motion noise per step");
    real("heading_noise_rad_per_m", [](O& o) -> double& { return o.filter.heading_noise_rad_per_m; },
         "rad/m", any, "heading noise per metre walked");
    real("wall_follow_offset_m", [](O& o) -> double& { return o.filter.wall_follow_offset_m; }, "m",
         any, "wall-following model: distance kept from the wall");
    real("wall_follow_sigma_m", [](O& o) -> double& { return o.filter.wall_follow_sigma_m; }, "m",
         any, "wall-following model: sigma of that distance");
    real("wall_follow_leave", [](O& o) -> double& { return o.filter.wall_follow_leave; }, "", any,
         "wall-following model: probability per step of leaving the wall");
    real("wall_follow_return", [](O& o) -> double& { return o.filter.wall_follow_return; }, "", any,
         "wall-following model: probability per step of returning to it");
    real("wall_follow_off_likelihood",
         [](O& o) -> double& { return o.filter.wall_follow_off_likelihood; }, "", any,
         "wall-following model: likelihood off the wall");
    real("wall_follow_converged_power",
         [](O& o) -> double& { return o.filter.wall_follow_converged_power; }, "", any,
         "wall-following weight once converged (0: only while uncertain)");
    real(
        "free_walk_share", [](O& o) -> double& { return o.filter.free_walk_share; }, "", any,
        "wall-following model: share of the particles that walk freely (0: searchers only)");
    real(
        "free_walk_switch", [](O& o) -> double& { return o.filter.free_walk_switch; }, "", any,
        "wall-following model: probability per step of drawing a particle's model again");
    real(
        "confirm_distinct_m", [](O& o) -> double& { return o.filter.confirm_distinct_m; }, "m", any,
        "a comparison confirms only if its best matches lie within this of each other (0: all)");
    real(
        "kld_epsilon", [](O& o) -> double& { return o.filter.kld_epsilon; }, "", any,
        "KLD-sampling: bound of the histogram's KL distance (0: a fixed number of particles)");
    real(
        "kld_quantile", [](O& o) -> double& { return o.filter.kld_quantile; }, "", any,
        "KLD-sampling: probability of that bound (1 - delta)");
    real(
        "kld_bin_m", [](O& o) -> double& { return o.filter.kld_bin_m; }, "m", any,
        "KLD-sampling: histogram bin of position, along the grid's axes");
    real(
        "kld_bin_rad", [](O& o) -> double& { return o.filter.kld_bin_rad; }, "rad", any,
        "KLD-sampling: histogram bin of heading offset");
    real("grid_m", [](O& o) -> double& { return o.sequences.grid.spacing_m; }, "m", any,
         "search-pattern grid spacing");
    real("pattern_length_m", [](O& o) -> double& { return o.comparison.pattern_length_m; }, "m",
         any, "odometry compared with the patterns");
    real("point_spacing_m", [](O& o) -> double& { return o.comparison.point_spacing_m; }, "m", any,
         "spacing of the compared points");
    real("icp_trim", [](O& o) -> double& { return o.comparison.icp.trim_fraction; }, "", any,
         "fraction of the worst ICP correspondences left out (0: the paper's plain ICP)");
    real("stairwell_veto_variance_m2", &O::stairwell_veto_variance_m2, "m^2", any,
         "a level change outside a stairwell is refused at or below this variance (0: never)");
    real("compare_every_m", &O::compare_every_m, "m", any, "distance walked between comparisons");
    real("variance_alarm_m2", &O::variance_alarm_m2, "m^2", any,
         "map-error indicator level (sec. V-E)");
    real("variance_alarm_min_s", &O::variance_alarm_min_s, "s", any,
         "how long the variance must stay above it");
    t.Flag("pseudo", [](O& o) -> bool& { return o.filter.pseudo_observations; },
           "pseudo observations from pattern comparisons (sec. IV)");
    t.Flag("resample", [](O& o) -> bool& { return o.filter.resample_from_patterns; },
           "resample the lowest-weight particles from the pattern observations");
    t.Flag("recover", [](O& o) -> bool& { return o.filter.recover_on_wall_alarm; },
           "recover on a wall alarm (ours)");
    t.Flag("recover_reweight_converged",
           [](O& o) -> bool& { return o.filter.recover_reweight_converged; },
           "forced comparisons also weight a converged belief");
    t.Flag("stay_inside", [](O& o) -> bool& { return o.filter.stay_inside; },
           "particles outside the building are eliminated");
    t.Flag("wall_follow", [](O& o) -> bool& { return o.filter.wall_follow; },
           "the directional search as a motion model (ours)");
    t.Flag(
        "exact_inside", [](O& o) -> bool& { return o.filter.exact_inside; },
        "the exact inside test instead of the 1 m grid cells (issue 23; no better on the houses)");
    t.Flag(
        "grid_align", [](O& o) -> bool& { return o.sequences.grid.align_to_walls; },
        "search grid along the walls' dominant direction (ours; false: the map's x/y axes)");
    t.Flag("dr_first", &O::dr_first,
           "an agent on a foot INS within its noise model (known start, stated heading) is "
           "written as its dead reckoning while the filter does not doubt it");
    t.Real(
        "stated_wall_follow_converged_power",
        [](O& o) -> double& { return o.filter.stated_wall_follow_converged_power; }, "",
        OptionBounds::Between(0, 1),
        "wall-following weight once converged for an agent on stated steps (0: only while "
        "uncertain)");
    t.Flag("stated_steps", &O::stated_steps,
           "a foot INS's steps move the particles by their own noise and the dead reckoning's "
           "shared errors per particle (else the paper's noise)");
    t.Include("", &O::dr_test, integrity::DeadReckoningFirstOptionTable());
    return t;
  }();
  return table;
}

namespace {

/// The dead reckoning's turn threshold (PdrOptions::turn_min_step_m) for the particles' turns.
const double kTurnMinStepM = PdrOptions{}.turn_min_step_m;

/// One level of the building: its plan, search sequences, grid and wall distances.
struct Level {
  int level = 0;
  FloorPlan plan;
  std::vector<NodeSequence> sequences;
  std::unique_ptr<SearchGrid> grid;
  std::shared_ptr<const DistanceField> wall_distance;  ///< shared by the agents' filters
  std::vector<const Room*> stairwells;
};

struct AgentTrack {
  std::map<std::size_t, std::unique_ptr<MapParticleFilter>> filters;  ///< by level index
  MapParticleFilter* filter = nullptr;  ///< the current level's
  std::size_t level = 0;                ///< index into Impl::levels
  std::uint64_t seed = 1;
  Vec2 odometry_n = Vec2::Zero();
  double walked_m = 0, since_compare_m = 0;
  double level_walked_m = 0;  ///< walked when the agent came to this level
  std::deque<std::pair<double, Vec2>> history;  ///< (distance walked, odometry position)
  bool alarm = false;
  /// The variance indicator watches a filter that has found its place: a known start at once,
  /// an unknown one once confirmed and its variance at or below the alarm level (issue 23: the
  /// search for the place is not a map error).
  bool indicator_armed = false;
  TimeS alarm_since = 0, t = 0;
  std::vector<std::pair<TimeS, TimeS>> alarms;
  std::vector<std::string> wall_alarms;  ///< when and where the walk crossed the map's walls
  std::size_t comparisons = 0, skipped_comparisons = 0;
  std::size_t level_changes = 0, level_changes_outside_stairwell = 0, level_changes_refused = 0;
  std::optional<int> refused_level;  ///< the level change being refused now
  std::vector<std::string> level_notes;
  /// dr_first: the foot INS's dead reckoning and the filter's verdict on it.
  std::optional<DeadReckoning> dr;
  std::optional<integrity::DeadReckoningFirst> dr_first;
  std::optional<Estimate> last;  ///< the estimate written last
  /// stated_steps: the shared errors' prior of its filters, and what they act on between steps
  /// (as the dead reckoning counts it).
  std::optional<SharedStepErrorPrior> shared;
  StepTurnCounter turns;
};

}  // namespace

struct MapMatchEstimator::Impl {
  MissionInfo info;
  MapMatchEstimatorOptions o;
  std::vector<Level> levels;
  std::map<std::string, AgentTrack> agents;
  const LevelSource* level_source = nullptr;
  EstimatorSummary setup;
  std::vector<IntegrityNote> dr_notes;  ///< dr_first: the filter's verdicts on dead reckoning
  std::size_t icp_runs = 0, icp_abandoned = 0, ignored = 0;
  std::size_t icp_iterations_abandoned = 0, icp_iterations_kept = 0;
  TimeS t_last = 0;

  std::vector<std::pair<TimeS, TimeS>> Alarms(const AgentTrack& a) const {
    auto alarms = a.alarms;
    if (a.alarm && t_last - a.alarm_since >= o.variance_alarm_min_s)
      alarms.emplace_back(a.alarm_since, t_last);
    return alarms;
  }
  std::optional<std::size_t> IndexOf(int level) const {
    for (std::size_t i = 0; i < levels.size(); ++i) {
      if (levels[i].level == level) return i;
    }
    return std::nullopt;
  }
  /// The filter of `a` on level index `i` (made on first use, with its own random stream).
  MapParticleFilter& FilterOn(AgentTrack& a, std::size_t i) {
    auto& f = a.filters[i];
    if (!f) {
      MapParticleFilterOptions fo = o.filter;
      fo.seed = a.seed + 7919 * i;
      const Level& l = levels[i];
      f = std::make_unique<MapParticleFilter>(*l.grid, l.sequences, fo, l.wall_distance);
      if (a.shared) f->UseSharedErrors(*a.shared);
    }
    return *f;
  }
  /// Moves the agent's belief to level index `to` at time t: the particles in a stairwell of
  /// either level go on; when no weight is in one, the change is refused while the belief is
  /// confident (stairwell_veto_variance_m2), else every particle goes on (noted).
  void ChangeLevel(const std::string& id, AgentTrack& a, std::size_t to, TimeS t) {
    const Level& from_level = levels[a.level];
    const Level& to_level = levels[to];
    const auto& particles = a.filter->particles();
    std::vector<char> keep(particles.size(), 0);
    double mass = 0;
    for (std::size_t k = 0; k < particles.size(); ++k) {
      for (const Level* l : {&from_level, &to_level}) {
        for (const Room* r : l->stairwells) {
          if (PointInPolygon(particles[k].position_n, r->ring)) keep[k] = 1;
        }
      }
      if (keep[k]) mass += particles[k].weight;
    }
    const bool marked = !from_level.stairwells.empty() || !to_level.stairwells.empty();
    const bool stairs = mass >= kMinStairwellMass;
    if (!stairs && marked && a.filter->Covariance().trace() <= o.stairwell_veto_variance_m2) {
      if (a.refused_level != to_level.level) {
        ++a.level_changes_refused;
        a.level_notes.push_back(fmt::format(
            "{}: t={:.1f} s level {} -> {} refused: {:.0f} % of the belief in a stairwell", id, t,
            from_level.level, to_level.level, 100 * mass));
      }
      a.refused_level = to_level.level;
      return;
    }
    a.refused_level.reset();
    if (!stairs) std::fill(keep.begin(), keep.end(), 1);
    MapParticleFilter& next = FilterOn(a, to);
    next.ContinueFrom(*a.filter, keep);
    ++a.level_changes;
    if (!stairs) {
      ++a.level_changes_outside_stairwell;
      a.level_notes.push_back(fmt::format(
          "{}: t={:.1f} s level {} -> {} with {:.0f} % of the belief in a stairwell{}: every "
          "particle kept",
          id, t, from_level.level, to_level.level, 100 * mass,
          marked ? "" : " (the plan marks none)"));
    }
    a.filter = &next;
    a.level = to;
    a.level_walked_m = a.walked_m;
    a.since_compare_m = 0;
    a.history.clear();
    a.history.emplace_back(a.walked_m, a.odometry_n);
  }
  /// Ours: a level change moves only the particles in a stairwell when they carry at least
  /// this share of the belief; below it, the stairwell is not where the filter thinks the
  /// walker is (or the plan marks none) and every particle goes on.
  static constexpr double kMinStairwellMass = 0.05;
};

MapMatchEstimator::MapMatchEstimator(const MissionInfo& info, FloorPlan plan,
                                     std::string plan_source, MapMatchEstimatorOptions options)
    : MapMatchEstimator(info, LevelPlans{{0, std::move(plan)}}, std::move(plan_source),
                        std::move(options)) {}

MapMatchEstimator::MapMatchEstimator(const MissionInfo& info, LevelPlans levels,
                                     std::string plan_source, MapMatchEstimatorOptions options)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.info = info;
  m.o = std::move(options);
  std::string why;
  if (!m.o.IsValid(&why)) throw std::invalid_argument("mapmatch: " + why);
  if (levels.empty()) throw std::invalid_argument("mapmatch: no floor plan");
  // The first agent's start, else the single base.
  std::optional<Vec3> start;
  for (const NodeInfo& n : info.nodes) {
    if (n.kind != NodeKind::kAgent) continue;
    if ((start = info.AgentStart(n))) break;
  }
  const bool multi = levels.size() > 1;
  std::size_t nodes = 0;
  double inside_m2 = 0;
  // The level the agents are taken to start on when they have no start: 0, else the lowest.
  int primary = levels.front().first;
  for (const auto& [level_number, plan] : levels) {
    if (level_number == 0) primary = 0;
    if (primary != 0) primary = std::min(primary, level_number);
  }
  m.levels.reserve(levels.size());  // the filters keep references into the levels
  for (auto& [level_number, plan] : levels) {
    const std::string prefix = multi ? fmt::format("level {}: ", level_number) : "";
    // In place from the start (reserved: no reallocation), so that the stairwells point into
    // the plan for good; a level left out is popped.
    Level& l = m.levels.emplace_back();
    l.level = level_number;
    l.plan = std::move(plan);
    for (const Room& r : l.plan.rooms()) {
      if (IsStairwell(r)) l.stairwells.push_back(&r);
    }
    std::vector<std::string> notes;
    try {
      for (const auto& p : CheckFloorPlan(l.plan, m.o.sequences.wall_snap_m)) {
        if (p.fatal) throw InputError(plan_source, 0, prefix + p.message);
        notes.push_back("floor plan: " + prefix + p.message);
      }
      // Where the searches of the level start: the entry (the first agent's start) on its
      // level, else the stairwell, else the building's corner.
      std::optional<Vec2> entry;
      if (start && (!multi || LevelAt(info.floors, start->z()) == l.level))
        entry = start->head<2>();
      if (!entry && !l.stairwells.empty()) {
        Vec2 c = Vec2::Zero();
        for (const Vec2& v : l.stairwells.front()->ring) c += v;
        entry = c / static_cast<double>(l.stairwells.front()->ring.size());
      }
      if (!entry && start) entry = start->head<2>();
      if (!entry) {
        entry = l.plan.Bounds().min;
        notes.push_back(prefix +
                        "no agent start or base: the search sequence starts at the building's "
                        "corner");
      }
      try {
        l.sequences = ExtractSearchSequences(l.plan, *entry, m.o.sequences);
        if (m.o.filter.wall_follow) {
          l.wall_distance = MakeWallDistanceField(
              l.plan, l.sequences.empty() ? 0.0 : l.sequences.front().grid_axis_rad);
        }
      } catch (const std::invalid_argument& e) {
        throw InputError(plan_source, 0, prefix + e.what());
      }
    } catch (const InputError& e) {
      // A level that cannot be matched on is left out, unless it is the one every agent
      // starts on when nothing says otherwise.
      if (!multi || level_number == primary) throw;
      m.setup.notes.push_back(fmt::format(
          "floor plan: level {} left out ({}): an agent on it keeps the plan of the level it came "
          "from",
          level_number, e.what()));
      m.levels.pop_back();
      continue;
    }
    m.setup.notes.insert(m.setup.notes.end(), notes.begin(), notes.end());
    l.grid = std::make_unique<SearchGrid>(l.plan, m.o.sequences.grid);
    for (const auto& s : l.sequences) nodes += s.nodes.size();
    const double cell = m.o.sequences.grid.spacing_m;
    inside_m2 += l.grid->inside_count() * cell * cell;
    m.setup.numbers["search_sequences"] += static_cast<double>(l.sequences.size());
  }
  m.setup.numbers["search_nodes"] = static_cast<double>(nodes);
  m.setup.numbers["inside_area_m2"] = inside_m2;
  if (m.levels.size() > 1) {
    m.setup.numbers["levels"] = static_cast<double>(m.levels.size());
    std::size_t stairwells = 0;
    for (const Level& l : m.levels) stairwells += l.stairwells.size();
    m.setup.numbers["stairwells"] = static_cast<double>(stairwells);
    if (stairwells == 0) {
      m.setup.notes.push_back(
          "floor plan: no room is a stairwell (a room named \"stair...\"): a level change "
          "keeps the whole belief");
    }
  }
}

void MapMatchEstimator::UseLevels(const LevelSource* levels) { impl_->level_source = levels; }

MapMatchEstimator::~MapMatchEstimator() = default;

void MapMatchEstimator::Add(const MissionRow& row, EstimateSink& sink) {
  Impl& m = *impl_;
  const auto* step = std::get_if<Step>(&row);
  if (step == nullptr) {
    ++m.ignored;
    return;
  }
  auto emit = [&](TimeS t, const std::string& id, AgentTrack& a) {
    Vec2 mean = a.filter->Mean();
    Mat2 c = a.filter->ReportedCovariance();
    if (a.dr_first) {
      // The verdict on the filter's own spread; the dead reckoning's region where it is
      // written (its covariance, as `pdr` writes it).
      const Vec2 dr_n = a.dr->position_n().head<2>();
      if (auto note = a.dr_first->Test(t, id, "the map matcher", mean, c, dr_n))
        m.dr_notes.push_back(std::move(*note));
      c = a.dr_first->Covariance(mean, c, dr_n, a.dr->covariance());
      mean = a.dr_first->Position(mean, dr_n);
      a.dr_first->Count();
    }
    a.t = t;
    Estimate e{t, id, Vec3(mean.x(), mean.y(), 0), c(0, 0), c(0, 1), c(1, 1)};
    if (m.levels.size() > 1) e.floor = m.levels[a.level].level;
    a.last = e;
    sink.Add(e);
  };
  auto it = m.agents.find(step->agent);
  if (it == m.agents.end()) {
    const NodeInfo* node = m.info.Find(step->agent);
    if (node == nullptr || node->kind != NodeKind::kAgent) {
      throw std::invalid_argument(
          fmt::format("'{}' has steps but is not an agent in mission.json", step->agent));
    }
    const auto start = m.info.AgentStart(*node);
    const bool known =
        m.o.init == StartMode::kKnown || (m.o.init == StartMode::kAuto && start.has_value());
    if (known && !start) {
      throw std::invalid_argument(
          fmt::format("init=known but agent '{}' has no start in mission.json", step->agent));
    }
    AgentTrack a;
    a.seed = m.o.filter.seed + m.agents.size();
    // The level it starts on: its start's, else its height channel's, else level 0 (or the
    // lowest the plan has).
    if (m.levels.size() > 1) {
      std::optional<int> level;
      if (start) level = LevelAt(m.info.floors, start->z());
      else if (m.level_source) {
        if (const auto b = m.level_source->NodeLevel(step->agent)) level = b->level;
      }
      a.level = m.IndexOf(level.value_or(0)).value_or(m.IndexOf(0).value_or(0));
    }
    if (m.o.stated_steps && step->heading_var_rad2) {
      const PdrOptions foot = PdrOptions{}.ForFootIns();
      a.shared = SharedStepErrorPrior{foot.step_scale_sigma, foot.turn_scale_sigma,
                                      foot.heading_drift_sigma_rad_per_s};
      m.setup.notes.push_back(fmt::format(
          "{}: steps from a foot INS within its noise model move the particles by their own "
          "noise and the INS's shared errors (stated_steps)",
          step->agent));
    }
    a.filter = &m.FilterOn(a, a.level);
    if (known) {
      // With the dead reckoning's errors (stated_steps), its start heading's too: the stated
      // sigma and the steps' own offset from it (the foot's toe-out), in quadrature.
      const double heading_sigma_rad =
          a.shared ? PdrOptions{}.StartHeadingSigma(node->start_heading_sigma_rad)
                   : node->start_heading_sigma_rad.value_or(m.o.default_start_heading_sigma_rad);
      a.filter->InitializeKnown(
          start->head<2>(), 0.0,
          std::max(node->start_sigma_m.value_or(m.o.default_start_sigma_m), m.o.min_start_sigma_m),
          std::max(heading_sigma_rad, m.o.min_start_heading_sigma_rad));
    } else {
      a.filter->InitializeUniform();
    }
    m.setup.notes.push_back(
        fmt::format("{}: initial state {}", step->agent, known ? "known" : "unknown (uniform)"));
    // dr_first: decided at the first step (a foot INS within its noise model gives its steps'
    // heading variance), for an agent whose start and heading the filter takes as known.
    if (m.o.dr_first && known && step->heading_var_rad2 && node->start_heading_rad) {
      a.dr.emplace(*start, node->start_sigma_m.value_or(m.o.default_start_sigma_m),
                   PdrOptions{}.ForFootIns(), node->start_heading_sigma_rad);
      a.dr_first.emplace(m.o.dr_test);
      m.setup.notes.push_back(fmt::format(
          "{}: steps from a foot INS within its noise model: its dead reckoning is written "
          "until it leaves the map matcher's {:g} % region (dr_first)",
          step->agent, 100 * m.o.dr_test.reject_probability));
    }
    it = m.agents.emplace(step->agent, std::move(a)).first;
    emit(step->t0, step->agent, it->second);
  }
  AgentTrack& a = it->second;
  // The level its height channel puts it on now (the step included).
  if (m.levels.size() > 1 && m.level_source) {
    if (const auto b = m.level_source->NodeLevel(step->agent)) {
      const auto to = m.IndexOf(b->level);
      if (to && *to != a.level) {
        m.ChangeLevel(step->agent, a, *to, step->t1);
      } else {
        a.refused_level.reset();
      }
    }
  }
  if (a.dr) {
    a.dr->AddStep(*step);
    if (!step->heading_var_rad2) {  // the IMU's mounting not found: no longer within its model
      if (auto note = a.dr_first->Abandon(step->t1, step->agent, "the map matcher"))
        m.dr_notes.push_back(std::move(*note));
    }
  }
  const Vec2 d = step->delta_n.head<2>();
  const StepTurnCounter::Since since = a.turns.Next(*step, kTurnMinStepM);
  if (a.shared && step->heading_var_rad2) {
    StatedStep stated;
    stated.dt_s = since.dt_s;
    stated.turn_rad = since.turn_rad;
    if (step->variance_m2) {
      stated.position_sigma_m =
          std::sqrt(0.5 * std::max(0.0, step->variance_m2->x() + step->variance_m2->y()));
    }
    stated.heading_sigma_rad = std::sqrt(std::max(0.0, *step->heading_var_rad2));
    a.filter->Predict(d, &stated);
  } else {
    a.filter->Predict(d);
  }
  a.odometry_n += d;
  a.walked_m += d.norm();
  a.since_compare_m += d.norm();
  a.history.emplace_back(a.walked_m, a.odometry_n);
  while (a.history.size() > 2 && a.history[1].first <= a.walked_m - m.o.comparison.pattern_length_m)
    a.history.pop_front();
  if (m.o.filter.pseudo_observations && a.since_compare_m >= m.o.compare_every_m &&
      a.walked_m - a.level_walked_m >= m.o.comparison.pattern_length_m) {
    a.since_compare_m = 0;
    if (!a.filter->WantsPatterns()) {
      ++a.skipped_comparisons;  // converged: the comparison would not be used
    } else {
      std::vector<Vec2> trajectory;
      for (const auto& h : a.history) trajectory.push_back(h.second);
      const PatternComparison pc =
          ComparePatterns(trajectory, m.levels[a.level].sequences, m.o.comparison);
      m.icp_runs += pc.icp_runs;
      m.icp_abandoned += pc.icp_abandoned;
      m.icp_iterations_abandoned += pc.icp_iterations_abandoned;
      m.icp_iterations_kept += pc.icp_iterations_kept;
      // The odometry's walking direction over its last metre.
      Vec2 dir = Vec2::Zero();
      for (auto h = a.history.rbegin(); h != a.history.rend(); ++h) {
        dir = a.odometry_n - h->second;
        if (a.walked_m - h->first >= m.o.walking_direction_m) break;
      }
      a.filter->UpdatePatterns(pc, std::atan2(dir.y(), dir.x()));
      ++a.comparisons;
    }
  }
  emit(step->t1, step->agent, a);
  // Map-error evidence (ours): the walk keeps crossing the map's walls (the filter's CUSUM
  // of the blocked share of the belief).
  if (a.filter->LastStepRaisedWallAlarm()) {
    const Vec2 where = a.filter->Mean();
    a.wall_alarms.push_back(
        fmt::format("t={:.1f} s near ({:.1f}, {:.1f})", step->t1, where.x(), where.y()));
  }
  // Map-error indicator (sec. V-E): the estimated variance above the alarm level.
  const double variance = a.filter->Covariance().trace();
  if (!a.indicator_armed && !a.filter->Unconfirmed() && variance <= m.o.variance_alarm_m2)
    a.indicator_armed = true;
  if (a.indicator_armed && !a.alarm && variance > m.o.variance_alarm_m2)
    a.alarm = true, a.alarm_since = step->t1;
  if (a.alarm && variance <= m.o.variance_alarm_m2) {
    a.alarm = false;
    if (step->t1 - a.alarm_since >= m.o.variance_alarm_min_s)
      a.alarms.emplace_back(a.alarm_since, step->t1);
  }
  m.t_last = step->t1;
}

std::optional<Estimate> MapMatchEstimator::Current(const std::string& node) const {
  const auto it = impl_->agents.find(node);
  if (it == impl_->agents.end()) return std::nullopt;
  return it->second.last;
}

std::optional<Mat2> MapMatchEstimator::StepTransform(const std::string& agent) const {
  const auto it = impl_->agents.find(agent);
  if (it == impl_->agents.end()) return std::nullopt;
  if (it->second.dr_first && it->second.dr_first->doubt() < 0.5)
    return std::nullopt;  // the steps as they come: the dead reckoning is written
  return Mat2(Eigen::Rotation2Dd(it->second.filter->MeanHeadingOffset()).toRotationMatrix());
}

std::optional<AgentMapEvidence> MapMatchEstimator::Evidence(const std::string& agent) const {
  const Impl& m = *impl_;
  const auto it = m.agents.find(agent);
  if (it == m.agents.end()) return std::nullopt;
  AgentMapEvidence e;
  e.variance_alarms = m.Alarms(it->second);
  e.wall_alarms = it->second.wall_alarms;
  // The verdict: the paper's variance indicator, or wall alarms repeated (one alarm can also
  // be a cloud that drifted off at a narrow door; a moved door makes the walk cross the map's
  // walls on every pass).
  e.map_error_suspected = !e.variance_alarms.empty() ||
                          static_cast<int>(e.wall_alarms.size()) >= m.o.map_error_wall_alarms;
  return e;
}

EstimatorSummary MapMatchEstimator::Summary() const {
  const Impl& m = *impl_;
  EstimatorSummary summary = m.setup;
  for (const auto& [id, a] : m.agents) {
    const AgentMapEvidence e = *Evidence(id);
    summary.notes.push_back(id + ": " + a.filter->summary().BriefReport());
    std::string periods;
    for (const auto& [t0, t1] : e.variance_alarms)
      periods += fmt::format("{}{:.1f}-{:.1f} s", periods.empty() ? "" : ", ", t0, t1);
    summary.notes.push_back(
        fmt::format("{}: variance above {:.1f} m^2 for {:.0f} s or more (map error, or not yet "
                    "converged): {}",
                    id, m.o.variance_alarm_m2, m.o.variance_alarm_min_s,
                    periods.empty() ? "never" : periods));
    summary.numbers[id + ".variance_alarms"] = static_cast<double>(e.variance_alarms.size());
    summary.numbers[id + ".wall_alarms"] = static_cast<double>(e.wall_alarms.size());
    std::string crossings;
    for (const auto& w : e.wall_alarms) crossings += (crossings.empty() ? "" : "; ") + w;
    summary.notes.push_back(
        fmt::format("{}: wall alarms (the walk kept crossing walls of the map): {}", id,
                    crossings.empty() ? "never" : crossings));
    summary.numbers[id + ".map_error_suspected"] = e.map_error_suspected ? 1.0 : 0.0;
    if (e.map_error_suspected) {
      summary.notes.push_back(fmt::format("{}: map error suspected ({})", id,
                                          !e.variance_alarms.empty()
                                              ? "the variance stayed high"
                                              : "the walk kept crossing the map's walls"));
    }
    summary.numbers[id + ".pattern_comparisons"] = static_cast<double>(a.comparisons);
    summary.numbers[id + ".comparisons_skipped_converged"] =
        static_cast<double>(a.skipped_comparisons);
    std::size_t eliminations = 0, restarts = 0, ambiguous = 0;
    for (const auto& [level, f] : a.filters) {
      eliminations += f->summary().wall_eliminations;
      restarts += f->summary().restarts;
      ambiguous += f->summary().ambiguous_updates;
    }
    // Issue 23: comparisons that matched equally well in places far apart, and whether the
    // place from an unknown start was ever confirmed (until then the ellipse covers the
    // building).
    summary.numbers[id + ".ambiguous_comparisons"] = static_cast<double>(ambiguous);
    const bool unconfirmed = a.filter->Unconfirmed();
    summary.numbers[id + ".place_unconfirmed"] = unconfirmed ? 1.0 : 0.0;
    if (unconfirmed) {
      summary.notes.push_back(fmt::format(
          "{}: its place was never confirmed by a distinctive pattern comparison ({} matched "
          "equally well in places far apart): its ellipse covers the building",
          id, ambiguous));
    }
    summary.numbers[id + ".wall_eliminations"] = static_cast<double>(eliminations);
    summary.numbers[id + ".restarts"] = static_cast<double>(restarts);
    if (m.levels.size() > 1) {
      summary.numbers[id + ".level_changes"] = static_cast<double>(a.level_changes);
      summary.numbers[id + ".level_changes_outside_stairwell"] =
          static_cast<double>(a.level_changes_outside_stairwell);
      summary.numbers[id + ".level_changes_refused"] =
          static_cast<double>(a.level_changes_refused);
      summary.numbers[id + ".final_level"] = m.levels[a.level].level;
      summary.notes.insert(summary.notes.end(), a.level_notes.begin(), a.level_notes.end());
    }
  }
  // dr_first: the share of each agent's estimates that are not its dead reckoning's.
  for (const auto& [id, a] : m.agents)
    if (a.dr_first)
      summary.numbers[id + ".dr_first_filter_share"] = a.dr_first->share_not_dead_reckoning();
  summary.integrity.insert(summary.integrity.end(), m.dr_notes.begin(), m.dr_notes.end());
  summary.numbers["icp_runs"] = static_cast<double>(m.icp_runs);
  summary.numbers["icp_abandoned"] = static_cast<double>(m.icp_abandoned);
  summary.numbers["icp_iterations_abandoned"] = static_cast<double>(m.icp_iterations_abandoned);
  summary.numbers["icp_iterations_kept"] = static_cast<double>(m.icp_iterations_kept);
  summary.numbers["rows_ignored"] = static_cast<double>(m.ignored);
  return summary;
}

}  // namespace trailmark::mapmatch

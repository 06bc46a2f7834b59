#include "trailmark/pipelines/beacons_pipeline.h"

#include <fmt/format.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <map>
#include <set>

#include "trailmark/beacons/beacon_map.h"
#include "trailmark/beacons/scaat_ekf.h"
#include "trailmark/core/error.h"
#include "trailmark/pipelines/merged_stream.h"
#include "trailmark/pipelines/pipeline_options.h"
#include "trailmark/pipelines/step_source.h"

namespace trailmark {

bool BeaconsPipeline::CanRun(const MissionDirectory& mission) const {
  if (!mission.Has("ranges.csv")) return false;
  return !track_ || HasSteps(mission);
}

namespace {

using beacons::BeaconMap;
using beacons::BeaconPosition;
using beacons::ScaatEkf;
using beacons::UpdateResult;

enum class Filter { kScaat, kUltrasoundOnly, kNone };
enum class UpdateMode { kRangeBearing, kPosition };

struct TrackerOptions {
  Filter filter = Filter::kScaat;
  UpdateMode update = UpdateMode::kRangeBearing;
  bool force_init_from_ultrasound = false;
  double mds_period_s = 2.0;
  double drop_sigma_m = 0.3;   ///< where a dropped beacon lands around the dropper's estimate
  double entry_track_m = 1.0;  ///< PDR track compared with the entry heading (0: never)
  double close_pass_m =
      1.5;  ///< a beacon with no drop event is anchored at the first range this short
  beacons::ScaatEkfOptions ekf;
  beacons::UltrasoundOnlyKfOptions us_kf;
  beacons::BeaconMapOptions map;
  beacons::InitOptions init;
};

struct PendingRange {
  TimeS t;
  std::string agent;
  int beacon;
  double range_m, sigma_m;
};

struct Agent {
  std::string id;
  Vec2 pdr_n = Vec2::Zero();  ///< dead reckoning (from the start, or from the init buffer)
  double pdr_var_m2 = 0.01;
  bool has_start = false;
  std::optional<ScaatEkf> ekf;
  std::optional<beacons::UltrasoundOnlyKf> us_kf;
  std::vector<beacons::InitMeasurement> init_buffer;
  std::string init_why;
  TimeS initialized_at = 0;
  std::map<int, TimeS> heard;  ///< beacon -> last time heard
  // Entry heading (mission.json start_heading): the PDR's direction over its first metre is
  // compared with it once, which fixes the PDR heading offset in the navigation frame.
  std::optional<double> entry_heading_rad;
  double entry_heading_sigma_rad = 0.05;
  Vec2 first_track_n = Vec2::Zero();
  bool heading_fixed = false;
  Vec2 start_n = Vec2::Zero();
  double pdr_rotation_rad = 0;  ///< applied to the dead reckoning of beacons-mds
};

/// Reads the merged streams of a mission and keeps the beacon map and the agents' filters.
class TrailTracker {
 public:
  TrailTracker(const MissionDirectory& mission, TrackerOptions options, EstimateSink* sink,
               PipelineSummary* summary)
      : mission_(mission), options_(options), map_(options.map), sink_(sink), summary_(summary) {
    for (const NodeInfo& n : mission.info().nodes) {
      if (n.kind == NodeKind::kAgent) {
        Agent a;
        a.id = n.id;
        const auto start = mission.info().AgentStart(n);
        if (start && !options_.force_init_from_ultrasound) {
          a.has_start = true;
          a.pdr_n = a.start_n = start->head<2>();
          a.entry_heading_rad = n.start_heading_rad;
          a.entry_heading_sigma_rad = n.start_heading_sigma_rad.value_or(0.05);
          const double s = n.start_sigma_m.value_or(options_.ekf.initial_position_sigma_m);
          if (options_.filter == Filter::kScaat) {
            a.ekf.emplace(a.pdr_n, Mat2::Identity() * s * s, 0.0,
                          options_.ekf.initial_heading_sigma_rad, 1.0,
                          options_.ekf.initial_scale_sigma, options_.ekf);
          }
        }
        agents_[n.id] = std::move(a);
      } else {
        declared_rank_[n.id] = static_cast<int>(declared_rank_.size());
        // Surveyed nodes (landmarks, the base) are beacons once they range.
        if (n.position)
          surveyed_[n.id] = {n.position->head<2>(), n.position_sigma_m.value_or(0.05)};
      }
    }
  }

  /// A beacon's index in the map, adding it (with its survey) on first sight.
  int Beacon(const std::string& id) {
    if (const auto i = map_.Find(id)) return *i;
    const int i = map_.Add(id);
    const auto s = surveyed_.find(id);
    if (s != surveyed_.end()) map_.SetSurveyed(i, s->second.first, s->second.second);
    return i;
  }

  /// Deployment order of every beacon: drops first (in drop order), then the others in the
  /// order mission.json declares them, then in order of first sight.
  std::vector<int> Ranks() const {
    std::vector<int> rank;
    const int n = static_cast<int>(map_.size());
    for (int i = 0; i < n; ++i) {
      const auto d = drop_rank_.find(map_.id(i));
      const auto m = declared_rank_.find(map_.id(i));
      rank.push_back(d != drop_rank_.end()
                         ? d->second
                         : (m != declared_rank_.end() ? 1000000 + m->second : 2000000 + i));
    }
    return rank;
  }
  std::vector<std::vector<int>> Neighbours() const {
    std::vector<std::vector<int>> nb;
    for (int i = 0; i < static_cast<int>(map_.size()); ++i) nb.push_back(map_.Neighbours(i));
    return nb;
  }

  void Process(const MissionRow& row) {
    const TimeS t = RowTime(row);
    if (t > pending_t_) FlushPending();
    if (!first_t_) first_t_ = t;
    last_t_ = t;
    if (const auto* e = std::get_if<MissionEvent>(&row)) {
      if (e->event == "drop" && !e->node.empty()) {
        const int i = Beacon(e->node);
        drop_rank_.emplace(e->node, static_cast<int>(drop_rank_.size()));
        auto it = agents_.find(e->agent);
        if (it != agents_.end()) {
          const auto [p, cov] = AgentEstimate(it->second);
          if (p)
            map_.SetAnchorHint(
                i, *p, *cov + Mat2::Identity() * options_.drop_sigma_m * options_.drop_sigma_m);
        }
      }
    } else if (const auto* step = std::get_if<Step>(&row)) {
      auto it = agents_.find(step->agent);
      if (it == agents_.end()) {
        throw InputError(mission_.Path("steps.csv").string(), 0,
                         "'" + step->agent + "' has steps but is not an agent");
      }
      Agent& a = it->second;
      const Vec2 d = Eigen::Rotation2Dd(a.pdr_rotation_rad) * Vec2(step->delta_n.head<2>());
      a.pdr_n += d;
      // Dead-reckoning drift for the drop hints of beacons-mds: ~5 % of the distance (1 sigma).
      a.pdr_var_m2 += std::pow(0.05 * d.norm(), 2) + step->variance_m2.value_or(Vec3::Zero()).x();
      if (a.ekf) {
        const Vec3 v = step->variance_m2.value_or(Vec3::Constant(0.0));
        Mat2 cov = Mat2::Zero();
        cov(0, 0) = v.x();
        cov(1, 1) = v.y();
        a.ekf->PredictStep(d, cov);
        FixEntryHeading(a, d);
        Emit(step->t1, a);
      } else {
        FixEntryHeading(a, d);
      }
    } else if (const auto* r = std::get_if<RangeMeasurement>(&row)) {
      if (!r->kind.empty() && r->kind != "ultrasound")
        return Ignore("ranges of another kind than ultrasound");
      const bool a_agent = agents_.count(r->a) != 0, b_agent = agents_.count(r->b) != 0;
      if (a_agent && b_agent) return Ignore("agent-to-agent ranges");
      if (!a_agent && !b_agent) {
        if (r->a == r->b) return Ignore("ranges of a node to itself");
        const int i = Beacon(r->a), j = Beacon(r->b);
        if (!map_.AddRange(i, j, r->range_m)) ++implausible_links_;
        return;
      }
      const std::string& agent = a_agent ? r->a : r->b;
      const int beacon = Beacon(a_agent ? r->b : r->a);
      agents_[agent].heard[beacon] = t;
      // A beacon without drop event or survey: anchored where an agent first passes close by.
      if (!map_.HasAnchor(beacon) && r->range_m <= options_.close_pass_m) {
        const auto [p, cov] = AgentEstimate(agents_[agent]);
        if (p) {
          map_.SetAnchorHint(beacon, *p, *cov + Mat2::Identity() * (r->range_m * r->range_m + 0.1));
          ++close_pass_anchors_;
        }
      }
      pending_.push_back({t, agent, beacon, r->range_m, r->sigma_m.value_or(0.0)});
      pending_t_ = t;
    } else if (const auto* b = std::get_if<BearingMeasurement>(&row)) {
      // Bearing from a beacon (a) to the agent (b).
      auto it = agents_.find(b->b);
      if (it == agents_.end() || agents_.count(b->a))
        return Ignore("bearings not from a beacon to an agent");
      const int beacon = Beacon(b->a);
      std::optional<PendingRange> range;
      for (auto p = pending_.begin(); p != pending_.end(); ++p) {
        if (p->agent == b->b && p->beacon == beacon && std::abs(p->t - t) < 1e-6) {
          range = *p;
          pending_.erase(p);
          break;
        }
      }
      Measure(it->second, t, beacon, range, b->bearing_rad, b->sigma_rad.value_or(0.0));
    }
    MaybeSolve(t);
  }

  void Finish() {
    FlushPending();
    if (map_.dirty())
      SolveAndEmit(last_t_);
    else
      EmitBeacons(last_t_);
  }

  BeaconMap& map() { return map_; }
  std::map<std::string, Agent>& agents() { return agents_; }
  TimeS last_t() const { return last_t_; }
  std::size_t implausible_links() const { return implausible_links_; }
  std::size_t no_position() const { return no_position_; }
  std::size_t us_kf_gated() const {
    std::size_t n = 0;
    for (const auto& [id, a] : agents_) n += a.us_kf ? a.us_kf->gated() : 0;
    return n;
  }

 private:
  std::pair<std::optional<Vec2>, std::optional<Mat2>> AgentEstimate(const Agent& a) const {
    if (a.ekf) return {a.ekf->position(), a.ekf->position_cov()};
    if (a.us_kf) return {a.us_kf->position(), a.us_kf->position_cov()};
    if (a.has_start) return {a.pdr_n, Mat2::Identity() * a.pdr_var_m2};
    return {std::nullopt, std::nullopt};
  }

  void Ignore(const std::string& reason) { ++ignored_[reason]; }

  void FixEntryHeading(Agent& a, const Vec2& d) {
    if (a.heading_fixed || !a.entry_heading_rad) return;
    a.first_track_n += d;
    if (a.first_track_n.norm() < options_.entry_track_m) return;
    a.heading_fixed = true;
    // PDR direction noise over ~1 m of steps: a few degrees on top of the entry's own sigma.
    const double sigma = std::hypot(a.entry_heading_sigma_rad, 0.05);
    const double psi =
        WrapAngle(*a.entry_heading_rad - std::atan2(a.first_track_n.y(), a.first_track_n.x()));
    if (a.ekf) {
      entry_fixes_ += a.ekf->UpdateHeadingCorrection(psi, sigma) == UpdateResult::kAccepted;
    } else if (options_.filter == Filter::kNone) {
      a.pdr_rotation_rad = psi;
      a.pdr_n = a.start_n + Eigen::Rotation2Dd(psi) * Vec2(a.pdr_n - a.start_n);
      ++entry_fixes_;
    }
  }

  void FlushPending() {
    auto pending = std::move(pending_);
    pending_.clear();
    for (const auto& p : pending) Measure(agents_[p.agent], p.t, p.beacon, p, std::nullopt, 0.0);
    pending_t_ = std::numeric_limits<double>::infinity();
  }

  void Measure(Agent& a, TimeS t, int beacon, const std::optional<PendingRange>& range,
               std::optional<double> bearing, double bearing_sigma) {
    if (options_.filter == Filter::kNone) return;
    const auto pos = map_.Position(beacon);
    if (!pos) {
      ++no_position_;
      return;
    }
    if (options_.filter == Filter::kUltrasoundOnly && !(range && bearing)) {
      return Ignore(
          "ranges or bearings without their pair (the ultrasound-only filter needs both)");
    }
    if (options_.filter == Filter::kUltrasoundOnly) {
      if (!a.us_kf) {
        if (a.has_start) {
          a.us_kf.emplace(a.pdr_n, t, options_.us_kf);
        } else {
          Vec2 z;
          Mat2 R;
          beacons::PolarToPosition(
              *pos, range->range_m, *bearing,
              range->sigma_m > 0 ? range->sigma_m : options_.us_kf.range_sigma_m,
              bearing_sigma > 0 ? bearing_sigma : options_.us_kf.bearing_sigma_rad, &z, &R);
          auto o = options_.us_kf;
          o.initial_position_sigma_m = std::sqrt(R.trace());
          a.us_kf.emplace(z, t, o);
          Emit(t, a);
          return;
        }
      }
      if (a.us_kf->UpdatePosition(t, *pos, range->range_m, *bearing, range->sigma_m,
                                  bearing_sigma) == UpdateResult::kAccepted) {
        Emit(t, a);
      }
      return;
    }
    if (!a.ekf) {
      beacons::InitMeasurement m;
      m.pdr_n = a.pdr_n;
      m.beacon_n = pos->position_n;
      if (range)
        m.range_m = range->range_m,
        m.range_sigma_m = range->sigma_m > 0 ? range->sigma_m : options_.ekf.range_sigma_m;
      else
        return;
      m.bearing_rad = bearing;
      m.bearing_sigma_rad = bearing_sigma > 0 ? bearing_sigma : options_.ekf.bearing_sigma_rad;
      a.init_buffer.push_back(m);
      const beacons::InitResult init =
          beacons::InitializeFromUltrasound(a.init_buffer, options_.init);
      if (!init.ok) {
        a.init_why = init.why;
        return;
      }
      a.ekf.emplace(beacons::StartFromInit(init, a.pdr_n, options_.ekf));
      a.initialized_at = t;
      a.init_buffer.clear();
      Emit(t, a);
      return;
    }
    bool accepted = false;
    if (options_.update == UpdateMode::kPosition && range && bearing) {
      accepted = a.ekf->UpdatePosition(*pos, range->range_m, *bearing, range->sigma_m,
                                       bearing_sigma) == UpdateResult::kAccepted;
    } else {
      if (range)
        accepted |=
            a.ekf->UpdateRange(*pos, range->range_m, range->sigma_m) == UpdateResult::kAccepted;
      if (bearing)
        accepted |= a.ekf->UpdateBearing(*pos, *bearing, bearing_sigma) == UpdateResult::kAccepted;
    }
    if (accepted) Emit(t, a);
  }

  void MaybeSolve(TimeS t) {
    if (map_.dirty() && t - last_solve_ >= options_.mds_period_s) SolveAndEmit(t);
  }

  void SolveAndEmit(TimeS t) {
    map_.Solve();
    last_solve_ = t;
    EmitBeacons(t);
  }

  void EmitBeacons(TimeS t) {
    if (sink_ == nullptr) return;
    for (int i = 0; i < static_cast<int>(map_.size()); ++i) {
      const auto p = map_.Position(i);
      if (!p) continue;
      sink_->Add({t, map_.id(i), Vec3(p->position_n.x(), p->position_n.y(), 0), p->cov(0, 0),
                  p->cov(0, 1), p->cov(1, 1)});
    }
  }

  // Agents are estimated only by the trackers (beacons-mds reports beacons alone).
  void Emit(TimeS t, const Agent& a) {
    if (sink_ == nullptr || options_.filter == Filter::kNone) return;
    const auto [p, c] = AgentEstimate(a);
    if (!p) return;
    sink_->Add({t, a.id, Vec3(p->x(), p->y(), 0), (*c)(0, 0), (*c)(0, 1), (*c)(1, 1)});
  }

  const MissionDirectory& mission_;
  TrackerOptions options_;
  BeaconMap map_;
  EstimateSink* sink_;
  PipelineSummary* summary_;
  std::map<std::string, Agent> agents_;
  std::map<std::string, std::pair<Vec2, double>> surveyed_;
  std::map<std::string, int> declared_rank_, drop_rank_;
  std::vector<PendingRange> pending_;
  TimeS pending_t_ = std::numeric_limits<double>::infinity();
  std::optional<TimeS> first_t_;
  TimeS last_t_ = 0;
  TimeS last_solve_ = -std::numeric_limits<double>::infinity();
  std::size_t implausible_links_ = 0, no_position_ = 0;

 public:
  std::map<std::string, std::size_t> ignored_;
  std::size_t close_pass_anchors_ = 0;
  std::size_t entry_fixes_ = 0;
};

TrackerOptions ParseOptions(const std::string& pipeline, bool track,
                            std::map<std::string, std::string>& rest) {
  PipelineOptions po(rest, pipeline);
  TrackerOptions o;
  o.filter = Filter::kNone;
  if (track) {
    const std::string filter = po.String("filter", "scaat");
    if (filter == "scaat")
      o.filter = Filter::kScaat;
    else if (filter == "us-only")
      o.filter = Filter::kUltrasoundOnly;
    else
      throw std::invalid_argument("pipeline " + pipeline +
                                  ": filter must be scaat or us-only, not '" + filter + "'");
    const std::string update = po.String("update", "range-bearing");
    if (update == "range-bearing")
      o.update = UpdateMode::kRangeBearing;
    else if (update == "position")
      o.update = UpdateMode::kPosition;
    else
      throw std::invalid_argument("pipeline " + pipeline +
                                  ": update must be range-bearing or position, not '" + update +
                                  "'");
    const std::string init = po.String("init", "auto");
    if (init == "ultrasound")
      o.force_init_from_ultrasound = true;
    else if (init != "auto")
      throw std::invalid_argument("pipeline " + pipeline + ": init must be auto or ultrasound");
    o.ekf.gate_sigma = po.Double("gate_sigma", o.ekf.gate_sigma);
    o.ekf.initial_heading_sigma_rad =
        po.Double("heading_sigma_rad", o.ekf.initial_heading_sigma_rad);
    o.ekf.heading_walk_rad_per_sqrt_m =
        po.Double("heading_walk_rad_per_sqrt_m", o.ekf.heading_walk_rad_per_sqrt_m);
    o.ekf.range_sigma_m = po.Double("range_sigma_m", o.ekf.range_sigma_m);
    o.ekf.bearing_sigma_rad = po.Double("bearing_sigma_rad", o.ekf.bearing_sigma_rad);
    std::string why;
    if (!o.ekf.IsValid(&why)) throw std::invalid_argument("pipeline " + pipeline + ": " + why);
  }
  const std::string positions = po.String("beacons", "auto");
  if (positions == "mds")
    o.map.mds_for_surveyed = true;
  else if (positions != "auto")
    throw std::invalid_argument("pipeline " + pipeline + ": beacons must be auto or mds");
  o.map.refine = po.Bool("refine", true);
  o.entry_track_m = po.Double("entry_track_m", o.entry_track_m);
  if (!(o.entry_track_m >= 0))
    throw std::invalid_argument("pipeline " + pipeline + ": entry_track_m must be >= 0");
  o.mds_period_s = po.Double("mds_period_s", o.mds_period_s);
  if (!(o.mds_period_s >= 0))
    throw std::invalid_argument("pipeline " + pipeline + ": mds_period_s must be >= 0");
  po.RejectUnknown();
  return o;
}

}  // namespace

PipelineSummary BeaconsPipeline::Run(const PipelineContext& context, EstimateSink& sink) const {
  const MissionDirectory& mission = context.mission;
  auto [ins_options, rest] = SplitInsOptions(context.options);
  const TrackerOptions options = ParseOptions(name(), track_, rest);
  PipelineSummary summary;
  mission.Require("ranges.csv", "the " + name() + " pipeline");
  // beacons-mds uses steps (when present) only to anchor the layout where beacons were dropped.
  const bool steps = track_ || HasSteps(mission);
  std::optional<std::vector<Step>> ins_steps;
  if (steps)
    ins_steps =
        InsStepsUnlessStepFile(mission, ins_options, "the " + name() + " pipeline", &summary);
  TrailTracker tracker(mission, options, &sink, &summary);
  MergedStream stream(mission, {.events = true,
                                .steps = steps,
                                .ranges = true,
                                .bearings = track_,
                                .rssi = false,
                                .steps_override = ins_steps ? &*ins_steps : nullptr});
  MissionRow row;
  std::size_t rows = 0;
  while (stream.Next(row)) {
    tracker.Process(row);
    if (++rows % 4096 == 0) context.progress(stream.Progress());
  }
  tracker.Finish();

  const auto& ms = tracker.map().summary();
  summary.notes.push_back(ms.BriefReport());
  for (const auto& [reason, n] : tracker.ignored_) {
    summary.notes.push_back(fmt::format("ignored {} row(s): {}", n, reason));
  }
  if (ms.unknown > 0) {
    summary.notes.push_back(fmt::format(
        "{} beacon(s) could not be placed in the navigation frame: the layout needs two surveyed "
        "beacons, or drop events with steps (the dropper's position), in its connected part",
        ms.unknown));
  }
  if (tracker.no_position() > 0) {
    summary.notes.push_back(
        fmt::format("{} ultrasound measurement(s) of beacons not yet placed were not used",
                    tracker.no_position()));
  }
  summary.numbers["beacons"] = static_cast<double>(tracker.map().size());
  summary.numbers["beacons_from_mds"] = static_cast<double>(ms.from_mds);
  summary.numbers["beacons_surveyed"] = static_cast<double>(ms.from_survey);
  summary.numbers["beacons_unplaced"] = static_cast<double>(ms.unknown);
  summary.numbers["mds_solves"] = static_cast<double>(ms.solves);
  summary.numbers["anchor_rms_m"] = ms.anchor_rms_m;
  summary.numbers["entry_heading_fixes"] = static_cast<double>(tracker.entry_fixes_);
  summary.numbers["beacons_anchored_by_close_pass"] =
      static_cast<double>(tracker.close_pass_anchors_);
  summary.numbers["implausible_beacon_links"] = static_cast<double>(tracker.implausible_links());
  if (track_) {
    summary.numbers["measurements_without_beacon_position"] =
        static_cast<double>(tracker.no_position());
    for (auto& [id, a] : tracker.agents()) {
      if (a.ekf) {
        const auto& s = a.ekf->summary();
        summary.notes.push_back(id + ": " + s.BriefReport());
        summary.numbers[id + ".range_updates"] = static_cast<double>(s.range_updates);
        summary.numbers[id + ".bearing_updates"] = static_cast<double>(s.bearing_updates);
        summary.numbers[id + ".position_updates"] = static_cast<double>(s.position_updates);
        summary.numbers[id + ".gated"] = static_cast<double>(s.gated);
        summary.numbers[id + ".heading_correction_rad"] = a.ekf->psi();
        summary.numbers[id + ".scale_correction"] = a.ekf->scale();
        if (!a.has_start) {
          summary.notes.push_back(fmt::format(
              "{}: no start; initialized from ultrasound at t = {:.2f} s", id, a.initialized_at));
          summary.numbers[id + ".initialized_at_s"] = a.initialized_at;
        }
      } else if (a.us_kf) {
        summary.numbers[id + ".position_updates"] = static_cast<double>(a.us_kf->accepted());
        summary.numbers[id + ".gated"] = static_cast<double>(a.us_kf->gated());
      } else {
        summary.notes.push_back(id + ": never initialized (" +
                                (a.init_why.empty() ? "no ultrasound measurement" : a.init_why) +
                                ")");
      }
      // The way back out from where the agent last heard beacons (sec. 4).
      std::vector<int> heard;
      for (const auto& [b, t] : a.heard) {
        if (t >= tracker.last_t() - 3.0) heard.push_back(b);
      }
      std::string why;
      const auto route = beacons::WayOut(tracker.Neighbours(), tracker.Ranks(), heard, &why);
      std::string text;
      for (int b : route) text += (text.empty() ? "" : " -> ") + tracker.map().id(b);
      if (!route.empty())
        summary.notes.push_back(id + ": way out " + text + (why.empty() ? "" : " (" + why + ")"));
      summary.numbers[id + ".way_out_hops"] = static_cast<double>(route.size());
    }
  }
  context.progress(1.0);
  return summary;
}

WayOutReport ComputeWayOut(const MissionDirectory& mission, const std::string& agent,
                           std::optional<TimeS> at_s, double window_s) {
  if (!mission.info().Find(agent) || mission.info().Find(agent)->kind != NodeKind::kAgent) {
    throw InputError(mission.Path("mission.json").string(), 0,
                     "no agent '" + agent + "' in mission.json");
  }
  mission.Require("ranges.csv", "the way out");
  std::map<std::string, std::string> none;
  TrackerOptions options = ParseOptions("wayout", false, none);
  PipelineSummary summary;
  TrailTracker tracker(mission, options, nullptr, &summary);
  // Steps (when present) place the layout where the beacons were dropped, as in beacons-mds.
  const bool steps = HasSteps(mission);
  std::optional<std::vector<Step>> ins_steps;
  if (steps) ins_steps = InsStepsUnlessStepFile(mission, {}, "the way out", &summary);
  MergedStream stream(mission, {.events = true,
                                .steps = steps,
                                .ranges = true,
                                .bearings = false,
                                .rssi = false,
                                .steps_override = ins_steps ? &*ins_steps : nullptr});
  MissionRow row;
  while (stream.Next(row)) {
    if (at_s && RowTime(row) > *at_s) break;
    tracker.Process(row);
  }
  tracker.map().Solve();
  const TimeS at = at_s.value_or(tracker.last_t());
  WayOutReport report;
  std::vector<int> heard;
  for (const auto& [b, t] : tracker.agents()[agent].heard) {
    if (t >= at - window_s) heard.push_back(b), report.heard.push_back(tracker.map().id(b));
  }
  std::string why;
  for (int b : beacons::WayOut(tracker.Neighbours(), tracker.Ranks(), heard, &why)) {
    report.route.push_back(tracker.map().id(b));
    const auto p = tracker.map().Position(b);
    report.route_positions_n.push_back(p ? std::optional<Vec2>(p->position_n) : std::nullopt);
  }
  if (!why.empty()) report.broken = why;
  return report;
}

}  // namespace trailmark

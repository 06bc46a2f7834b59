// SPDX-License-Identifier: MIT
#include "trailmark/pipelines/registry.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <cmath>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include "trailmark/beacons/trail_estimator.h"
#include "trailmark/breadcrumb/breadcrumb_estimator.h"
#include "trailmark/fusion/fusion_estimator.h"
#include "trailmark/ins/dead_reckoning.h"
#include "trailmark/ins/ins_estimator.h"
#include "trailmark/integrity/consistency.h"
#include "trailmark/integrity/dead_reckoning_guard.h"
#include "trailmark/landmarks/landmark_estimator.h"
#include "trailmark/mapmatch/map_match_estimator.h"

namespace trailmark {

namespace {

/// A pipeline's options: its estimator's, how its steps come (`ins.` keys, and `reorder_s`
/// where rows are put in time order), its dead-reckoning guard (`integrity.` keys) and the
/// floor it works on.
template <class EstimatorOptions>
struct PipelineOptions {
  EstimatorOptions estimator;
  StepFrontEndOptions steps;
  integrity::GuardOptions guard;
  integrity::StreamCheckOptions streams;
  std::optional<int> level;
};

const OptionTable<PdrOptions>& PdrOptionTable() {
  static const OptionTable<PdrOptions> table = [] {
    OptionTable<PdrOptions> t;
    t.Real("step_noise_m", &PdrOptions::default_step_noise_m, "m", OptionBounds::NonNegative(),
           "per-axis sigma of a step without variances: this + step_relative_sigma x length");
    t.Real("step_relative_sigma", &PdrOptions::default_step_relative_sigma, "",
           OptionBounds::NonNegative(), "per-axis sigma of such a step, fraction of its length");
    t.Real("start_heading_sigma_rad", &PdrOptions::start_heading_sigma_rad, "rad",
           OptionBounds::NonNegative(),
           "heading error at the start where mission.json gives no start_heading_sigma");
    t.Real("track_heading_offset_sigma_rad", &PdrOptions::track_heading_offset_sigma_rad, "rad",
           OptionBounds::NonNegative(),
           "the steps' own heading offset from the stated start heading, added in quadrature");
    t.Real("heading_drift_sigma_rad_per_s", &PdrOptions::heading_drift_sigma_rad_per_s, "rad/s",
           OptionBounds::NonNegative(),
           "heading drift rate shared by all steps (grows while standing too), 1 sigma");
    t.Real("heading_walk_sigma_rad", &PdrOptions::heading_walk_sigma_rad, "rad",
           OptionBounds::NonNegative(), "heading random walk per moving step, 1 sigma");
    t.Real("step_scale_sigma", &PdrOptions::step_scale_sigma, "", OptionBounds::NonNegative(),
           "step-length scale error shared by all steps, 1 sigma (fraction)");
    t.Real("turn_scale_sigma", &PdrOptions::turn_scale_sigma, "", OptionBounds::NonNegative(),
           "gyro scale-factor error shared by all turns, 1 sigma (fraction of the angle turned)");
    t.Real("turn_min_step_m", &PdrOptions::turn_min_step_m, "m", OptionBounds::NonNegative(),
           "steps shorter than this do not count as turns of the walking direction");
    t.Flag(
        "foot_ins.own_errors", [](PdrOptions& o) -> bool& { return o.foot_ins.own_errors; },
        "steps of a foot INS (imu.csv) with the INS's own errors: the foot_ins. sigmas and each "
        "step's yaw variance (false: the PDR's above)");
    t.Real(
        "foot_ins.heading_drift_sigma_rad_per_s",
        [](PdrOptions& o) -> double& { return o.foot_ins.heading_drift_sigma_rad_per_s; }, "rad/s",
        OptionBounds::NonNegative(), "a foot INS's heading drift rate (gyro bias after ZARU)");
    t.Real(
        "foot_ins.step_scale_sigma",
        [](PdrOptions& o) -> double& { return o.foot_ins.step_scale_sigma; }, "",
        OptionBounds::NonNegative(), "a foot INS's step-length scale error, 1 sigma");
    t.Real(
        "foot_ins.turn_scale_sigma",
        [](PdrOptions& o) -> double& { return o.foot_ins.turn_scale_sigma; }, "",
        OptionBounds::NonNegative(), "a foot INS's gyro scale-factor error over turns, 1 sigma");
    return t;
  }();
  return table;
}

enum class Front { kNone, kPerAgent, kGlobal };

/// The entry of one pipeline: typed options (defaults, table), the front end and the factory
/// of the inner estimator.
template <class E>
PipelineSpec Make(PipelineSpec spec, E defaults, const OptionTable<E>& table, Front front,
                  std::function<std::unique_ptr<OnlineEstimator>(const EstimatorInputs&,
                                                                 const E&)>
                      inner) {
  using P = PipelineOptions<E>;
  auto all = std::make_shared<OptionTable<P>>();
  all->Include("", &P::estimator, table);
  if (front == Front::kPerAgent) all->Include("", &P::steps, StepSourceOptionTable());
  if (front == Front::kGlobal) all->Include("", &P::steps, OrderedStepSourceOptionTable());
  // Every steps-based estimator's agents are moved on between rows by the front end's view.
  if (front != Front::kNone) all->Include("", &P::steps, StepViewOptionTable());
  // Every steps-based estimator but dead reckoning itself runs beside its dead-reckoning
  // shadow (integrity/dead_reckoning_guard.h).
  const bool guarded = front != Front::kNone && !spec.baseline;
  if (guarded) all->Include("", &P::guard, integrity::GuardOptionTable());
  // Every pipeline watches its streams for frozen readings (integrity/consistency.h).
  all->Include("", &P::streams, integrity::StreamCheckOptionTable());
  if (spec.needs_floor_plan) {
    all->Integer("level", &P::level, OptionBounds::Between(-1000000, 1000000),
                 "work on this floor of a multi-floor plan only",
                 "every level, each agent on its height channel's");
  }
  P default_options;
  default_options.estimator = defaults;
  spec.options = all->Describe(default_options);
  const std::string name = spec.name;
  auto parse = [all, default_options, name](const OptionValues& values) {
    P o = default_options;
    std::string why;
    if (!all->Apply(values, &o, &why)) throw std::invalid_argument("pipeline " + name + ": " + why);
    return o;
  };
  spec.floor_level = [parse](const OptionValues& values) { return parse(values).level; };
  if constexpr (requires(const E& e) { mapmatch::SearchSequenceOptions(e.sequences); }) {
    spec.search_patterns = [parse](const OptionValues& values) {
      return parse(values).estimator.sequences;
    };
  }
  const bool needs_plan = spec.needs_floor_plan;
  // The estimator and its guard, checked options: what `make` wraps and the fusion's members.
  auto guarded_inner = [parse, inner, name, needs_plan, guarded](
                           const EstimatorInputs& in,
                           const P& o) -> std::unique_ptr<OnlineEstimator> {
    std::string why;
    if constexpr (requires(const E& e) { e.IsValid(&why); }) {
      if (!o.estimator.IsValid(&why)) throw std::invalid_argument("pipeline " + name + ": " + why);
    }
    if (!o.steps.IsValid(&why)) throw std::invalid_argument("pipeline " + name + ": " + why);
    if (!o.guard.IsValid(&why) || !o.streams.IsValid(&why))
      throw std::invalid_argument("pipeline " + name + ": " + why);
    if (needs_plan && in.floor_plan == nullptr)
      throw std::invalid_argument("the " + name + " pipeline needs the incident's floor plan");
    std::unique_ptr<OnlineEstimator> estimator = inner(in, o.estimator);
    bool guard = guarded;
    if constexpr (requires(const E& e) { e.UsesMissionStart(); }) {
      guard = guard && o.estimator.UsesMissionStart();
    }
    if (guard) {
      estimator =
          std::make_unique<integrity::DeadReckoningGuard>(in.info, o.guard, std::move(estimator));
    }
    return estimator;
  };
  if (front != Front::kNone) {
    spec.make_member = [parse, guarded_inner](const EstimatorInputs& in,
                                              const OptionValues& values) {
      return guarded_inner(in, parse(values));
    };
  }
  spec.make = [parse, guarded_inner, front](const EstimatorInputs& in, const OptionValues& values,
                                            Feed feed) -> std::unique_ptr<OnlineEstimator> {
    const P o = parse(values);
    std::unique_ptr<OnlineEstimator> estimator = guarded_inner(in, o);
    if (front != Front::kNone) {
      estimator = std::make_unique<StepFrontEnd>(
          in.info, o.steps, front == Front::kGlobal ? RowOrder::kGlobal : RowOrder::kPerAgent,
          feed, std::move(estimator));
    }
    return std::make_unique<integrity::StreamCheck>(o.streams, std::move(estimator));
  };
  return spec;
}

const StreamSet kStepStreams = kStepOrImuStreams;

/// The fusion's options: its own, and which pipelines may be its members (each at its
/// defaults; the ablation turns one off).
struct FusionPipelineOptions {
  fusion::FusionOptions fusion;
  bool use_pdr = true;
  bool use_breadcrumb = true;
  bool use_beacons = true;
  bool use_landmarks = true;
  bool use_stopgo = false;
  bool use_mapmatch = true;
  bool IsValid(std::string* why) const { return fusion.IsValid(why); }
};

const OptionTable<FusionPipelineOptions>& FusionPipelineOptionTable() {
  static const OptionTable<FusionPipelineOptions> table = [] {
    using F = FusionPipelineOptions;
    OptionTable<F> t;
    t.Include("", &F::fusion, fusion::FusionOptionTable());
    t.Flag("use.pdr", &F::use_pdr,
           "member: dead reckoning (pdr), used where no other member has an estimate");
    t.Flag("use.breadcrumb", &F::use_breadcrumb,
           "member: the breadcrumb network (RSSI/ranges to crumbs and between agents)");
    t.Flag("use.beacons", &F::use_beacons,
           "member: the beacon trail's EKF (beacons-ekf), when the mission has ranges");
    t.Flag("use.landmarks", &F::use_landmarks,
           "member: the landmark filter (landmarks-ukf), with 3+ landmarks and RSSI");
    t.Flag("use.stopgo", &F::use_stopgo,
           "member: the landmarks' stop fixes (landmarks-stopgo), with 3+ landmarks, RSSI and "
           "stop/go events");
    t.Flag("use.mapmatch", &F::use_mapmatch,
           "member: map matching (mapmatch), when the mission has a floor plan");
    return t;
  }();
  return table;
}

/// The fusion's members for an incident: each allowed pipeline the mission's streams, nodes
/// and floor plan can feed, built at its defaults.
std::vector<fusion::FusionMember> FusionMembers(const EstimatorInputs& in,
                                                const FusionPipelineOptions& o,
                                                std::vector<std::string>* notes) {
  struct Candidate {
    const char* name;
    bool use;
    StreamSet evidence;  // the streams of its own evidence (fusion_estimator.h)
    int static_rank;     // whose estimates of static nodes come first (fusion_estimator.h)
  };
  const Candidate allowed[] = {
      {"breadcrumb", o.use_breadcrumb, {Stream::kRssi, Stream::kRanges}, 2},
      {"beacons-ekf", o.use_beacons, {Stream::kRanges, Stream::kBearings}, 0},
      {"landmarks-ukf", o.use_landmarks, {Stream::kRssi}, 1},
      {"landmarks-stopgo", o.use_stopgo, {Stream::kRssi}, 1},
      {"mapmatch", o.use_mapmatch, {}, 3}};
  // Members get steps from the fusion's front end: imu.csv feeds them as steps.csv does. The
  // streams only spare members that would never see their evidence (the estimates are the
  // same without them: a member is used once its evidence arrives).
  StreamSet present;
  if (in.streams) {
    present = *in.streams;
    if (present.Has(Stream::kImu)) present.Add(Stream::kSteps);
  } else {
    for (Stream s : kAllStreams) present.Add(s);
  }
  std::vector<fusion::FusionMember> members;
  for (const auto& [name, use, evidence, rank] : allowed) {
    if (!use) continue;
    const PipelineSpec& p = RequirePipeline(name);
    if (!p.make_member || !p.CanRun(in.info, present, in.floor_plan != nullptr)) continue;
    // A member that cannot use this incident (a floor plan that encloses nothing, for map
    // matching) is left out with a note; the others still run.
    try {
      members.push_back({.name = name,
                         .estimator = p.make_member(in, {}),
                         .evidence = evidence,
                         .static_rank = rank});
    } catch (const std::exception& e) {
      notes->push_back(fmt::format("{} not used: {}", name, e.what()));
    }
  }
  // Every member dead-reckons the same steps: dead reckoning of a phone's PDR adds no
  // information of its own to any of them (as a full member it pulled the fusion toward its
  // drift, its ellipse far too small), so it is used only where no other member has an
  // estimate (before any evidence, an agent no other tracks). Of a foot INS it is a full member
  // (docs/fusion.md: better than the members that correct it, and honest).
  if (o.use_pdr) {
    fusion::FusionMember dr{"pdr", RequirePipeline("pdr").make_member(in, {})};
    dr.fallback_only = true;
    dr.full_with_foot_ins = true;
    dr.static_rank = 4;
    members.push_back(std::move(dr));
  }
  return members;
}

std::vector<PipelineSpec> BuildRegistry() {
  std::vector<PipelineSpec> out;
  {
    PipelineSpec s;
    s.name = "pdr";
    s.description = "dead reckoning of PDR steps from each agent's start (baseline)";
    s.needs = {kStepStreams};
    s.uses = {Stream::kSteps, Stream::kImu, Stream::kBaro};
    s.steps_based = true;
    s.baseline = true;
    s.serve_rank = 6;
    out.push_back(Make<PdrOptions>(
        s, {}, PdrOptionTable(), Front::kPerAgent,
        [](const EstimatorInputs& in, const PdrOptions& o) {
          return std::make_unique<DeadReckoningEstimator>(in.info, o);
        }));
  }
  {
    PipelineSpec s;
    s.name = "breadcrumb";
    s.description =
        "breadcrumb paper: incremental generalized-electrical-network estimator over PDR "
        "steps, RSSI/ranges between agents and dropped crumbs (IV)";
    s.needs = {kStepStreams};
    s.uses = {Stream::kSteps, Stream::kImu, Stream::kRssi, Stream::kRanges, Stream::kEvents,
              Stream::kBaro};
    s.steps_based = true;
    s.serve_rank = 1;
    out.push_back(Make<breadcrumb::BreadcrumbEstimatorOptions>(
        s, {}, breadcrumb::BreadcrumbOptionTable(), Front::kGlobal,
        [](const EstimatorInputs& in, const breadcrumb::BreadcrumbEstimatorOptions& o) {
          return std::make_unique<breadcrumb::BreadcrumbEstimator>(in.info, o);
        }));
  }
  {
    PipelineSpec s;
    s.name = "ins";
    s.description =
        "zero-velocity-aided INS of raw foot IMU samples (ZUPT/ZARU error-state KF; detectors "
        "shoe, are, mv, mag, adaptive)";
    s.needs = {{Stream::kImu}};
    s.uses = {Stream::kImu, Stream::kBaro};
    s.serve_rank = 5;
    s.report_options = {{"output_hz", "10"}};  // the truth's rate: keeps reports small
    out.push_back(Make<ins::InsEstimatorOptions>(
        s, {}, ins::InsEstimatorOptionTable(), Front::kNone,
        [](const EstimatorInputs& in, const ins::InsEstimatorOptions& o) {
          return std::make_unique<ins::InsEstimator>(in.info, o);
        }));
  }
  for (const bool ukf : {false, true}) {
    PipelineSpec s;
    s.name = ukf ? "landmarks-ukf" : "landmarks-stopgo";
    s.description =
        ukf ? "radio-landmarks paper, continuous tracking with every RSSI answer: by default an "
              "error-state filter (ours, issue 24: PDR heading, drift, turn and step scale, each "
              "phone's path loss and each link's shadowing as states, unknown landmarks placed "
              "from the walk); filter=paper: the paper's UKF (sec. 5.4)"
            : "radio-landmarks paper: stop-and-go localization of landmarks and stops (sec. "
              "5.3, 6.2); by default the stops solved with the landmarks under the dead "
              "reckoning's joint prior and the track conditioned on them (ours, issue 21); "
              "fix_fusion=independent: the paper's re-anchoring at each stop";
    s.needs = {kStepStreams, {Stream::kRssi}};
    s.uses = {Stream::kSteps, Stream::kImu, Stream::kRssi, Stream::kEvents, Stream::kBaro};
    s.min_landmarks = 3;
    s.steps_based = true;
    if (ukf) s.serve_rank = 3;
    s.paper_scenarios = {"landmark-corridor"};
    landmarks::LandmarkEstimatorOptions defaults;
    defaults.tracking = ukf ? landmarks::Tracking::kUkf : landmarks::Tracking::kStopAndGo;
    if (!ukf) defaults.filter = landmarks::TrackingFilter::kPaper;  // no continuous tracker
    if (ukf) defaults.fix_fusion = landmarks::FixFusion::kIndependent;  // no stop fixes
    out.push_back(Make<landmarks::LandmarkEstimatorOptions>(
        s, defaults, landmarks::LandmarkOptionTable(defaults.tracking), Front::kGlobal,
        [](const EstimatorInputs& in, const landmarks::LandmarkEstimatorOptions& o) {
          return std::make_unique<landmarks::LandmarkEstimator>(in.info, o);
        }));
  }
  for (const bool track : {false, true}) {
    PipelineSpec s;
    s.name = track ? "beacons-ekf" : "beacons-mds";
    s.description =
        track ? "ultrasound-beacons paper: SCAAT EKF (position, PDR heading and scale "
                "corrections) on PDR steps and ultrasound range/bearing (sec. 6)"
              : "ultrasound-beacons paper: beacon positions by MDS with shortest-path "
                "completion and SMACOF refinement, anchored online (sec. 5)";
    s.needs = track ? std::vector<StreamSet>{kStepStreams, {Stream::kRanges}}
                    : std::vector<StreamSet>{{Stream::kRanges}};
    s.uses = {Stream::kSteps, Stream::kImu, Stream::kRanges, Stream::kEvents, Stream::kBaro};
    if (track) s.uses.Add(Stream::kBearings);
    s.steps_based = true;
    if (track) s.serve_rank = 2;
    s.paper_scenarios = {"beacon-trail"};
    beacons::BeaconTrailOptions defaults;
    defaults.tracker = track ? beacons::Tracker::kScaat : beacons::Tracker::kNone;
    out.push_back(Make<beacons::BeaconTrailOptions>(
        s, defaults, track ? beacons::BeaconTrackerOptionTable() : beacons::BeaconMapOptionTable(),
        Front::kGlobal, [](const EstimatorInputs& in, const beacons::BeaconTrailOptions& o) {
          return std::make_unique<beacons::BeaconTrailEstimator>(in.info, o);
        }));
  }
  {
    PipelineSpec s;
    s.name = "mapmatch";
    s.description =
        "map-aided search paper: particle filter on odometry and the floor plan with pseudo "
        "observations from directional-search patterns (ICP); no initial position needed";
    s.needs = {kStepStreams};
    s.uses = {Stream::kSteps, Stream::kImu, Stream::kBaro};
    s.needs_floor_plan = true;
    s.steps_based = true;
    s.raises_map_alerts = true;
    s.serve_rank = 4;
    s.paper_scenarios = {"house1-search"};
    out.push_back(Make<mapmatch::MapMatchEstimatorOptions>(
        s, {}, mapmatch::MapMatchOptionTable(), Front::kPerAgent,
        [](const EstimatorInputs& in, const mapmatch::MapMatchEstimatorOptions& o) {
          if (in.floor_levels != nullptr && in.floor_levels->size() > 1) {
            return std::make_unique<mapmatch::MapMatchEstimator>(in.info, *in.floor_levels,
                                                                 in.floor_plan_source, o);
          }
          return std::make_unique<mapmatch::MapMatchEstimator>(in.info, *in.floor_plan,
                                                               in.floor_plan_source, o);
        }));
  }
  {
    PipelineSpec s;
    s.name = "fusion";
    s.description =
        "issue 27, first part: track-to-track fusion by covariance intersection of every "
        "pipeline the mission can feed (pdr, breadcrumb, beacons-ekf, landmarks-ukf, mapmatch), "
        "members that disagree with the others left out";
    s.needs = {kStepStreams};
    s.uses = {Stream::kSteps,    Stream::kImu,    Stream::kRssi, Stream::kRanges,
              Stream::kBearings, Stream::kEvents, Stream::kBaro};
    s.uses_floor_plan = true;
    s.steps_based = true;
    s.prefers_foot_imu = true;
    s.serve_rank = 0;  // what `trailmark serve` runs unless told otherwise (issue 27)
    s.paper_scenarios = {"landmark-corridor", "beacon-trail", "house1-search"};
    out.push_back(
        Make<FusionPipelineOptions>(s, {}, FusionPipelineOptionTable(), Front::kGlobal,
                                    [](const EstimatorInputs& in, const FusionPipelineOptions& o) {
                                      std::vector<std::string> notes;
                                      auto members = FusionMembers(in, o, &notes);
                                      return std::make_unique<fusion::FusionEstimator>(
                                          in.info, o.fusion, std::move(members), std::move(notes));
                                    }));
  }
  return out;
}

std::string StreamsText(StreamSet set, const char* separator) {
  std::string text;
  for (Stream s : set.List()) text += (text.empty() ? "" : separator) + std::string(StreamFileName(s));
  return text;
}

}  // namespace

bool PipelineSpec::CanRun(const MissionInfo& info, StreamSet present, bool has_floor_plan) const {
  for (const StreamSet& alternatives : needs) {
    bool any = false;
    for (Stream s : alternatives.List()) any = any || present.Has(s);
    if (!any) return false;
  }
  if (needs_floor_plan && !has_floor_plan) return false;
  int landmarks = 0;
  for (const NodeInfo& n : info.nodes) landmarks += n.kind == NodeKind::kLandmark;
  return landmarks >= min_landmarks;
}

std::vector<std::string> PipelineSpec::NeedsText() const {
  std::vector<std::string> out;
  for (const StreamSet& alternatives : needs) out.push_back(StreamsText(alternatives, " or "));
  if (needs_floor_plan) out.push_back("floorplan.geojson (mission.json \"floorplan\")");
  if (min_landmarks > 0) out.push_back(fmt::format("{}+ landmarks in mission.json", min_landmarks));
  return out;
}

const std::vector<PipelineSpec>& Pipelines() {
  static const std::vector<PipelineSpec> registry = BuildRegistry();
  return registry;
}

const PipelineSpec* FindPipeline(std::string_view name) {
  for (const auto& p : Pipelines()) {
    if (p.name == name) return &p;
  }
  return nullptr;
}

const PipelineSpec& RequirePipeline(std::string_view name) {
  if (const PipelineSpec* p = FindPipeline(name)) return *p;
  std::string known;
  for (const auto& p : Pipelines()) known += (known.empty() ? "" : ", ") + p.name;
  throw std::invalid_argument(fmt::format("unknown pipeline '{}' (known: {})", name, known));
}

namespace {

nlohmann::json OptionJson(const OptionInfo& o) {
  nlohmann::json j = {{"key", o.key},
                      {"type", ToString(o.type)},
                      {"default", o.default_value},
                      {"unit", o.unit},
                      {"description", o.description}};
  if (o.type == OptionType::kReal || o.type == OptionType::kInteger) {
    if (std::isfinite(o.bounds.min)) j["min"] = o.bounds.min;
    if (std::isfinite(o.bounds.max)) j["max"] = o.bounds.max;
    if (o.bounds.min_open) j["min_exclusive"] = true;
    if (o.bounds.max_open) j["max_exclusive"] = true;
    j["range"] = o.bounds.Describe();
  }
  if (o.type == OptionType::kChoice) j["choices"] = o.choices;
  return j;
}

}  // namespace

std::string RegistryJson() {
  nlohmann::json all = nlohmann::json::array();
  for (const auto& p : Pipelines()) {
    nlohmann::json uses = nlohmann::json::array();
    for (Stream s : p.uses.List()) uses.push_back(std::string(StreamFileName(s)));
    nlohmann::json options = nlohmann::json::array();
    for (const auto& o : p.options) options.push_back(OptionJson(o));
    all.push_back({{"name", p.name},
                   {"description", p.description},
                   {"needs", p.NeedsText()},
                   {"uses", uses},
                   {"live", true},
                   {"capabilities",
                    {{"steps_from_imu", p.steps_based},
                     {"needs_floor_plan", p.needs_floor_plan},
                     {"raises_map_alerts", p.raises_map_alerts},
                     {"baseline", p.baseline}}},
                   {"options", options}});
  }
  return all.dump(2);
}

std::string RegistryMarkdown() {
  std::string md =
      "# Pipeline options\n\n"
      "Generated from the registry (`trailmark pipelines --markdown`; a test checks that this "
      "file is up to date). Every key is set with `--option key=value` on `trailmark run`, "
      "`serve` and `reproduce`; an unknown key, a malformed value or one out of range is an "
      "error that names the key (and, for an unknown one, the valid keys). Defaults come from "
      "each estimator's `Options` struct, which cites where they come from.\n";
  for (const auto& p : Pipelines()) {
    md += fmt::format("\n## `{}`\n\n{}.\n\nNeeds: {}. Uses when present: {}.\n\n", p.name,
                      p.description, fmt::join(p.NeedsText(), "; "), StreamsText(p.uses, ", "));
    if (p.options.empty()) {
      md += "No options.\n";
      continue;
    }
    md += "| key | type | default | unit | range | description |\n|---|---|---|---|---|---|\n";
    for (const auto& o : p.options) {
      std::string type = ToString(o.type);
      if (o.type == OptionType::kChoice) type = fmt::format("{}", fmt::join(o.choices, " \\| "));
      const std::string range =
          (o.type == OptionType::kReal || o.type == OptionType::kInteger) ? o.bounds.Describe() : "";
      md += fmt::format("| `{}` | {} | {} | {} | {} | {} |\n", o.key, type, o.default_value,
                        o.unit, range, o.description);
    }
  }
  return md;
}

}  // namespace trailmark

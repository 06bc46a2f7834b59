// SPDX-License-Identifier: MIT
#include "trailmark/breadcrumb/breadcrumb_estimator.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

namespace trailmark::breadcrumb {

bool BreadcrumbEstimatorOptions::IsValid(std::string* why) const {
  const LocalizerOptions& l = localizer;
  if (!(l.state_period_s >= 0) || !(l.max_latency_s >= 0) || !(l.encounter_sigma_m > 0) ||
      !(l.own_drop_encounter_after_s >= 0) || !(l.encounter.half_window_s >= 0) ||
      !(l.drop_sigma_m > 0) || !(l.default_range_sigma_m > 0) || !(l.gate_sigma > 0) ||
      !(l.huber_k > 0) || !(l.moved_sigma_m > 0) || !(l.max_speed_mps > 0) ||
      !(static_period_s >= 0) || !(l.solve_period_s >= 0) || !(l.covariance_period_s >= 0)) {
    if (why) *why = "sigmas, gates and periods must be positive";
    return false;
  }
  if (!(l.track_heading_offset_sigma_rad >= 0) ||
      !std::isfinite(l.track_heading_offset_sigma_rad)) {
    if (why) *why = "track_heading_offset_sigma_rad must be finite and >= 0";
    return false;
  }
  if (!(l.fixed_lag_s >= 0) || !std::isfinite(l.fixed_lag_s)) {
    if (why) *why = "fixed_lag_s must be finite and >= 0";
    return false;
  }
  if (!(l.motion_noise_scale_max >= 1) || !std::isfinite(l.motion_noise_scale_max)) {
    if (why) *why = "motion_noise_scale_max must be finite and >= 1";
    return false;
  }
  return l.integrity.IsValid(why) && dr_test.IsValid(why);
}

const OptionTable<BreadcrumbEstimatorOptions>& BreadcrumbOptionTable() {
  static const OptionTable<BreadcrumbEstimatorOptions> table = [] {
    using L = LocalizerOptions;
    OptionTable<L> t;
    const auto pos = OptionBounds::Positive(), nonneg = OptionBounds::NonNegative();
    t.Real("state_period_s", &L::state_period_s, "s", nonneg,
           "measurements closer in time share one agent state (IV-E)");
    t.Real("solve_period_s", &L::solve_period_s, "s", nonneg,
           "re-solve the network at most this often (mission time; estimates between solves: "
           "the last solution plus the PDR since; 0: at every estimate)");
    t.Real("covariance_period_s", &L::covariance_period_s, "s", nonneg,
           "refresh a node's marginal covariance at most this often (between: the last one "
           "plus the PDR's variance since; 0: at every estimate)");
    t.Real(
        "dense_fill_share", [](L& o) -> double& { return o.gen.dense_fill_share; }, "",
        OptionBounds::Between(0, 1),
        "factorize the network as a dense matrix while its sparse factor fills more than this "
        "share of the lower triangle (the same solution, faster; 1: always sparse)");
    t.Real("max_latency_s", &L::max_latency_s, "s", nonneg,
           "how long a radio measurement may wait for the PDR to cover its time");
    t.Real("step_sigma_floor_m", &L::step_sigma_floor_m, "m", nonneg,
           "floor of a step's per-axis sigma: this + step_sigma_floor_relative x length");
    t.Real("step_sigma_floor_relative", &L::step_sigma_floor_relative, "", nonneg,
           "floor of a step's per-axis sigma, fraction of its length");
    t.Flag("heading_scale", &L::estimate_heading_scale,
           "estimate each agent's PDR heading and scale correction (ours)");
    t.Real("heading_per_turn_sigma", &L::heading_per_turn_sigma, "", nonneg,
           "heading random walk per turn, fraction of its angle");
    t.Flag("gyro_scale", &L::estimate_gyro_scale,
           "estimate each agent's gyro scale-factor error (ours)");
    t.Flag("heading_rate", &L::estimate_heading_rate,
           "estimate each agent's PDR heading drift rate, walking or standing (issue 25)");
    t.Real("heading_rate_sigma0", &L::heading_rate_sigma0_rad_per_s, "rad/s", nonneg,
           "prior sigma of the heading drift rate");
    t.Real("heading_rw", &L::heading_rw_rad_per_sqrt_s, "rad/sqrt(s)", nonneg,
           "heading random walk over time");
    t.Flag(
        "foot_ins_errors", [](L& l) -> bool& { return l.foot_ins.own_errors; },
        "an agent whose steps come from a foot INS (imu.csv) moves with the INS's own errors "
        "(each step's yaw variance, step and turn scale 1 %, a fifth of the step floor); false: "
        "a phone PDR's");
    t.Real("track_heading_offset_sigma_rad", &L::track_heading_offset_sigma_rad, "rad", nonneg,
           "the steps' own heading offset, a consider parameter per agent (reported covariance "
           "only; 0: none)");
    t.Real("start_heading_sigma_floor", &L::start_heading_sigma_floor_rad, "rad", nonneg,
           "a stated start_heading_sigma below this is raised to it (0: as stated)");
    t.Flag("entry_heading", &L::entry_heading,
           "the steps' rotation into the frame measured once: the stated start_heading minus "
           "the direction of the first entry_track_m of steps (issue 25)");
    t.Real("entry_track_m", &L::entry_track_m, "m", pos, "the entry track's length");
    t.Real("entry_unstated_sigma", &L::entry_unstated_sigma_rad, "rad", pos,
           "the sigma of a start_heading given without start_heading_sigma, as a measurement");
    t.Real("entry_track_heading_sigma", &L::entry_track_heading_sigma_rad, "rad", nonneg,
           "the entry track's own direction noise");
    t.Real("entry_gate_sigma", &L::entry_gate_sigma, "", pos,
           "the entry heading's gates: the stated start heading sigma refuted, the entry not "
           "walked along the start heading");
    t.Real("entry_prior_sigma", &L::entry_prior_sigma_rad, "rad", pos,
           "the heading node's weak prior until the entry heading");
    t.Real("min_rssi_dbm", &L::min_rssi_dbm, "dBm", OptionBounds::Any(),
           "weaker packets are not range edges (mostly NLOS); the paper's channel's, see "
           "relative_rssi");
    t.Flag("relative_rssi", &L::relative_rssi_thresholds,
           "min_rssi_dbm and encounter_dbm move with this channel's level at 1 m (near-field "
           "packets after drops; else the given model's alpha)");
    t.Flag("agent_rssi", &L::use_agent_rssi, "use agent-to-node RSSI as range edges");
    t.Flag("static_rssi", &L::use_static_rssi, "use node-to-node RSSI links");
    t.Flag("encounters", &L::use_encounters, "encounters as ~1 m edges (sec. V-A)");
    t.Real("encounter_dbm", [](L& o) -> double& { return o.encounter.threshold_dbm; }, "dBm",
           OptionBounds::Any(), "an RSSI peak above this is an encounter (paper: -40 dBm)");
    t.Real("encounter_sigma_m", &L::encounter_sigma_m, "m", pos, "sigma of an encounter edge");
    t.Real(
        "encounter_window_s", [](L& o) -> double& { return o.encounter.half_window_s; }, "s",
        nonneg, "an encounter's peak is its link's strongest packet within +- this");
    t.Flag("robust_encounters", &L::robust_encounters,
           "encounters beyond Huber's constant down-weighted (IV-F), as every other measurement");
    t.Flag("encounter_places_crumbs", &L::encounter_places_crumbs,
           "a crumb no drop named enters the network at its first encounter");
    t.Real("own_drop_encounter_after_s", &L::own_drop_encounter_after_s, "s", nonneg,
           "a dropper's peak from its own crumb this soon after the drop is not an encounter");
    t.Real("drop_sigma_m", &L::drop_sigma_m, "m", pos,
           "where a dropped crumb lies around the foot");
    t.Real("range_sigma_m", &L::default_range_sigma_m, "m", pos,
           "sigma of ranges.csv rows without one");
    t.Real("agent_rssi_sigma_db", &L::agent_rssi_sigma_db, "dB", nonneg,
           "per-packet sigma of agent RSSI edges (0: agent_rssi_sigma_factor x calibrated sigma)");
    t.Real("agent_rssi_sigma_factor", &L::agent_rssi_sigma_factor, "", pos,
           "packets of a link are correlated: sigma = this x the calibrated sigma");
    t.Flag("calibrate", &L::calibrate_online,
           "fit the path-loss model online from local geometry (else mission.json's model)");
    t.Flag("truncated_rssi", &L::model_rssi_truncation,
           "packets >= min_rssi_dbm only: fitted and predicted as a truncated sample (issue 25)");
    t.Real("calibration_timeout_s", &L::calibration_timeout_s, "s", nonneg,
           "> 0: use mission.json's model when no fit after this long (0: never)");
    t.Real("rssi_nlos_k", &L::rssi_nlos_k, "", pos,
           "a packet weaker than predicted is down-weighted beyond this many sigma");
    t.Real("static_link_floor", &L::static_link_floor_fraction, "", nonneg,
           "crumb-crumb link variance floor, fraction of sigma^2");
    t.Flag("range_bias", &L::estimate_range_bias,
           "estimate a range offset (and scale) per range kind");
    t.Real("range_scale_sigma", &L::range_scale_sigma0, "", nonneg,
           "prior sigma of the range scale (0: scale fixed at 1)");
    t.Choice("rssi_offsets", &L::rssi_offsets,
             std::vector<std::pair<std::string, L::RssiOffsets>>{
                 {"innovations", L::RssiOffsets::kInnovations},
                 {"network", L::RssiOffsets::kNetwork},
                 {"off", L::RssiOffsets::kOff}},
             "an RSSI offset per crumb / landmark (issue 25): innovations: from each node's "
             "packet innovations; network: a state of the network (slow); off");
    t.Real("rssi_node_offset_sigma_db", &L::rssi_node_offset_sigma_db, "dB", pos,
           "prior sigma of a node's RSSI offset");
    t.Real("moved_min_z", [](L& o) -> double& { return o.link_change.min_z; }, "", nonneg,
           "a link's RSSI shift must also be this many of its own standard errors (0: dB only)");
    t.Real("gate_sigma", &L::gate_sigma, "", pos,
           "reject a measurement whose innovation exceeds this many sigma (IV-F)");
    t.Real("huber_k", &L::huber_k, "", pos, "Huber down-weighting beyond this many sigma");
    t.Flag("adapt_motion_noise", &L::adapt_motion_noise,
           "each agent's step and heading noise scaled up while its radio and range edges' "
           "innovations exceed one measurement's noise plus the stated position uncertainty");
    t.Real("motion_noise_scale_max", &L::motion_noise_scale_max, "", OptionBounds::AtLeast(1),
           "the largest such factor (in variance)");
    t.Flag("second_order", &L::second_order,
           "an agent's range edges carry their model's second-order terms at the nodes' "
           "uncertainty (mean shift and variance) when linearized and committed (issue 25)");
    t.Real("fixed_lag_s", &L::fixed_lag_s, "s", nonneg,
           "an agent's states of this last span stay in the network and its range edges are "
           "re-linearized at every solve until their state leaves (issue 25); 0: off");
    t.Flag("fixed_lag_rssi", &L::fixed_lag_rssi,
           "with fixed_lag_s, the agents' RSSI edges are re-linearized in the window too");
    t.Flag("detect_moved", &L::detect_moved, "detect kicked crumbs (sec. V-C)");
    t.Real("moved_sigma_m", &L::moved_sigma_m, "m", pos, "size of a kick (\"1 to 2 metres\")");
    t.Real("max_speed_mps", &L::max_speed_mps, "m/s", pos,
           "steps faster than this are dropped (IV-F)");

    t.Include("", &L::integrity, integrity::ConsistencyOptionTable());
    using O = BreadcrumbEstimatorOptions;
    OptionTable<O> out;
    out.Include("", &O::localizer, t);
    out.Real("static_period_s", &O::static_period_s, "s", nonneg,
             "how often static estimates are checked for output");
    out.Flag("gate_other_floors", &O::gate_other_floors,
             "radio between nodes on different levels is not used");
    out.Flag("dr_first", &O::dr_first,
             "an agent on a foot INS within its noise model (known start, stated heading) is "
             "written as its dead reckoning while the network does not doubt it");
    out.Include("", &O::dr_test, integrity::DeadReckoningFirstOptionTable());
    return out;
  }();
  return table;
}

BreadcrumbEstimator::BreadcrumbEstimator(const MissionInfo& info,
                                         BreadcrumbEstimatorOptions options)
    : options_(std::move(options)), info_(info), mission_levels_(info) {
  std::string why;
  if (!options_.IsValid(&why)) throw std::invalid_argument("breadcrumb: " + why);
  if (info.radio && info.radio->Complete()) {
    options_.localizer.radio = radio::LogDistanceModel::From(*info.radio);
    options_.localizer.radio_given = true;
  } else if (info.radio) {
    // A partial block is not a calibration: the default model, with the given sigma.
    if (info.radio->sigma_given) options_.localizer.radio.sigma_db = info.radio->shadowing_sigma_db;
    setup_notes_.push_back(fmt::format(
        "mission.json's radio is not a whole calibration (alpha_dbm and path_loss_exponent both "
        "needed): default log-distance model (alpha {:g} dBm at 1 m, n {:g}), sigma {:g} dB{}",
        options_.localizer.radio.alpha_dbm, options_.localizer.radio.path_loss_exponent,
        options_.localizer.radio.sigma_db, info.radio->sigma_given ? " (given)" : ""));
  } else {
    setup_notes_.push_back(
        "mission.json has no radio calibration: default log-distance model (alpha -40 dBm at "
        "1 m, n 2.3, sigma 4 dB)");
  }
  loc_ = std::make_unique<BreadcrumbLocalizer>(options_.localizer);
  for (const NodeInfo& n : info.nodes) {
    switch (n.kind) {
      case NodeKind::kAgent: {
        const auto start = info.AgentStart(n);
        loc_->AddAgent(n.id, start ? std::optional<Vec2>(start->head<2>()) : std::nullopt,
                       n.start_sigma_m.value_or(options_.localizer.known_start_sigma_m),
                       n.start_heading_sigma_rad, n.start_heading_rad);
        agents_.push_back(n.id);
        agent_z_[n.id] = start ? start->z() : 0.0;
        if (start) known_starts_.push_back(n.id);
        if (!start) {
          setup_notes_.push_back(fmt::format(
              "agent '{}' has no start: it is localized from its ranges only (1 km prior)", n.id));
        }
        break;
      }
      default:
        if (n.position) {
          loc_->AddKnownNode(n.id, n.position->head<2>(), n.position_sigma_m.value_or(0.0));
        } else {
          loc_->AddUnknownNode(n.id);
        }
    }
  }
}

BreadcrumbEstimator::~BreadcrumbEstimator() = default;

void BreadcrumbEstimator::Emit(const Estimate& e, EstimateSink& sink) {
  current_[e.id] = e;
  sink.Add(e);
}

void BreadcrumbEstimator::EmitAgent(const std::string& id, EstimateSink& sink) {
  auto e = loc_->Estimate(id);
  if (!e) return;
  const TimeS t = loc_->AgentTime(id);
  Vec2 p = e->position_n;
  Mat2 c = e->covariance;
  if (const auto it = dr_first_.find(id); it != dr_first_.end()) {
    // The verdict on the network's own covariance: the consider terms are the steps' heading
    // offset, which the dead reckoning shares.
    auto& [dr, verdict] = it->second;
    const Vec2 dr_n = dr.position_n().head<2>();
    if (auto note = verdict.Test(t, id, "the network", p, e->own_covariance, dr_n))
      dr_notes_.push_back(std::move(*note));
    c = verdict.Covariance(p, c, dr_n, dr.covariance());
    p = verdict.Position(p, dr_n);
    verdict.Count();
  }
  Emit({t, id, Vec3(p.x(), p.y(), agent_z_[id]), c(0, 0), c(0, 1), c(1, 1)}, sink);
}

void BreadcrumbEstimator::DecideDeadReckoningFirst(const Step& step) {
  if (!options_.dr_first || !step.heading_var_rad2) return;
  const NodeInfo* node = info_.Find(step.agent);
  if (!node || !node->start_heading_rad) return;
  const auto start = info_.AgentStart(*node);
  if (!start) return;
  const double start_sigma_m = node->start_sigma_m.value_or(options_.localizer.known_start_sigma_m);
  dr_first_.emplace(step.agent, DeadReckoningFirstState{
                                    DeadReckoning(*start, start_sigma_m, PdrOptions{}.ForFootIns(),
                                                  node->start_heading_sigma_rad),
                                    integrity::DeadReckoningFirst(options_.dr_test)});
  setup_notes_.push_back(fmt::format(
      "'{}': steps from a foot INS within its noise model: its dead reckoning is written until "
      "it leaves the network's {:g} % region (dr_first)",
      step.agent, 100 * options_.dr_test.reject_probability));
}

void BreadcrumbEstimator::EmitStatic(TimeS t, bool all, EstimateSink& sink) {
  if (all) {
    // Declared known nodes no measurement named: their survey, as the network would give it.
    for (const auto& [id, d] : loc_->DeclaredOnly()) {
      const double v = d.sigma_m * d.sigma_m;
      Emit({t, id, Vec3(d.position_n.x(), d.position_n.y(), 0.0), v, 0.0, v}, sink);
    }
  }
  for (const auto& id : loc_->StaticNodes()) {
    auto e = loc_->Estimate(id);
    if (!e) continue;
    auto it = last_static_.find(id);
    if (!all && it != last_static_.end() && (it->second - e->position_n).norm() < 0.02) continue;
    last_static_[id] = e->position_n;
    const Mat2& c = e->covariance;
    Emit({t, id, Vec3(e->position_n.x(), e->position_n.y(), 0.0), c(0, 0), c(0, 1), c(1, 1)},
         sink);
  }
}

void BreadcrumbEstimator::Add(const MissionRow& row, EstimateSink& sink) {
  const bool used = std::holds_alternative<Step>(row) || std::holds_alternative<RssiPacket>(row) ||
                    std::holds_alternative<RangeMeasurement>(row) ||
                    std::holds_alternative<MissionEvent>(row);
  if (!used) {
    ++ignored_;  // bearings, IMU (the StepFrontEnd turns it into steps), barometer
    return;
  }
  const TimeS t = RowTime(row);
  if (const auto* step = std::get_if<Step>(&row); step && !loc_->IsAgent(step->agent)) {
    throw std::invalid_argument(
        fmt::format("'{}' has steps but is not an agent in mission.json", step->agent));
  }
  if (!any_) {
    // Emit the known nodes (base, surveyed landmarks) and the agents' starts once, at the
    // first time in the data (a first step's t0: the start is known a priori).
    const auto* first_step = std::get_if<Step>(&row);
    const TimeS t_start = first_step ? std::min(first_step->t0, t) : t;
    EmitStatic(t_start, true, sink);
    for (const auto& id : known_starts_) {
      if (auto e = loc_->Estimate(id)) {
        const Mat2& c = e->covariance;
        Emit({t_start, id, Vec3(e->position_n.x(), e->position_n.y(), agent_z_[id]), c(0, 0),
              c(0, 1), c(1, 1)},
             sink);
      }
    }
    next_static_ = t + options_.static_period_s;
    any_ = true;
  }
  t_last_ = std::max(t_last_, t);
  const auto clock0 = std::chrono::steady_clock::now();
  if (const auto* step = std::get_if<Step>(&row)) {
    if (const auto f = foot_ins_.find(step->agent); f != foot_ins_.end()) {
      if (step->heading_var_rad2) loc_->UseFootInsMotion(step->agent);
      loc_->NoEntryHeading(step->agent);  // any foot INS: its mounting search is the entry's
      DecideDeadReckoningFirst(*step);
      foot_ins_.erase(f);  // decided at the first step
    }
    loc_->AddStep(*step);
    if (const auto it = dr_first_.find(step->agent); it != dr_first_.end()) {
      it->second.dr.AddStep(*step);
      if (!step->heading_var_rad2) {  // the IMU's mounting not found
        if (auto note = it->second.verdict.Abandon(step->t1, step->agent, "the network"))
          dr_notes_.push_back(std::move(*note));
      }
    }
    EmitAgent(step->agent, sink);
  } else if (const auto* p = std::get_if<RssiPacket>(&row)) {
    if (OnOtherFloors(p->rx, p->tx)) {
      ++other_floor_;
    } else {
      loc_->AddRssi(*p);
    }
  } else if (const auto* r = std::get_if<RangeMeasurement>(&row)) {
    if (OnOtherFloors(r->a, r->b)) {
      ++other_floor_;
    } else {
      loc_->AddRange(*r);
    }
  } else if (const auto* e = std::get_if<MissionEvent>(&row)) {
    loc_->AddEvent(*e);
  }
  if (t >= next_static_) {
    EmitStatic(t, false, sink);
    next_static_ = t + options_.static_period_s;
  }
  // Per-row latency: the row's processing plus any estimate it produced.
  latency_us_.Add(
      std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - clock0).count());
}

bool BreadcrumbEstimator::OnOtherFloors(const std::string& a, const std::string& b) const {
  return options_.gate_other_floors && mission_levels_.Differ(levels_, a, b);
}

void BreadcrumbEstimator::Finish(EstimateSink& sink) {
  loc_->Finish();
  for (const auto& id : agents_) {
    if (std::isfinite(loc_->AgentTime(id))) EmitAgent(id, sink);
  }
  // The final rows at the end of the mission (negative mission times too); with no data, at 0.
  EmitStatic(any_ ? t_last_ : 0.0, true, sink);
}

std::optional<Mat2> BreadcrumbEstimator::StepTransform(const std::string& agent) const {
  if (const auto it = dr_first_.find(agent);
      it != dr_first_.end() && it->second.verdict.doubt() < 0.5)
    return std::nullopt;  // the steps as they come: the dead reckoning is written
  return loc_->StepTransform(agent);
}

std::optional<Estimate> BreadcrumbEstimator::Current(const std::string& node) const {
  const auto it = current_.find(node);
  if (it == current_.end()) return std::nullopt;
  return it->second;
}

EstimatorSummary BreadcrumbEstimator::Summary() const {
  EstimatorSummary summary;
  summary.notes = setup_notes_;
  const auto& s = loc_->summary();
  auto& num = summary.numbers;
  num["steps"] = static_cast<double>(s.steps);
  num["steps_rejected"] = static_cast<double>(s.steps_rejected);
  num["rssi_packets"] = static_cast<double>(s.rssi_packets);
  num["rssi_below_min"] = static_cast<double>(s.rssi_weak);
  num["rssi_near_field_samples"] = static_cast<double>(s.near_field_samples);
  num["rssi_threshold_shift_db"] = s.rssi_threshold_shift_db;
  num["rssi_agent_edges"] = static_cast<double>(s.rssi_agent_used);
  num["rssi_static_packets"] = static_cast<double>(s.rssi_static_used);
  num["range_edges"] = static_cast<double>(s.ranges_used);
  num["gated"] = static_cast<double>(s.gated);
  num["refused_by_integrity"] = static_cast<double>(s.refused);
  num["refusals_blamed_on_motion"] = static_cast<double>(s.refusals_blamed_on_motion);
  loc_->node_integrity().Report(summary);
  num["downweighted"] = static_cast<double>(s.downweighted);
  num["encounters"] = static_cast<double>(s.encounters);
  num["encounters_after_own_drop"] = static_cast<double>(s.encounters_after_own_drop);
  num["crumbs_placed_by_encounters"] = static_cast<double>(s.crumbs_placed_by_encounters);
  num["encounters_downweighted"] = static_cast<double>(s.encounters_downweighted);
  num["drops"] = static_cast<double>(s.drops);
  num["moved_detected"] = static_cast<double>(s.moved_detected);
  num["agent_states"] = static_cast<double>(s.agent_states);
  num["entry_headings"] = static_cast<double>(s.entry_headings);
  num["entry_headings_refuted"] = static_cast<double>(s.entry_headings_refuted);
  num["entry_headings_refused"] = static_cast<double>(s.entry_headings_refused);
  num["delayed_initializations"] = static_cast<double>(s.delayed_initializations);
  num["static_nodes_never_localized"] = static_cast<double>(s.pending_uninitialized);
  num["unusable"] = static_cast<double>(s.unusable);
  num["factorizations"] = static_cast<double>(s.factorizations);
  num["symbolic_analyses"] = static_cast<double>(s.symbolic_analyses);
  num["dense_factorizations"] = static_cast<double>(s.dense_factorizations);
  num["sensitivity_solves"] = static_cast<double>(s.sensitivity_solves);
  num["network_dimension_max"] = s.max_dimension;
  num["factor_nonzeros_max"] = static_cast<double>(s.max_factor_nonzeros);
  num["rows_ignored"] = static_cast<double>(ignored_);
  // Per agent: the PDR corrections estimated (heading offset and scale, gyro scale and drift).
  constexpr double kDeg = 180.0 / 3.14159265358979323846;
  for (const std::string& id : loc_->AgentIds()) {
    if (const auto hs = loc_->HeadingScale(id)) {
      num[id + ".heading_correction_deg"] = hs->x() * kDeg;
      num[id + ".step_scale_error"] = hs->y();
    }
    if (const auto m = loc_->MotionNoiseScale(id)) num[id + ".motion_noise_scale"] = *m;
    if (const auto kb = loc_->GyroScaleRate(id)) {
      num[id + ".gyro_scale_error"] = kb->x();
      num[id + ".heading_rate_deg_per_min"] = kb->y() * kDeg * 60.0;
    }
  }
  // Per crumb or landmark: its RSSI offset as estimated (rssi_offsets; issue 25).
  for (const std::string& id : loc_->StaticNodes()) {
    if (const auto o = loc_->RssiOffsetDb(id)) num[id + ".rssi_offset_db"] = *o;
  }
  num["radio_other_floor"] = static_cast<double>(other_floor_);
  if (latency_us_.count() > 0) {
    num["update_latency_us_p50"] = latency_us_.Percentile(50);
    num["update_latency_us_p99"] = latency_us_.Percentile(99);
    num["update_latency_us_max"] = latency_us_.max();
  }
  num["calibrations"] = static_cast<double>(s.calibrations);
  num["calibration_pairs"] = static_cast<double>(s.calibration_pairs);
  if (s.calibration) {
    num["calibrated_alpha_dbm"] = s.calibration->model.alpha_dbm;
    num["calibrated_path_loss_exponent"] = s.calibration->model.path_loss_exponent;
    num["calibrated_sigma_db"] = s.calibration->model.sigma_db;
    num["calibrated_body_loss_db"] = s.calibration->model.body_loss_db;
  }
  for (const char* kind : {"uwb", "ultrasound", "rssi", ""}) {
    if (auto b = loc_->RangeBias(kind)) {
      num[std::string("range_offset_m_") + (*kind ? kind : "unknown")] = b->x();
      num[std::string("range_scale_") + (*kind ? kind : "unknown")] = b->y();
    }
  }
  for (const auto& n : s.notes) summary.notes.push_back(n);
  summary.integrity.insert(summary.integrity.end(), dr_notes_.begin(), dr_notes_.end());
  // dr_first: the share of the agent's estimates that are not its dead reckoning's.
  for (const auto& [id, d] : dr_first_)
    num[id + ".dr_first_network_share"] = d.verdict.share_not_dead_reckoning();
  for (const auto& [t, id] : loc_->MovedNodes()) {
    summary.notes.push_back(fmt::format("t={:.1f}: breadcrumb '{}' detected as moved", t, id));
  }
  return summary;
}

}  // namespace trailmark::breadcrumb

#include "trailmark/pipelines/breadcrumb_pipeline.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>

#include "trailmark/core/error.h"
#include "trailmark/pipelines/merged_stream.h"
#include "trailmark/pipelines/pipeline_options.h"
#include "trailmark/pipelines/step_source.h"

namespace trailmark {

using breadcrumb::BreadcrumbLocalizer;
using breadcrumb::LocalizerOptions;

LocalizerOptions BreadcrumbOptionsFrom(const std::map<std::string, std::string>& values,
                                       double* static_period_s) {
  PipelineOptions o(values, "breadcrumb");
  LocalizerOptions l;
  l.state_period_s = o.Double("state_period_s", l.state_period_s);
  l.step_sigma_floor_m = o.Double("step_sigma_floor_m", l.step_sigma_floor_m);
  l.step_sigma_floor_relative = o.Double("step_sigma_floor_relative", l.step_sigma_floor_relative);
  l.estimate_heading_scale = o.Bool("heading_scale", l.estimate_heading_scale);
  l.heading_per_turn_sigma = o.Double("heading_per_turn_sigma", l.heading_per_turn_sigma);
  l.estimate_gyro_scale = o.Bool("gyro_scale", l.estimate_gyro_scale);
  l.heading_rw_rad_per_sqrt_s = o.Double("heading_rw", l.heading_rw_rad_per_sqrt_s);
  l.max_latency_s = o.Double("max_latency_s", l.max_latency_s);
  l.min_rssi_dbm = o.Double("min_rssi_dbm", l.min_rssi_dbm);
  l.use_agent_rssi = o.Bool("agent_rssi", l.use_agent_rssi);
  l.use_static_rssi = o.Bool("static_rssi", l.use_static_rssi);
  l.use_encounters = o.Bool("encounters", l.use_encounters);
  l.encounter.threshold_dbm = o.Double("encounter_dbm", l.encounter.threshold_dbm);
  l.encounter_sigma_m = o.Double("encounter_sigma_m", l.encounter_sigma_m);
  l.drop_sigma_m = o.Double("drop_sigma_m", l.drop_sigma_m);
  l.default_range_sigma_m = o.Double("range_sigma_m", l.default_range_sigma_m);
  l.agent_rssi_sigma_db = o.Double("agent_rssi_sigma_db", l.agent_rssi_sigma_db);
  l.agent_rssi_sigma_factor = o.Double("agent_rssi_sigma_factor", l.agent_rssi_sigma_factor);
  l.calibrate_online = o.Bool("calibrate", l.calibrate_online);
  l.calibration_timeout_s = o.Double("calibration_timeout_s", l.calibration_timeout_s);
  l.rssi_nlos_k = o.Double("rssi_nlos_k", l.rssi_nlos_k);
  l.static_link_floor_fraction = o.Double("static_link_floor", l.static_link_floor_fraction);
  l.estimate_range_bias = o.Bool("range_bias", l.estimate_range_bias);
  l.range_scale_sigma0 = o.Double("range_scale_sigma", l.range_scale_sigma0);
  l.gate_sigma = o.Double("gate_sigma", l.gate_sigma);
  l.huber_k = o.Double("huber_k", l.huber_k);
  l.detect_moved = o.Bool("detect_moved", l.detect_moved);
  l.moved_sigma_m = o.Double("moved_sigma_m", l.moved_sigma_m);
  l.max_speed_mps = o.Double("max_speed_mps", l.max_speed_mps);
  const double period = o.Double("static_period_s", 1.0);
  if (static_period_s) *static_period_s = period;
  o.RejectUnknown();
  if (!(l.state_period_s >= 0) || !(l.max_latency_s >= 0) || !(l.encounter_sigma_m > 0) ||
      !(l.drop_sigma_m > 0) || !(l.default_range_sigma_m > 0) || !(l.gate_sigma > 0) ||
      !(l.huber_k > 0) || !(l.moved_sigma_m > 0) || !(l.max_speed_mps > 0) || !(period >= 0)) {
    throw std::invalid_argument("pipeline breadcrumb: sigmas, gates and periods must be positive");
  }
  return l;
}

bool BreadcrumbPipeline::CanRun(const MissionDirectory& mission) const { return HasSteps(mission); }

BreadcrumbSession::BreadcrumbSession(const MissionInfo& info,
                                     const std::map<std::string, std::string>& options,
                                     PipelineSummary* notes)
    : options_(BreadcrumbOptionsFrom(options, &static_period_s_)) {
  if (info.radio) {
    options_.radio = radio::LogDistanceModel::From(*info.radio);
  } else if (notes) {
    notes->notes.push_back(
        "mission.json has no radio calibration: default log-distance model (alpha -40 dBm at "
        "1 m, n 2.3, sigma 4 dB)");
  }
  loc_ = std::make_unique<BreadcrumbLocalizer>(options_);
  for (const NodeInfo& n : info.nodes) {
    switch (n.kind) {
      case NodeKind::kAgent: {
        const auto start = info.AgentStart(n);
        loc_->AddAgent(n.id, start ? std::optional<Vec2>(start->head<2>()) : std::nullopt,
                       n.start_sigma_m.value_or(options_.known_start_sigma_m),
                       n.start_heading_sigma_rad);
        agent_z_[n.id] = start ? start->z() : 0.0;
        if (start) known_starts_.push_back(n.id);
        if (!start && notes) {
          notes->notes.push_back(fmt::format(
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

BreadcrumbSession::~BreadcrumbSession() = default;

void BreadcrumbSession::EmitAgent(const std::string& id, EstimateSink& sink) {
  if (auto e = loc_->Estimate(id)) {
    const Mat2& c = e->covariance;
    sink.Add({loc_->AgentTime(id), id, Vec3(e->position_n.x(), e->position_n.y(), agent_z_[id]),
              c(0, 0), c(0, 1), c(1, 1)});
  }
}

void BreadcrumbSession::EmitStatic(TimeS t, bool all, EstimateSink& sink) {
  for (const auto& id : loc_->StaticNodes()) {
    auto e = loc_->Estimate(id);
    if (!e) continue;
    auto it = last_static_.find(id);
    if (!all && it != last_static_.end() && (it->second - e->position_n).norm() < 0.02) continue;
    last_static_[id] = e->position_n;
    const Mat2& c = e->covariance;
    sink.Add({t, id, Vec3(e->position_n.x(), e->position_n.y(), 0.0), c(0, 0), c(0, 1), c(1, 1)});
  }
}

void BreadcrumbSession::Add(const MissionRow& row, EstimateSink& sink) {
  const TimeS t = RowTime(row);
  if (!any_) {
    // Emit the known nodes (base, surveyed landmarks) and the agents' starts once, at the
    // first time in the data (a first step's t0: the start is known a priori).
    const auto* first_step = std::get_if<Step>(&row);
    const TimeS t_start = first_step ? std::min(first_step->t0, t) : t;
    EmitStatic(t_start, true, sink);
    for (const auto& id : known_starts_) {
      if (auto e = loc_->Estimate(id)) {
        const Mat2& c = e->covariance;
        sink.Add({t_start, id, Vec3(e->position_n.x(), e->position_n.y(), agent_z_[id]), c(0, 0),
                  c(0, 1), c(1, 1)});
      }
    }
    next_static_ = t + static_period_s_;
    any_ = true;
  }
  t_last_ = std::max(t_last_, t);
  const auto clock0 = std::chrono::steady_clock::now();
  if (const auto* step = std::get_if<Step>(&row)) {
    if (!loc_->IsAgent(step->agent)) {
      throw std::invalid_argument(
          fmt::format("'{}' has steps but is not an agent in mission.json", step->agent));
    }
    loc_->AddStep(*step);
    EmitAgent(step->agent, sink);
  } else if (const auto* p = std::get_if<RssiPacket>(&row)) {
    loc_->AddRssi(*p);
  } else if (const auto* r = std::get_if<RangeMeasurement>(&row)) {
    loc_->AddRange(*r);
  } else if (const auto* e = std::get_if<MissionEvent>(&row)) {
    loc_->AddEvent(*e);
  }
  if (t >= next_static_) {
    EmitStatic(t, false, sink);
    next_static_ = t + static_period_s_;
  }
  // Per-row latency: the row's processing plus any estimate it produced.
  latency_us_.push_back(static_cast<float>(
      std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - clock0)
          .count()));
}

void BreadcrumbSession::Finish(const MissionInfo& info, EstimateSink& sink) {
  loc_->Finish();
  for (const NodeInfo& n : info.nodes) {
    if (n.kind == NodeKind::kAgent && std::isfinite(loc_->AgentTime(n.id))) EmitAgent(n.id, sink);
  }
  EmitStatic(t_last_, true, sink);
}

void BreadcrumbSession::Summarize(PipelineSummary& summary) {
  const auto& s = loc_->summary();
  auto& num = summary.numbers;
  num["steps"] = static_cast<double>(s.steps);
  num["steps_rejected"] = static_cast<double>(s.steps_rejected);
  num["rssi_packets"] = static_cast<double>(s.rssi_packets);
  num["rssi_below_min"] = static_cast<double>(s.rssi_weak);
  num["rssi_agent_edges"] = static_cast<double>(s.rssi_agent_used);
  num["rssi_static_packets"] = static_cast<double>(s.rssi_static_used);
  num["range_edges"] = static_cast<double>(s.ranges_used);
  num["gated"] = static_cast<double>(s.gated);
  num["downweighted"] = static_cast<double>(s.downweighted);
  num["encounters"] = static_cast<double>(s.encounters);
  num["drops"] = static_cast<double>(s.drops);
  num["moved_detected"] = static_cast<double>(s.moved_detected);
  num["agent_states"] = static_cast<double>(s.agent_states);
  num["delayed_initializations"] = static_cast<double>(s.delayed_initializations);
  num["static_nodes_never_localized"] = static_cast<double>(s.pending_uninitialized);
  num["unusable"] = static_cast<double>(s.unusable);
  num["factorizations"] = static_cast<double>(s.factorizations);
  if (!latency_us_.empty()) {
    std::vector<float> l = latency_us_;
    auto pct = [&](double q) {
      const auto k = static_cast<std::size_t>(q / 100.0 * (l.size() - 1));
      std::nth_element(l.begin(), l.begin() + k, l.end());
      return static_cast<double>(l[k]);
    };
    num["update_latency_us_p50"] = pct(50);
    num["update_latency_us_p99"] = pct(99);
    num["update_latency_us_max"] = pct(100);
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
  for (const auto& [t, id] : loc_->MovedNodes()) {
    summary.notes.push_back(fmt::format("t={:.1f}: breadcrumb '{}' detected as moved", t, id));
  }
}

PipelineSummary BreadcrumbPipeline::Run(const PipelineContext& context, EstimateSink& sink) const {
  const MissionDirectory& mission = context.mission;
  const auto [ins_options, rest] = SplitInsOptions(context.options);
  PipelineSummary summary;
  BreadcrumbSession session(mission.info(), rest, &summary);
  // Steps from steps.csv, or from imu.csv through the INS (then merged from memory).
  const auto ins_steps = InsStepsUnlessStepFile(mission, ins_options, "the breadcrumb pipeline", &summary);
  MergedStream stream(mission, {.events = true, .steps = true, .ranges = true, .bearings = false,
                                .rssi = true, .steps_override = ins_steps ? &*ins_steps : nullptr});
  MissionRow row;
  std::size_t rows = 0;
  while (stream.Next(row)) {
    try {
      session.Add(row, sink);
    } catch (const std::invalid_argument& e) {
      throw InputError(mission.dir().string(), 0, e.what());
    }
    if ((++rows & 0xfff) == 0) context.progress(stream.Progress());
  }
  session.Finish(mission.info(), sink);
  context.progress(1.0);
  session.Summarize(summary);
  return summary;
}

}  // namespace trailmark

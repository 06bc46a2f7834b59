// SPDX-License-Identifier: MIT
#include "trailmark/breadcrumb/localizer.h"

#include <fmt/format.h>

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>

namespace trailmark::breadcrumb {

namespace {

Mat2 Diag(const Vec2& v) { return v.asDiagonal(); }
/// v turned by +90 degrees: d/dtheta of R(theta) v at theta = 0.
Vec2 Turn90(const Vec2& v) { return Vec2(-v.y(), v.x()); }

/// adapt_motion_noise: each node's running mean over about 10 edges (counted from 3), the
/// nodes heard in the last 30 s (at least 3), the factor's integral gain per edge (about 100
/// edges) from the agent's 20th edge on.
constexpr double kMotionNodeWeight = 0.1;
constexpr std::size_t kMotionNodeMinEdges = 3;
constexpr double kMotionNodeWindowS = 30.0;
constexpr std::size_t kMotionMinNodes = 3;
constexpr double kMotionGain = 0.01;
constexpr std::size_t kMotionWarmEdges = 20;
/// A flagged node whose mean is within this factor of the agent's median is like its peers.
constexpr double kMotionPeerFactor = 4.0;

/// The radius of a 2-D innovation's Mahalanobis distance with the tail probability of a scalar
/// residual beyond k sigma: P(chi2_2 > r^2) = exp(-r^2 / 2) = 2 (1 - Phi(k)) (1.5 -> 2.01).
double HuberRadius2d(double k) {
  const double tail = std::erfc(k / std::sqrt(2.0));
  return std::sqrt(-2.0 * std::log(std::max(tail, 1e-300)));
}

double Huber(double r, double k) {
  const double a = std::abs(r);
  return a <= k ? 0.5 * r * r : k * (a - 0.5 * k);
}

}  // namespace

BreadcrumbLocalizer::BreadcrumbLocalizer(LocalizerOptions options)
    : options_(options), gen_(options.gen), node_integrity_("node", options.integrity) {
  stated_alpha_dbm_ =
      options_.radio_given ? options_.radio.alpha_dbm : options_.paper_reference_dbm;
  UpdateRssiShift();
}

void BreadcrumbLocalizer::UpdateRssiShift() {
  if (!options_.relative_rssi_thresholds) {
    rssi_shift_db_ = 0;
    return;
  }
  double level = stated_alpha_dbm_;
  const int n = static_cast<int>(near_field_.size());
  if (n >= options_.reference_min_samples) {
    // The body loss behind the dropper: anything in [0, max] (a fit's body term is confounded
    // with its alpha when most of its pairs are behind): the middle, and half the range allowed.
    const double body_loss = 0.5 * options_.reference_body_loss_max_db;
    std::vector<double> v;
    v.reserve(near_field_.size());
    for (const NearField& s : near_field_) v.push_back(s.dbm_at_1m + body_loss * s.body_factor);
    const auto mid = v.begin() + n / 2;
    std::nth_element(v.begin(), mid, v.end());
    // The median's standard error (1.25 sigma / sqrt(m) for a normal sample), m the drops: the
    // packets of one drop, a few seconds at a few metres, share one shadowing.
    const double standard_error =
        1.25 * options_.radio.sigma_db / std::sqrt(static_cast<double>(near_field_drops_.size()));
    const double allowed = 0.5 * options_.reference_body_loss_max_db + 3.0 * standard_error;
    // Once contradicted, the statement stays refuted (no flapping at the margin).
    stated_contradicted_ = stated_contradicted_ || std::abs(*mid - stated_alpha_dbm_) > allowed;
    if (stated_contradicted_) level = *mid;
    if (std::abs(level - options_.paper_reference_dbm - rssi_shift_db_) > 1.0 &&
        summary_.notes.size() < 200) {
      summary_.notes.push_back(fmt::format(
          "t={:.1f}: RSSI thresholds {:+.1f} dB from the paper's: the drops' near-field level "
          "{:.1f} dBm at 1 m ({} packets) {} the stated {:.1f} dBm",
          now_, level - options_.paper_reference_dbm, *mid, n,
          stated_contradicted_ ? "contradicts" : "agrees with", stated_alpha_dbm_));
    }
  }
  rssi_shift_db_ = level - options_.paper_reference_dbm;
  summary_.rssi_threshold_shift_db = rssi_shift_db_;
}

void BreadcrumbLocalizer::NearFieldPacket(const Agent& a, const std::string& node, TimeS t,
                                          double rssi_dbm) {
  if (!options_.relative_rssi_thresholds) return;
  const auto it = a.dropped.find(node);
  if (it == a.dropped.end() || t < it->second || t - it->second > options_.reference_window_s)
    return;
  // The crumb lies where the foot was at the drop: its distance is the PDR's since then.
  const Vec2 to = CumAt(a, it->second, nullptr) - CumAt(a, t, nullptr);
  const double d = std::max(to.norm(), 0.5);
  if (d > options_.reference_max_distance_m || near_field_.size() >= 1000) return;
  near_field_drops_.insert({a.id, node});
  near_field_.push_back({rssi_dbm + 10.0 * options_.radio.path_loss_exponent * std::log10(d),
                         radio::BodyFactor(Vec2::Zero(), HeadingAt(a, t), to)});
  ++summary_.near_field_samples;
  UpdateRssiShift();
}

void BreadcrumbLocalizer::Enqueue(Agent& a, const Pending& q) {
  // After any of the same time: rows of equal time keep their arrival order.
  a.pending.insert(std::upper_bound(a.pending.begin(), a.pending.end(), q.t,
                                    [](TimeS v, const Pending& x) { return v < x.t; }),
                   q);
}

ScalarModel BreadcrumbLocalizer::RssiModel() const {
  ScalarModel m;
  m.kind = ScalarModel::Kind::kRssiDb;
  m.alpha_dbm = options_.radio.alpha_dbm;
  m.path_loss_exponent = options_.radio.path_loss_exponent;
  if (options_.model_rssi_truncation) {
    m.truncation_dbm = MinRssiDbm();
    m.sigma_db = options_.radio.sigma_db;
  }
  return m;
}

double BreadcrumbLocalizer::AgentRssiVariance() const {
  const double s = options_.agent_rssi_sigma_db > 0
                       ? options_.agent_rssi_sigma_db
                       : options_.agent_rssi_sigma_factor * options_.radio.sigma_db;
  return s * s;
}

void BreadcrumbLocalizer::MaybeCalibrate(TimeS t) {
  first_agent_rssi_t_ = std::min(first_agent_rssi_t_, t);
  if (!options_.calibrate_online || t < next_calibration_) return;
  if (calibration_pairs_.size() < options_.calibration_min_pairs) {
    if (!calibrated_ && options_.calibration_timeout_s > 0 &&
        t - first_agent_rssi_t_ > options_.calibration_timeout_s) {
      calibrated_ = true;  // fall back to the given model; keep collecting pairs
      summary_.notes.push_back(fmt::format(
          "t={:.1f}: too few local calibration pairs ({}): using the given radio model", t,
          calibration_pairs_.size()));
    }
    return;
  }
  next_calibration_ = t + options_.calibration_period_s;
  radio::PathLossCalibrationOptions fit_options = options_.calibration;
  if (options_.model_rssi_truncation) fit_options.truncation_dbm = MinRssiDbm();
  const radio::PathLossCalibration c = radio::CalibratePathLoss(
      calibration_pairs_, fit_options,
      summary_.calibration && calibrated_ ? &summary_.calibration->model : nullptr);
  if (c.status != radio::CalibrationStatus::kOk) return;
  options_.radio = c.fit.model;
  for (auto& [key, link] : links_) {
    if (link.edge >= 0) gen_.SetPersistentModel(link.edge, RssiModel());
  }
  summary_.calibration = c.fit;
  ++summary_.calibrations;
  calibrated_ = true;
  UpdateRssiShift();
}

void BreadcrumbLocalizer::AddKnownNode(const std::string& id, const Vec2& position_n,
                                       double sigma_m) {
  if (static_.count(id) || agents_.count(id)) return;
  declared_known_[id] = {position_n, std::max(sigma_m, 1e-3)};
}

void BreadcrumbLocalizer::AddUnknownNode(const std::string& id) {
  if (static_.count(id) || agents_.count(id)) return;
  if (const auto d = declared_known_.find(id); d != declared_known_.end()) {
    // A declared known node named by its first measurement: into the network with its prior.
    StaticNode node;
    node.id = id;
    node.known = true;
    node.index = gen_.AddNode(d->second.position_n);
    const double s = d->second.sigma_m;
    gen_.AddPrior(node.index, d->second.position_n, Mat2::Identity() * s * s);
    node.cached_cov = Mat2::Identity() * s * s;
    static_[id] = node;
    static_order_.push_back(id);
    declared_known_.erase(d);
    return;
  }
  StaticNode node;
  node.id = id;
  static_[id] = node;
}

void BreadcrumbLocalizer::AddAgent(const std::string& id, const std::optional<Vec2>& start,
                                   double start_sigma_m,
                                   std::optional<double> start_heading_sigma_rad,
                                   std::optional<double> start_heading_rad) {
  Agent a;
  a.id = id;
  const Vec2 x0 = start.value_or(Vec2::Zero());
  const double s = start ? std::max(start_sigma_m, 1e-3) : options_.unknown_start_sigma_m;
  a.state = gen_.AddNode(x0);
  gen_.AddPrior(a.state, x0, Mat2::Identity() * s * s);
  const bool entry = options_.entry_heading && options_.estimate_heading_scale &&
                     start_heading_rad.has_value() && std::isfinite(*start_heading_rad);
  if (options_.track_heading_offset_sigma_rad > 0) a.consider = gen_.AddConsider();
  a.cached_cov = Mat2::Identity() * s * s;
  if (options_.estimate_heading_scale) {
    double sh = std::max({start_heading_sigma_rad.value_or(options_.heading_sigma0_rad),
                          options_.start_heading_sigma_floor_rad, 1e-4});
    if (entry) {
      a.entry_heading_rad = *start_heading_rad;
      a.entry_heading_sigma_rad = sh;
      a.entry_value_sigma_rad =
          start_heading_sigma_rad ? sh : std::max(sh, options_.entry_unstated_sigma_rad);
      sh = std::max(options_.entry_prior_sigma_rad, sh);  // weak until the entry (EntryHeading)
    }
    a.theta = gen_.AddNode(Vec2::Zero());
    gen_.AddPrior(a.theta, Vec2::Zero(),
                  Vec2(sh * sh, options_.scale_sigma0 * options_.scale_sigma0).asDiagonal());
    if (options_.estimate_gyro_scale || options_.estimate_heading_rate) {
      // (k, b): a component not estimated is held at 0 by a prior of 1e-12.
      a.gyro = gen_.AddNode(Vec2::Zero());
      const double g = options_.estimate_gyro_scale ? options_.gyro_scale_sigma0 : 1e-6;
      // b unconnected when not estimated (G below): its prior then does not matter
      const double b = options_.estimate_heading_rate ? options_.heading_rate_sigma0_rad_per_s : 1.0;
      gen_.AddPrior(a.gyro, Vec2::Zero(), Vec2(g * g, b * b).asDiagonal());
    }
  }
  agents_[id] = std::move(a);
  ++summary_.agent_states;
}

void BreadcrumbLocalizer::UseFootInsMotion(const std::string& id) {
  const auto it = agents_.find(id);
  if (it == agents_.end() || it->second.foot_ins || !options_.foot_ins.own_errors) return;
  Agent& a = it->second;
  a.foot_ins = true;
  // A second prior N(0, c) on a component whose prior was N(0, old^2) leaves it N(0, new^2)
  // for 1/c = 1/new^2 - 1/old^2 (none where the new is not tighter); the other component gets
  // no information (a variance of 1e12).
  auto tighten = [](double old_sigma, double new_sigma) {
    const double info = 1 / (new_sigma * new_sigma) - 1 / (old_sigma * old_sigma);
    return info > 0 ? 1 / info : 0.0;
  };
  constexpr double kNone = 1e12;
  if (a.theta >= 0) {
    const double c = tighten(options_.scale_sigma0, options_.foot_ins.scale_sigma0);
    if (c > 0) gen_.AddPrior(a.theta, Vec2::Zero(), Vec2(kNone, c).asDiagonal());
  }
  if (a.gyro >= 0 && options_.estimate_gyro_scale) {
    const double c = tighten(options_.gyro_scale_sigma0, options_.foot_ins.gyro_scale_sigma0);
    if (c > 0) gen_.AddPrior(a.gyro, Vec2::Zero(), Vec2(c, kNone).asDiagonal());
  }
}

BreadcrumbLocalizer::StaticNode* BreadcrumbLocalizer::FindStatic(const std::string& id) {
  auto it = static_.find(id);
  return it == static_.end() ? nullptr : &it->second;
}

BreadcrumbLocalizer::Agent& BreadcrumbLocalizer::StartedAgent(const std::string& id, TimeS t) {
  auto it = agents_.find(id);
  if (it == agents_.end()) throw std::invalid_argument("'" + id + "' is not a known agent");
  Agent& a = it->second;
  if (!a.started) {
    a.started = true;
    a.state_t = t;
    a.knots.push_back({t, Vec2::Zero(), Vec2::Zero()});
    a.state_cum = Vec2::Zero();
    a.state_cum_var = Vec2::Zero();
  }
  return a;
}

std::vector<ConsiderRate> BreadcrumbLocalizer::Turned(const Agent& a, const Vec2& v) const {
  if (a.consider < 0) return {};
  return {{a.consider, Turn90(v)}};
}

std::optional<Mat2> BreadcrumbLocalizer::StepTransform(const std::string& id) const {
  const auto it = agents_.find(id);
  if (it == agents_.end() || it->second.theta < 0) return std::nullopt;
  const Vec2 th = gen_.Estimate(it->second.theta);
  return Mat2((1.0 + th.y()) * Eigen::Rotation2Dd(th.x()).toRotationMatrix());
}

Vec2 BreadcrumbLocalizer::Corrected(const Agent& a, const Vec2& raw) const {
  if (a.theta < 0) return raw;
  const Vec2 th = gen_.Estimate(a.theta);
  return (1.0 + th.y()) * (Eigen::Rotation2Dd(th.x()) * raw);
}

double BreadcrumbLocalizer::HeadingAt(const Agent& a, TimeS t) const {
  const auto& k = a.knots;
  auto hi = std::upper_bound(k.begin(), k.end(), t,
                             [](TimeS v, const Knot& knot) { return v < knot.t; });
  if (hi == k.end()) return k.back().heading;
  return hi->heading;
}

void BreadcrumbLocalizer::CalibrationPacket(Agent& a, const std::string& node, TimeS t,
                                            double rssi_dbm) {
  auto& history = a.link_history[node];
  history.emplace_back(t, rssi_dbm);
  while (!history.empty() && history.front().first < t - options_.calibration_window_s) {
    history.pop_front();
  }
  auto anchor = a.link_anchor.find(node);
  if (anchor == a.link_anchor.end() || std::abs(t - anchor->second) > options_.calibration_window_s) {
    return;
  }
  // The node sits where the foot was at the anchor time (drop or encounter): its position
  // relative to the agent is the PDR displacement in between.
  const Vec2 to = CumAt(a, anchor->second, nullptr) - CumAt(a, t, nullptr);
  const double d = to.norm();
  if (d < options_.calibration_min_distance_m || calibration_pairs_.size() >= 200000) return;
  calibration_pairs_.push_back({d, rssi_dbm, radio::BodyFactor(Vec2::Zero(), HeadingAt(a, t), to)});
  ++summary_.calibration_pairs;
}

void BreadcrumbLocalizer::SetCalibrationAnchor(Agent& a, const std::string& node, TimeS t) {
  if (!options_.calibrate_online) return;
  a.link_anchor[node] = t;
  // Packets heard before the anchor (approaching an encounter) were buffered.
  auto it = a.link_history.find(node);
  if (it == a.link_history.end()) return;
  const auto history = it->second;
  it->second.clear();
  for (const auto& [tp, rssi] : history) CalibrationPacket(a, node, tp, rssi);
}

double BreadcrumbLocalizer::AgentHeading(const Agent& a) const {
  const double psi = a.theta >= 0 ? gen_.Estimate(a.theta).x() : 0.0;
  return a.last_heading.value_or(0.0) + psi;
}

std::optional<Vec2> BreadcrumbLocalizer::HeadingScale(const std::string& id) const {
  auto it = agents_.find(id);
  if (it == agents_.end() || it->second.theta < 0) return std::nullopt;
  return gen_.Estimate(it->second.theta);
}

std::optional<double> BreadcrumbLocalizer::MotionNoiseScale(const std::string& id) const {
  const auto it = agents_.find(id);
  if (it == agents_.end()) return std::nullopt;
  return it->second.motion_noise_scale;
}

std::optional<Vec2> BreadcrumbLocalizer::GyroScaleRate(const std::string& id) const {
  auto it = agents_.find(id);
  if (it == agents_.end() || it->second.gyro < 0) return std::nullopt;
  return gen_.Estimate(it->second.gyro);
}

std::vector<std::string> BreadcrumbLocalizer::AgentIds() const {
  std::vector<std::string> ids;
  for (const auto& [id, a] : agents_) ids.push_back(id);
  return ids;
}

Vec2 BreadcrumbLocalizer::CumAt(const Agent& a, TimeS t, Vec2* cum_var, double* cum_turn,
                                double* cum_turn_signed, double* cum_heading_var) const {
  const auto& k = a.knots;
  auto at = [&](const Knot& knot) {
    if (cum_var) *cum_var = knot.cum_var;
    if (cum_turn) *cum_turn = knot.cum_turn;
    if (cum_turn_signed) *cum_turn_signed = knot.cum_turn_signed;
    if (cum_heading_var) *cum_heading_var = knot.cum_heading_var;
    return knot.cum;
  };
  if (t >= k.back().t) return at(k.back());
  if (t <= k.front().t) return at(k.front());
  auto hi = std::upper_bound(k.begin(), k.end(), t,
                             [](TimeS v, const Knot& knot) { return v < knot.t; });
  auto lo = hi - 1;
  const double span = hi->t - lo->t;
  const double f = span > 0 ? (t - lo->t) / span : 1.0;
  if (cum_var) *cum_var = lo->cum_var + f * (hi->cum_var - lo->cum_var);
  if (cum_turn) *cum_turn = lo->cum_turn + f * (hi->cum_turn - lo->cum_turn);
  if (cum_turn_signed) {
    *cum_turn_signed = lo->cum_turn_signed + f * (hi->cum_turn_signed - lo->cum_turn_signed);
  }
  if (cum_heading_var) {
    *cum_heading_var = lo->cum_heading_var + f * (hi->cum_heading_var - lo->cum_heading_var);
  }
  return lo->cum + f * (hi->cum - lo->cum);
}

void BreadcrumbLocalizer::AddStep(const Step& step) {
  Agent& a = StartedAgent(step.agent, step.t0);
  ++summary_.steps;
  const Vec2 d = step.delta_n.head<2>();
  const double dt = step.t1 - step.t0;
  // IV-F: a displacement no firefighter can make is dropped, not trusted.
  if (!(d.allFinite()) || d.norm() > options_.max_speed_mps * std::max(dt, 0.1)) {
    ++summary_.steps_rejected;
    if (summary_.steps_rejected <= 5) {
      summary_.notes.push_back(fmt::format("step of {} at t={:.3f} rejected: {:.2f} m in {:.3f} s",
                                           step.agent, step.t1, d.norm(), dt));
    }
    AdvanceTo(step.t1);
    return;
  }
  Knot last = a.knots.back();
  TimeS t0 = std::max(step.t0, last.t);
  if (t0 > last.t) {  // stationary gap
    a.knots.push_back({t0, last.cum, last.cum_var, last.cum_turn, last.heading,
                       last.cum_turn_signed, last.cum_heading_var});
  }
  if (a.gyro >= 0 && options_.estimate_heading_rate &&
      t0 >= a.state_t + options_.heading_rate_state_period_s) {
    // A state before this step, so that the heading drift of the time since the last one (a
    // standstill, or a walk without radio) turns this step and the next, not only the next state.
    ProcessAgent(a, t0);
    AttachState(a, t0);
  }
  double turn = 0, turn_signed = 0;
  if (d.norm() > 0.2) {
    const double h = std::atan2(d.y(), d.x());
    if (a.last_heading) {
      turn_signed = WrapAngle(h - *a.last_heading);
      turn = std::abs(turn_signed);
    }
    a.last_heading = h;
  }
  Vec2 var;
  if (step.variance_m2) {
    var = step.variance_m2->head<2>();
  } else {
    const double s = options_.default_step_sigma_m + options_.default_step_relative_sigma * d.norm();
    var = Vec2::Constant(s * s);
  }
  const auto& fi = options_.foot_ins;
  const double floor =
      a.foot_ins ? fi.step_sigma_floor_m + fi.step_sigma_floor_relative * d.norm()
                 : options_.step_sigma_floor_m + options_.step_sigma_floor_relative * d.norm();
  var = var.cwiseMax(std::max(options_.min_step_variance_m2, floor * floor));
  const double own = step.heading_var_rad2.value_or(0.0);
  const double heading_var = std::isfinite(own) ? std::max(own, 0.0) : 0.0;
  const TimeS t1 = std::max(step.t1, t0);
  if (t1 > a.knots.back().t) {
    a.knots.push_back({t1, last.cum + d, last.cum_var + var, last.cum_turn + turn,
                       a.last_heading.value_or(0.0), last.cum_turn_signed + turn_signed,
                       last.cum_heading_var + heading_var});
  } else {  // zero-duration step: fold into the last knot
    a.knots.back().cum += d;
    a.knots.back().cum_var += var;
    a.knots.back().cum_turn += turn;
    a.knots.back().cum_turn_signed += turn_signed;
    a.knots.back().cum_heading_var += heading_var;
  }
  if (a.entry_heading_rad) {
    a.entry_walked_m += d.norm();
    if (a.knots.back().cum.norm() >= options_.entry_track_m ||
        a.entry_walked_m >= 3.0 * options_.entry_track_m) {
      EntryHeading(a);
    }
  }
  AdvanceTo(step.t1);
}

void BreadcrumbLocalizer::NoEntryHeading(const std::string& id) {
  const auto it = agents_.find(id);
  if (it == agents_.end() || !it->second.entry_heading_rad) return;
  EntryHeading(it->second, /*measured=*/false);
}

void BreadcrumbLocalizer::EntryHeading(Agent& a, bool measured) {
  const double stated = a.entry_heading_sigma_rad;
  const double weak = std::max(options_.entry_prior_sigma_rad, stated);
  const double wide = std::hypot(stated, options_.track_heading_offset_sigma_rad);
  const double start_heading = *a.entry_heading_rad;
  a.entry_heading_rad.reset();
  // psi ~ N(mean, sigma^2) on the current heading node, its scale left free.
  auto psi_prior = [&](double mean, double sigma) {
    gen_.AddPrior(a.theta, Vec2(mean, 0.0), Vec2(sigma * sigma, 1e12).asDiagonal());
  };
  // The prior that makes the weak one `sigma` (information adds).
  auto prior_to = [&](double sigma) {
    if (sigma < weak) psi_prior(0.0, 1.0 / std::sqrt(1.0 / (sigma * sigma) - 1.0 / (weak * weak)));
  };
  if (!measured) {
    prior_to(stated);
    return;
  }
  const Vec2 track = a.knots.back().cum;
  if (track.norm() < options_.entry_track_m) {  // walked without leaving the start
    prior_to(wide);
    return;
  }
  // The PDR's direction over its first entry_track_m against the stated start heading: the
  // rotation of the steps into the navigation frame (their heading correction psi).
  const double m = WrapAngle(start_heading - std::atan2(track.y(), track.x()));
  const double sigma_m =
      std::hypot(a.entry_value_sigma_rad, options_.entry_track_heading_sigma_rad);
  const double deg = 180.0 / std::numbers::pi;
  if (std::abs(m) <= options_.entry_gate_sigma * std::hypot(stated, sigma_m)) {
    prior_to(stated);  // the claim holds
    psi_prior(m, sigma_m);
    ++summary_.entry_headings;
  } else if (std::abs(m) <= options_.entry_gate_sigma * std::hypot(wide, sigma_m)) {
    psi_prior(m, sigma_m);  // the claim is refuted: the measurement alone
    ++summary_.entry_headings_refuted;
    summary_.notes.push_back(fmt::format(
        "{}: its first {:.1f} m of steps are turned {:.1f} deg from the stated start heading, "
        "beyond its stated sigma ({:.1f} deg): the steps' rotation is taken from them",
        a.id, options_.entry_track_m, m * deg, stated * deg));
  } else {
    prior_to(wide);
    ++summary_.entry_headings_refused;
    summary_.notes.push_back(fmt::format(
        "{}: its first {:.1f} m of steps go {:.1f} deg from the stated start heading: not walked "
        "along it, the entry heading is not used (the stated sigma widened by the steps' own "
        "offset, {:.1f} deg)",
        a.id, options_.entry_track_m, m * deg, wide * deg));
  }
}

void BreadcrumbLocalizer::AddRssi(const RssiPacket& p) {
  ++summary_.rssi_packets;
  now_ = std::max(now_, p.t);
  const bool rx_agent = agents_.count(p.rx) != 0, tx_agent = agents_.count(p.tx) != 0;
  if (!rx_agent && !tx_agent) {  // weak static packets still feed the moved-crumb detector
    StaticPacket(p);
    return;
  }
  const std::string& agent = rx_agent ? p.rx : p.tx;
  const std::string& other = rx_agent ? p.tx : p.rx;
  if (p.rssi_dbm < MinRssiDbm()) {
    // Too weak for an edge, but the encounter detector sees that the link is weaker; from a
    // crumb its dropper has just dropped, a near-field sample.
    const auto ait = agents_.find(agent);
    if (ait != agents_.end() && ait->second.started) DetectEncounter(ait->second, other, p);
    if (options_.relative_rssi_thresholds && ait != agents_.end() && ait->second.started) {
      Agent& a = ait->second;
      const auto d = a.dropped.find(other);
      if (d != a.dropped.end() && p.t >= d->second &&
          p.t - d->second <= options_.reference_window_s) {
        Pending q{p.t, Kind::kRssi, other, p.rssi_dbm, 0, {}, true};
        Enqueue(a, q);
        AdvanceTo(p.t);
        return;
      }
    }
    ++summary_.rssi_weak;
    return;
  }
  Agent& a = StartedAgent(agent, p.t);
  if (!agents_.count(other)) AddUnknownNode(other);
  if (options_.use_agent_rssi) {
    Pending q{p.t, Kind::kRssi, other, p.rssi_dbm, 0, {}};
    Enqueue(a, q);
  }
  DetectEncounter(a, other, p);
  AdvanceTo(p.t);
}

void BreadcrumbLocalizer::DetectEncounter(Agent& a, const std::string& other, const RssiPacket& p) {
  if (!options_.use_encounters || agents_.count(other)) return;
  auto& det = encounter_.try_emplace({a.id, other}, options_.encounter).first->second;
  // The threshold is the near field's level: a node whose packets run hot by an offset (its
  // transmitter, antenna, mounting) passes it metres out unless the offset is taken off.
  double offset_db = 0;
  if (options_.rssi_offsets == LocalizerOptions::RssiOffsets::kInnovations) {
    if (const StaticNode* node = FindStatic(other)) offset_db = InnovationOffsetDb(*node);
  }
  const auto peak = det.Add(p.t, p.rssi_dbm - rssi_shift_db_ - offset_db);
  if (!peak) return;
  const auto d = a.dropped.find(other);
  if (d != a.dropped.end() && *peak >= d->second &&
      *peak - d->second < options_.own_drop_encounter_after_s) {
    // The drop's edge and the steps since (precise over seconds) already say where the crumb
    // is: such a peak adds only its own error (the walker leaving it: 2-4 m behind).
    ++summary_.encounters_after_own_drop;
    return;
  }
  Pending q{*peak, Kind::kEncounter, other, 0, 0, {}};
  Enqueue(a, q);
}

void BreadcrumbLocalizer::AddRange(const RangeMeasurement& r) {
  now_ = std::max(now_, r.t);
  const double sigma = r.sigma_m.value_or(options_.default_range_sigma_m);
  const bool a_agent = agents_.count(r.a) != 0, b_agent = agents_.count(r.b) != 0;
  if (!(r.range_m >= 0) || !(sigma > 0)) {
    ++summary_.unusable;
    return;
  }
  if (!a_agent && !b_agent) {
    StaticNode* na = FindStatic(r.a);
    StaticNode* nb = FindStatic(r.b);
    if (!na) { AddUnknownNode(r.a); na = FindStatic(r.a); }
    if (!nb) { AddUnknownNode(r.b); nb = FindStatic(r.b); }
    if (na->index >= 0 && nb->index >= 0) {
      ScalarModel m;
      AddScalarRobust(na->index, nb->index, na->cached_cov, nb->cached_cov, r.range_m,
                      sigma * sigma, m, Vec2::Zero(), options_.huber_k);
      ++summary_.ranges_used;
    } else if (na->index >= 0) {
      ObserveUninitialized(*nb, gen_.Estimate(na->index), r.range_m, sigma);
    } else if (nb->index >= 0) {
      ObserveUninitialized(*na, gen_.Estimate(nb->index), r.range_m, sigma);
    } else {
      ++summary_.unusable;
    }
    return;
  }
  const std::string& agent = a_agent ? r.a : r.b;
  const std::string& other = a_agent ? r.b : r.a;
  if (!agents_.count(other)) AddUnknownNode(other);
  Agent& a = StartedAgent(agent, r.t);
  Pending q{r.t, Kind::kRange, other, r.range_m, sigma, r.kind};
  Enqueue(a, q);
  AdvanceTo(r.t);
}

void BreadcrumbLocalizer::AddEvent(const MissionEvent& e) {
  now_ = std::max(now_, e.t);
  if (e.event == "drop" && !e.node.empty() && agents_.count(e.agent)) {
    if (agents_.count(e.node)) {
      summary_.notes.push_back(fmt::format("drop of agent '{}' ignored", e.node));
      ++summary_.unusable;
      return;
    }
    AddUnknownNode(e.node);
    Agent& a = StartedAgent(e.agent, e.t);
    a.dropped[e.node] = e.t;
    Pending q{e.t, Kind::kDrop, e.node, 0, 0, {}};
    Enqueue(a, q);
  }
  AdvanceTo(e.t);
}

void BreadcrumbLocalizer::AdvanceTo(TimeS t) {
  now_ = std::max(now_, t);
  for (auto& [id, a] : agents_) {
    if (!a.started || a.pending.empty()) continue;
    ProcessAgent(a, std::max(a.knots.back().t, now_ - options_.max_latency_s));
  }
}

void BreadcrumbLocalizer::Finish() {
  for (auto& [id, a] : agents_) {
    if (a.started) ProcessAgent(a, std::numeric_limits<double>::infinity());
  }
}

void BreadcrumbLocalizer::ProcessAgent(Agent& a, TimeS covered) {
  while (!a.pending.empty() && a.pending.front().t <= covered) {
    const Pending p = a.pending.front();
    a.pending.pop_front();
    ApplyPending(a, p);
  }
}

void BreadcrumbLocalizer::AttachState(Agent& a, TimeS t) {
  if (t < a.state_t + options_.state_period_s) return;
  // IV-E: AddNode+(new state) -> AddMeasurement(PDR) -> DeleteNode+(old state)
  Vec2 var_t;
  double turn_t = 0, turn_signed_t = 0, heading_var_t = 0;
  const Vec2 cum_t = CumAt(a, t, &var_t, &turn_t, &turn_signed_t, &heading_var_t);
  const Vec2 delta = cum_t - a.state_cum;
  const Vec2 q =
      (var_t - a.state_cum_var).cwiseMax(options_.min_step_variance_m2) * a.motion_noise_scale;
  const Vec2 predicted = Corrected(a, delta);
  // Held by the PDR edge from the state before: no regularization prior of its own.
  const NodeIndex next = gen_.AddNode(gen_.Estimate(a.state) + predicted, /*regularize=*/false);
  if (a.theta < 0) {
    gen_.AddRelative(next, a.state, delta, Diag(q), Turned(a, delta));
    const NodeIndex old_state = a.state;
    if (options_.fixed_lag_s > 0) {
      a.window.push_back({old_state, -1, a.state_t, std::move(a.state_edges)});
      a.state_edges.clear();
      a.state = next;
    } else {
      gen_.DeleteNode(old_state);
      a.state = gen_.MoveNode(next, old_state);
    }
  } else {
    // x_new - x_old - J_theta theta_old = (1 + s) R(psi) delta - J_theta theta_hat (linearized)
    const Vec2 th = gen_.Estimate(a.theta);
    const Eigen::Rotation2Dd R(th.x());
    Mat2 dR;
    dR << -std::sin(th.x()), -std::cos(th.x()), std::cos(th.x()), -std::sin(th.x());
    Mat2 J_theta;
    J_theta.col(0) = (1.0 + th.y()) * (dR * delta);
    J_theta.col(1) = R * delta;
    const Mat2 Rm = R.toRotationMatrix();
    const Mat2 cov = Rm * Diag(q) * Rm.transpose();
    const double dt = t - a.state_t;
    const double turn = turn_t - a.state_cum_turn;
    // A foot INS's heading walk is its own (the steps' yaw variance growth), else the PDR's.
    const double walk =
        a.foot_ins ? heading_var_t - a.state_cum_heading_var
                   : options_.heading_rw_rad_per_sqrt_s * options_.heading_rw_rad_per_sqrt_s * dt;
    const double per_turn =
        a.foot_ins ? options_.foot_ins.heading_per_turn_sigma : options_.heading_per_turn_sigma;
    const double scale_rw =
        a.foot_ins ? options_.foot_ins.scale_rw_per_sqrt_s : options_.scale_rw_per_sqrt_s;
    const double q_psi =
        (std::max(walk, 0.0) + std::pow(per_turn * turn, 2)) * a.motion_noise_scale;
    const double q_s = scale_rw * scale_rw * dt;
    const double turned = turn_signed_t - a.state_cum_turn_signed;
    const Vec2 kb_hat = a.gyro >= 0 ? gen_.Estimate(a.gyro) : Vec2::Zero();
    const double rate_dt = options_.estimate_heading_rate ? dt : 0.0;
    const NodeIndex next_theta =
        gen_.AddNode(th + Vec2(kb_hat.x() * turned + kb_hat.y() * rate_dt, 0.0),
                     /*regularize=*/false);
    const Mat2 Q_theta = Vec2(std::max(q_psi, 1e-12), std::max(q_s, 1e-14)).asDiagonal();
    if (a.gyro >= 0) {
      // theta_new - theta_old - (k Delta + b dt, 0) = 0: the gyro scale factor turns psi at each
      // turn, the gyro bias with time (standing included)
      Mat2 G = Mat2::Zero();
      G(0, 0) = turned;
      G(0, 1) = rate_dt;
      gen_.AddLinear({next_theta, a.theta, a.gyro}, {Mat2::Identity(), -Mat2::Identity(), -G},
                     Vec2::Zero(), Q_theta);
    } else {
      gen_.AddRelative(next_theta, a.theta, Vec2::Zero(), Q_theta);
    }
    // The observation is linear in delta: with the steps turned by the offset it moves by
    // itself at delta turned by 90 degrees.
    std::vector<ConsiderRate> rates;
    if (a.consider >= 0) {
      const Vec2 turned = Turn90(delta);
      Mat2 J_turned;
      J_turned.col(0) = (1.0 + th.y()) * (dR * turned);
      J_turned.col(1) = R * turned;
      rates.push_back({a.consider, Corrected(a, turned) - J_turned * th});
    }
    gen_.AddLinear({next, a.state, a.theta}, {Mat2::Identity(), -Mat2::Identity(), -J_theta},
                   predicted - J_theta * th, cov, rates);
    // DeleteNode+ of the old position and heading states together (one 4x4 Schur pivot).
    const NodeIndex old_theta = a.theta, old_state = a.state;
    if (options_.fixed_lag_s > 0) {
      a.window.push_back({old_state, old_theta, a.state_t, std::move(a.state_edges)});
      a.state_edges.clear();
      a.theta = next_theta;
      a.state = next;
    } else {
      gen_.DeleteNodes(old_state, old_theta);
      a.theta = gen_.MoveNode(next_theta, old_theta);
      a.state = gen_.MoveNode(next, old_state);
    }
  }
  RetireLagged(a, t);
  a.state_t = t;
  a.state_cum = cum_t;
  a.state_cum_var = var_t;
  a.state_cum_turn = turn_t;
  a.state_cum_turn_signed = turn_signed_t;
  a.state_cum_heading_var = heading_var_t;
  // The cached covariance follows the new state by its edge's variance and is then as of
  // state_cum_var: an estimate before the next refresh must not add that walk's variance again
  // (it did, found by a review 2026-12-06).
  a.cached_cov += Diag(q);
  a.cov_cum_var = var_t;
  ++summary_.agent_states;
  // Keep ~30 s of PDR history behind the state for late (encounter) measurements.
  while (a.knots.size() > 2 && a.knots[1].t < t - 30.0) a.knots.pop_front();
}

void BreadcrumbLocalizer::RetireLagged(Agent& a, TimeS t) {
  while (!a.window.empty() && a.window.front().t < t - options_.fixed_lag_s) {
    const Agent::Lagged old = std::move(a.window.front());
    a.window.pop_front();
    if (options_.second_order) {
      // The state's range edges are committed now, linearized at the current estimates: their
      // second-order terms at the uncertainty the nodes have now (the sum of the marginals,
      // as for an edge committed at once).
      // The covariances first, from one solve (adding the terms makes the network dirty).
      std::vector<std::pair<int, Mat2>> terms;
      for (const int edge : old.edges) {
        if (!gen_.IsPersistentActive(edge)) continue;
        if (terms.empty() && !gen_.Solve()) break;  // not positive definite: none added
        const auto [i, j] = gen_.PersistentNodes(edge);
        const NodeIndex other = i == old.state ? j : i;
        terms.emplace_back(edge, gen_.Covariance(other));
      }
      if (!terms.empty()) {
        const Mat2 cov_state = gen_.Covariance(old.state);
        for (const auto& [edge, cov_other] : terms)
          gen_.AddSecondOrderTerms(edge, cov_state + cov_other);
      }
    }
    if (old.theta >= 0)
      gen_.DeleteNodes(old.state, old.theta);
    else
      gen_.DeleteNode(old.state);
  }
}

std::optional<BreadcrumbLocalizer::EdgeInnovation> BreadcrumbLocalizer::AddScalarRobust(
    NodeIndex i, NodeIndex j, const Mat2& cov_i, const Mat2& cov_j, double z, double variance,
    const ScalarModel& model, const Vec2& offset, double k_negative, NodeIndex bias,
    const std::string* source, TimeS t, const Agent* agent,
    const std::vector<ConsiderRate>& rates) {
  const Vec2 diff = gen_.Estimate(i) + offset - gen_.Estimate(j);
  const double d = diff.norm();
  const Vec2 u = d > 1e-9 ? Vec2(diff / d) : Vec2(1.0, 0.0);
  const ScalarModel::Linear lin = model.Linearize(d);
  const double slope = lin.slope;
  const Vec2 bias_hat = bias >= 0 ? gen_.Estimate(bias) : Vec2::Zero();
  const Mat2 cov_sum = cov_i + cov_j;
  // An agent's edge in the fixed-lag window (not a static link: those stay as they were).
  Agent* owner = nullptr;
  if (options_.fixed_lag_s > 0 &&
      (model.kind == ScalarModel::Kind::kRange || options_.fixed_lag_rssi)) {
    for (auto& [id, ag] : agents_) owner = ag.state == i ? &ag : owner;
  }
  const bool persistent = owner != nullptr;
  const double z_raw = z, variance_raw = variance;
  if (options_.second_order && model.kind == ScalarModel::Kind::kRange) {
    // z = (1 + scale) h(d) + offset: the expected h at the nodes' uncertainty, not at their
    // estimates. Their difference's covariance is taken as the marginals' sum (the cross-
    // covariance is not formed): for ranges to beacons being placed that is the node's own,
    // but an agent and the crumbs it dropped share its PDR error, and the sum overstates
    // their difference: RSSI edges are left first-order (measured, docs/breadcrumb.md).
    const ScalarModel::SecondOrder so = model.SecondOrderTerms(diff, cov_sum);
    const double f = 1.0 + bias_hat.y();
    z -= f * so.mean_shift;
    variance += f * f * so.variance;
  }
  const double position_variance = slope * slope * u.dot(cov_sum * u);
  const double S = variance + position_variance;
  const double nu = z - (1.0 + bias_hat.y()) * lin.predicted - bias_hat.x();
  const double normalized = std::abs(nu) / std::sqrt(S);
  const EdgeInnovation edge{nu, position_variance};
  if (!std::isfinite(normalized)) {
    ++summary_.gated;
    return std::nullopt;
  }
  if (source != nullptr && !node_integrity_.Record(*source, t, nu * nu / S, 1)) {
    if (agent == nullptr || !BlameMotion(*agent, *source)) {
      ++summary_.refused;
      return edge;
    }
    ++summary_.refusals_blamed_on_motion;
  }
  if (normalized > options_.gate_sigma) {
    ++summary_.gated;
    return edge;
  }
  const double k = nu < 0 ? k_negative : options_.huber_k;
  double huber = 1.0;
  if (normalized > k) {
    huber = normalized / k;  // IV-F: lessen a noisy measurement's effect (Huber weight)
    variance *= huber;
    ++summary_.downweighted;
  }
  if (persistent) {
    // Re-linearized in the window: the model as it is; its second-order terms when committed
    // (RetireLagged), at the uncertainty its nodes have then.
    const int e =
        gen_.AddScalarPersistent(i, j, z_raw, variance_raw * huber, model, offset, bias, rates);
    if (model.kind == ScalarModel::Kind::kRange) owner->state_edges.push_back(e);
  } else {
    gen_.AddScalar(i, j, z, variance, model, offset, bias, rates);
  }
  return edge;
}

bool BreadcrumbLocalizer::BlameMotion(const Agent& a, const std::string& node) const {
  if (!options_.adapt_motion_noise || !(a.motion_median > 1.0)) return false;
  const auto it = a.motion_nis.find(node);
  return it != a.motion_nis.end() && it->second.mean <= kMotionPeerFactor * a.motion_median;
}

void BreadcrumbLocalizer::ObserveMotion(Agent& a, const std::string& node, TimeS t,
                                        const std::optional<EdgeInnovation>& edge,
                                        double measurement_variance) {
  if (!options_.adapt_motion_noise || !edge) return;
  const double cap = options_.gate_sigma * options_.gate_sigma;
  const double e2 = std::min(
      edge->nu * edge->nu / std::max(measurement_variance + edge->position_variance, 1e-12), cap);
  Agent::NodeNis& m = a.motion_nis[node];
  m.mean = m.edges == 0 ? e2 : m.mean + kMotionNodeWeight * (e2 - m.mean);
  ++m.edges;
  m.t = t;
  // The median over the nodes heard lately (each with a few edges): the agent's motion, not
  // one node, when most of them disagree.
  std::vector<double>& means = motion_means_;
  means.clear();
  for (auto it = a.motion_nis.begin(); it != a.motion_nis.end();) {
    if (it->second.t < t - kMotionNodeWindowS) {
      it = a.motion_nis.erase(it);
      continue;
    }
    if (it->second.edges >= kMotionNodeMinEdges) means.push_back(it->second.mean);
    ++it;
  }
  if (means.size() < kMotionMinNodes) {
    a.motion_median = 0;
    return;
  }
  auto mid = means.begin() + static_cast<std::ptrdiff_t>(means.size() / 2);
  std::nth_element(means.begin(), mid, means.end());
  const double median = *mid;
  a.motion_median = median;
  if (++a.motion_edges >= kMotionWarmEdges) {  // integral control toward a median of 1
    a.motion_noise_scale =
        std::clamp(a.motion_noise_scale * std::pow(std::max(median, 1e-3), kMotionGain), 1.0,
                   options_.motion_noise_scale_max);
  }
}

NodeIndex BreadcrumbLocalizer::RangeBiasNode(const std::string& kind) {
  if (!options_.estimate_range_bias) return -1;
  auto it = range_bias_.find(kind);
  if (it != range_bias_.end()) return it->second;
  const NodeIndex n = gen_.AddNode(Vec2::Zero());
  const double s = options_.range_bias_sigma0_m;
  const double ss = std::max(options_.range_scale_sigma0, 1e-6);
  gen_.AddPrior(n, Vec2::Zero(), Vec2(s * s, ss * ss).asDiagonal());
  range_bias_[kind] = n;
  return n;
}

NodeIndex BreadcrumbLocalizer::RssiOffsetNode(StaticNode& node) {
  if (options_.rssi_offsets != LocalizerOptions::RssiOffsets::kNetwork) return -1;
  if (node.rssi_offset < 0) {
    node.rssi_offset = gen_.AddNode(Vec2::Zero());
    const double s = options_.rssi_node_offset_sigma_db;
    gen_.AddPrior(node.rssi_offset, Vec2::Zero(), Vec2(s * s, 1e-12).asDiagonal());
  }
  return node.rssi_offset;
}

std::optional<double> BreadcrumbLocalizer::RssiOffsetDb(const std::string& id) const {
  const auto it = static_.find(id);
  if (it == static_.end()) return std::nullopt;
  switch (options_.rssi_offsets) {
    case LocalizerOptions::RssiOffsets::kOff:
      return std::nullopt;
    case LocalizerOptions::RssiOffsets::kInnovations:
      return InnovationOffsetDb(it->second);
    case LocalizerOptions::RssiOffsets::kNetwork:
      break;
  }
  if (it->second.rssi_offset < 0) return std::nullopt;
  return gen_.Estimate(it->second.rssi_offset).x();
}

double BreadcrumbLocalizer::InnovationOffsetDb(const StaticNode& node) const {
  const double s0 = options_.rssi_node_offset_sigma_db;
  return node.offset_sum / (node.offset_info + 1.0 / (s0 * s0));
}

std::optional<Vec2> BreadcrumbLocalizer::RangeBias(const std::string& kind) const {
  auto it = range_bias_.find(kind);
  if (it == range_bias_.end()) return std::nullopt;
  return gen_.Estimate(it->second);
}

void BreadcrumbLocalizer::ApplyPending(Agent& a, const Pending& p) {
  if (p.kind == Kind::kRssi && (p.weak || p.value < MinRssiDbm())) {
    // Too weak for an edge (a near-field sample at most): no agent state for it.
    if (FindStatic(p.other) != nullptr) NearFieldPacket(a, p.other, p.t, p.value);
    ++summary_.rssi_weak;
    return;
  }
  AttachState(a, p.t);
  Vec2 var_t;
  const Vec2 cum_t = CumAt(a, p.t, &var_t);
  const Vec2 offset = Corrected(a, cum_t - a.state_cum);
  const Vec2 offset_var = (var_t - a.state_cum_var).cwiseAbs();
  const Vec2 here = gen_.Estimate(a.state) + offset;
  const Mat2 cov_here = a.cached_cov + Diag(offset_var);

  // x_crumb - x_state = offset + e, e ~ N(0, sigma^2 + PDR variance since the state): a drop,
  // or the first encounter of a crumb no drop named and its packets have not placed yet
  auto place_here = [&](StaticNode& node, double sigma_m) {
    if (node.index >= 0)
      gen_.DeleteNode(node.index);  // picked up and dropped again
    else
      static_order_.push_back(node.id);
    node.index = gen_.AddNode(here);
    gen_.AddRelative(node.index, a.state, offset,
                     Mat2::Identity() * sigma_m * sigma_m + Diag(offset_var), Turned(a, offset));
    node.cached_cov = cov_here;
    node.init.clear();
    SetCalibrationAnchor(a, node.id, p.t);
    for (auto it = links_.begin(); it != links_.end();) {
      it = (it->first.first == node.id || it->first.second == node.id) ? links_.erase(it) : ++it;
    }
  };
  if (p.kind == Kind::kDrop) {
    if (declared_known_.count(p.other)) AddUnknownNode(p.other);  // into the network first
    StaticNode& node = static_[p.other];
    node.id = p.other;
    place_here(node, options_.drop_sigma_m);
    ++summary_.drops;
    return;
  }

  if (auto ait = agents_.find(p.other); ait != agents_.end()) {  // agent <-> agent
    Agent& b = ait->second;
    if (!b.started || &b == &a) {
      ++summary_.unusable;
      return;
    }
    Vec2 var_b;
    const Vec2 off_b = Corrected(b, CumAt(b, p.t, &var_b) - b.state_cum);
    const Mat2 cov_b = b.cached_cov + Diag((var_b - b.state_cum_var).cwiseAbs());
    ScalarModel model = p.kind == Kind::kRssi ? RssiModel() : ScalarModel{};
    double var = p.kind == Kind::kRssi ? AgentRssiVariance() : p.sigma * p.sigma;
    std::vector<ConsiderRate> rates = Turned(a, offset);
    for (const ConsiderRate& r : Turned(b, -off_b)) rates.push_back(r);
    AddScalarRobust(a.state, b.state, cov_here, cov_b, p.value, var, model, offset - off_b,
                    p.kind == Kind::kRssi ? options_.rssi_nlos_k : options_.huber_k, -1, nullptr, 0,
                    nullptr, rates);
    p.kind == Kind::kRssi ? ++summary_.rssi_agent_used : ++summary_.ranges_used;
    return;
  }

  StaticNode* node = FindStatic(p.other);
  if (!node) {
    ++summary_.unusable;
    return;
  }
  if (p.kind == Kind::kRssi) NearFieldPacket(a, p.other, p.t, p.value);
  if (node->index < 0) {
    if (p.kind == Kind::kRssi) {
      // One packet of a link carries the edges' share of the shadowing (agent_rssi_sigma_factor:
      // a link's packets are correlated), not a whole sigma_db: with sigma_db, crumbs heard
      // without a drop were initialized with ellipses that held none of their truth (issue 25).
      const auto r = radio::ToRange(options_.radio, p.value);
      const double per_packet =
          std::sqrt(AgentRssiVariance()) / std::max(options_.radio.sigma_db, 1e-6);
      ObserveUninitialized(*node, here, r.range_m, r.sigma_m * per_packet);
    } else if (p.kind == Kind::kRange) {
      const Vec2 bias = RangeBias(p.range_kind).value_or(Vec2::Zero());
      ObserveUninitialized(*node, here, (p.value - bias.x()) / (1.0 + bias.y()), p.sigma,
                           options_.estimate_range_bias);
    } else if (p.kind == Kind::kEncounter && options_.encounter_places_crumbs && !node->known) {
      // Passed within ~1 m of a crumb nothing has placed: where it lies, as a drop would say.
      place_here(*node, options_.encounter_sigma_m);
      ++summary_.encounters;
      ++summary_.crumbs_placed_by_encounters;
    }
    return;
  }
  switch (p.kind) {
    case Kind::kRssi: {
      const double body = a.last_heading ? radio::BodyFactor(here, AgentHeading(a),
                                                              gen_.Estimate(node->index))
                                         : 0.0;
      if (options_.calibrate_online) {
        CalibrationPacket(a, p.other, p.t, p.value);
        MaybeCalibrate(p.t);
        if (!calibrated_) break;
      }
      const ScalarModel model = RssiModel();
      const double d = std::max((here - gen_.Estimate(node->index)).norm(), model.min_distance_m);
      const double slope = model.Slope(d);
      const double var = AgentRssiVariance() + slope * slope * offset_var.mean();
      double z = p.value + options_.radio.body_loss_db * body;
      if (options_.rssi_offsets == LocalizerOptions::RssiOffsets::kInnovations) {
        // The node's offset from its packets before this one (prior-shrunk information-weighted
        // mean of their innovations; gross ones left out), then this packet's innovation added.
        const double o = InnovationOffsetDb(*node);
        const Vec2 diff = here - gen_.Estimate(node->index);
        const Vec2 u = diff.norm() > 1e-9 ? Vec2(diff / diff.norm()) : Vec2(1, 0);
        const double S = var + slope * slope * u.dot((cov_here + node->cached_cov) * u);
        const double nu = z - model.Linearize(diff.norm()).predicted;
        if (std::abs(nu - o) < options_.gate_sigma * std::sqrt(S)) {
          node->offset_sum += nu / S;
          node->offset_info += 1.0 / S;
        }
        z -= o;
      }
      const auto edge = AddScalarRobust(a.state, node->index, cov_here, node->cached_cov, z, var,
                                        model, offset, options_.rssi_nlos_k, RssiOffsetNode(*node),
                                        &p.other, p.t, &a, Turned(a, offset));
      // One packet's noise: the calibrated sigma (var is inflated for the link's correlation).
      ObserveMotion(
          a, p.other, p.t, edge,
          options_.radio.sigma_db * options_.radio.sigma_db + slope * slope * offset_var.mean());
      ++summary_.rssi_agent_used;
      break;
    }
    case Kind::kRange: {
      const double var = p.sigma * p.sigma + offset_var.mean();
      const auto edge = AddScalarRobust(
          a.state, node->index, cov_here, node->cached_cov, p.value, var, ScalarModel{}, offset,
          options_.huber_k, RangeBiasNode(p.range_kind), &p.other, p.t, &a, Turned(a, offset));
      ObserveMotion(a, p.other, p.t, edge, var);
      ++summary_.ranges_used;
      break;
    }
    case Kind::kEncounter: {
      // x_state + offset - x_node = 0 + e: passed within ~1 m (sec. V-A)
      const double var = options_.encounter_sigma_m * options_.encounter_sigma_m;
      const Vec2 innovation = gen_.Estimate(node->index) - here;
      const Mat2 P = cov_here + node->cached_cov;
      const Mat2 S = Mat2::Identity() * var + P;
      const double nis = innovation.dot(S.ldlt().solve(innovation));
      if (nis > options_.gate_sigma * options_.gate_sigma) {
        ++summary_.gated;
        break;
      }
      // Down-weighted beyond IV-F's Huber constant, as every other measurement is (its 2-D
      // radius: the same tail probability, 2.0 for huber_k 1.5): the innovation's covariance
      // scaled to put it on that radius, the positions' share left as it is (Chang 2014,
      // J. Geodesy 88: R~ = kappa R + (kappa - 1) P). On a poor channel peaks 10-20 m from a
      // crumb pass the threshold; at 1 m each moved the agent by nearly all of its innovation.
      // The agent's motion found beyond its stated noise (adapt_motion_noise's median over the
      // nodes it hears) explains a larger innovation: the test uses P scaled by it.
      const double motion = std::max(1.0, a.motion_median);
      const double d_test =
          motion > 1.0 ? std::sqrt(innovation.dot(
                             (Mat2::Identity() * var + P * motion).ldlt().solve(innovation)))
                       : std::sqrt(nis);
      const double kappa = options_.robust_encounters
                               ? std::max(1.0, d_test / HuberRadius2d(options_.huber_k))
                               : 1.0;
      const Mat2 R = Mat2::Identity() * (kappa * var) + (kappa - 1.0) * P;
      if (kappa > 1.0) ++summary_.encounters_downweighted;
      gen_.AddRelative(a.state, node->index, -offset, R + Diag(offset_var), Turned(a, -offset));
      ++summary_.encounters;
      SetCalibrationAnchor(a, p.other, p.t);
      break;
    }
    case Kind::kDrop:
      break;
  }
}

void BreadcrumbLocalizer::StaticPacket(const RssiPacket& p) {
  StaticNode* rx = FindStatic(p.rx);
  StaticNode* tx = FindStatic(p.tx);
  if (!rx) { AddUnknownNode(p.rx); rx = FindStatic(p.rx); }
  if (!tx) { AddUnknownNode(p.tx); tx = FindStatic(p.tx); }
  if (rx->index < 0 || tx->index < 0) {
    if (rx->index >= 0 || tx->index >= 0) {
      StaticNode& unknown = rx->index < 0 ? *rx : *tx;
      const StaticNode& known = rx->index < 0 ? *tx : *rx;
      const auto r = radio::ToRange(options_.radio, p.rssi_dbm);
      ObserveUninitialized(unknown, gen_.Estimate(known.index), r.range_m, r.sigma_m);
    }
    return;
  }
  const auto key = p.rx < p.tx ? std::make_pair(p.rx, p.tx) : std::make_pair(p.tx, p.rx);
  auto [it, fresh] = links_.try_emplace(key);
  Link& link = it->second;
  if (fresh) link.change = radio::LinkChangeDetector(options_.link_change);
  const bool use = options_.use_static_rssi && p.rssi_dbm >= MinRssiDbm() &&
                   (calibrated_ || !options_.calibrate_online);
  if (use) {
    if (link.edge < 0) {
      link.edge = gen_.AddPersistent(rx->index, tx->index, RssiModel());
      gen_.SetPersistentFloor(link.edge, options_.static_link_floor_fraction *
                                             options_.radio.sigma_db * options_.radio.sigma_db);
    }
    gen_.AccumulatePersistent(link.edge, p.rssi_dbm,
                              options_.radio.sigma_db * options_.radio.sigma_db);
    ++summary_.rssi_static_used;
  } else {
    ++summary_.rssi_weak;
  }
  if (!options_.detect_moved) return;
  if (link.change.Add(p.rssi_dbm)) {
    // Which end moved (sec. V-C)? A knocked-over crumb's antenna changes all its links the same
    // way: the mean change over the crumb's links must pass the threshold with one sign on
    // every link; a crumb with one link only is blamed when the other end's links are steady.
    // A known node (base, surveyed landmark) never moves.
    const double threshold = options_.link_change.threshold_db;
    for (StaticNode* end : {rx, tx}) {
      if (end->known) continue;
      int eligible = 0, positive = 0, negative = 0;
      double sum = 0;
      for (const auto& [k, l] : links_) {
        if ((k.first != end->id && k.second != end->id) || !l.change.Ready()) continue;
        const double c = l.change.CurrentChange();
        ++eligible;
        sum += c;
        positive += c > 0.5 * threshold;
        negative += c < -0.5 * threshold;
      }
      if (eligible == 0) continue;
      const double mean = sum / eligible;
      bool moved = false;
      if (eligible >= 2) {
        moved = std::abs(mean) > threshold && (positive == eligible || negative == eligible);
      } else {
        const std::string& other_id = end == rx ? tx->id : rx->id;
        const StaticNode* other = FindStatic(other_id);
        bool other_steady = other->known;
        for (const auto& [k, l] : links_) {
          if ((k.first != other_id && k.second != other_id) || k == key || !l.change.Ready()) continue;
          if (std::abs(l.change.CurrentChange()) < 0.5 * threshold) other_steady = true;
        }
        moved = other_steady;
      }
      if (moved) {
        MarkMoved(end->id, p.t);
        return;
      }
    }
  }
}

void BreadcrumbLocalizer::MarkMoved(const std::string& id, TimeS t) {
  StaticNode& node = static_.at(id);
  // The crumb becomes a new state tied to its old one by a kick-sized covariance: old
  // measurements stay valid for the old position (marginalized, eq. (17)).
  const NodeIndex next = gen_.AddNode(gen_.Estimate(node.index));
  gen_.AddRelative(next, node.index, Vec2::Zero(),
                   Mat2::Identity() * options_.moved_sigma_m * options_.moved_sigma_m);
  gen_.DeleteNode(node.index);
  node.index = next;
  node.cached_cov += Mat2::Identity() * options_.moved_sigma_m * options_.moved_sigma_m;
  for (auto it = links_.begin(); it != links_.end();) {
    it = (it->first.first == id || it->first.second == id) ? links_.erase(it) : ++it;
  }
  moved_.emplace_back(t, id);
  ++summary_.moved_detected;
}

void BreadcrumbLocalizer::ObserveUninitialized(StaticNode& node, const Vec2& from, double range_m,
                                               double sigma_m, bool biased) {
  if (!(range_m >= 0) || !(sigma_m > 0) || !from.allFinite()) return;
  if (node.init.size() >= 2000) return;  // plenty: keep memory bounded
  node.init.push_back({from, range_m, sigma_m, biased});
  TryInitialize(node);
}

void BreadcrumbLocalizer::TryInitialize(StaticNode& node) {
  const int n = static_cast<int>(node.init.size());
  if (n < options_.init_min_measurements) return;
  if (n < node.next_try) return;
  node.next_try = std::max(n + 1, static_cast<int>(n * 1.25));
  Vec2 lo = node.init[0].from, hi = lo, mean = Vec2::Zero();
  double max_range = 0;
  for (const auto& o : node.init) {
    lo = lo.cwiseMin(o.from);
    hi = hi.cwiseMax(o.from);
    mean += o.from;
    max_range = std::max(max_range, o.range_m);
  }
  mean /= n;
  if ((hi - lo).norm() < options_.init_min_spread_m) return;
  const double reach = std::min(max_range, 150.0) + 2.0;
  lo.array() -= reach;
  hi.array() += reach;
  const double step = std::max(options_.init_grid_m, (hi - lo).maxCoeff() / 200.0);
  // IV-F: the same Huber constant as every other measurement of the network.
  const double k = options_.huber_k;
  auto weight = [k](double r) { return std::abs(r) <= k ? 1.0 : k / std::abs(r); };
  auto cost = [&](const Vec2& x) {
    double c = 0;
    for (const auto& o : node.init) c += Huber(((x - o.from).norm() - o.range_m) / o.sigma_m, k);
    return c;
  };
  Vec2 best = mean;
  double best_cost = std::numeric_limits<double>::infinity();
  std::vector<std::pair<Vec2, double>> cells;
  for (double x = lo.x(); x <= hi.x(); x += step) {
    for (double y = lo.y(); y <= hi.y(); y += step) {
      const Vec2 c(x, y);
      const double v = cost(c);
      cells.emplace_back(c, v);
      if (v < best_cost) best_cost = v, best = c;
    }
  }
  // Gauss-Newton with Huber weights (IRLS) from the best cell.
  Mat2 H = Mat2::Identity();
  for (int it = 0; it < 20; ++it) {
    H.setZero();
    Vec2 g = Vec2::Zero();
    for (const auto& o : node.init) {
      const Vec2 diff = best - o.from;
      const double d = std::max(diff.norm(), 1e-6);
      const Vec2 J = diff / d;
      const double r = (o.range_m - d) / o.sigma_m;
      const double w = weight(r) / (o.sigma_m * o.sigma_m);
      H += w * J * J.transpose();
      g += w * J * (o.range_m - d);
    }
    H += Mat2::Identity() * 1e-9;
    const Vec2 dx = H.ldlt().solve(g);
    best += dx;
    if (dx.norm() < 1e-4) break;
  }
  best_cost = cost(best);
  double mirror = std::numeric_limits<double>::infinity();
  const double exclusion = std::max(3.0, 3.0 * step);
  for (const auto& [c, v] : cells) {
    if ((c - best).norm() > exclusion) mirror = std::min(mirror, v);
  }
  if (mirror - best_cost < options_.init_ambiguity_chi2) return;  // still ambiguous
  // With an unknown range offset, the prior is the (x, y) marginal of the (x, y, offset)
  // information at the solution, the offset having its prior sigma: radial directions, which
  // trade off against the offset, stay loose.
  Eigen::Matrix4d H4 = Eigen::Matrix4d::Zero();
  bool any_biased = false;
  for (const auto& o : node.init) {
    const Vec2 diff = best - o.from;
    const double d = std::max(diff.norm(), 1e-6);
    const double r = (o.range_m - d) / o.sigma_m;
    const double w = weight(r) / (o.sigma_m * o.sigma_m);
    const Eigen::Vector4d J(diff.x() / d, diff.y() / d, o.biased ? 1.0 : 0.0, o.biased ? d : 0.0);
    H4 += w * J * J.transpose();
    any_biased = any_biased || o.biased;
  }
  H4(2, 2) += 1.0 / (options_.range_bias_sigma0_m * options_.range_bias_sigma0_m);
  H4(3, 3) += 1.0 / std::pow(std::max(options_.range_scale_sigma0, 1e-6), 2);
  H4 += Eigen::Matrix4d::Identity() * 1e-9;
  const Mat2 cov = (any_biased ? Mat2(H4.inverse().topLeftCorner<2, 2>()) : Mat2(H.inverse())) *
                   options_.init_covariance_inflation;
  if (!cov.allFinite() || cov.trace() > 1e4) return;
  node.index = gen_.AddNode(best);
  gen_.AddPrior(node.index, best, cov);
  node.cached_cov = cov;
  node.init.clear();
  node.init.shrink_to_fit();
  static_order_.push_back(node.id);
  ++summary_.delayed_initializations;
}

bool BreadcrumbLocalizer::SolveThrottled() {
  if (!gen_.dirty()) return true;
  if (options_.solve_period_s > 0 && now_ - last_solve_t_ < options_.solve_period_s) return false;
  gen_.Solve();
  last_solve_t_ = now_;
  return true;
}

std::optional<NodeEstimate> BreadcrumbLocalizer::Estimate(const std::string& id) {
  if (auto it = agents_.find(id); it != agents_.end()) {
    Agent& a = it->second;
    const bool fresh = SolveThrottled();
    if (options_.covariance_period_s <= 0 ||
        (fresh && now_ - a.cov_t >= options_.covariance_period_s)) {
      if (a.theta >= 0) {
        const Eigen::Matrix4d joint = gen_.JointCovariance(a.state, a.theta);
        a.cached_cov = joint.topLeftCorner<2, 2>();
        a.cached_cross = joint.topRightCorner<2, 2>();
        a.cached_theta = joint.bottomRightCorner<2, 2>();
      } else {
        a.cached_cov = gen_.Covariance(a.state);
      }
      a.cov_t = now_;
      a.cov_cum_var = a.state_cum_var;
      if (SensitivitiesDue()) {
        const int C = gen_.considers();
        a.cached_sens_state.assign(C, Vec2::Zero());
        a.cached_sens_theta.assign(C, Vec2::Zero());
        for (int c = 0; c < C; ++c) {
          a.cached_sens_state[c] = gen_.Sensitivity(a.state, c);
          if (a.theta >= 0) a.cached_sens_theta[c] = gen_.Sensitivity(a.theta, c);
        }
        a.sens_state_cum = a.state_cum;
      }
    } else if (a.state_cum_var != a.cov_cum_var) {  // the state moved on: add its PDR variance
      a.cached_cov += Diag((a.state_cum_var - a.cov_cum_var).cwiseAbs());
      a.cov_cum_var = a.state_cum_var;
    }
    Vec2 var;
    Vec2 cum = a.started ? CumAt(a, a.knots.back().t, &var) : Vec2::Zero();
    if (!a.started) var = Vec2::Zero();
    NodeEstimate e;
    e.id = id;
    const Vec2 walked = cum - a.state_cum;  // the PDR since the state, as measured
    e.position_n = gen_.Estimate(a.state) + Corrected(a, walked);
    e.covariance = a.cached_cov + Diag((var - a.state_cum_var).cwiseAbs());
    if (a.theta >= 0 && walked.squaredNorm() > 0) {
      // p = x + (1 + s) R(psi) walked: the walk since the state turns and stretches with the
      // heading/scale node's error (first order), correlated with the state's own error.
      const Vec2 th = gen_.Estimate(a.theta);
      const Eigen::Rotation2Dd R(th.x());
      const Vec2 turned = R * walked;
      Mat2 J;
      J.col(0) = (1.0 + th.y()) * Vec2(-turned.y(), turned.x());
      J.col(1) = turned;
      const Mat2 cross = a.cached_cross * J.transpose();
      e.covariance += J * a.cached_theta * J.transpose() + cross + cross.transpose();
      e.covariance = 0.5 * (e.covariance + e.covariance.transpose());
    }
    e.own_covariance = e.covariance;
    if (a.started) e.covariance += ConsiderCovariance(a, cum);
    return e;
  }
  StaticNode* node = FindStatic(id);
  if (!node || node->index < 0) return std::nullopt;
  const bool fresh = SolveThrottled();
  if (options_.covariance_period_s <= 0 ||
      (fresh && now_ - node->cov_t >= options_.covariance_period_s)) {
    node->cached_cov = gen_.Covariance(node->index);
    if (SensitivitiesDue()) {
      node->cached_consider.setZero();
      const double sigma = options_.track_heading_offset_sigma_rad;
      for (int c = 0; c < gen_.considers(); ++c) {
        const Vec2 s = gen_.Sensitivity(node->index, c);
        node->cached_consider += sigma * sigma * s * s.transpose();
      }
    }
    node->cov_t = now_;
  }
  return NodeEstimate{id, gen_.Estimate(node->index), node->cached_cov + node->cached_consider,
                      node->cached_cov};
}

bool BreadcrumbLocalizer::SensitivitiesDue() {
  // While edges wait for a solve a state may be new in its slot: keep the last values (with
  // the PDR displacement they were for) until the network is solved.
  if (gen_.considers() == 0 || gen_.dirty()) return false;
  if (gen_.sensitivities_current()) return true;
  if (options_.covariance_period_s > 0 && now_ - last_sensitivity_t_ < options_.covariance_period_s)
    return false;
  last_sensitivity_t_ = now_;
  return true;
}

Mat2 BreadcrumbLocalizer::ConsiderCovariance(const Agent& a, const Vec2& cum) const {
  // p = x_state + (1 + s) R(psi) W, W the PDR walked since the state of the last refresh: its
  // sensitivity to parameter c is the state's, the heading node's through the walk, and (its
  // own agent's) the walk itself turned.
  Mat2 out = Mat2::Zero();
  const int C = gen_.considers();
  if (C == 0) return out;
  const Vec2 walked = cum - a.sens_state_cum;
  Mat2 J = Mat2::Zero();
  if (a.theta >= 0) {
    const Vec2 th = gen_.Estimate(a.theta);
    const Vec2 turned = Eigen::Rotation2Dd(th.x()) * walked;
    J.col(0) = (1.0 + th.y()) * Turn90(turned);
    J.col(1) = turned;
  }
  const double sigma = options_.track_heading_offset_sigma_rad;
  const auto cached = [](const std::vector<Vec2>& v, int c) {
    return static_cast<std::size_t>(c) < v.size() ? v[c] : Vec2::Zero();  // not refreshed yet
  };
  for (int c = 0; c < C; ++c) {
    Vec2 s = cached(a.cached_sens_state, c) + J * cached(a.cached_sens_theta, c);
    if (c == a.consider) s += Corrected(a, Turn90(walked));
    out += sigma * sigma * s * s.transpose();
  }
  return out;
}

TimeS BreadcrumbLocalizer::AgentTime(const std::string& id) const {
  const Agent& a = agents_.at(id);
  return a.started ? a.knots.back().t : -std::numeric_limits<double>::infinity();
}

LocalizerSummary BreadcrumbLocalizer::summary() const {
  LocalizerSummary s = summary_;
  s.factorizations = gen_.factorizations();
  s.symbolic_analyses = gen_.symbolic_analyses();
  s.dense_factorizations = gen_.dense_factorizations();
  s.sensitivity_solves = gen_.sensitivity_solves();
  s.max_dimension = gen_.max_dimension();
  s.max_factor_nonzeros = gen_.max_factor_nonzeros();
  s.pending_uninitialized = 0;
  for (const auto& [id, n] : static_) s.pending_uninitialized += n.index < 0 ? 1 : 0;
  return s;
}

}  // namespace trailmark::breadcrumb

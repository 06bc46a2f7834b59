// SPDX-License-Identifier: MIT
#include "trailmark/ins/dead_reckoning.h"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <Eigen/LU>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace trailmark {

bool PdrOptions::IsValid(std::string* why) const {
  for (double x :
       {default_step_noise_m, default_step_relative_sigma, start_heading_sigma_rad,
        track_heading_offset_sigma_rad, heading_drift_sigma_rad_per_s, heading_walk_sigma_rad,
        step_scale_sigma, turn_scale_sigma, turn_min_step_m, foot_ins.heading_drift_sigma_rad_per_s,
        foot_ins.step_scale_sigma, foot_ins.turn_scale_sigma}) {
    if (!(x >= 0) || !std::isfinite(x)) {
      if (why) {
        *why =
            "step noise, heading, drift, scale and turn-scale sigmas and the turn's minimum "
            "step must be finite and >= 0";
      }
      return false;
    }
  }
  return true;
}

double PdrOptions::StartHeadingSigma(std::optional<double> stated_rad) const {
  return std::hypot(stated_rad.value_or(start_heading_sigma_rad), track_heading_offset_sigma_rad);
}

double PdrOptions::HeadingWalkVariance(const Step& step) const {
  // A step that moves turns the body; a zero-length step (standing) adds no turn error. A
  // source's own heading variance growth counts where it is larger (a foot INS's, standing
  // time included).
  const double walk = step.delta_n.head<2>().squaredNorm() > 0
                          ? heading_walk_sigma_rad * heading_walk_sigma_rad
                          : 0.0;
  const double own = step.heading_var_rad2.value_or(0.0);
  return std::isfinite(own) ? std::max(walk, own) : walk;
}

PdrOptions PdrOptions::ForFootIns() const {
  PdrOptions o = *this;
  o.heading_drift_sigma_rad_per_s = foot_ins.heading_drift_sigma_rad_per_s;
  o.heading_walk_sigma_rad = 0.0;
  o.step_scale_sigma = foot_ins.step_scale_sigma;
  o.turn_scale_sigma = foot_ins.turn_scale_sigma;
  return o;
}

PdrOptions PdrOptions::SharedErrorsScaled(double factor) const {
  if (!(factor > 0) || !std::isfinite(factor)) {
    throw std::invalid_argument("pdr: a scale of the shared error sigmas must be finite and > 0");
  }
  PdrOptions o = *this;
  o.start_heading_sigma_rad *= factor;
  o.heading_drift_sigma_rad_per_s *= factor;
  o.heading_walk_sigma_rad *= factor;
  o.step_scale_sigma *= factor;
  o.turn_scale_sigma *= factor;
  o.foot_ins.heading_drift_sigma_rad_per_s *= factor;
  o.foot_ins.step_scale_sigma *= factor;
  o.foot_ins.turn_scale_sigma *= factor;
  return o;
}

DeadReckoning::DeadReckoning(const Vec3& start_n, double start_sigma_m, const PdrOptions& options,
                             std::optional<double> start_heading_sigma_rad)
    : options_(options), position_n_(start_n) {
  // Considered: the offset is carried beside the state (its sensitivity starts as the heading
  // error's), not in the start heading's variance.
  const double heading = options_.track_heading_offset_considered
                             ? start_heading_sigma_rad.value_or(options_.start_heading_sigma_rad)
                             : options_.StartHeadingSigma(start_heading_sigma_rad);
  if (options_.track_heading_offset_considered) {
    considered_sigma_rad_ = options_.track_heading_offset_sigma_rad;
    offset_sens_(kHeading) = 1.0;
  }
  error_cov_.setZero();
  error_cov_(kX, kX) = error_cov_(kY, kY) = start_sigma_m * start_sigma_m;
  error_cov_(kHeading, kHeading) = heading * heading;
  error_cov_(kRate, kRate) = options_.heading_drift_sigma_rad_per_s * options_.heading_drift_sigma_rad_per_s;
  error_cov_(kScale, kScale) = options_.step_scale_sigma * options_.step_scale_sigma;
  error_cov_(kTurnScale, kTurnScale) = options_.turn_scale_sigma * options_.turn_scale_sigma;
}

StepTurnCounter::Since StepTurnCounter::Next(const Step& step, double turn_min_step_m) {
  Since since;
  if (last_t_) since.dt_s = std::max(0.0, step.t1 - *last_t_);
  last_t_ = step.t1;
  const Vec2 d_n = step.delta_n.head<2>();
  if (d_n.norm() >= std::max(turn_min_step_m, 1e-9)) {
    const double direction = std::atan2(d_n.y(), d_n.x());
    if (last_direction_rad_) since.turn_rad = WrapAngle(direction - *last_direction_rad_);
    last_direction_rad_ = direction;
  }
  return since;
}

void DeadReckoning::AddStep(const Step& step) {
  // Time since the last step (or none at the first): the heading error grows by the rate error;
  // and by the turn-scale error x the walking direction's turn since the last step that said
  // where the body faces.
  const StepTurnCounter::Since since = turns_.Next(step, options_.turn_min_step_m);
  Mat6 f = Mat6::Identity();
  f(kHeading, kRate) = since.dt_s;
  f(kHeading, kTurnScale) = since.turn_rad;
  // The step, turned by the heading error and stretched by the scale error (first order):
  // p += d + d_heading (-d_y, d_x) + d_scale d.
  const double dx = step.delta_n.x(), dy = step.delta_n.y();
  Mat6 g = Mat6::Identity();
  g(kX, kHeading) = -dy;
  g(kY, kHeading) = dx;
  g(kX, kScale) = dx;
  g(kY, kScale) = dy;
  const Mat6 fg = g * f;
  Mat6 q = Mat6::Zero();
  if (step.variance_m2) {
    q(kX, kX) = step.variance_m2->x();
    q(kY, kY) = step.variance_m2->y();
  } else {
    const double s = options_.default_step_noise_m +
                     options_.default_step_relative_sigma * step.delta_n.head<2>().norm();
    q(kX, kX) = q(kY, kY) = s * s;
  }
  q(kHeading, kHeading) = options_.HeadingWalkVariance(step);
  error_cov_ = fg * error_cov_ * fg.transpose() + q;
  error_cov_ = 0.5 * (error_cov_ + error_cov_.transpose());
  last_transition_ = fg;
  offset_sens_ = fg * offset_sens_;  // the error's transition, without the step's own noise
  position_n_ += step.delta_n;
}

void DeadReckoning::AddHeadingVariance(double variance_rad2) {
  if (!(variance_rad2 >= 0) || !std::isfinite(variance_rad2))
    throw std::invalid_argument("DeadReckoning: a heading variance must be finite and >= 0");
  error_cov_(kHeading, kHeading) += variance_rad2;
}

Mat2 DeadReckoning::covariance() const {
  const Vec2 s = offset_sens_.head<2>();
  return own_covariance() + considered_sigma_rad_ * considered_sigma_rad_ * s * s.transpose();
}

namespace {

// A fix and its covariance, checked: finite, symmetric to rounding (a solver's covariance is),
// positive definite; returned exactly symmetric.
Mat2 CheckedFixCovariance(const char* what, const Vec2& fix_n, const Mat2& cov) {
  const bool symmetric =
      std::abs(cov(0, 1) - cov(1, 0)) <= 1e-9 * (std::abs(cov(0, 0)) + std::abs(cov(1, 1)));
  const Mat2 sym = 0.5 * (cov + cov.transpose());
  if (!fix_n.allFinite() || !cov.allFinite() || !symmetric ||
      Eigen::LLT<Mat2>(sym).info() != Eigen::Success) {
    throw std::invalid_argument(std::string("DeadReckoning::") + what +
                                ": the fix and its covariance must be finite, the covariance "
                                "symmetric positive definite");
  }
  return sym;
}

}  // namespace

void DeadReckoning::SetPosition(const Vec2& position_n, const Mat2& cov, const Mat2& offset_kept) {
  const Mat2 c = CheckedFixCovariance("SetPosition", position_n, cov);
  if (!offset_kept.allFinite()) {
    throw std::invalid_argument("DeadReckoning::SetPosition: offset_kept must be finite");
  }
  offset_sens_.head<2>() = offset_kept * offset_sens_.head<2>();
  position_n_.head<2>() = position_n;
  error_cov_.topLeftCorner<2, 2>() = c;
  error_cov_.block<2, kSharedErrors>(kX, kHeading).setZero();
  error_cov_.block<kSharedErrors, 2>(kHeading, kX).setZero();
}

double DeadReckoning::FusePosition(const Vec2& fix_n, const Mat2& fix_cov_in) {
  const Mat2 fix_cov = CheckedFixCovariance("FusePosition", fix_n, fix_cov_in);
  const Mat2 P = own_covariance();
  // The trace (mean squared error) of the intersection's position covariance,
  // (omega P^-1 + (1 - omega) R^-1)^-1; its minimum over (0, 1) by golden-section search (the
  // trace of the inverse of a matrix affine in omega is convex: one minimum). The trace, not
  // the determinant: the determinant chose thin fixes whole, with their long axis (landmark
  // corridor variants: p75 1.05 m against 0.93 m).
  const Mat2 Pi = P.inverse(), Ri = fix_cov.inverse();
  const auto trace_at = [&](double w) { return (w * Pi + (1 - w) * Ri).inverse().trace(); };
  double lo = 0.0, hi = 1.0;
  const double g = 0.5 * (std::sqrt(5.0) - 1);
  double a = hi - g * (hi - lo), b = lo + g * (hi - lo), fa = trace_at(a), fb = trace_at(b);
  for (int k = 0; k < 60; ++k) {
    if (fa < fb) {
      hi = b, b = a, fb = fa, a = hi - g * (hi - lo), fa = trace_at(a);
    } else {
      lo = a, a = b, fa = fb, b = lo + g * (hi - lo), fb = trace_at(b);
    }
  }
  double omega = 0.5 * (lo + hi);
  // The ends: the fix alone or the estimate alone, if better than any mixture.
  if (trace_at(1.0) <= trace_at(omega)) omega = 1.0;
  if (omega >= 1.0 - 1e-9) return 1.0;
  omega = std::max(omega, 1e-6);
  // The gain of the intersection (position rows only: Schmidt, the shared errors are not
  // estimated, so their own covariance stays as it is).
  const Mat2 K2 = (P / omega) * (P / omega + fix_cov / (1 - omega)).inverse();
  Eigen::Matrix<double, kErrors, 2> K = Eigen::Matrix<double, kErrors, 2>::Zero();
  K.topRows<2>() = K2;
  Eigen::Matrix<double, 2, kErrors> H = Eigen::Matrix<double, 2, kErrors>::Zero();
  H(0, kX) = H(1, kY) = 1;
  // Joseph form with that gain (positive semi-definite for any gain; exact if the fix were
  // independent), then its position block replaced by the intersection's, which is larger
  // whatever the correlation: the joint stays positive semi-definite.
  const Mat6 IKH = Mat6::Identity() - K * H;
  error_cov_ = IKH * error_cov_ * IKH.transpose() + K * fix_cov * K.transpose();
  // The considered offset is not in the fix: the fused error keeps (I - K H) of its sensitivity.
  offset_sens_ = IKH * offset_sens_;
  const Mat2 I2K = Mat2::Identity() - K2;
  error_cov_.topLeftCorner<2, 2>() =
      I2K * (P / omega) * I2K.transpose() + K2 * (fix_cov / (1 - omega)) * K2.transpose();
  error_cov_ = 0.5 * (error_cov_ + error_cov_.transpose());
  const Vec2 dp = K.topRows<2>() * (fix_n - position_n_.head<2>());
  position_n_.head<2>() += dp;
  return omega;
}

Mat2 UnknownHeadingCovariance(const Vec2& displacement_n) {
  return 0.5 * displacement_n.squaredNorm() * Mat2::Identity() +
         displacement_n * displacement_n.transpose();
}

DeadReckoningEstimator::DeadReckoningEstimator(MissionInfo info, PdrOptions options)
    : info_(std::move(info)), options_(options) {
  std::string why;
  if (!options_.IsValid(&why)) throw std::invalid_argument("pdr: " + why);
}

void DeadReckoningEstimator::Add(const MissionRow& row, EstimateSink& sink) {
  const auto* step = std::get_if<Step>(&row);
  if (step == nullptr) {
    ++ignored_;
    return;
  }
  auto it = agents_.find(step->agent);
  if (it == agents_.end()) {
    const NodeInfo* node = info_.Find(step->agent);
    if (node == nullptr || node->kind != NodeKind::kAgent) {
      throw std::invalid_argument(
          fmt::format("'{}' has steps but is not an agent in mission.json", step->agent));
    }
    const auto start = info_.AgentStart(*node);
    if (!start) {
      throw std::invalid_argument(fmt::format(
          "agent '{}' has no 'start' in mission.json and the mission has no single base: pdr "
          "needs a known start",
          step->agent));
    }
    // A foot INS's own errors where its first step carries its heading variance (the INS holds
    // its noise model: ZuptIns::OwnErrorsHold).
    const bool from_foot_ins = foot_ins_.count(step->agent) != 0;
    const bool foot_ins =
        options_.foot_ins.own_errors && from_foot_ins && step->heading_var_rad2.has_value();
    PdrOptions o = foot_ins ? options_.ForFootIns() : options_;
    std::optional<double> heading_sigma = node->start_heading_sigma_rad;
    // A foot INS without a stated heading: its frame is its own, turned by an unknown angle (the
    // unknown heading's covariance instead of any heading sigma at the start).
    const bool unknown_heading = from_foot_ins && !node->start_heading_rad;
    if (unknown_heading) {
      o.track_heading_offset_sigma_rad = 0.0;
      heading_sigma = 0.0;
      unknown_heading_.insert(step->agent);
    }
    it = agents_
             .emplace(step->agent, Agent{DeadReckoning(*start, node->start_sigma_m.value_or(0.0), o,
                                                       heading_sigma),
                                         step->t0})
             .first;
    if (unknown_heading) it->second.unknown_heading_start = start->head<2>();
    it->second.own_errors = foot_ins;
    sink.Add(EstimateOf(step->agent, it->second, step->t0));
  }
  Agent& a = it->second;
  if (a.own_errors && !step->heading_var_rad2 && !a.unknown_heading_start) {
    // The INS stopped claiming its own heading errors: its IMU's mounting was not found, and
    // the walk is turned about the start by an unknown angle from here on.
    const NodeInfo* node = info_.Find(step->agent);
    a.unknown_heading_start = info_.AgentStart(*node)->head<2>();
    mount_not_found_.insert(step->agent);
  }
  a.dr.AddStep(*step);
  a.t = step->t1;
  ++a.steps;
  ++steps_;
  sink.Add(EstimateOf(step->agent, a, step->t1));
}

Estimate DeadReckoningEstimator::EstimateOf(const std::string& id, const Agent& a, TimeS t) const {
  Mat2 c = a.dr.covariance();
  if (a.unknown_heading_start) {
    c += UnknownHeadingCovariance(a.dr.position_n().head<2>() - *a.unknown_heading_start);
  }
  return Estimate{t, id, a.dr.position_n(), c(0, 0), c(0, 1), c(1, 1)};
}

std::optional<Estimate> DeadReckoningEstimator::Current(const std::string& node) const {
  const auto it = agents_.find(node);
  if (it == agents_.end()) return std::nullopt;
  return EstimateOf(node, it->second, it->second.t);
}

EstimatorSummary DeadReckoningEstimator::Summary() const {
  EstimatorSummary s;
  s.numbers["steps"] = static_cast<double>(steps_);
  s.numbers["agents"] = static_cast<double>(agents_.size());
  s.numbers["rows_ignored"] = static_cast<double>(ignored_);
  for (const auto& [id, a] : agents_) s.notes.push_back(fmt::format("{}: {} steps", id, a.steps));
  for (const auto& id : unknown_heading_) {
    s.notes.push_back(fmt::format(
        "{}: foot INS steps without a start_heading in mission.json: the walk is in the INS's "
        "own frame, turned by an unknown angle about the start (its ellipse covers every turn)",
        id));
  }
  for (const auto& id : mount_not_found_) {
    s.notes.push_back(fmt::format(
        "{}: its foot IMU's mounting was not found (the INS's steps stopped claiming its own "
        "heading errors): from then on the walk is turned by an unknown angle about the start "
        "(its ellipse covers every turn)",
        id));
  }
  return s;
}

}  // namespace trailmark

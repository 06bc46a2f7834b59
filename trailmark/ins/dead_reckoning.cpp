// SPDX-License-Identifier: MIT
#include "trailmark/ins/dead_reckoning.h"

#include <fmt/format.h>

#include <stdexcept>

namespace trailmark {

bool PdrOptions::IsValid(std::string* why) const {
  if (default_step_noise_m >= 0 && default_step_relative_sigma >= 0) return true;
  if (why) *why = "default step noise must be >= 0";
  return false;
}

DeadReckoning::DeadReckoning(const Vec3& start_n, double start_sigma_m, const PdrOptions& options)
    : options_(options), position_n_(start_n) {
  covariance_ = Mat2::Identity() * start_sigma_m * start_sigma_m;
}

void DeadReckoning::AddStep(const Step& step) {
  position_n_ += step.delta_n;
  if (step.variance_m2) {
    covariance_(0, 0) += step.variance_m2->x();
    covariance_(1, 1) += step.variance_m2->y();
  } else {
    const double s = options_.default_step_noise_m +
                     options_.default_step_relative_sigma * step.delta_n.head<2>().norm();
    covariance_ += Mat2::Identity() * s * s;
  }
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
    it = agents_
             .emplace(step->agent,
                      Agent{DeadReckoning(*start, node->start_sigma_m.value_or(0.0), options_),
                            step->t0})
             .first;
    const Mat2& c = it->second.dr.covariance();
    sink.Add({step->t0, step->agent, *start, c(0, 0), c(0, 1), c(1, 1)});
  }
  Agent& a = it->second;
  a.dr.AddStep(*step);
  a.t = step->t1;
  ++a.steps;
  ++steps_;
  const Mat2& c = a.dr.covariance();
  sink.Add({step->t1, step->agent, a.dr.position_n(), c(0, 0), c(0, 1), c(1, 1)});
}

std::optional<Estimate> DeadReckoningEstimator::Current(const std::string& node) const {
  const auto it = agents_.find(node);
  if (it == agents_.end()) return std::nullopt;
  const Mat2& c = it->second.dr.covariance();
  return Estimate{it->second.t, node, it->second.dr.position_n(), c(0, 0), c(0, 1), c(1, 1)};
}

EstimatorSummary DeadReckoningEstimator::Summary() const {
  EstimatorSummary s;
  s.numbers["steps"] = static_cast<double>(steps_);
  s.numbers["agents"] = static_cast<double>(agents_.size());
  s.numbers["rows_ignored"] = static_cast<double>(ignored_);
  for (const auto& [id, a] : agents_) s.notes.push_back(fmt::format("{}: {} steps", id, a.steps));
  return s;
}

}  // namespace trailmark

// SPDX-License-Identifier: MIT
#pragma once
/// Pedestrian dead reckoning: every agent starts at its `start` (or the single base, spec) and
/// adds its steps. The baseline every other estimator is compared with, and the `pdr`
/// estimator. No I/O.

#include <map>
#include <optional>
#include <string>

#include "trailmark/core/mission.h"
#include "trailmark/core/online_estimator.h"
#include "trailmark/core/options.h"

namespace trailmark {

struct PdrOptions {
  /// Per-axis sigma of a step that has no variance in steps.csv: a + b * length, i.e.
  /// (5 cm)^2 + (3 % of length)^2 of variance (ours: a consumer PDR's step noise).
  double default_step_noise_m = 0.05;
  double default_step_relative_sigma = 0.03;
  bool IsValid(std::string* why) const;
};

/// Dead reckoning of one agent, usable without files.
class DeadReckoning {
 public:
  DeadReckoning(const Vec3& start_n, double start_sigma_m, const PdrOptions& options = {});
  /// Adds one step's displacement and its variance.
  void AddStep(const Step& step);
  const Vec3& position_n() const { return position_n_; }
  const Mat2& covariance() const { return covariance_; }

 private:
  PdrOptions options_;
  Vec3 position_n_;
  Mat2 covariance_;
};

/// `pdr`: each agent's dead reckoning, an estimate at every step (and its start at the first
/// step's t0). Agents are independent: each agent's steps in time order is all it needs.
class DeadReckoningEstimator : public OnlineEstimator {
 public:
  explicit DeadReckoningEstimator(MissionInfo info, PdrOptions options = {});
  /// Steps; other rows are counted and ignored. Throws std::invalid_argument for steps of a
  /// node that is not an agent, or of an agent without a start (none in the mission and no
  /// single base).
  void Add(const MissionRow& row, EstimateSink& sink) override;
  void Finish(EstimateSink&) override {}
  std::optional<Estimate> Current(const std::string& node) const override;
  EstimatorSummary Summary() const override;

 private:
  struct Agent {
    DeadReckoning dr;
    TimeS t = 0;
    std::size_t steps = 0;
  };
  MissionInfo info_;
  PdrOptions options_;
  std::map<std::string, Agent> agents_;
  std::size_t steps_ = 0, ignored_ = 0;
};

}  // namespace trailmark

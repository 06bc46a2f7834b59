// SPDX-License-Identifier: MIT
#include "trailmark/sim/pdr_error_model.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

namespace trailmark {

PdrErrorModel::PdrErrorModel(const PdrErrorOptions& options, Random rng)
    : options_(options), rng_(rng), heading_error_rad_(options.initial_heading_error_rad) {
  drift_rad_per_s_ = options.heading_drift_rad_per_s
                         ? *options.heading_drift_rad_per_s
                         : rng_.Normal(0.0, options.heading_drift_sigma_rad_per_s);
  scale_ = 1.0 + rng_.Normal(0.0, options.scale_error_sigma);
  turn_scale_ = rng_.Normal(0.0, options.turn_scale_error_sigma);
}

Vec2 PdrErrorModel::Apply(const Vec2& delta_true_n, double dt_s) {
  heading_error_rad_ +=
      drift_rad_per_s_ * dt_s + rng_.Normal(0.0, options_.heading_random_walk_rad);
  if (delta_true_n.norm() > std::max(1e-6, options_.turn_min_step_m)) {
    const double heading = std::atan2(delta_true_n.y(), delta_true_n.x());
    if (last_true_heading_rad_) {
      heading_error_rad_ += turn_scale_ * WrapAngle(heading - *last_true_heading_rad_);
    }
    last_true_heading_rad_ = heading;
  }
  const Eigen::Rotation2Dd rot(heading_error_rad_);
  Vec2 measured = scale_ * (rot * delta_true_n);
  measured.x() += rng_.Normal(0.0, options_.step_noise_m);
  measured.y() += rng_.Normal(0.0, options_.step_noise_m);
  return measured;
}

double PdrErrorModel::ReportedVariance(double step_length_m) const {
  const double heading_term = step_length_m * options_.reported_heading_sigma_rad;
  const double scale_term = step_length_m * options_.scale_error_sigma;
  return options_.step_noise_m * options_.step_noise_m + heading_term * heading_term +
         0.5 * scale_term * scale_term;
}

void AppendPdrWalk(PdrErrorModel& pdr, const Walk& walk, const std::string& agent, MissionData& m) {
  for (const auto& st : walk.steps) {
    const Vec2 d = pdr.Apply(st.to - st.from, st.t1 - st.t0);
    const double var = pdr.ReportedVariance((st.to - st.from).norm());
    m.steps.push_back({st.t0, st.t1, agent, Vec3(d.x(), d.y(), 0), Vec3(var, var, 1e-4)});
  }
  for (const auto& s : walk.truth)
    m.truth.push_back({s.t, agent, Vec3(s.position.x(), s.position.y(), 0)});
}

}  // namespace trailmark

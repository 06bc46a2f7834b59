// SPDX-License-Identifier: MIT
#include "trailmark/ins/mount_yaw.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <numbers>

namespace trailmark::ins {

namespace {

double Median(std::vector<double> v) {
  const std::size_t n = v.size();
  std::nth_element(v.begin(), v.begin() + n / 2, v.end());
  const double upper = v[n / 2];
  if (n % 2 == 1) return upper;
  return 0.5 * (upper + *std::max_element(v.begin(), v.begin() + n / 2));
}

}  // namespace

bool MountYawOptions::IsValid(std::string* why) const {
  const char* problem = nullptr;
  if (strides < 0)
    problem = "mount_yaw_strides must be >= 0";
  else if (!(min_stride_m > 0) || !std::isfinite(min_stride_m))
    problem = "mount_yaw_min_stride_m must be > 0";
  else if (!(max_spread_rad > 0) || !std::isfinite(max_spread_rad))
    problem = "mount_yaw_max_spread must be > 0";
  else if (!(max_turn_rad > 0) || !std::isfinite(max_turn_rad))
    problem = "mount_yaw_max_turn must be > 0";
  else if (!(min_turn_rad >= 0) || !std::isfinite(min_turn_rad))
    problem = "mount_yaw_min_turn must be >= 0";
  else if (!(hold_above_rad >= 0) || !std::isfinite(hold_above_rad))
    problem = "mount_yaw_hold_above must be >= 0";
  else if (hold_first_landings < 0)
    problem = "mount_yaw_hold_first_landings must be >= 0";
  else if (!(hold_first_release_rad >= 0) || !std::isfinite(hold_first_release_rad))
    problem = "mount_yaw_hold_first_release must be >= 0";
  else if (!(interval_max_turn_rad >= 0) || !std::isfinite(interval_max_turn_rad))
    problem = "mount_yaw_interval_max_turn must be >= 0";
  else if (!(interval_margin_rad >= 0) || !std::isfinite(interval_margin_rad))
    problem = "mount_yaw_interval_margin must be >= 0";
  else if (interval_min_strides < 1)
    problem = "mount_yaw_interval_min_strides must be >= 1";
  else if (gait_min_strides < 0 || (gait_min_strides > 0 && gait_min_strides < 4))
    problem = "mount_yaw_gait_min_strides must be 0 (off) or >= 4 (three parameters)";
  else if (!(gait_max_turn_rad > 0) || !std::isfinite(gait_max_turn_rad))
    problem = "mount_yaw_gait_max_turn must be > 0";
  else if (!(gait_max_sigma_rad > 0) || !std::isfinite(gait_max_sigma_rad))
    problem = "mount_yaw_gait_max_sigma must be > 0";
  else if (!(gait_noise_floor_rad > 0) || !std::isfinite(gait_noise_floor_rad))
    problem = "mount_yaw_gait_noise_floor must be > 0";
  else if (max_landings < strides)
    problem = "mount_yaw_max_landings must be >= mount_yaw_strides";
  if (problem && why) *why = problem;
  return problem == nullptr;
}

MountYawEstimator::MountYawEstimator(MountYawOptions options, double stated_heading_rad)
    : options_(options), stated_heading_rad_(stated_heading_rad) {}

void MountYawEstimator::Start(const Eigen::Quaterniond& q_nb) {
  if (reference_b_) return;
  const Vec3 along_n(std::cos(stated_heading_rad_), std::sin(stated_heading_rad_), 0.0);
  reference_b_ = q_nb.conjugate() * along_n;
}

double MountYawEstimator::HeadingOf(const Eigen::Quaterniond& q_nb) const {
  const Vec3 r_n = q_nb * *reference_b_;
  return std::atan2(r_n.y(), r_n.x());
}

void MountYawEstimator::AddLanding(const Vec3& position_n, const Eigen::Quaterniond& q_nb) {
  if (decided_) return;
  Start(q_nb);
  ++landings_;
  const double heading = HeadingOf(q_nb);
  if (last_landing_n_) {
    const Vec2 stride = (position_n - *last_landing_n_).head<2>();
    const double turned = WrapAngle(heading - last_heading_rad_);
    // Straight: the foot did not turn, nor did the walk into the stride or out of it (the
    // chords before and after): a foot that anticipates its next stride turns little over a
    // zig-zag's stride whose chords turned a lot, and lands turned toward the next; that stride's
    // angle is then off by a share of those turns. So a straight stride counts once the next
    // chord is seen straight too.
    const double chord = std::atan2(stride.y(), stride.x());
    const bool valid = stride.norm() >= options_.min_stride_m;
    const bool straight_in =
        !last_chord_rad_ || std::abs(WrapAngle(chord - *last_chord_rad_)) <= options_.max_turn_rad;
    if (valid) {
      if (straight_pending_rad_ && straight_in) {
        double angle = *straight_pending_rad_;
        if (!angles_rad_.empty())
          angle = angles_rad_.front() + WrapAngle(angle - angles_rad_.front());
        angles_rad_.push_back(angle);
      }
      straight_pending_rad_.reset();
      last_chord_rad_ = chord;
      if (std::abs(turned) <= options_.max_turn_rad && straight_in) {
        // The reference's heading half way through the stride (the foot turns in the air).
        const double mid = last_heading_rad_ + 0.5 * turned;
        straight_pending_rad_ = WrapAngle(chord - mid);
      }
    }
    if (options_.gait_min_strides > 0) {
      // The gait regression's row of the last stride, now that this chord says where it went
      // next; then this stride waits for the next.
      if (gait_pending_ && valid) {
        const double next_turn = WrapAngle(chord - gait_pending_->chord_rad);
        if (std::abs(next_turn) <= options_.gait_max_turn_rad)
          gait_rows_.push_back({gait_pending_->alpha_rad, next_turn, gait_pending_->foot_turn_rad});
      }
      gait_pending_.reset();
      // Not the first stride: a foot setting off from standing is not yet walking (its turn from
      // where it stood is no gait's).
      if (valid && std::abs(turned) <= options_.gait_max_turn_rad && landings_ > 2) {
        double alpha = WrapAngle(chord - heading);
        if (!gait_anchor_rad_) gait_anchor_rad_ = alpha;
        alpha = *gait_anchor_rad_ + WrapAngle(alpha - *gait_anchor_rad_);
        gait_pending_ = GaitPending{chord, alpha, turned};
      }
    }
    if (stride.norm() >= options_.min_stride_m &&
        std::abs(turned) <= options_.interval_max_turn_rad) {
      // The angle from the reference at landing; at lift-off it is that plus the turn.
      double at_landing = WrapAngle(std::atan2(stride.y(), stride.x()) - heading);
      if (!unwrap_anchor_rad_) unwrap_anchor_rad_ = at_landing + 0.5 * turned;
      at_landing = *unwrap_anchor_rad_ + WrapAngle(at_landing - *unwrap_anchor_rad_);
      const double m = options_.interval_margin_rad;
      bounds_rad_.emplace_back(std::min(at_landing, at_landing + turned) - m,
                               std::max(at_landing, at_landing + turned) + m);
    }
  }
  last_landing_n_ = position_n;
  last_heading_rad_ = heading;
  // Straight strides first (exact on a straight walk, whatever the gait), then the gait's
  // regression (a walk that turns at every stride), then the bounds (off by default).
  if (static_cast<int>(angles_rad_.size()) >= options_.strides) TryDecide(false);
  if (!decided_ && options_.gait_min_strides > 0) TryDecideByGait();
  if (!decided_) TryDecideByBounds();
  if (!decided_ && landings_ >= options_.max_landings) Settle();
}

void MountYawEstimator::TryDecide(bool force) {
  const std::size_t n = angles_rad_.size();
  if (n < (force ? 3u : static_cast<std::size_t>(std::max(options_.strides, 1)))) return;
  // Decided when three in four strides (all of the first three) lie within the spread of their
  // median: a walk forward with a stride taken sideways now and then, not a zig-zag.
  const double median = Median(angles_rad_);
  double sum = 0, sum2 = 0;
  std::size_t inliers = 0;
  for (double a : angles_rad_) {
    if (std::abs(a - median) > options_.max_spread_rad) continue;
    ++inliers;
    sum += a - median;
    sum2 += (a - median) * (a - median);
  }
  if (4 * inliers < 3 * n || inliers < 3) return;
  const double mean = sum / static_cast<double>(inliers);
  const double var = std::max(0.0, sum2 / static_cast<double>(inliers) - mean * mean);
  decided_ = true;
  correction_rad_ = -WrapAngle(median);
  sigma_rad_ = std::sqrt(var / static_cast<double>(inliers));
}

void MountYawEstimator::TryDecideByBounds() {
  const std::size_t n = bounds_rad_.size();
  if (options_.interval_max_turn_rad <= 0 || options_.strides == 0 ||
      n < static_cast<std::size_t>(options_.interval_min_strides))
    return;
  // The stretch shared by the most bounds: a sweep over their ends (an opening before a closing
  // at the same angle, so bounds that touch share it). Decided only by one such stretch.
  std::vector<std::pair<double, int>> ends;
  ends.reserve(2 * n);
  for (const auto& [lo, hi] : bounds_rad_) {
    ends.emplace_back(lo, +1);
    ends.emplace_back(hi, -1);
  }
  std::sort(ends.begin(), ends.end(), [](const auto& a, const auto& b) {
    return a.first < b.first || (a.first == b.first && a.second > b.second);
  });
  int covered = 0, best = 0, stretches = 0;
  double from = 0, to = 0;
  for (std::size_t k = 0; k + 1 < ends.size(); ++k) {
    covered += ends[k].second;
    if (covered > best) {
      best = covered;
      stretches = 1;
      from = ends[k].first;
      to = ends[k + 1].first;
    } else if (covered == best && best > 0) {
      if (ends[k].first > to) ++stretches;  // another stretch as wide in agreement
      to = ends[k + 1].first;
    }
  }
  const std::size_t shared = static_cast<std::size_t>(best);
  if (stretches != 1 || shared < static_cast<std::size_t>(options_.interval_min_strides) ||
      4 * shared < 3 * n)
    return;
  // No wider than one straight stride's bounds: a walk turning one way at every stride (a
  // circle) shares a stretch as wide as its turns, whose centre depends on the gait.
  if (to - from > 2 * options_.interval_margin_rad + options_.max_turn_rad) return;
  const double centre = 0.5 * (from + to);
  const double sigma = (to - from) / (2 * std::sqrt(3.0));
  // Only a mounting clearly turned from the foot's, a turn worth taking (3 sigma is 0.87 of
  // the stretch's width, so zero lies outside it); a mounting about the foot's waits for the
  // straight strides' median.
  if (std::abs(WrapAngle(centre)) <= std::max(3 * sigma, options_.min_turn_rad)) return;
  decided_ = by_bounds_ = true;
  correction_rad_ = -WrapAngle(centre);
  sigma_rad_ = sigma;
}

void MountYawEstimator::TryDecideByGait() {
  const std::size_t n = gait_rows_.size();
  if (options_.strides == 0 || options_.gait_min_strides == 0 ||
      n < static_cast<std::size_t>(options_.gait_min_strides))
    return;
  // alpha = mu - a dnext - b tau: iteratively reweighted least squares with Huber's weights
  // (k = 1.5 robust scales), weak priors a, b ~ N(0, 10^2) in the normal equations (a straight
  // walk, whose turns say nothing of them, gives the mean).
  Eigen::Matrix3d info;
  Eigen::Vector3d beta = Eigen::Vector3d::Zero();
  std::vector<double> w(n, 1.0), residual(n, 0.0);
  double scale = options_.gait_noise_floor_rad;
  for (int iteration = 0; iteration < 10; ++iteration) {
    info = Eigen::Vector3d(0.0, 0.01, 0.01).asDiagonal();  // the priors' information
    Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
    for (std::size_t k = 0; k < n; ++k) {
      const GaitRow& g = gait_rows_[k];
      const Eigen::Vector3d x(1.0, -g.next_turn_rad, -g.foot_turn_rad);
      info += w[k] * x * x.transpose();
      rhs += w[k] * g.alpha_rad * x;
    }
    beta = info.ldlt().solve(rhs);
    for (std::size_t k = 0; k < n; ++k) {
      const GaitRow& g = gait_rows_[k];
      residual[k] = g.alpha_rad - (beta(0) - beta(1) * g.next_turn_rad - beta(2) * g.foot_turn_rad);
    }
    std::vector<double> magnitudes(n);
    for (std::size_t k = 0; k < n; ++k) magnitudes[k] = std::abs(residual[k]);
    scale = std::max(options_.gait_noise_floor_rad, 1.4826 * Median(magnitudes));
    const double huber = 1.5 * scale;
    for (std::size_t k = 0; k < n; ++k)
      w[k] = std::abs(residual[k]) <= huber ? 1.0 : huber / std::abs(residual[k]);
  }
  std::size_t inliers = 0;
  for (double r : residual) inliers += std::abs(r) <= options_.max_spread_rad ? 1 : 0;
  if (4 * inliers < 3 * n) return;
  // The residuals' scale from n residuals of a three-parameter fit: widened by sqrt(n / (n - 3)).
  const double sigma = scale * std::sqrt(static_cast<double>(n) / static_cast<double>(n - 3)) *
                       std::sqrt(info.inverse()(0, 0));
  if (!(sigma <= options_.gait_max_sigma_rad) || !std::isfinite(beta(0))) return;
  decided_ = by_gait_ = true;
  correction_rad_ = -WrapAngle(beta(0));
  sigma_rad_ = sigma;
  gait_shares_ = {beta(1), beta(2)};
}

double MountYawEstimator::TurnWorthTakingRad() const {
  const double c = correction_rad_;
  return decided_ && std::abs(c) > std::max(3 * sigma_rad_, options_.min_turn_rad) ? c : 0.0;
}

void MountYawEstimator::Settle() {
  if (decided_) return;
  // At the end the gait's regression before the straight strides' median, which is forced
  // here (three strides within the spread suffice).
  if (options_.gait_min_strides > 0) TryDecideByGait();
  if (!decided_) TryDecide(true);
  if (!decided_) TryDecideByBounds();
  if (decided_) return;
  decided_ = true;
  correction_rad_ = sigma_rad_ = 0;
  note_ = fmt::format(
      "the IMU's mounting about the vertical not found from {} strides in {} landings (no "
      "forward walk): its forward axis taken as the foot's",
      angles_rad_.size(), landings_);
}

}  // namespace trailmark::ins

// SPDX-License-Identifier: MIT
#include "trailmark/ins/height.h"

#include <Eigen/Dense>
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace trailmark {

double PressureAltitudeM(double pressure_hpa) {
  // ICAO standard atmosphere, troposphere: h = T0/L (1 - (p/p0)^(R L / g)).
  return 44330.77 * (1.0 - std::pow(pressure_hpa / 1013.25, 0.190263));
}

bool HeightOptions::IsValid(std::string* why) const {
  auto fail = [&](const char* what) {
    if (why) *why = what;
    return false;
  };
  if (!(stairs_min_rise_m > 0)) return fail("height.stairs_min_rise_m must be > 0");
  if (stairs_window_steps < 1) return fail("height.stairs_window_steps must be >= 1");
  if (!(flat_step_sigma_m >= 0) || !(unknown_step_sigma_m >= 0) || !(baro_sigma_m > 0) ||
      !(baro_drift_m_per_sqrt_s >= 0)) {
    return fail("height: sigmas must be >= 0 (baro_sigma_m > 0)");
  }
  if (!(unknown_step_szz_m2 > 0)) return fail("height.unknown_step_szz_m2 must be > 0");
  if (!(gate_chi2 > 0)) return fail("height.gate_chi2 must be > 0");
  if (!(jump_persist_s >= 0) || !(stuck_after_s > 0) || !(max_vertical_speed_mps > 0)) {
    return fail("height: jump_persist_s >= 0, stuck_after_s > 0, max_vertical_speed_mps > 0");
  }
  if (shared_air_min_agents < 2) return fail("height.shared_air_min_agents must be >= 2");
  if (!(floor_prior_window_s > 0) || !(floor_prior_level_m > 0) || !(floor_prior_gate_m > 0) ||
      !(floor_prior_period_s >= 0) || !(floor_prior_sigma_m > 0))
    return fail("height.floor_prior_*: window, level, gate and sigma > 0, period >= 0");
  return true;
}

const OptionTable<HeightOptions>& HeightOptionTable() {
  static const OptionTable<HeightOptions> table = [] {
    OptionTable<HeightOptions> t;
    t.Real("stairs_min_rise_m", &HeightOptions::stairs_min_rise_m, "m", OptionBounds::Positive(),
           "a step height change counts once the steps' dz reach this (stairs)");
    t.Integer("stairs_window_steps", &HeightOptions::stairs_window_steps,
              OptionBounds::Between(1, 1000),
              "... within this many steps; less is a level floor (the INS's vertical noise)");
    t.Real("flat_step_sigma_m", &HeightOptions::flat_step_sigma_m, "m",
           OptionBounds::NonNegative(), "height noise per level step, 1 sigma");
    t.Real("unknown_step_szz_m2", &HeightOptions::unknown_step_szz_m2, "m^2",
           OptionBounds::Positive(), "a step with szz above this does not know its height");
    t.Real("unknown_step_sigma_m", &HeightOptions::unknown_step_sigma_m, "m",
           OptionBounds::NonNegative(), "height random walk per such step, 1 sigma");
    t.Real("baro_sigma_m", &HeightOptions::baro_sigma_m, "m", OptionBounds::Positive(),
           "barometer reading noise as height, 1 sigma");
    t.Real("baro_drift_m_per_sqrt_s", &HeightOptions::baro_drift_m_per_sqrt_s, "m/sqrt(s)",
           OptionBounds::NonNegative(), "barometer offset random walk (weather)");
    t.Real("gate_chi2", &HeightOptions::gate_chi2, "", OptionBounds::Positive(),
           "barometer innovation gate (chi-square, 1 dof)");
    t.Real("jump_persist_s", &HeightOptions::jump_persist_s, "s", OptionBounds::NonNegative(),
           "rejected readings agreeing this long are a pressure jump or a height change");
    t.Real("max_vertical_speed_mps", &HeightOptions::max_vertical_speed_mps, "m/s",
           OptionBounds::Positive(), "a faster change is the air (a door), not the agent");
    t.Real("stuck_after_s", &HeightOptions::stuck_after_s, "s", OptionBounds::Positive(),
           "the same reading this long is a stuck barometer");
    t.Flag("use_baro", &HeightOptions::use_baro, "use baro.csv (off: step heights only)");
    t.Flag("shared_air", &HeightOptions::shared_air,
           "a change of the air seen at once by several barometers, faster than a person "
           "climbs, is taken out of each of their readings (a fan started while one was on the "
           "stairs)");
    t.Flag("floor_prior", &HeightOptions::floor_prior,
           "the floors as a prior: on a level for a while near a level of `floors`, h is "
           "measured there (the barometer's offset takes the weather)");
    t.Real("floor_prior_window_s", &HeightOptions::floor_prior_window_s, "s",
           OptionBounds::Positive(), "floor prior: how long the height must stay level");
    t.Real("floor_prior_level_m", &HeightOptions::floor_prior_level_m, "m",
           OptionBounds::Positive(), "floor prior: the height's span over that time");
    t.Real("floor_prior_gate_m", &HeightOptions::floor_prior_gate_m, "m", OptionBounds::Positive(),
           "floor prior: the nearest level within this");
    t.Real("floor_prior_period_s", &HeightOptions::floor_prior_period_s, "s",
           OptionBounds::NonNegative(), "floor prior: at most one every this long");
    t.Real("floor_prior_sigma_m", &HeightOptions::floor_prior_sigma_m, "m",
           OptionBounds::Positive(), "floor prior: sigma of the level as a measurement of h");
    t.Integer("shared_air_min_agents", &HeightOptions::shared_air_min_agents,
              OptionBounds::Between(2, 1000000),
              "barometers (and half of those reporting) that must see a change of the air at "
              "once");
    return t;
  }();
  return table;
}

HeightFilter::HeightFilter(double start_z_m, double start_sigma_m, const HeightOptions& options)
    : options_(options) {
  std::string why;
  if (!options_.IsValid(&why)) throw std::invalid_argument(why);
  if (!std::isfinite(start_z_m) || !(start_sigma_m >= 0)) {
    throw std::invalid_argument("HeightFilter: start height and sigma must be finite");
  }
  x_ << start_z_m, 0.0;
  P_ << start_sigma_m * start_sigma_m, 0.0, 0.0, 0.0;
}

void HeightFilter::Predict(double q_h_m2) { P_(0, 0) += q_h_m2; }

void HeightFilter::DriftTo(TimeS t) {
  if (last_baro_t_ && t > *last_baro_t_) {
    const double q = options_.baro_drift_m_per_sqrt_s;
    P_(1, 1) += q * q * (t - *last_baro_t_);
  }
  if (!last_baro_t_ || t > *last_baro_t_) last_baro_t_ = t;
}

void HeightFilter::AddStep(const Step& step) {
  ++steps_;
  const double dz = step.delta_n.z();
  const double szz = step.variance_m2 ? step.variance_m2->z() : 0.02 * 0.02;
  if (!std::isfinite(dz) || !std::isfinite(szz)) return;
  steps_know_height_ = szz <= options_.unknown_step_szz_m2;
  if (!steps_know_height_) {
    // The step does not know its height: a random walk (the barometer carries the height).
    Predict(options_.unknown_step_sigma_m * options_.unknown_step_sigma_m);
    return;
  }
  if (climbing_steps_left_ > 0) {
    // On a flight of stairs: each step's dz counts at once.
    x_[0] += dz;
    committed_since_agreement_ += dz;
    Predict(szz);
    ++stairs_steps_;
    if (std::abs(dz) >= options_.stairs_min_rise_m / 3) {
      climbing_steps_left_ = options_.stairs_window_steps;
    } else {
      --climbing_steps_left_;
    }
    return;
  }
  pending_.push_back({dz, szz});
  pending_dz_ += dz;
  if (std::abs(pending_dz_) >= options_.stairs_min_rise_m) {
    // A height change that persists: commit the window's steps, the flight has begun.
    x_[0] += pending_dz_;
    committed_since_agreement_ += pending_dz_;
    double var = 0;
    for (const auto& [d, v] : pending_) var += v;
    Predict(var);
    stairs_steps_ += pending_.size();
    pending_.clear();
    pending_dz_ = 0;
    climbing_steps_left_ = options_.stairs_window_steps;
    return;
  }
  if (static_cast<int>(pending_.size()) > options_.stairs_window_steps) {
    // The oldest step's dz did not persist: a level floor, its dz is the INS's noise.
    pending_dz_ -= pending_.front().first;
    pending_.pop_front();
    Predict(options_.flat_step_sigma_m * options_.flat_step_sigma_m);
  }
}

namespace {
// The (upper) median: a lone spike moves it not.
/// A change of the air rising linearly over rise_s from since: the share of it at t.
double AirRamp(TimeS t, TimeS since, double rise_s) {
  if (t < since) return 0.0;
  return rise_s > 0 ? std::min(1.0, (t - since) / rise_s) : 1.0;
}

double Median(std::vector<double> v) {
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}
}  // namespace

std::optional<PressureJumpFit> FitPressureJump(const std::vector<std::pair<TimeS, double>>& ty,
                                               double sigma_m, bool with_rate) {
  if (ty.size() < 8 || !(sigma_m > 0)) return std::nullopt;
  // Spikes: further than 5 sigma from the median of the five readings around them.
  std::vector<std::pair<TimeS, double>> pts;
  for (std::size_t i = 0; i < ty.size(); ++i) {
    const std::size_t lo = i >= 2 ? i - 2 : 0, hi = std::min(ty.size(), i + 3);
    std::vector<double> near;
    for (std::size_t k = lo; k < hi; ++k) near.push_back(ty[k].second);
    if (std::abs(ty[i].second - Median(std::move(near))) <= 5 * sigma_m) pts.push_back(ty[i]);
  }
  if (pts.size() < 8) return std::nullopt;
  const TimeS t_end = pts.back().first;
  // Columns: a, J, and r when fitted; the model's row at time t for a jump from t_j over rise.
  auto row = [&](TimeS t, TimeS t_j, double rise) {
    Eigen::Vector3d a;
    a << 1.0, AirRamp(t, t_j, rise), t - t_end;
    return a;
  };
  std::optional<PressureJumpFit> best;
  double best_sse = std::numeric_limits<double>::infinity();
  for (const double rise : {0.0, 0.5, 1.0, 2.0}) {
    for (std::size_t j = 1; j + 1 < pts.size(); ++j) {
      const TimeS t_j = pts[j].first;
      Eigen::Matrix3d AtA = Eigen::Matrix3d::Zero();
      Eigen::Vector3d Aty = Eigen::Vector3d::Zero();
      for (const auto& [t, y] : pts) {
        const Eigen::Vector3d a = row(t, t_j, rise);
        AtA += a * a.transpose();
        Aty += a * y;
      }
      if (!with_rate) AtA(2, 2) = 1.0, Aty[2] = 0.0;  // r = 0: decoupled, solved as 0
      if (!with_rate) AtA(0, 2) = AtA(2, 0) = AtA(1, 2) = AtA(2, 1) = 0.0;
      const Eigen::LDLT<Eigen::Matrix3d> ldlt(AtA);
      if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > 1e-9)) continue;
      const Eigen::Vector3d x = ldlt.solve(Aty);
      double sse = 0;
      for (const auto& [t, y] : pts) {
        const double r = y - row(t, t_j, rise).dot(x);
        sse += r * r;
      }
      if (sse < best_sse) {
        best_sse = sse;
        Eigen::Matrix3d C = ldlt.solve(Eigen::Matrix3d::Identity()) * sigma_m * sigma_m;
        if (!with_rate) C(2, 2) = 0.0;
        const Eigen::Vector3d end(1.0, 1.0, 0.0);
        PressureJumpFit f;
        f.jump_m = x[1];
        f.jump_var_m2 = C(1, 1);
        f.rate_mps = x[2];
        f.rate_var = C(2, 2);
        f.level_end_m = x[0] + x[1];
        f.level_end_var_m2 = end.dot(C * end);
        f.jump_start = t_j;
        f.rise_s = rise;
        f.used = pts.size();
        f.sse_m2 = sse;
        best = f;
      }
    }
  }
  return best;
}

bool HeightFilter::LevelShift(TimeS t, double y) {
  // Where the steps do not measure height, the filter follows the barometer closely and a fast
  // change of the air would pass the gate as a climb. The median of the last second against
  // the second before: a change faster than a person climbs (beyond 3 sigma of the two
  // medians) is the air's. The readings of the next seconds settle it (SettleShift).
  if (shift_) {
    shift_->readings.emplace_back(t, y);
    if (t - shift_->since < kShiftSettleS) return true;  // settling: not used
    SettleShift(t);
    return true;
  }
  recent_.push_back({t, y, x_[1], P_(1, 1), x_[0]});
  while (!recent_.empty() && recent_.front().t < t - kShiftHistoryS) recent_.pop_front();
  // Medians: a lone spike moves neither.
  std::vector<double> fresh, older;
  for (const auto& r : recent_) {
    if (r.t > t - kShiftWindowS) {
      fresh.push_back(r.y);
    } else if (r.t > t - 2 * kShiftWindowS) {
      older.push_back(r.y);
    }
  }
  if (fresh.size() < 4 || older.size() < 4) return false;
  const double before = Median(older);
  const double d = Median(fresh) - before;
  // The median's standard error is 1.25 sigma / sqrt(n) for Gaussian noise.
  const double sigma_d = 1.25 * options_.baro_sigma_m *
                         std::sqrt(1.0 / static_cast<double>(fresh.size()) +
                                   1.0 / static_cast<double>(older.size()));
  if (std::abs(d) <= options_.max_vertical_speed_mps * kShiftWindowS + 3 * sigma_d) return false;
  // The offset before the change: the filter's at the window's first reading — unless that was
  // the reference itself, one reading moments ago (a firefighter walking in through a door into
  // a fan's overpressure 3 s after the first reading): then the median of the readings' y - h
  // before the change (all of them ~5 s after the reference).
  double offset_m = recent_.front().offset_m, offset_var_m2 = recent_.front().offset_var_m2;
  if (reference_t_ && recent_.front().t - *reference_t_ <= 0.5) {
    std::vector<double> pre;
    for (const auto& r : recent_)
      if (r.t <= t - 2 * kShiftWindowS) pre.push_back(r.y - r.h_m);
    if (pre.size() >= 5) {
      offset_var_m2 =
          1.57 * options_.baro_sigma_m * options_.baro_sigma_m / static_cast<double>(pre.size());
      offset_m = Median(std::move(pre));
    }
  }
  shift_ = Shift{t, before, offset_m, offset_var_m2, {}};
  for (const auto& r : recent_) shift_->readings.emplace_back(r.t, r.y);
  return true;
}

void HeightFilter::SettleShift(TimeS t) {
  // The window's readings as the agent's climb at a constant rate plus the air's jump J: the
  // offset takes J on top of what it was before the window, and h is the fitted level now
  // seen through that offset (a climb of those seconds stays the agent's; what the filter
  // lagged behind the readings is not frozen into the offset).
  const Shift shift = std::move(*shift_);
  shift_.reset();
  recent_.clear();
  rejected_run_.clear();
  // A climb only where the readings show one: a rate within 2 sigma of zero is a level floor
  // (most of the time), and the jump is fitted without one.
  auto fit = FitPressureJump(shift.readings, options_.baro_sigma_m, true);
  if (fit && !(std::abs(fit->rate_mps) > kRateSignificance * std::sqrt(fit->rate_var))) {
    fit = FitPressureJump(shift.readings, options_.baro_sigma_m, false);
  }
  double change = 0;
  if (fit && std::abs(fit->rate_mps) <= options_.max_vertical_speed_mps) {
    // J's variance: that of the level after it and of the level before it, which the fit
    // shares; the level's own is a fair bound for both.
    x_[1] = shift.offset_m + fit->jump_m;
    P_(1, 1) = shift.offset_var_m2 + 2 * fit->level_end_var_m2;
    x_[0] = fit->level_end_m - x_[1];
    P_(0, 0) = P_(1, 1) + fit->level_end_var_m2;
    P_(0, 1) = P_(1, 0) = -P_(1, 1);
    change = fit->jump_m;
  } else {
    // No fit (too few readings) or a rate no person climbs at: the offset takes the change
    // of the medians, h stays.
    std::vector<double> after;
    for (const auto& [ti, yi] : shift.readings) {
      if (ti >= shift.since) after.push_back(yi);
    }
    change = Median(after) - shift.before_m;
    x_[1] = shift.offset_m + change;
    P_(1, 1) = shift.offset_var_m2 + 2 * options_.baro_sigma_m * options_.baro_sigma_m /
                                         static_cast<double>(after.size());
    P_(0, 1) = P_(1, 0) = 0.0;
  }
  Agree(t);
  ++jumps_;
  notes_.push_back({t, "", "", "repeats",
                    fmt::format("barometer changed by {:+.2f} m ({:+.2f} hPa) within seconds, "
                                "faster than a person climbs: taken as a pressure change (a "
                                "door, ventilation), re-referenced",
                                change, -change / 8.3)});
}

void HeightFilter::Agree(TimeS t) {
  agreed_ = Agreement{t, x_[0], x_[1], P_(0, 0) + P_(1, 1) + 2 * P_(0, 1)};
  committed_since_agreement_ = 0;
}

std::optional<std::pair<double, double>> HeightFilter::baro_offset() const {
  if (!referenced_) return std::nullopt;
  return std::pair{x_[1], P_(1, 1)};
}

HeightFilter::BaroUse HeightFilter::AddBaro(const BaroSample& sample) {
  if (!options_.use_baro) return BaroUse::kOff;
  const TimeS t = sample.t;
  const double p = sample.pressure_hpa;
  if (!std::isfinite(p) || !std::isfinite(t)) return BaroUse::kRejected;
  // A stuck sensor repeats one value exactly (a live one's noise changes its last digits).
  if (repeated_since_ && p == repeated_value_) {
    if (t - *repeated_since_ >= options_.stuck_after_s) {
      if (!stuck_) {
        stuck_ = true;
        notes_.push_back({t, "", "", "excluded",
                          fmt::format("barometer stuck at {:.2f} hPa for {:.0f} s: its readings "
                                      "are skipped until it changes",
                                      p, t - *repeated_since_)});
      }
      ++stuck_readings_;
      return BaroUse::kStuck;
    }
  } else {
    if (stuck_) {
      stuck_ = false;
      notes_.push_back({t, "", "", "readmitted", "barometer reads again (its value changed)"});
      // Its offset is unknown after the gap: re-referenced at the next reading.
      referenced_ = false;
    }
    repeated_value_ = p;
    repeated_since_ = t;
  }
  const double y = PressureAltitudeM(p) - air_m_;
  const double r2 = options_.baro_sigma_m * options_.baro_sigma_m;
  DriftTo(t);
  if (!referenced_) {
    // b = H(p) - h: the reading defines the offset; cov(h, b) = -P_hh.
    x_[1] = y - x_[0];
    P_(1, 1) = P_(0, 0) + r2;
    P_(0, 1) = P_(1, 0) = -P_(0, 0);
    referenced_ = true;
    reference_t_ = t;
    Agree(t);
    rejected_run_.clear();
    return BaroUse::kReference;
  }
  if (!steps_know_height_ && LevelShift(t, y)) return BaroUse::kJump;
  const BaroUse use = UseReading(t, y);
  if (use == BaroUse::kUsed && options_.floor_prior && !floors_.empty()) FloorPrior(t);
  return use;
}

void HeightFilter::FloorPrior(TimeS t) {
  level_h_.emplace_back(t, x_[0]);
  while (!level_h_.empty() && level_h_.front().first < t - options_.floor_prior_window_s)
    level_h_.pop_front();
  if (last_floor_prior_t_ && t - *last_floor_prior_t_ < options_.floor_prior_period_s) return;
  if (t - level_h_.front().first < 0.8 * options_.floor_prior_window_s) return;
  double lo = x_[0], hi = x_[0];
  for (const auto& [ti, hi_m] : level_h_) lo = std::min(lo, hi_m), hi = std::max(hi, hi_m);
  if (hi - lo > options_.floor_prior_level_m) return;  // on stairs, or not settled
  const FloorLevel* nearest = nullptr;
  for (const FloorLevel& f : floors_) {
    if (!nearest || std::abs(f.elevation_m - x_[0]) < std::abs(nearest->elevation_m - x_[0]))
      nearest = &f;
  }
  if (!nearest || std::abs(nearest->elevation_m - x_[0]) > options_.floor_prior_gate_m) return;
  // h measured at the level: H = [1, 0].
  const double r2 = options_.floor_prior_sigma_m * options_.floor_prior_sigma_m;
  const double S = P_(0, 0) + r2;
  const Eigen::Vector2d K = P_.col(0) / S;
  x_ += K * (nearest->elevation_m - x_[0]);
  Eigen::Matrix2d I_KH = Eigen::Matrix2d::Identity();
  I_KH.col(0) -= K;
  P_ = I_KH * P_ * I_KH.transpose() + K * r2 * K.transpose();
  P_ = 0.5 * (P_ + P_.transpose());
  last_floor_prior_t_ = t;
  ++floor_priors_;
}

HeightFilter::BaroUse HeightFilter::UseReading(TimeS t, double y) {
  const double r2 = options_.baro_sigma_m * options_.baro_sigma_m;
  const Eigen::RowVector2d H(1.0, 1.0);
  auto update = [&](double residual) {
    const double S = (H * P_ * H.transpose())(0, 0) + r2;
    const Eigen::Vector2d K = P_ * H.transpose() / S;
    x_ += K * residual;
    // Joseph form keeps P symmetric positive definite.
    const Eigen::Matrix2d I_KH = Eigen::Matrix2d::Identity() - K * H;
    P_ = I_KH * P_ * I_KH.transpose() + K * r2 * K.transpose();
    P_ = 0.5 * (P_ + P_.transpose());
  };
  const double residual = y - (x_[0] + x_[1]);
  const double S = (H * P_ * H.transpose())(0, 0) + r2;
  if (residual * residual / S <= options_.gate_chi2) {
    update(residual);
    // Where the reading agrees with the state (1 sigma), the offset is as good as it gets: a
    // height change the steps miss later is measured from here.
    if (residual * residual <= S) Agree(t);
    rejected_run_.clear();
    ++used_;
    return BaroUse::kUsed;
  }
  ++rejected_;
  // Readings of a run agree with each other (within 3 sigma of their mean, plus a climb).
  rejected_run_.emplace_back(t, y);
  {
    double mean = 0;
    for (const auto& [ti, yi] : rejected_run_) mean += yi;
    mean /= static_cast<double>(rejected_run_.size());
    const double span = rejected_run_.back().first - rejected_run_.front().first;
    const double allowed = 3 * options_.baro_sigma_m + options_.max_vertical_speed_mps * span;
    while (rejected_run_.size() > 1 && std::abs(rejected_run_.front().second - mean) > allowed) {
      rejected_run_.erase(rejected_run_.begin());  // an earlier lone outlier
    }
  }
  const double span = rejected_run_.back().first - rejected_run_.front().first;
  if (span < options_.jump_persist_s) return BaroUse::kRejected;
  const std::size_t run_size = rejected_run_.size();
  double mean = 0;
  for (const auto& [ti, yi] : rejected_run_) mean += yi;
  mean /= static_cast<double>(rejected_run_.size());
  const TimeS t_first = rejected_run_.front().first;
  rejected_run_.clear();
  // What the height's own change since the readings last agreed does not explain, and how
  // fast it came: faster than a person climbs is the air (a door, a fan), not the agent. The
  // height expected now is the agreed one plus what the steps committed since.
  const double expected_h = agreed_->h_m + committed_since_agreement_;
  const double excess = mean - (expected_h + agreed_->offset_m);
  const double dt = std::max(t_first - agreed_->t, 1e-3);
  const double margin =
      3 * std::sqrt(r2 / static_cast<double>(run_size) + agreed_->innovation_var_m2);
  const bool sudden = std::abs(excess) - margin > options_.max_vertical_speed_mps * dt;
  if (sudden || steps_know_height_) {
    // The offset takes it. Where the steps measure height (a foot INS sees stairs), a slower
    // disagreement is also the air's: the steps win, and the note says so.
    // What the readings moved h by since they agreed goes back (steps of unknown height let
    // them), and the offset takes the change.
    x_[0] = expected_h;
    x_[1] = mean - x_[0];
    P_(1, 1) += r2;
    Agree(t);
    // The readings held for a change of the air carry the offset before this one: a change
    // opened on them would go back to it (a spike taken as the first reading's reference put a
    // firefighter 16 m up for ten minutes that way).
    recent_.clear();
    ++jumps_;
    notes_.push_back(
        {t, "", "", "repeats",
         sudden ? fmt::format("barometer jumped by {:+.2f} m ({:+.2f} hPa) in {:.1f} s, faster "
                              "than a person climbs: taken as a pressure change (a door, "
                              "ventilation), re-referenced",
                              excess, -excess / 8.3, dt)
                : fmt::format("barometer disagrees with the steps' height by {:+.2f} m for {:.1f} "
                              "s: the steps measure height, the barometer is re-referenced",
                              excess, dt)});
    return BaroUse::kJump;
  }
  // A height change the steps could not see (they do not measure height), slower than a jump of
  // the air, faster than the weather: the agent moved. The offset takes back what it absorbed
  // since the readings last agreed, and h takes the whole change.
  x_[0] = expected_h;
  x_[1] = agreed_->offset_m;
  P_(0, 0) += excess * excess;
  update(y - (x_[0] + x_[1]));
  Agree(t);
  ++height_changes_;
  return BaroUse::kHeightChange;
}

namespace {
double NormalCdf(double z) { return 0.5 * std::erfc(-z / std::sqrt(2.0)); }
}  // namespace

std::pair<int, double> HeightFilter::Level(const std::vector<FloorLevel>& floors) const {
  const double h = x_[0];
  const double sigma = std::sqrt(std::max(P_(0, 0), 1e-8));
  auto probability = [&](int level) {
    const auto [lo, hi] = LevelHeightInterval(floors, level);
    if (!(hi > lo)) return 0.0;
    const double upper = std::isinf(hi) ? 1.0 : NormalCdf((hi - h) / sigma);
    const double lower = std::isinf(lo) ? 0.0 : NormalCdf((lo - h) / sigma);
    return std::max(0.0, upper - lower);
  };
  std::vector<int> candidates;
  if (floors.empty()) {
    const int at = LevelAt(floors, h);
    for (int l = at - 2; l <= at + 2; ++l) candidates.push_back(l);
  } else {
    for (const FloorLevel& f : floors) candidates.push_back(f.level);
  }
  int best = LevelAt(floors, h);
  double best_p = -1;
  for (int l : candidates) {
    const double pl = probability(l);
    if (pl > best_p) best = l, best_p = pl;
  }
  return {best, std::max(best_p, 0.0)};
}

void HeightFilter::AirChanged(TimeS since, double rise_s, double jump_m) {
  air_m_ += jump_m;
  ++air_changes_;
  for (Recent& r : recent_) r.y -= jump_m * AirRamp(r.t, since, rise_s);
  for (auto& [ti, yi] : rejected_run_) yi -= jump_m * AirRamp(ti, since, rise_s);
  if (shift_) {
    // The change that opened the shift was the air's, now taken out: the shift is over, and
    // its readings since it opened are used as any other (a climb in them is the agent's).
    Shift shift = std::move(*shift_);
    shift_.reset();
    recent_.clear();
    for (auto& [ti, yi] : shift.readings) {
      if (ti >= shift.since) UseReading(ti, yi - jump_m * AirRamp(ti, since, rise_s));
    }
  }
}

std::map<std::string, double> HeightFilter::Counters() const {
  std::map<std::string, double> c{{"steps", static_cast<double>(steps_)},
                                  {"baro_air_changes", static_cast<double>(air_changes_)},
                                  {"stairs_steps", static_cast<double>(stairs_steps_)},
                                  {"baro_used", static_cast<double>(used_)},
                                  {"baro_rejected", static_cast<double>(rejected_)},
                                  {"baro_jumps", static_cast<double>(jumps_)},
                                  {"baro_height_changes", static_cast<double>(height_changes_)},
                                  {"baro_stuck", static_cast<double>(stuck_readings_)}};
  if (options_.floor_prior) c["floor_priors"] = static_cast<double>(floor_priors_);
  return c;
}

std::vector<IntegrityNote> HeightFilter::TakeNotes(const std::string& agent) {
  std::vector<IntegrityNote> out;
  out.swap(notes_);
  for (auto& n : out) {
    n.source = "barometer " + agent;
    n.node = agent;
  }
  return out;
}

namespace {
// The start's height: known to a few centimetres at the entrance (its level is given).
constexpr double kStartSigmaM = 0.05;
}  // namespace

HeightChannel::HeightChannel(MissionInfo info, HeightOptions options)
    : info_(std::move(info)), options_(options) {
  std::string why;
  if (!options_.IsValid(&why)) throw std::invalid_argument(why);
}

HeightFilter& HeightChannel::FilterOf(const std::string& agent) {
  auto it = filters_.find(agent);
  if (it != filters_.end()) return it->second;
  double z = 0;
  if (const NodeInfo* node = info_.Find(agent)) {
    if (const auto start = info_.AgentStart(*node)) z = start->z();
  }
  HeightFilter& f = filters_.emplace(agent, HeightFilter(z, kStartSigmaM, options_)).first->second;
  if (options_.floor_prior) f.SetFloors(info_.floors);
  return f;
}

const HeightFilter* HeightChannel::Filter(const std::string& agent) const {
  const auto it = filters_.find(agent);
  return it == filters_.end() ? nullptr : &it->second;
}

namespace {
bool IsAgent(const MissionInfo& info, const std::string& id) {
  const NodeInfo* node = info.Find(id);
  return node != nullptr && node->kind == NodeKind::kAgent;
}
}  // namespace

void HeightChannel::Add(const MissionRow& row) {
  if (const auto* step = std::get_if<Step>(&row)) {
    if (IsAgent(info_, step->agent)) FilterOf(step->agent).AddStep(*step);
  } else if (const auto* baro = std::get_if<BaroSample>(&row)) {
    if (!IsAgent(info_, baro->agent)) return;
    HeightFilter& f = FilterOf(baro->agent);
    if (options_.shared_air && options_.use_baro && std::isfinite(baro->pressure_hpa) &&
        std::isfinite(baro->t)) {
      air_recent_[baro->agent].emplace_back(baro->t,
                                            PressureAltitudeM(baro->pressure_hpa) - f.air_m());
      if (baro->t >= air_checked_t_ + kAirCheckS) CheckSharedAir(baro->t);
    }
    f.AddBaro(*baro);
    for (auto& n : f.TakeNotes(baro->agent)) notes_.push_back(std::move(n));
  } else if (const auto* event = std::get_if<MissionEvent>(&row)) {
    if (event->event != "drop" || event->node.empty() || !IsAgent(info_, event->agent)) return;
    const HeightFilter& f = FilterOf(event->agent);
    dropped_[event->node] = {f.height_m(), f.height_variance_m2(), f.Level(info_.floors).first};
  }
}

void HeightChannel::CheckSharedAir(TimeS t) {
  air_checked_t_ = t;
  // Each agent's change: the median of its last second against that of the second before the
  // one before (the second between holds a change of the air while it rises: a fan's takes a
  // second or two), from barometers that reported in both. A lone spike moves neither.
  struct Change {
    std::string agent;
    double d_m;
    double before_m;
  };
  std::vector<Change> changes;
  std::size_t readings = 0;
  for (auto& [agent, q] : air_recent_) {
    while (!q.empty() && q.front().first <= t - 3 * kAirWindowS) q.pop_front();
    std::vector<double> fresh, older;
    for (const auto& [ti, yi] : q) {
      if (ti > t - kAirWindowS) fresh.push_back(yi);
      if (ti <= t - 2 * kAirWindowS) older.push_back(yi);
    }
    if (fresh.size() < 3 || older.size() < 3) continue;
    readings += fresh.size() + older.size();
    const double before = Median(older);
    changes.push_back({agent, Median(std::move(fresh)) - before, before});
  }
  const std::size_t n = changes.size();
  if (n < static_cast<std::size_t>(options_.shared_air_min_agents)) return;
  std::vector<double> d;
  for (const Change& c : changes) d.push_back(c.d_m);
  const double shared = Median(d);
  // Faster than a person climbs, beyond the noise of the median of the medians (1.25 sigma /
  // sqrt(n) each; the change of one agent: two medians of ~5 readings).
  const double per_agent_sigma =
      1.25 * options_.baro_sigma_m * std::sqrt(2.0 / std::max(3.0, readings / (2.0 * n)));
  const double sigma_shared = 1.25 * per_agent_sigma / std::sqrt(static_cast<double>(n));
  const double climb_m = options_.max_vertical_speed_mps * 2 * kAirWindowS;
  if (std::abs(shared) <= climb_m + 3 * sigma_shared) return;
  // The barometers that saw it: nearer the shared change than no change (one in the street
  // does not share the building's air), and no further from it than a climb and the noise.
  const double allowed = climb_m + 3 * per_agent_sigma;
  std::vector<const Change*> saw;
  for (const Change& c : changes) {
    if (std::abs(c.d_m - shared) < std::abs(c.d_m) && std::abs(c.d_m - shared) <= allowed)
      saw.push_back(&c);
  }
  if (saw.size() < static_cast<std::size_t>(options_.shared_air_min_agents) || 2 * saw.size() < n)
    return;
  // The change as the air's: a level per barometer and one change for all, rising linearly
  // from t_j over `rise` (FitPressureJump's model without a climb), by least squares over their
  // readings; taken only once it is over (its end a second before the newest reading), so that
  // the whole of it comes out.
  struct Fit {
    double sse = std::numeric_limits<double>::infinity(), jump = 0, since = 0, rise = 0;
  };
  // The sum of squares of one barometer's readings about its level and the change j.
  auto barometer_sse = [&](const Change* c, double j, TimeS t_j, double rise_s) {
    const auto& q = air_recent_[c->agent];
    double level = 0;
    for (const auto& [ti, yi] : q) level += yi - j * AirRamp(ti, t_j, rise_s);
    level /= static_cast<double>(q.size());
    double sse = 0;
    for (const auto& [ti, yi] : q) {
      const double r = yi - level - j * AirRamp(ti, t_j, rise_s);
      sse += r * r;
    }
    return sse;
  };
  auto fit = [&](const std::vector<const Change*>& group) {
    Fit best;
    for (const double rise_s : {0.0, 0.5, 1.0, 2.0}) {
      for (const auto& [t_j, unused] : air_recent_[group.front()->agent]) {
        if (t_j <= t - 3 * kAirWindowS + 0.5) continue;
        // Per barometer, the level a_i and the shared J: with u the ramp, J = sum (y - ybar_i)
        // (u - ubar_i) / sum (u - ubar_i)^2.
        double num = 0, den = 0;
        for (const Change* c : group) {
          double ybar = 0, ubar = 0;
          const auto& q = air_recent_[c->agent];
          for (const auto& [ti, yi] : q) {
            ybar += yi;
            ubar += AirRamp(ti, t_j, rise_s);
          }
          ybar /= static_cast<double>(q.size());
          ubar /= static_cast<double>(q.size());
          for (const auto& [ti, yi] : q) {
            const double du = AirRamp(ti, t_j, rise_s) - ubar;
            num += (yi - ybar) * du;
            den += du * du;
          }
        }
        if (!(den > 1e-9)) continue;
        const double j = num / den;
        double sse = 0;
        for (const Change* c : group) sse += barometer_sse(c, j, t_j, rise_s);
        if (sse < best.sse) best = {sse, j, t_j, rise_s};
      }
    }
    return best;
  };
  Fit f = fit(saw);
  // Each barometer must have changed when the air did: one that changed a second or more
  // later (a firefighter who walked in through the door into the fan's air) is left to its own
  // filter — the shared ramp taken out of its readings from before it entered put it 1.7 m up
  // for the rest of its search (all-sources-4h --minutes 10, seed 305, ff9). Each barometer's
  // own time of the change (the fitted change as a step, from its readings alone) against the
  // median of them all (the group's fit would stretch its ramp to the late one).
  if (std::isfinite(f.sse)) {
    std::vector<TimeS> own(saw.size());
    for (std::size_t i = 0; i < saw.size(); ++i) {
      double best_sse = std::numeric_limits<double>::infinity();
      for (const auto& [t_j, unused] : air_recent_[saw[i]->agent]) {
        const double sse = barometer_sse(saw[i], f.jump, t_j, 0.0);
        if (sse < best_sse) best_sse = sse, own[i] = t_j;
      }
    }
    const TimeS when = Median(own);
    std::vector<const Change*> same_time;
    for (std::size_t i = 0; i < saw.size(); ++i) {
      if (std::abs(own[i] - when) <= kAirSameTimeS) same_time.push_back(saw[i]);
    }
    if (same_time.size() < saw.size()) {
      if (same_time.size() < static_cast<std::size_t>(options_.shared_air_min_agents)) return;
      saw = std::move(same_time);
      f = fit(saw);
    }
  }
  const double best_sse = f.sse, jump = f.jump, since = f.since, rise = f.rise;
  // Not over yet (or not the air's after all): later.
  if (!std::isfinite(best_sse) || since + rise > t - kAirWindowS || std::abs(jump) <= climb_m)
    return;
  for (const Change* c : saw) {
    filters_.at(c->agent).AirChanged(since, rise, jump);
    for (auto& [ti, yi] : air_recent_[c->agent]) yi -= jump * AirRamp(ti, since, rise);
  }
  const double shared_m = jump;
  ++air_jumps_;
  notes_.push_back({since, "barometers", "", "repeats",
                    fmt::format("the air changed by {:+.2f} m ({:+.2f} hPa) for {} of {} "
                                "barometers at once, faster than a person climbs (a fan, a "
                                "door): taken out of their readings",
                                shared_m, -shared_m / 8.3, saw.size(), n)});
}

std::optional<LevelBelief> HeightChannel::NodeLevel(const std::string& node) const {
  if (const auto it = filters_.find(node); it != filters_.end()) {
    const auto [level, p] = it->second.Level(info_.floors);
    return LevelBelief{level, p, it->second.height_m(), it->second.height_variance_m2()};
  }
  if (const auto it = dropped_.find(node); it != dropped_.end()) {
    return LevelBelief{it->second.level, 1.0, it->second.z_m, it->second.szz_m2};
  }
  if (IsAgent(info_, node)) {  // no step nor reading yet: at its start's height
    const auto start = info_.AgentStart(*info_.Find(node));
    const double z = start ? start->z() : 0.0;
    return LevelBelief{LevelAt(info_.floors, z), 1.0, z, kStartSigmaM * kStartSigmaM};
  }
  return std::nullopt;
}

void HeightChannel::Annotate(Estimate& e) const {
  if (const auto b = NodeLevel(e.id)) {
    e.position_n.z() = b->z_m;
    e.szz = b->szz_m2;
    if (!e.floor) e.floor = b->level;  // an estimator's own level (map matching) stands
  }
}

void HeightChannel::AddToSummary(EstimatorSummary& summary) const {
  for (const auto& [agent, f] : filters_) {
    for (const auto& [key, value] : f.Counters()) {
      summary.numbers["height." + agent + "." + key] = value;
    }
    const auto [level, p] = f.Level(info_.floors);
    summary.numbers["height." + agent + ".final_level"] = level;
    summary.numbers["height." + agent + ".final_level_probability"] = p;
    summary.numbers["height." + agent + ".final_z_m"] = f.height_m();
  }
  if (options_.shared_air) summary.numbers["height.shared_air_changes"] = air_jumps_;
  summary.integrity.insert(summary.integrity.end(), notes_.begin(), notes_.end());
}

}  // namespace trailmark

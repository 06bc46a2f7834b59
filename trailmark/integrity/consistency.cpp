// SPDX-License-Identifier: MIT
#include "trailmark/integrity/consistency.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <boost/math/distributions/chi_squared.hpp>
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>

namespace trailmark::integrity {

double ChiSquareQuantile(double dof, double p) {
  if (!(dof > 0) || !std::isfinite(dof) || !(p > 0 && p < 1)) {
    throw std::invalid_argument(
        fmt::format("chi-square quantile: need dof > 0 and 0 < p < 1, got dof {} p {}", dof, p));
  }
  return boost::math::quantile(boost::math::chi_squared_distribution<double>(dof), p);
}

bool ConsistencyOptions::IsValid(std::string* why) const {
  auto fail = [&](const char* text) {
    if (why) *why = text;
    return false;
  };
  if (!(window_s > 0) || !std::isfinite(window_s)) return fail("integrity window_s must be > 0");
  if (min_updates < 1) return fail("integrity min_updates must be >= 1");
  if (!(false_alarm > 0 && false_alarm < 0.5)) return fail("integrity false_alarm must be in (0, 0.5)");
  if (!(clip_probability > 0 && clip_probability < 0.5))
    return fail("integrity clip_probability must be in (0, 0.5)");
  return true;
}

const OptionTable<ConsistencyOptions>& ConsistencyOptionTable() {
  static const OptionTable<ConsistencyOptions> table = [] {
    OptionTable<ConsistencyOptions> t;
    t.Flag("integrity.exclude", &ConsistencyOptions::exclude,
           "leave out a source whose windowed NIS is inconsistent with its stated noise (false: "
           "report only)");
    t.Real("integrity.window_s", &ConsistencyOptions::window_s, "s", OptionBounds::Positive(),
           "sliding window of each source's normalized innovations");
    t.Integer("integrity.min_updates", &ConsistencyOptions::min_updates,
              OptionBounds::Between(1, 1000000), "updates in the window before a verdict");
    t.Real("integrity.false_alarm", &ConsistencyOptions::false_alarm, "",
           OptionBounds::Inside(0, 0.5), "probability that one window test flags an honest source");
    return t;
  }();
  return table;
}

ConsistencyMonitor::ConsistencyMonitor(std::string what, ConsistencyOptions options)
    : what_(std::move(what)), options_(options) {
  std::string why;
  if (!options_.IsValid(&why)) throw std::invalid_argument(why);
}

double ConsistencyMonitor::Clip(int dof) {
  auto [it, added] = clip_.try_emplace(dof, 0.0);
  if (added) it->second = ChiSquareQuantile(dof, 1 - options_.clip_probability);
  return it->second;
}

double ConsistencyMonitor::Threshold(int dof) {
  auto [it, added] = threshold_cache_.try_emplace(dof, 0.0);
  if (added) it->second = ChiSquareQuantile(dof, 1 - options_.false_alarm);
  return it->second;
}

bool ConsistencyMonitor::Record(const std::string& source, TimeS t, double nis, int dof) {
  if (dof < 1) throw std::invalid_argument("integrity: an innovation has at least 1 dimension");
  const double gate = Clip(dof);
  const double clipped = std::isfinite(nis) && nis >= 0 ? std::min(nis, gate) : gate;
  Source& s = sources_[source];
  s.window.push_back({t, clipped, dof});
  s.sum += clipped;
  s.dof += dof;
  while (!s.window.empty() && s.window.front().t < t - options_.window_s) {
    s.sum -= s.window.front().nis;
    s.dof -= s.window.front().dof;
    s.window.pop_front();
  }
  if (s.window.size() < options_.min_updates) {
    // Too few to judge. A source already flagged stays flagged until a full window clears it.
    if (s.verdict != Verdict::kInconsistent) s.verdict = Verdict::kUnknown;
  } else {
    const double threshold = Threshold(s.dof);
    s.ratio = s.sum / threshold;
    const Verdict now = s.sum > threshold ? Verdict::kInconsistent : Verdict::kConsistent;
    if (now != s.verdict && (now == Verdict::kInconsistent || s.verdict == Verdict::kInconsistent)) {
      const bool flagged = now == Verdict::kInconsistent;
      if (flagged) s.ever_flagged = true;
      notes_.push_back(IntegrityNote{
          t, fmt::format("{} {}", what_, source), "", flagged ? "excluded" : "readmitted",
          fmt::format("{} {} {} at t {:.1f} s: NIS {:.1f} over {} updates ({} dof) against the "
                      "{:g} % threshold {:.1f} of its stated noise",
                      what_, source, flagged ? "excluded" : "readmitted", t, s.sum,
                      s.window.size(), s.dof, 100 * (1 - options_.false_alarm), threshold)});
    }
    s.verdict = now;
  }
  const bool use = s.verdict != Verdict::kInconsistent || !options_.exclude;
  if (!use) ++refused_;
  return use;
}

Verdict ConsistencyMonitor::verdict(const std::string& source) const {
  auto it = sources_.find(source);
  return it == sources_.end() ? Verdict::kUnknown : it->second.verdict;
}

double ConsistencyMonitor::ratio(const std::string& source) const {
  auto it = sources_.find(source);
  return it == sources_.end() ? 0.0 : it->second.ratio;
}

std::size_t ConsistencyMonitor::flagged_sources() const {
  std::size_t n = 0;
  for (const auto& [id, s] : sources_) n += s.ever_flagged ? 1 : 0;
  return n;
}

void ConsistencyMonitor::Report(EstimatorSummary& summary) const {
  summary.numbers["integrity." + what_ + ".flagged"] = static_cast<double>(flagged_sources());
  summary.numbers["integrity." + what_ + ".refused"] = static_cast<double>(refused_);
  summary.integrity.insert(summary.integrity.end(), notes_.begin(), notes_.end());
}

RepeatDetector::RepeatDetector(std::string what, std::size_t max_repeats)
    : what_(std::move(what)), max_repeats_(max_repeats) {
  if (max_repeats_ < 2) throw std::invalid_argument("integrity: max_repeats must be >= 2");
}

bool RepeatDetector::Record(const std::string& source, TimeS t, std::span<const double> reading) {
  Run& run = runs_[source];
  if (run.count > 0 && std::equal(reading.begin(), reading.end(), run.value.begin(), run.value.end())) {
    ++run.count;
  } else {
    if (run.flagged) {
      notes_.push_back(IntegrityNote{t, fmt::format("{} {}", what_, source), "", "readmitted",
                                     fmt::format("{} {} readmitted at t {:.1f} s: its readings "
                                                 "change again",
                                                 what_, source, t)});
    }
    run.value.assign(reading.begin(), reading.end());
    run.count = 1;
    run.flagged = false;
  }
  if (run.count >= max_repeats_ && !run.flagged) {
    run.flagged = true;
    notes_.push_back(IntegrityNote{
        t, fmt::format("{} {}", what_, source), "", "repeats",
        fmt::format("{} {} at t {:.1f} s: the same reading ({}) {} times in a row (a frozen or "
                    "replayed stream)",
                    what_, source, t, fmt::join(run.value, ", "), run.count)});
  }
  if (run.flagged) ++refused_;
  return !run.flagged;
}

bool StreamCheckOptions::IsValid(std::string* why) const {
  if (max_repeats < 2) {
    if (why) *why = "integrity.max_repeats must be >= 2";
    return false;
  }
  return true;
}

const OptionTable<StreamCheckOptions>& StreamCheckOptionTable() {
  static const OptionTable<StreamCheckOptions> table = [] {
    OptionTable<StreamCheckOptions> t;
    t.Flag("integrity.streams", &StreamCheckOptions::enabled,
           "watch each link's RSSI, ranges and bearings and each IMU for frozen (repeated) "
           "readings");
    t.Integer("integrity.max_repeats", &StreamCheckOptions::max_repeats,
              OptionBounds::Between(2, 1000000), "equal readings in a row that make a frozen stream");
    return t;
  }();
  return table;
}

StreamCheck::StreamCheck(StreamCheckOptions options, std::unique_ptr<OnlineEstimator> inner)
    : options_(options),
      inner_(std::move(inner)),
      radio_("link", options.max_repeats),
      imu_("imu", options.max_repeats) {
  std::string why;
  if (!options_.IsValid(&why)) throw std::invalid_argument(why);
}

void StreamCheck::Add(const MissionRow& row, EstimateSink& sink) {
  if (options_.enabled) {
    bool pass = true;
    // The link's name is built in a reused buffer: no allocation per row once seen.
    auto link = [this](const char* kind, const std::string& from, const char* sep,
                       const std::string& to) -> const std::string& {
      key_.assign(kind).append(from).append(sep).append(to);
      return key_;
    };
    if (const auto* p = std::get_if<RssiPacket>(&row)) {
      pass = radio_.Record(link("rssi ", p->tx, "->", p->rx), p->t, p->rssi_dbm);
    } else if (const auto* r = std::get_if<RangeMeasurement>(&row)) {
      pass = radio_.Record(link("range ", r->a, "-", r->b), r->t, r->range_m);
    } else if (const auto* b = std::get_if<BearingMeasurement>(&row)) {
      pass = radio_.Record(link("bearing ", b->a, "-", b->b), b->t, b->bearing_rad);
    } else if (const auto* s = std::get_if<ImuSample>(&row)) {
      const double v[6] = {s->accel_b.x(), s->accel_b.y(), s->accel_b.z(),
                           s->gyro_b.x(),  s->gyro_b.y(),  s->gyro_b.z()};
      imu_.Record(s->agent, s->t, v);  // noted, passed on
    }
    if (!pass) return;
  }
  inner_->Add(row, sink);
}

EstimatorSummary StreamCheck::Summary() const {
  EstimatorSummary s = inner_->Summary();
  if (!options_.enabled) return s;
  s.numbers["integrity.repeated_rows"] = static_cast<double>(radio_.refused());
  s.numbers["integrity.frozen_imu_samples"] = static_cast<double>(imu_.refused());
  s.integrity.insert(s.integrity.end(), radio_.notes().begin(), radio_.notes().end());
  s.integrity.insert(s.integrity.end(), imu_.notes().begin(), imu_.notes().end());
  std::stable_sort(s.integrity.begin(), s.integrity.end(),
                   [](const IntegrityNote& a, const IntegrityNote& b) { return a.t < b.t; });
  return s;
}

}  // namespace trailmark::integrity

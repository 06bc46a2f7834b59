// SPDX-License-Identifier: MIT
#pragma once
/// Integrity (issue 21, item 3): the one mechanism every estimator uses to check that what a
/// source says agrees with its stated noise. A source is anything whose errors may be wrong
/// together: a landmark, a beacon, a crumb, a device, a whole sensing method. Each would-be
/// update of a source gives its normalized innovation squared (NIS = nu' S^-1 nu, with S the
/// innovation covariance the estimator believes: state and measurement noise); for a source
/// that is what it claims, the NIS of n updates sum to a chi-square variable of sum(dof)
/// degrees of freedom. The monitor keeps each source's NIS over a sliding window and flags the
/// source when the sum exceeds the (1 - false_alarm) quantile; a flagged source is not to be
/// used until its window (its innovations computed against the estimate that no longer uses it)
/// passes again. Each NIS is clipped before it is summed, so gross outliers (gated by the
/// estimator anyway) cannot flag a source unless they are a large share of its window. As in the RAIM / NIS tests of GNSS integrity (Bar-Shalom, Li, Kirubarajan,
/// "Estimation with applications to tracking and navigation", sec. 5.4: the windowed NIS
/// test). No I/O.

#include <cstddef>
#include <deque>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <unordered_map>
#include <vector>

#include "trailmark/core/online_estimator.h"
#include "trailmark/core/options.h"
#include "trailmark/core/types.h"

namespace trailmark::integrity {

/// The p-quantile of the chi-square distribution with `dof` degrees of freedom (Boost.Math).
/// dof > 0, 0 < p < 1; std::invalid_argument otherwise.
double ChiSquareQuantile(double dof, double p);

struct ConsistencyOptions {
  /// Leave a flagged source out (false: only report it).
  bool exclude = true;
  /// Sliding window of a source's NIS, s (ours: long enough for tens of updates of a landmark
  /// or beacon at 1-10 Hz, short enough to react within a corridor's length of walking).
  double window_s = 20.0;
  /// Fewer updates in the window: no verdict (the source is used, gated per update only).
  std::size_t min_updates = 8;
  /// Probability that a consistent source is flagged by one window test.
  double false_alarm = 1e-3;
  /// Each update's NIS is clipped at its (1 - clip_probability) chi-square quantile before it
  /// is summed (1 %: 6.6 for one dof), and the sum is compared with the unclipped chi-square
  /// quantile: sporadic outliers that the estimator gates anyway (NLOS ranges, bearing
  /// outliers) need to be a third of the window to flag a source, while a source that is off
  /// all the time (moved, offset, scaled) flags within min_updates.
  double clip_probability = 1e-2;
  bool IsValid(std::string* why) const;
};

/// The `integrity.` keys of an estimator that checks its sources (`integrity.exclude`,
/// `integrity.window_s`, `integrity.min_updates`, `integrity.false_alarm`).
const OptionTable<ConsistencyOptions>& ConsistencyOptionTable();

/// What the window of a source says.
enum class Verdict {
  kUnknown,       ///< too few updates in the window
  kConsistent,    ///< the window's NIS sum is below the threshold
  kInconsistent,  ///< above: the source is not to be used
};

/// Windowed NIS test of each source.
class ConsistencyMonitor {
 public:
  /// `what`: names the kind of source in notes ("landmark", "beacon", ...).
  explicit ConsistencyMonitor(std::string what, ConsistencyOptions options = {});

  /// One would-be update of `source` at time `t` (non-decreasing per source): its NIS and the
  /// dimension of its innovation. Returns whether the update may be used: false while the
  /// source's window, this update included, is inconsistent (and `exclude` is set). A change
  /// of verdict adds a note.
  /// A non-finite or negative NIS counts as an update beyond the gate.
  bool Record(const std::string& source, TimeS t, double nis, int dof);

  /// The source's verdict after its last Record (kUnknown for a source never recorded).
  Verdict verdict(const std::string& source) const;
  /// The window's NIS sum over its threshold for the source (< 1: consistent), 0 if unknown.
  double ratio(const std::string& source) const;
  /// Sources flagged at least once, updates refused, and the notes of every change of verdict.
  std::size_t flagged_sources() const;
  std::size_t refused_updates() const { return refused_; }
  const std::vector<IntegrityNote>& notes() const { return notes_; }
  /// Adds "integrity.<what>.flagged", "integrity.<what>.refused" and the notes to `summary`.
  void Report(EstimatorSummary& summary) const;

 private:
  struct Update {
    TimeS t;
    double nis;
    int dof;
  };
  struct Source {
    std::deque<Update> window;
    double sum = 0;
    int dof = 0;
    Verdict verdict = Verdict::kUnknown;
    double ratio = 0;
    bool ever_flagged = false;
  };
  std::string what_;
  ConsistencyOptions options_;
  std::map<std::string, Source> sources_;
  std::map<int, double> clip_, threshold_cache_;
  std::size_t refused_ = 0;
  std::vector<IntegrityNote> notes_;
  double Clip(int dof);
  double Threshold(int dof);
};

/// Flags a stream that freezes or repeats: the same reading `max_repeats` times in a row from
/// one source (a real sensor's noise makes exact repeats of a floating-point reading rare; a
/// stuck driver or a replayed buffer repeats). Keyed by source; a reading is one or more values.
class RepeatDetector {
 public:
  explicit RepeatDetector(std::string what, std::size_t max_repeats = 20);
  /// One reading; returns false while the source repeats (from its max_repeats-th equal
  /// reading on, until a different one).
  bool Record(const std::string& source, TimeS t, std::span<const double> reading);
  bool Record(const std::string& source, TimeS t, double value) {
    return Record(source, t, std::span<const double>(&value, 1));
  }
  const std::vector<IntegrityNote>& notes() const { return notes_; }
  std::size_t refused() const { return refused_; }

 private:
  struct Run {
    std::vector<double> value;
    std::size_t count = 0;
    bool flagged = false;
  };
  std::string what_;
  std::size_t max_repeats_;
  std::unordered_map<std::string, Run> runs_;  ///< hashed: one look-up per radio row
  std::vector<IntegrityNote> notes_;
  std::size_t refused_ = 0;
};

/// The stream check of every pipeline (registry): each device's RSSI, range and bearing
/// readings of one link, and each agent's IMU samples, watched for repeats (RepeatDetector).
/// Repeated radio and ultrasound readings are not passed on (excluded, noted); a frozen IMU
/// is noted but passed on (the INS sees a foot at rest, which is what a frozen IMU looks
/// like; a gap in its samples would be worse). Everything else passes through unchanged.
struct StreamCheckOptions {
  bool enabled = true;
  /// Equal readings in a row that make a frozen stream. Every reading before it is still
  /// used, so it is kept short: 10. For float readings (ranges, bearings, IMU) a chance run of
  /// 10 is nil; for RSSI in whole dBm with a spread of 2 dB or more two packets are equal with
  /// probability <= 0.14, a chance run of 10 is <= 0.14^9 = 2e-8 per packet (0.02 false
  /// freezes per hour at a million packets an hour).
  std::size_t max_repeats = 10;
  bool IsValid(std::string* why) const;
};
const OptionTable<StreamCheckOptions>& StreamCheckOptionTable();

class StreamCheck : public OnlineEstimator {
 public:
  StreamCheck(StreamCheckOptions options, std::unique_ptr<OnlineEstimator> inner);
  void Add(const MissionRow& row, EstimateSink& sink) override;
  void Finish(EstimateSink& sink) override { inner_->Finish(sink); }
  void UseLevels(const LevelSource* levels) override { inner_->UseLevels(levels); }
  void StepsFromFootIns(const std::string& agent, bool foot_ins) override {
    inner_->StepsFromFootIns(agent, foot_ins);
  }
  std::optional<Mat2> StepTransform(const std::string& agent) const override {
    return inner_->StepTransform(agent);
  }
  std::vector<SourceShare> Sources(const std::string& node) const override {
    return inner_->Sources(node);
  }
  std::optional<Estimate> Current(const std::string& node) const override {
    return inner_->Current(node);
  }
  /// The inner summary, integrity.repeated_rows and the notes.
  EstimatorSummary Summary() const override;

 private:
  StreamCheckOptions options_;
  std::unique_ptr<OnlineEstimator> inner_;
  RepeatDetector radio_, imu_;
  std::string key_;
};

}  // namespace trailmark::integrity

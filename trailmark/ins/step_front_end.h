// SPDX-License-Identifier: MIT
#pragma once
/// How every steps-based estimator (pdr, breadcrumb, landmarks, beacons, mapmatch) gets its
/// steps and its row order, in batch and live alike:
///  - each agent's steps come from its `steps` rows or from its foot IMU through the ZUPT INS,
///    whichever arrives first (rows of the other kind are counted and ignored);
///  - an estimator that needs every row in global time order (RowOrder::kGlobal) gets them
///    through a TimeOrderBuffer: a row is released once no earlier row can still come — in a
///    time-ordered feed (a batch merge of the mission's files) when every INS has processed
///    past it; in a live feed also a reorder window behind the newest row, since devices deliver
///    their own rows in order but not in step with each other: `reorder_s` by default, or
///    with `reorder_adaptive` the feed's measured lateness (ReorderWindow), at most `reorder_s`.
///    Steps of an agent's INS are put in their place by their end time t1, as if read from
///    steps.csv;
///  - in global order, a steps.csv step that starts in its agent's declared stop (events.csv
///    `stop` .. `go`) is not motion and is not passed on (`ignore_steps_in_stops`).
/// The inner estimator sees steps, never IMU samples. Every row it gets also feeds the agents'
/// height channel (ins/height.h), which sets z, szz and floor of what it estimates. No I/O.

#include <cstdint>
#include <deque>
#include <limits>
#include <memory>
#include <string>

#include "trailmark/core/mission.h"
#include "trailmark/core/online_estimator.h"
#include "trailmark/core/options.h"
#include "trailmark/core/time_order_buffer.h"
#include "trailmark/ins/height.h"
#include "trailmark/ins/ins_estimator.h"

namespace trailmark {

/// The INS of the step consumers: their first steps wait for the IMU's mounting, at most 12
/// landings (ins::MountYawOptions::hold_first_landings; docs/ins.md): a step given out in the
/// INS's own frame is where a beacon or a crumb is dropped. A priori: three straight strides
/// usually come within the first metres; 12 landings are 10-15 s of a slow walk at most.
inline ins::InsOptions StepFrontEndInsDefaults() {
  ins::InsOptions o;
  o.mount_yaw.hold_first_landings = 12;
  return o;
}

struct StepFrontEndOptions {
  ins::InsOptions ins =
      StepFrontEndInsDefaults();  ///< for agents whose steps come from their foot IMU
  /// Live feed, global order: the longest (s) a row waits behind the newest row for older rows
  /// of other devices (1 s covers a batch of 0.1-1 s per device); with `reorder_adaptive` off
  /// (the default), every row waits this long (estimates lag by it).
  double reorder_s = 1.0;
  /// Live feed, global order: the window follows the feed's lateness instead (ReorderWindow):
  /// twice the largest lateness of the last 20-30 s of rows plus 50 ms, at least 0.2 s, at
  /// most `reorder_s`; `reorder_s` until the feed has spanned 10 s. Off by default: a device
  /// whose lateness grows past the learned window has rows late (out of order) once, which the
  /// fixed window avoids up to `reorder_s` (seen in the CLI test's free-running replay).
  bool reorder_adaptive = false;
  /// Global order: a step of steps.csv that starts after its agent's declared stop (events.csv
  /// `stop`) and before the next `go` is not motion: it is ignored and counted. A hand-held
  /// phone's step detector reads swaying while standing as steps; the stop/go events say the
  /// agent stands (the stop-and-go paper's premise). Steps of a foot INS are measured
  /// displacement and always kept. A stop explains away at most kMaxStepsInStop steps: more
  /// is walking, and the stop is taken as ended (its `go` missing; noted).
  bool ignore_steps_in_stops = true;
  static constexpr int kMaxStepsInStop = 4;
  /// Every agent's height channel (`height.` keys): z, szz and floor of the estimates.
  HeightOptions height;
  /// m: the foot is not the walker. A foot INS's steps say where the foot lands, the truth is
  /// the walker's body: the body passes over a standing foot, from half a stride behind it to
  /// half a stride ahead (a stride of 1.2-1.4 m: uniform over +-0.6-0.7 m, sigma 0.35-0.4 m),
  /// and a foot is half a foot's width beside the body's line (0.1 m). Added to the covariance
  /// of every estimate of an agent whose steps come from its foot INS: `along` on the walking
  /// direction of its last step, `across` on the other axis (set a priori; the `ins` pipeline's
  /// own `foot_offset_sigma_m`, ins_estimator.h, is the along one on both axes). 0: none.
  double foot_offset_along_sigma_m = 0.35;
  double foot_offset_across_sigma_m = 0.1;
  /// s; the view between rows (ours, issues 20 and 21): a steps-based estimator knows an agent
  /// only as of its last step's end, while the walker walks on and the next step ends ~0.6 s
  /// later (scored at the truth's instants, a held estimate lags by up to a step). Before each
  /// row at t, every `view_period_s` after an agent's last estimate and before t gets that
  /// estimate moved on at the last step's velocity, turned and scaled as the estimator moves
  /// steps (OnlineEstimator::StepTransform) — at most one step ahead, back to the last estimate
  /// once 1.5 steps' durations passed without a step or a declared stop came (the walker
  /// stands where the step ended) — its covariance grown by `view_speed_sigma` x that speed x
  /// the time ahead per axis (walking on, slowing, turning, stopping): the model of
  /// beacons-ekf's own view (docs/beacons.md). From the rows before it only, so live = batch.
  /// 0: at the estimator's own estimates only. 0.1: a 10 Hz display (a priori, as
  /// beacons-ekf's).
  double view_period_s = 0.1;
  double view_speed_sigma = 0.5;
  /// Beyond one step ahead, how many steps' durations without a step make the view go back to
  /// the last estimate (a priori: a step 50 % slower than the last is still walking).
  static constexpr double kViewStoppedSteps = 1.5;
  /// The view's velocity is the last steps' over at least this span (a stride of a foot INS's
  /// two steps; a priori), steps that follow each other within kViewContiguousS.
  static constexpr double kViewBaselineS = 0.5;
  static constexpr double kViewContiguousS = 0.1;
  bool IsValid(std::string* why) const;
};
/// The `ins.` keys (the INS options with the prefix).
const OptionTable<StepFrontEndOptions>& StepSourceOptionTable();
/// The `ins.` keys, `reorder_s` and `reorder_adaptive`, for estimators that need global time
/// order.
const OptionTable<StepFrontEndOptions>& OrderedStepSourceOptionTable();
/// `view_period_s` and `view_speed_sigma`, for estimators that do not write their own view
/// between rows.
const OptionTable<StepFrontEndOptions>& StepViewOptionTable();

/// How long a live row waits behind the newest row for older rows of other devices, from what
/// the feed shows: a row's lateness is how far its time is behind the newest row seen before
/// it (a device's batch that comes after another's, network delay, a clock behind). The window
/// is twice the largest lateness of the current and the two previous 10 s buckets of mission
/// time, plus 50 ms, at least 0.2 s (sparse rows show a device's lateness only slowly) and at
/// most the cap; the cap until the feed has spanned 10 s (many batches of every device: they
/// send 0.1-1 s at a time). A row later than the window is late (TimeOrderBuffer counts it); a
/// feed that gets later widens the window with its first late row. O(1) a row, no allocation.
class ReorderWindow {
 public:
  static constexpr double kBucketS = 10.0;  ///< mission seconds per lateness bucket
  static constexpr double kMargin = 2.0;    ///< window / largest lateness
  static constexpr double kSlackS = 0.05;   ///< added to the window, s
  static constexpr double kFloorS = 0.2;    ///< the least window, s (below the cap)
  static constexpr double kWarmUpS = 10.0;  ///< mission seconds at the cap first
  explicit ReorderWindow(double cap_s) : cap_s_(cap_s) {}
  /// A row of time `t` arrived when the newest row seen before it was `newest` (-inf: none).
  void Observe(TimeS t, TimeS newest);
  /// The window (s) now.
  double seconds() const;
  /// The largest lateness (s) in the window's memory.
  double peak_lateness_s() const;

 private:
  double cap_s_;
  TimeS first_ = std::numeric_limits<double>::quiet_NaN();
  TimeS newest_ = -std::numeric_limits<double>::infinity();
  std::int64_t bucket_ = 0;     ///< the current bucket's index
  double peak_[3] = {0, 0, 0};  ///< the current bucket's and the two before it
};

/// Whether the inner estimator needs all rows in global time order or only each agent's.
enum class RowOrder { kPerAgent, kGlobal };
/// How rows arrive: in global time order (a batch merge of files, ties as MissionRow's order)
/// or live (each device's rows of a stream in time order, devices interleaved).
enum class Feed { kTimeOrdered, kLive };

class StepFrontEnd : public OnlineEstimator {
 public:
  StepFrontEnd(MissionInfo info, StepFrontEndOptions options, RowOrder order, Feed feed,
               std::unique_ptr<OnlineEstimator> inner);
  /// Throws std::invalid_argument for IMU samples or steps of a node that is not an agent, or
  /// an IMU sample the INS refuses; and whatever the inner estimator throws.
  void Add(const MissionRow& row, EstimateSink& sink) override;
  void Finish(EstimateSink& sink) override;
  std::optional<Estimate> Current(const std::string& node) const override;
  std::optional<Mat2> StepTransform(const std::string& agent) const override {
    return inner_->StepTransform(agent);
  }
  std::vector<SourceShare> Sources(const std::string& node) const override {
    return inner_->Sources(node);
  }
  /// The inner estimator's summary, and: rows ignored, late and waiting, the INS's steps.
  EstimatorSummary Summary() const override;
  OnlineEstimator& inner() { return *inner_; }
  const OnlineEstimator& inner() const { return *inner_; }

 private:
  void Deliver(const MissionRow& row, EstimateSink& sink);
  /// The row to the height channel and the inner estimator, its estimates annotated.
  void Pass(const MissionRow& row, EstimateSink& sink);
  void Release(EstimateSink& sink);
  bool UseSource(const std::string& agent, bool imu);
  /// The foot's offset from the walker (foot_offset_*_sigma_m) in the covariance of an
  /// estimate of an agent on foot-INS steps.
  void AddFootOffset(Estimate& e) const;
  /// The view between rows (StepFrontEndOptions::view_period_s) of `agent` before a row at `t`.
  struct View;
  void EmitViews(View& view, TimeS t, EstimateSink& sink);

  MissionInfo info_;
  StepFrontEndOptions options_;
  RowOrder order_;
  Feed feed_;
  std::unique_ptr<OnlineEstimator> inner_;
  ins::MultiAgentIns ins_;
  HeightChannel height_;
  EstimateSink* sink_ = nullptr;
  TimeOrderBuffer buffer_;
  ReorderWindow window_;
  std::map<std::string, bool> source_is_imu_;
  /// Agents on foot-INS steps: the unit direction of the last step that moved.
  std::map<std::string, Vec2> walking_direction_;
  /// Per agent: its latest estimate out (the inner estimator's or a view), the latest of the
  /// inner estimator's, and the last step passed to it (the view's base and velocity).
  struct View {
    std::string agent;
    TimeS out_t = -std::numeric_limits<double>::infinity();
    /// A declared stop (events.csv) since the last step: no view ahead from then on.
    TimeS stopped_t = std::numeric_limits<double>::infinity();
    std::optional<Estimate> inner;
    /// The walk's velocity over its latest contiguous steps spanning kViewBaselineS (a foot
    /// INS's two steps a stride, from the landing and from mid-swing, are 0.8 and 0.2 s long:
    /// one alone is a foot's speed, not the walker's), and the longest of their durations.
    Vec2 velocity_n = Vec2::Zero();
    double step_s = 0;
    struct Recent {
      TimeS t0, t1;
      Vec2 delta_n;
    };
    std::deque<Recent> recent;
  };
  std::map<std::string, View> views_;
  /// Global order: no agent's view is due before this (a lower bound; +inf: none can be).
  TimeS next_view_t_ = -std::numeric_limits<double>::infinity();
  std::size_t view_rows_ = 0;
  /// Passes estimates on and keeps each agent's latest in views_.
  class ViewRecordingSink;
  /// Agents standing by a declared stop (events.csv), and since when (global order only).
  struct DeclaredStop {
    TimeS since = 0;
    int steps = 0;  ///< steps ignored in it so far
  };
  std::map<std::string, DeclaredStop> stopped_;
  std::size_t steps_in_stops_ = 0, stops_without_go_ = 0;
  TimeS newest_ = -1e300;
  std::size_t ignored_ = 0, ins_steps_ = 0;
};

}  // namespace trailmark

// SPDX-License-Identifier: MIT
#pragma once
/// How every steps-based estimator (pdr, breadcrumb, landmarks, beacons, mapmatch) gets its
/// steps and its row order, in batch and live alike:
///  - each agent's steps come from its `steps` rows or from its foot IMU through the ZUPT INS,
///    whichever arrives first (rows of the other kind are counted and ignored);
///  - an estimator that needs every row in global time order (RowOrder::kGlobal) gets them
///    through a TimeOrderBuffer: a row is released once no earlier row can still come — in a
///    time-ordered feed (a batch merge of the mission's files) when every INS has processed
///    past it; in a live feed also `reorder_s` behind the newest row, since devices deliver
///    their own rows in order but not in step with each other. Steps of an agent's INS are put
///    in their place by their end time t1, as if read from steps.csv.
/// The inner estimator sees steps, never IMU samples. Every row it gets also feeds the agents'
/// height channel (ins/height.h), which sets z, szz and floor of what it estimates. No I/O.

#include <memory>
#include <string>

#include "trailmark/core/mission.h"
#include "trailmark/core/online_estimator.h"
#include "trailmark/core/options.h"
#include "trailmark/core/time_order_buffer.h"
#include "trailmark/ins/height.h"
#include "trailmark/ins/ins_estimator.h"

namespace trailmark {

struct StepFrontEndOptions {
  ins::InsOptions ins;  ///< for agents whose steps come from their foot IMU
  /// Live feed, global order: how long (s) a row waits behind the newest row for older rows of
  /// other devices (ours: 1 s covers a batch of 0.1-1 s per device; estimates lag by it).
  double reorder_s = 1.0;
  /// Every agent's height channel (`height.` keys): z, szz and floor of the estimates.
  HeightOptions height;
  bool IsValid(std::string* why) const;
};
/// The `ins.` keys (the INS options with the prefix).
const OptionTable<StepFrontEndOptions>& StepSourceOptionTable();
/// The `ins.` keys and `reorder_s`, for estimators that need global time order.
const OptionTable<StepFrontEndOptions>& OrderedStepSourceOptionTable();

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

  MissionInfo info_;
  StepFrontEndOptions options_;
  RowOrder order_;
  Feed feed_;
  std::unique_ptr<OnlineEstimator> inner_;
  ins::MultiAgentIns ins_;
  HeightChannel height_;
  EstimateSink* sink_ = nullptr;
  TimeOrderBuffer buffer_;
  std::map<std::string, bool> source_is_imu_;
  TimeS newest_ = -1e300;
  std::size_t ignored_ = 0, ins_steps_ = 0;
};

}  // namespace trailmark

#pragma once
/// The live (incremental) form of a pipeline, for the server's live mode: rows arrive one at a
/// time — each node's rows of a stream in non-decreasing time, streams and nodes interleaved as
/// the network delivers them — and the estimates they produce come out at once, instead of
/// re-running the batch pipeline over the whole journal. The batch `ins` pipeline runs through
/// the same code; `pdr` is tested equal to its batch form (tests/pipelines/live_estimator_test).

#include <map>
#include <memory>
#include <string>
#include <variant>

#include "trailmark/core/measurements.h"
#include "trailmark/core/mission.h"
#include "trailmark/geometry/floor_plan.h"
#include "trailmark/pipelines/pipeline.h"

namespace trailmark {

using LiveRow =
    std::variant<ImuSample, Step, RssiPacket, RangeMeasurement, BearingMeasurement, MissionEvent>;

/// The node whose device produced the row (the agent of IMU, steps and events; the receiver of
/// RSSI; the first node of ranges and bearings): a node's rows of one stream come in time order.
const std::string& RowNode(const LiveRow& row);
/// The row's time (t1 for steps).
TimeS RowTime(const LiveRow& row);

class LiveEstimator {
 public:
  virtual ~LiveEstimator() = default;
  /// One row; the estimates it produces go to `sink` (in non-decreasing time per node). Throws
  /// std::invalid_argument for a row the estimator cannot use (e.g. steps of a node that is not
  /// an agent); rows of streams the estimator does not use are ignored and counted.
  virtual void Add(const LiveRow& row, EstimateSink& sink) = 0;
  /// What the estimator reports so far (rows used and ignored, per-agent figures).
  virtual PipelineSummary Summary() const = 0;
};

/// The live form of pipeline `name` for an incident described by `info` (and its floor plan,
/// which mapmatch needs; may be null otherwise), or null when the pipeline has none (the server
/// then re-runs the batch pipeline on the journal). `info` and `plan` must outlive it. Throws
/// std::invalid_argument on bad options or a missing floor plan.
std::unique_ptr<LiveEstimator> MakeLiveEstimator(const std::string& name, const MissionInfo& info,
                                                 const std::map<std::string, std::string>& options,
                                                 const FloorPlan* plan = nullptr);

}  // namespace trailmark

// SPDX-License-Identifier: MIT
#pragma once
/// The one interface every estimator of trailmark implements (pdr, ins, breadcrumb,
/// landmarks-stopgo, landmarks-ukf, beacons-mds, beacons-ekf, mapmatch), as OpenVINS'
/// `feed_measurement_*` / `get_state()` or GTSAM's `ISAM2::update` / `calculateEstimate` do:
/// mission rows go in one at a time, estimates come out to a sink as they become known, the
/// current estimate of any node can be asked for at any time, a summary reports, and `Finish`
/// ends the data. The batch run (`trailmark run`) is a mission's streams merged in time order
/// into it; the live server feeds the same object from its committed journal rows. No I/O.

#include <cstdint>
#include <initializer_list>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <unordered_map>
#include <variant>
#include <vector>

#include "trailmark/core/measurements.h"

namespace trailmark {

/// One row of any measurement stream. At equal times rows go in this order (the variant's):
/// events, steps, ranges, bearings, RSSI, IMU, barometer — how a time-ordered merge of a
/// mission's streams breaks ties.
using MissionRow = std::variant<MissionEvent, Step, RangeMeasurement, BearingMeasurement,
                                RssiPacket, ImuSample, BaroSample>;

/// The time a row became known: t1 for steps, t for every other row.
TimeS RowTime(const MissionRow& row);
/// The node whose device produced the row (the agent of IMU, steps, events and barometer; the
/// receiver of RSSI; the first node of ranges and bearings): its rows of one stream come in
/// time order.
const std::string& RowNode(const MissionRow& row);

/// The measurement streams of the mission format (spec: "Streams").
enum class Stream : std::uint8_t { kSteps, kImu, kRssi, kRanges, kBearings, kEvents, kBaro };
inline constexpr Stream kAllStreams[] = {Stream::kSteps,  Stream::kImu,      Stream::kRssi,
                                         Stream::kRanges, Stream::kBearings, Stream::kEvents,
                                         Stream::kBaro};
/// "imu.csv", "steps.csv", ... (the spec's file names).
std::string_view StreamFileName(Stream stream);
/// The stream a row belongs to.
Stream RowStream(const MissionRow& row);

/// A set of streams (a bit per Stream).
class StreamSet {
 public:
  constexpr StreamSet() = default;
  constexpr StreamSet(std::initializer_list<Stream> streams) {
    for (Stream s : streams) bits_ |= Bit(s);
  }
  constexpr bool Has(Stream s) const { return (bits_ & Bit(s)) != 0; }
  constexpr StreamSet& Add(Stream s) {
    bits_ |= Bit(s);
    return *this;
  }
  constexpr bool empty() const { return bits_ == 0; }
  std::vector<Stream> List() const;
  friend constexpr bool operator==(StreamSet, StreamSet) = default;

 private:
  static constexpr std::uint16_t Bit(Stream s) {
    return static_cast<std::uint16_t>(1u << static_cast<unsigned>(s));
  }
  std::uint16_t bits_ = 0;
};

/// Receives estimates as an estimator produces them (each node's in non-decreasing time).
class EstimateSink {
 public:
  virtual ~EstimateSink() = default;
  virtual void Add(const Estimate& estimate) = 0;
};

/// Keeps every estimate in memory (tests, reproductions, the server's replay).
class VectorSink : public EstimateSink {
 public:
  void Add(const Estimate& estimate) override { rows.push_back(estimate); }
  /// The rows in non-decreasing time (stable: equal times keep their order); empties the sink.
  std::vector<Estimate> TakeSortedByTime();
  std::vector<Estimate> rows;
};

/// Drops every estimate (an estimator run for its final state or its summary only).
class NullSink : public EstimateSink {
 public:
  void Add(const Estimate&) override {}
};

/// An integrity note (issue 21, trailmark/integrity/): a source found inconsistent with its
/// stated noise and no longer used, or used again; an agent's estimate that left its own dead
/// reckoning's region and fell back to it, or came back. The live server raises each as an
/// `integrity` alert; the batch run writes them to diagnostics.json.
struct IntegrityNote {
  TimeS t = 0;          ///< mission time of the change, s
  std::string source;   ///< "landmark L3", "beacon B2", "agent ff1"
  std::string node;     ///< the node concerned (the agent of a fallback), may be empty
  std::string action;   ///< "excluded", "readmitted", "fallback", "resumed", "repeats"
  std::string message;  ///< in words, with the statistic and its threshold
};

/// What an estimator reports besides its estimates: counters and figures by name, notes in
/// words and integrity notes (written to diagnostics.json by the batch run, served by the live
/// server). Each estimator also has a typed summary of its own; this is its flat form.
struct EstimatorSummary {
  std::map<std::string, double> numbers;
  std::vector<std::string> notes;
  std::vector<IntegrityNote> integrity;
  /// Adds every number and note of `other` (numbers of the same name are overwritten).
  void Merge(const EstimatorSummary& other);
  /// One line: the numbers as "key value" pairs.
  std::string BriefReport() const;
};

/// Where a node is vertically: its level, how probable that level is, its z and variance.
struct LevelBelief {
  int level = 0;
  double probability = 1.0;
  double z_m = 0.0;
  double szz_m2 = 0.0;
};

/// What is known of every node's level when a row reaches an estimator: the agents' height
/// channel (ins/height.h), which sees every row before the estimator does.
class LevelSource {
 public:
  virtual ~LevelSource() = default;
  /// nullopt for a node it knows nothing of (not an agent, not dropped by one).
  virtual std::optional<LevelBelief> NodeLevel(const std::string& node) const = 0;
};

struct MissionInfo;

/// The level of a node: the source's (null: none), else for a node of known position in
/// mission.json its z's — an agent's by the spec's rule (LevelAt), a static node's as a mounted
/// device's (MountedLevelAt: a ceiling landmark stays on its storey); nullopt when neither knows.
std::optional<int> NodeLevelOf(const LevelSource* levels, const MissionInfo& info,
                               const std::string& node);
/// Whether two nodes are known to be on different levels (radio estimators leave such
/// measurements out: their models have no floors).
bool OnDifferentLevels(const LevelSource* levels, const MissionInfo& info, const std::string& a,
                       const std::string& b);

/// NodeLevelOf and OnDifferentLevels with mission.json's part read once: every node's level by
/// its z (or none), looked up by id instead of a search of the nodes at every packet. Equal to
/// the free functions for every node of `info` (tested); an id `info` does not name is asked of
/// the level source only.
class MissionLevels {
 public:
  explicit MissionLevels(const MissionInfo& info);
  std::optional<int> Of(const LevelSource* levels, const std::string& node) const;
  bool Differ(const LevelSource* levels, const std::string& a, const std::string& b) const;

 private:
  std::unordered_map<std::string, std::optional<int>> by_id_;
};

/// One source of a node's current estimate and its share of it (the fusion's members).
struct SourceShare {
  std::string source;   ///< a member pipeline's name ("beacons-ekf"), or "dead reckoning"
  double weight = 0.0;  ///< its share of the estimate, 0..1
};

class OnlineEstimator {
 public:
  virtual ~OnlineEstimator() = default;
  /// The nodes' levels, for estimators that use floors (map matching changes the level of its
  /// plan, radio estimators gate packets through floors); `levels` outlives the estimator.
  /// Wrappers pass it on. Default: not used.
  virtual void UseLevels(const LevelSource* /*levels*/) {}
  /// Where an agent's steps come from, told once per agent before its first step by the step
  /// front end that chose it (ins/step_front_end.h): a foot IMU through the ZUPT INS, or the
  /// mission's steps (a phone's PDR). Wrappers pass it on. Default: not used.
  virtual void StepsFromFootIns(const std::string& /*agent*/, bool /*foot_ins*/) {}
  /// One row. Each node's rows of one stream come in non-decreasing time; an estimator that
  /// needs all rows in global time order says so in its documentation (the pipeline registry
  /// then feeds it through a StepFrontEnd that restores the order). Rows of streams the
  /// estimator does not use are counted and ignored. Estimates the row produces go to `sink`.
  /// Throws std::invalid_argument for a row it cannot use (e.g. steps of a node that is not an
  /// agent of the mission); the estimator stays usable.
  virtual void Add(const MissionRow& row, EstimateSink& sink) = 0;
  /// End of data: whatever the estimator still holds is processed, final estimates emitted.
  virtual void Finish(EstimateSink& sink) = 0;
  /// The current estimate of `node` (its latest position and horizontal covariance), nullopt
  /// when the estimator has none (an unknown node, or one not yet localized).
  virtual std::optional<Estimate> Current(const std::string& node) const = 0;
  /// What the estimator reports so far.
  virtual EstimatorSummary Summary() const = 0;
  /// Which sources the node's latest estimate uses, with their shares (the fusion: its
  /// members and their weights); empty when the estimator does not say (a single-source
  /// estimator). Wrappers pass it on.
  virtual std::vector<SourceShare> Sources(const std::string& /*node*/) const { return {}; }
  /// How the estimator turns and stretches the agent's steps now (its estimated heading and
  /// step-scale corrections: a step d moves its estimate by M d), for the view between rows
  /// (ins/step_front_end.h); nullopt: as the steps come. Wrappers pass it on.
  virtual std::optional<Mat2> StepTransform(const std::string& /*agent*/) const {
    return std::nullopt;
  }
};

}  // namespace trailmark

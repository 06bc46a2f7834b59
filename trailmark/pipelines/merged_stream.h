#pragma once
/// Reads several streams of a mission directory as one sequence in time order (steps by t1,
/// the time their displacement became known), as an online estimator receives them. Ties:
/// events, then steps, ranges, bearings, RSSI. Streams that the mission lacks are skipped.

#include <memory>
#include <optional>
#include <variant>
#include <vector>

#include "trailmark/io/mission_io.h"

namespace trailmark {

using MissionRow = std::variant<MissionEvent, Step, RangeMeasurement, BearingMeasurement, RssiPacket>;

struct MergedStreamOptions {
  bool events = true, steps = true, ranges = true, bearings = true, rssi = true;
  /// Steps from memory (ordered by t1) instead of steps.csv, e.g. from the INS.
  const std::vector<Step>* steps_override = nullptr;
};

class MergedStream {
 public:
  explicit MergedStream(const MissionDirectory& mission, MergedStreamOptions options = {});
  ~MergedStream();
  MergedStream(const MergedStream&) = delete;
  MergedStream& operator=(const MergedStream&) = delete;
  /// False at the end of every stream. Throws InputError on bad input.
  bool Next(MissionRow& row);
  /// Fraction of the input bytes consumed, for progress bars.
  double Progress() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// The time a row became known: t1 for steps, t for every other row (std::visit it).
struct RowTimeOf {
  TimeS operator()(const Step& s) const { return s.t1; }
  template <class Row>
  TimeS operator()(const Row& r) const {
    return r.t;
  }
};

/// Time of a row (t1 for steps).
TimeS RowTime(const MissionRow& row);

}  // namespace trailmark

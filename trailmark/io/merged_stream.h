// SPDX-License-Identifier: MIT
#pragma once
/// Reads several streams of a mission directory as one sequence in time order (steps by t1,
/// the time their displacement became known), as an online estimator receives them in a batch
/// run. Ties: the MissionRow order (events, steps, ranges, bearings, RSSI, IMU, barometer), then
/// file order. Streams the mission lacks, or not asked for, are skipped. Each file is read in
/// 1 MiB chunks (io/streams.h): a multi-hour mission is never held in memory.

#include <memory>
#include <string>

#include "trailmark/core/online_estimator.h"
#include "trailmark/io/mission_io.h"

namespace trailmark {

class MergedStream {
 public:
  MergedStream(const MissionDirectory& mission, StreamSet streams);
  ~MergedStream();
  MergedStream(const MergedStream&) = delete;
  MergedStream& operator=(const MergedStream&) = delete;
  /// False at the end of every stream. Throws InputError on bad input.
  bool Next(MissionRow& row);
  /// Fraction of the input bytes consumed, for progress bars.
  double Progress() const;
  /// An InputError at the row last returned by Next (its file and line).
  [[noreturn]] void Fail(const std::string& problem) const;
  /// The streams being read (those asked for that the mission has).
  StreamSet streams() const { return present_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  StreamSet present_;
};

}  // namespace trailmark

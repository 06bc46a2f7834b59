// SPDX-License-Identifier: MIT
#pragma once
/// Rows held until no earlier row can still come, then handed out in time order: by time, then
/// by stream (the MissionRow variant's order: events, steps, ranges, bearings, RSSI, IMU,
/// barometer), then by node (RowNode), then by arrival. An estimator that needs global time
/// order gets its rows through one of these (live devices deliver their own rows in order but
/// not in step with each other; steps from a foot IMU come some samples after they end).
/// Simultaneous rows of different devices (a packet heard by several receivers) are ordered by
/// node, not by when they arrived: however the network interleaves the devices, the estimator
/// sees the same sequence as a batch run of the mission's files. No I/O.

#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include "trailmark/core/online_estimator.h"

namespace trailmark {

class TimeOrderBuffer {
 public:
  /// Holds `row`. A row older than one already released is late: counted, and released with
  /// the next call (it cannot go back in time).
  void Push(MissionRow row) {
    const TimeS t = RowTime(row);
    if (t < released_t_) ++late_;
    heap_.push_back({t, row.index(), arrivals_++, std::move(row)});
    std::push_heap(heap_.begin(), heap_.end(), Later);
  }
  /// Hands every held row with time < `until` to `out(const MissionRow&)`, in order.
  template <class Out>
  void ReleaseBefore(TimeS until, Out&& out) {
    while (!heap_.empty() && heap_.front().t < until) Pop(out);
  }
  /// Hands out every held row, in order.
  template <class Out>
  void ReleaseAll(Out&& out) {
    while (!heap_.empty()) Pop(out);
  }
  std::size_t size() const { return heap_.size(); }
  std::size_t late() const { return late_; }

 private:
  struct Held {
    TimeS t;
    std::size_t stream;
    std::uint64_t arrival;
    MissionRow row;
  };
  /// The heap's order (a max-heap of "later"): time, stream, node, arrival; the node is read
  /// from the rows only for simultaneous rows of one stream.
  static bool Later(const Held& a, const Held& b) {
    if (a.t != b.t) return a.t > b.t;
    if (a.stream != b.stream) return a.stream > b.stream;
    if (const int c = RowNode(a.row).compare(RowNode(b.row)); c != 0) return c > 0;
    return a.arrival > b.arrival;
  }
  template <class Out>
  void Pop(Out& out) {
    std::pop_heap(heap_.begin(), heap_.end(), Later);
    Held held = std::move(heap_.back());
    heap_.pop_back();
    released_t_ = std::max(released_t_, held.t);
    out(held.row);
  }
  std::vector<Held> heap_;
  std::uint64_t arrivals_ = 0;
  TimeS released_t_ = -1e300;
  std::size_t late_ = 0;
};

}  // namespace trailmark

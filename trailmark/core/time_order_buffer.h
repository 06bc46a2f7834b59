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
  /// Holds `row`. A row that sorts before one already released (older, or simultaneous and of a
  /// stream or node that comes first) is late: counted, and released with the next call (it
  /// cannot go back in time).
  void Push(MissionRow row) {
    const TimeS t = RowTime(row);
    const auto stream = static_cast<std::uint32_t>(row.index());
    const std::uint64_t prefix = NodePrefix(RowNode(row));
    // Late: it sorts before the last row released (a simultaneous row of a node that sorts
    // first counts too; ids sharing their first 8 bytes are not told apart here).
    if (t < released_t_ ||
        (t == released_t_ && (stream < released_stream_ ||
                              (stream == released_stream_ && prefix < released_prefix_)))) {
      ++late_;
    }
    std::uint32_t slot;
    if (free_.empty()) {
      slot = static_cast<std::uint32_t>(rows_.size());
      rows_.push_back(std::move(row));
    } else {
      slot = free_.back();
      free_.pop_back();
      rows_[slot] = std::move(row);
    }
    heap_.push_back({t, stream, slot, prefix, arrivals_++});
    std::push_heap(heap_.begin(), heap_.end(), Later{&rows_});
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
  /// The heap holds small keys; the rows stay in their slots (a heap of rows moved every row
  /// several times, strings included).
  struct Key {
    TimeS t;
    std::uint32_t stream;
    std::uint32_t slot;
    std::uint64_t node_prefix;  ///< the node's first 8 bytes, big-endian (NodePrefix)
    std::uint64_t arrival;
  };
  /// The first 8 bytes of an id, zero-padded, as a big-endian number: two ids whose prefixes
  /// differ compare as their strings do (ids hold no NUL); equal prefixes need the strings.
  static std::uint64_t NodePrefix(const std::string& id) {
    std::uint64_t key = 0;
    for (std::size_t k = 0; k < 8; ++k) {
      key = (key << 8) | (k < id.size() ? static_cast<unsigned char>(id[k]) : 0u);
    }
    return key;
  }
  /// The heap's order (a max-heap of "later"): time, stream, node, arrival; the node's strings
  /// are compared only for simultaneous rows of one stream whose ids share 8 bytes.
  struct Later {
    const std::vector<MissionRow>* rows;
    bool operator()(const Key& a, const Key& b) const {
      if (a.t != b.t) return a.t > b.t;
      if (a.stream != b.stream) return a.stream > b.stream;
      if (a.node_prefix != b.node_prefix) return a.node_prefix > b.node_prefix;
      if (const int c = RowNode((*rows)[a.slot]).compare(RowNode((*rows)[b.slot])); c != 0)
        return c > 0;
      return a.arrival > b.arrival;
    }
  };
  template <class Out>
  void Pop(Out& out) {
    std::pop_heap(heap_.begin(), heap_.end(), Later{&rows_});
    const Key key = heap_.back();
    heap_.pop_back();
    if (key.t >= released_t_) {
      released_t_ = key.t;
      released_stream_ = key.stream;
      released_prefix_ = key.node_prefix;
    }
    // Out of its slot before `out` runs (which may push, and so grow the slots).
    const MissionRow row = std::move(rows_[key.slot]);
    free_.push_back(key.slot);
    out(row);
  }
  std::vector<MissionRow> rows_;
  std::vector<std::uint32_t> free_;
  std::vector<Key> heap_;
  std::uint64_t arrivals_ = 0;
  TimeS released_t_ = -1e300;  ///< the last released row's sort key (a late row's is less)
  std::uint32_t released_stream_ = 0;
  std::uint64_t released_prefix_ = 0;
  std::size_t late_ = 0;
};

}  // namespace trailmark

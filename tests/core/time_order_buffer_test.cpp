// SPDX-License-Identifier: MIT
// TimeOrderBuffer against a reference: a stable sort of the same rows by (time, stream).
#include "trailmark/core/time_order_buffer.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

namespace trailmark {
namespace {

TEST(TimeOrderBuffer, ReleasesInTheOrderOfATimeOrderedMerge) {
  std::mt19937 rng(3);
  std::vector<MissionRow> rows;
  for (int i = 0; i < 400; ++i) {
    const double t = std::uniform_int_distribution<int>(0, 60)(rng) * 0.5;  // many equal times
    switch (i % 3) {
      case 0: rows.emplace_back(RssiPacket{t, "a" + std::to_string(i), "b", -60.0 - i}); break;
      case 1: rows.emplace_back(Step{t - 0.5, t, "ff" + std::to_string(i), Vec3::Zero(), {}}); break;
      default: rows.emplace_back(MissionEvent{t, "ff1", "stop", std::to_string(i)});
    }
  }
  // The reference: by time, then stream, then node, then arrival.
  std::vector<MissionRow> expected = rows;
  std::stable_sort(expected.begin(), expected.end(), [](const MissionRow& a, const MissionRow& b) {
    if (RowTime(a) != RowTime(b)) return RowTime(a) < RowTime(b);
    if (a.index() != b.index()) return a.index() < b.index();
    return RowNode(a) < RowNode(b);
  });
  TimeOrderBuffer buffer;
  std::vector<MissionRow> out;
  auto take = [&](const MissionRow& r) { out.push_back(r); };
  for (const MissionRow& r : rows) buffer.Push(r);
  buffer.ReleaseBefore(10.0, take);
  for (const MissionRow& r : out) EXPECT_LT(RowTime(r), 10.0);
  EXPECT_EQ(buffer.late(), 0u);
  buffer.ReleaseAll(take);
  ASSERT_EQ(out.size(), expected.size());
  for (std::size_t i = 0; i < out.size(); ++i) {
    EXPECT_EQ(RowTime(out[i]), RowTime(expected[i])) << i;
    EXPECT_EQ(RowNode(out[i]), RowNode(expected[i])) << i;
  }
  // A row older than one released is late: counted, still handed out.
  buffer.Push(RssiPacket{1.0, "x", "y", -50});
  EXPECT_EQ(buffer.late(), 1u);
  buffer.ReleaseBefore(2.0, take);
  EXPECT_EQ(RowNode(out.back()), "x");
  EXPECT_EQ(buffer.size(), 0u);
}

// A simultaneous row that sorts before the last one released (a packet heard by another
// receiver, whose device's batch came later) is late too; one that sorts after it is not.
TEST(TimeOrderBuffer, ASimultaneousRowThatSortsFirstIsLate) {
  TimeOrderBuffer buffer;
  std::vector<MissionRow> out;
  auto take = [&](const MissionRow& r) { out.push_back(r); };
  buffer.Push(RssiPacket{5.0, "ff2", "c1", -60});
  buffer.ReleaseBefore(5.5, take);
  ASSERT_EQ(out.size(), 1u);
  buffer.Push(RssiPacket{5.0, "ff3", "c1", -61});  // after ff2 in the order: in time
  EXPECT_EQ(buffer.late(), 0u);
  buffer.Push(ImuSample{5.0, "ff1", Vec3(0, 0, 9.8), Vec3::Zero()});  // IMU after RSSI
  EXPECT_EQ(buffer.late(), 0u);
  buffer.Push(RssiPacket{5.0, "ff1", "c1", -62});  // ff1 before ff2: late
  EXPECT_EQ(buffer.late(), 1u);
  buffer.Push(Step{4.5, 5.0, "ff9", Vec3::Zero(), {}});  // steps before RSSI: late
  EXPECT_EQ(buffer.late(), 2u);
  buffer.ReleaseBefore(5.5, take);
  buffer.Push(RssiPacket{5.0, "ff4", "c1", -63});  // after the IMU sample released: late
  EXPECT_EQ(buffer.late(), 3u);
}

// Simultaneous rows of one stream whose ids share their first 8 characters (the buffer's key
// holds 8), equal ids among them: node order, then arrival, as a stable sort gives.
TEST(TimeOrderBuffer, IdsThatShareTheirFirstEightCharactersAreOrderedByTheWholeId) {
  std::mt19937 rng(5);
  const std::vector<std::string> ids = {"landmark-1", "landmark-10", "landmark-2", "landmark",
                                        "landmar",    "lm",          "landmark-1b"};
  std::vector<MissionRow> rows;
  for (int i = 0; i < 300; ++i) {
    const double t = std::floor(i / 60.0);  // five instants, in time order as a batch feeds them
    const std::string& rx = ids[std::uniform_int_distribution<std::size_t>(0, ids.size() - 1)(rng)];
    rows.emplace_back(RssiPacket{t, rx, "b", -60.0 - i});  // rssi tells the arrival
  }
  std::vector<MissionRow> expected = rows;
  std::stable_sort(expected.begin(), expected.end(), [](const MissionRow& a, const MissionRow& b) {
    if (RowTime(a) != RowTime(b)) return RowTime(a) < RowTime(b);
    return RowNode(a) < RowNode(b);
  });
  TimeOrderBuffer buffer;
  std::vector<MissionRow> out;
  for (std::size_t i = 0; i < rows.size(); ++i) {
    buffer.Push(rows[i]);
    buffer.ReleaseBefore(RowTime(rows[i]), [&](const MissionRow& r) { out.push_back(r); });
  }
  buffer.ReleaseAll([&](const MissionRow& r) { out.push_back(r); });
  ASSERT_EQ(out.size(), expected.size());
  for (std::size_t i = 0; i < out.size(); ++i) {
    EXPECT_EQ(std::get<RssiPacket>(out[i]).rssi_dbm, std::get<RssiPacket>(expected[i]).rssi_dbm)
        << i;
  }
}

}  // namespace
}  // namespace trailmark

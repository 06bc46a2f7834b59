// SPDX-License-Identifier: MIT
// TimeOrderBuffer against a reference: a stable sort of the same rows by (time, stream).
#include "trailmark/core/time_order_buffer.h"

#include <gtest/gtest.h>

#include <algorithm>
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

}  // namespace
}  // namespace trailmark

// SPDX-License-Identifier: MIT
#include "trailmark/sim/lies.h"

#include <gtest/gtest.h>

#include <cmath>

namespace trailmark {
namespace {

MissionData Small() {
  MissionData m;
  m.info.nodes.push_back(NodeInfo::Agent("ff1", Vec3::Zero(), 0.1));
  NodeInfo lm;
  lm.id = "lm1";
  lm.kind = NodeKind::kLandmark;
  m.info.nodes.push_back(lm);
  lm.id = "lm2";
  m.info.nodes.push_back(lm);
  m.truth.push_back({0, "lm1", Vec3(3, 4, 0)});
  m.truth.push_back({0, "lm2", Vec3(-1, 2, 0)});
  for (int k = 0; k < 6; ++k) {
    m.rssi.push_back({double(k), "ff1", k % 2 ? "lm1" : "lm2", -60.0 - k});
    m.ranges.push_back({double(k), "ff1", "lm1", 2.0 + k, std::nullopt, k % 2 ? "uwb" : "ultrasound"});
  }
  return m;
}

TEST(LieInjection, EachKindChangesWhatItSaysAndNothingElse) {
  MissionData m = Small();
  SurveyAtTruth(m, NodeKind::kLandmark, 0.2);
  ASSERT_TRUE(m.info.nodes[1].position);
  EXPECT_EQ(*m.info.nodes[1].position, Vec3(3, 4, 0));
  EXPECT_EQ(*m.info.nodes[2].position_sigma_m, 0.2);

  MissionData moved = m;
  ApplyLie(moved, {LieKind::kMovedNode, "lm1", 5.0});
  EXPECT_NEAR((*moved.info.nodes[1].position - Vec3(3, 4, 0)).norm(), 5.0, 1e-12);
  EXPECT_NEAR(std::atan2(moved.info.nodes[1].position->y() - 4, moved.info.nodes[1].position->x() - 3),
              40.0 * M_PI / 180.0, 1e-12);
  EXPECT_EQ(*moved.info.nodes[2].position, *m.info.nodes[2].position);
  EXPECT_EQ(moved.truth[0].position_n, Vec3(3, 4, 0));  // the truth stays

  MissionData offset = m;
  ApplyLie(offset, {LieKind::kRssiOffset, "lm1", 10.0});
  for (std::size_t k = 0; k < m.rssi.size(); ++k)
    EXPECT_EQ(offset.rssi[k].rssi_dbm, m.rssi[k].rssi_dbm + (m.rssi[k].tx == "lm1" ? 10.0 : 0.0));

  MissionData scaled = m;
  ApplyLie(scaled, {LieKind::kRangeScale, "ultrasound", 1.1});
  for (std::size_t k = 0; k < m.ranges.size(); ++k)
    EXPECT_DOUBLE_EQ(scaled.ranges[k].range_m, m.ranges[k].range_m * (k % 2 ? 1.0 : 1.1));

  MissionData frozen = m;
  ApplyLie(frozen, {LieKind::kFrozenLink, "lm2", 0, 1.5});  // lm2 answers at t 0, 2, 4
  EXPECT_EQ(frozen.rssi[0].rssi_dbm, -60.0);
  EXPECT_EQ(frozen.rssi[2].rssi_dbm, -62.0);
  EXPECT_EQ(frozen.rssi[4].rssi_dbm, -62.0);
  EXPECT_EQ(frozen.rssi[5].rssi_dbm, -65.0);

  EXPECT_THROW(ApplyLie(m, {LieKind::kRssiOffset, "nobody", 1}), std::invalid_argument);
  MissionData unsurveyed = Small();
  EXPECT_THROW(ApplyLie(unsurveyed, {LieKind::kMovedNode, "lm1", 1}), std::invalid_argument);
  EXPECT_EQ(Describe({LieKind::kRssiOffset, "lm2", 10}), "lm2 RSSI +10 dB");
}

}  // namespace
}  // namespace trailmark

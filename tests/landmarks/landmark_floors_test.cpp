// SPDX-License-Identifier: MIT
// Radio landmarks across floors (issue 26, item 4): a packet between an agent and a landmark on
// another level is not used (counted), one on the agent's level is; with the gate off every
// packet is used. The agent's level comes from the level source (the height channel's role),
// a landmark's from its surveyed z.
#include <gtest/gtest.h>

#include "set_levels.h"
#include "trailmark/landmarks/landmark_estimator.h"

namespace trailmark::landmarks {
namespace {

using testing::SetLevels;

MissionInfo TwoStoreys() {
  MissionInfo info;
  info.floors = {{0, 0.0}, {1, 3.0}};
  info.nodes.push_back(NodeInfo::Agent("ff1", Vec3(0, 0, 0), 0.1, 0.0, 0.02));
  for (const auto& [id, z] : {std::pair{"L1", 1.0}, {"L2", 1.0}, {"L3", 1.0}, {"U1", 4.0}}) {
    NodeInfo n;
    n.id = id;
    n.kind = NodeKind::kLandmark;
    n.position = Vec3(5, 2, z);
    info.nodes.push_back(n);
  }
  return info;
}

double OtherFloor(bool gate, int agent_level) {
  LandmarkEstimatorOptions o;
  o.tracking = Tracking::kUkf;
  o.fix_fusion = FixFusion::kIndependent;
  o.gate_other_floors = gate;
  LandmarkEstimator e(TwoStoreys(), o);
  SetLevels levels;
  levels.level["ff1"] = agent_level;
  e.UseLevels(&levels);
  NullSink sink;
  e.Add(Step{0.0, 0.5, "ff1", Vec3(0.5, 0, 0), Vec3(0.01, 0.01, 0.01)}, sink);
  for (const char* lm : {"L1", "L2", "L3", "U1"}) {
    e.Add(RssiPacket{0.6, "ff1", lm, -60.0}, sink);
    e.Add(RssiPacket{0.7, lm, "ff1", -61.0}, sink);
  }
  return e.Summary().numbers.at("radio_other_floor");
}

TEST(LandmarkFloors, PacketsFromAnotherLevelAreLeftOut) {
  EXPECT_EQ(OtherFloor(true, 0), 2.0);  // U1's two packets
  EXPECT_EQ(OtherFloor(true, 1), 6.0);  // the ground floor's landmarks
  EXPECT_EQ(OtherFloor(false, 0), 0.0);
  EXPECT_EQ(OtherFloor(false, 1), 0.0);
}

}  // namespace
}  // namespace trailmark::landmarks

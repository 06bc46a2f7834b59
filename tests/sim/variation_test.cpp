// SPDX-License-Identifier: MIT
// Randomized scenario families (issue 21, item 1): each family changes what it says and nothing
// else, a variant is deterministic per (seed, K), every variant is a valid mission, and a mission
// written in another style the spec allows reads back to the same rows.
#include "trailmark/sim/variation.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <set>

#include "test_util.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/io/streams.h"
#include "trailmark/pipelines/batch_run.h"
#include "trailmark/sim/imu_sim.h"
#include "trailmark/sim/scenarios.h"

namespace trailmark {
namespace {

SimulatedMission Varied(const std::string& scenario, std::uint64_t seed, VariationFamily f,
                        std::uint64_t k, std::vector<std::string>* notes = nullptr) {
  SimulatedMission sim = SimulateScenario(scenario, seed);
  const auto n = ApplyVariation(DrawVariation(f, k), sim);
  if (notes) *notes = n;
  return sim;
}

TEST(Variation, FamiliesParseAndUnknownNamesTheKnownOnes) {
  for (const auto& [f, name] : VariationFamilies()) EXPECT_EQ(ParseVariationFamily(name), f);
  try {
    ParseVariationFamily("weather");
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("frame, radio"), std::string::npos) << e.what();
  }
}

TEST(Variation, DeterministicPerKAndTheAllFamilyIsTheUnionOfTheOthers) {
  for (std::uint64_t k : {0u, 1u, 17u}) {
    const Variation a = DrawVariation(VariationFamily::kAll, k);
    EXPECT_EQ(a.Describe(), DrawVariation(VariationFamily::kAll, k).Describe());
    // Each family's part of "all" is that family's own draw for the same K.
    EXPECT_EQ(a.frame.angle_rad, DrawVariation(VariationFamily::kFrame, k).frame.angle_rad);
    EXPECT_EQ(a.alpha_dbm, DrawVariation(VariationFamily::kRadio, k).alpha_dbm);
    EXPECT_EQ(a.nlos_fraction, DrawVariation(VariationFamily::kRanges, k).nlos_fraction);
    EXPECT_EQ(a.heading_drift_rad_per_s, DrawVariation(VariationFamily::kPdr, k).heading_drift_rad_per_s);
  }
  EXPECT_NE(DrawVariation(VariationFamily::kAll, 1).frame.angle_rad,
            DrawVariation(VariationFamily::kAll, 2).frame.angle_rad);
  // A single family leaves the others at their defaults.
  const Variation radio = DrawVariation(VariationFamily::kRadio, 3);
  EXPECT_EQ(radio.frame.angle_rad, 0.0);
  EXPECT_EQ(radio.nlos_fraction, 0.0);
  EXPECT_FALSE(radio.write.csv_comments || radio.write.csv_shuffled_columns);
  // The same (seed, K) gives the same mission, row for row.
  const SimulatedMission m1 = Varied("office-loop-1lap", 4, VariationFamily::kAll, 9);
  const SimulatedMission m2 = Varied("office-loop-1lap", 4, VariationFamily::kAll, 9);
  ASSERT_EQ(m1.data.rssi.size(), m2.data.rssi.size());
  for (std::size_t i = 0; i < m1.data.rssi.size(); ++i)
    ASSERT_EQ(m1.data.rssi[i].rssi_dbm, m2.data.rssi[i].rssi_dbm);
  ASSERT_EQ(m1.data.steps.size(), m2.data.steps.size());
  EXPECT_EQ(m1.data.steps.back().delta_n, m2.data.steps.back().delta_n);
}

TEST(Variation, TheFrameFamilyMovesEverythingRigidly) {
  const SimulatedMission base = SimulateScenario("office-loop-1lap", 2);
  const Variation v = DrawVariation(VariationFamily::kFrame, 4);
  SimulatedMission moved = base;
  ApplyVariation(v, moved);
  ASSERT_EQ(moved.data.truth.size(), base.data.truth.size());
  for (std::size_t i = 0; i < base.data.truth.size(); i += 97) {
    const Vec2 back = v.frame.Back(Vec2(moved.data.truth[i].position_n.head<2>()));
    EXPECT_NEAR((back - base.data.truth[i].position_n.head<2>()).norm(), 0.0, 1e-9);
  }
  // Steps keep their length and turn by the frame's angle.
  for (std::size_t i = 0; i < base.data.steps.size(); i += 31) {
    const Vec3& a = base.data.steps[i].delta_n;
    const Vec3& b = moved.data.steps[i].delta_n;
    EXPECT_NEAR(a.norm(), b.norm(), 1e-12);
    if (a.head<2>().norm() > 0.1) {
      EXPECT_NEAR(WrapAngle(std::atan2(b.y(), b.x()) - std::atan2(a.y(), a.x()) - v.frame.angle_rad),
                  0.0, 1e-9);
    }
  }
  // RSSI is untouched by a frame; the base is no longer at the origin.
  EXPECT_EQ(moved.data.rssi.back().rssi_dbm, base.data.rssi.back().rssi_dbm);
  EXPECT_GT(moved.data.info.Find("base")->position->head<2>().norm(), 1.0);
}

// imu.csv is in "the body frame", its axes unstated: the frame family also mounts the foot IMU
// another way — turned about its vertical, maybe upside down. Each sample is the same vector
// read in the turned axes (its length kept; at rest gravity reads along -z when upside down),
// and the variant says what it drew.
TEST(Variation, TheFrameFamilyMountsTheFootImuAnotherWay) {
  SimulatedMission base = SimulateScenario("office-loop-1lap", 2);
  ImuSimOptions o;
  o.rate_hz = 100;
  AddFootImu(base, o, 3);
  ASSERT_FALSE(base.data.imu.empty());
  std::uint64_t k = 0;
  while (!DrawVariation(VariationFamily::kFrame, k).imu_z_down) ++k;
  const Variation v = DrawVariation(VariationFamily::kFrame, k);
  SimulatedMission moved = base;
  const auto notes = ApplyVariation(v, moved);
  ASSERT_EQ(moved.data.imu.size(), base.data.imu.size());
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(v.imu_mount_yaw_rad, Vec3::UnitZ()) *
                             Eigen::AngleAxisd(std::numbers::pi, Vec3::UnitX()))
                                .toRotationMatrix();
  for (std::size_t i = 0; i < base.data.imu.size(); i += 101) {
    const ImuSample& a = base.data.imu[i];
    const ImuSample& b = moved.data.imu[i];
    EXPECT_NEAR((R * b.accel_b - a.accel_b).norm(), 0.0, 1e-9);
    EXPECT_NEAR((R * b.gyro_b - a.gyro_b).norm(), 0.0, 1e-9);
  }
  EXPECT_LT(moved.data.imu.front().accel_b.z(), -9.0);  // at rest, upside down
  EXPECT_GT(base.data.imu.front().accel_b.z(), 9.0);
  bool said = false;
  for (const auto& n : notes) said = said || n.find("foot IMU mounted turned") != std::string::npos;
  EXPECT_TRUE(said);
  bool described = false;
  for (const auto& [key, value] : v.Describe()) described = described || key == "imu_mount_yaw_deg";
  EXPECT_TRUE(described);
}

TEST(Variation, DoorsAcrossGapsCutTheSameOpenings) {
  // Find a K whose frame variant draws the other door convention.
  std::uint64_t k = 0;
  while (!DrawVariation(VariationFamily::kFrame, k).doors_across_gaps) ++k;
  const SimulatedMission base = SimulateScenario("office-loop-1lap", 2);
  SimulatedMission moved = base;
  const Variation v = DrawVariation(VariationFamily::kFrame, k);
  ApplyVariation(v, moved);
  // The walls as drawn have the gaps; the solid walls (what blocks) are the same set.
  double solid_base = 0, solid_moved = 0;
  for (const auto& w : base.plan.solid_walls()) solid_base += (w.b - w.a).norm();
  for (const auto& w : moved.plan.solid_walls()) solid_moved += (w.b - w.a).norm();
  EXPECT_NEAR(solid_base, solid_moved, 1e-6);
  double drawn_base = 0, drawn_moved = 0;
  for (const auto& w : base.plan.walls()) drawn_base += (w.b - w.a).norm();
  for (const auto& w : moved.plan.walls()) drawn_moved += (w.b - w.a).norm();
  EXPECT_GT(drawn_base, drawn_moved + 1.0);  // the doors' lengths are no longer drawn as wall
  // A line through a door in one frame passes in the other.
  const Segment2& door = base.plan.doors().front();
  const Vec2 mid = 0.5 * (door.a + door.b);
  const Vec2 normal = Vec2(door.a.y() - door.b.y(), door.b.x() - door.a.x()).normalized();
  EXPECT_FALSE(base.plan.Crosses(mid - 0.3 * normal, mid + 0.3 * normal));
  EXPECT_FALSE(moved.plan.Crosses(v.frame.Point(Vec2(mid - 0.3 * normal)),
                                  v.frame.Point(Vec2(mid + 0.3 * normal))));
}

TEST(Variation, RadioMovesThePathLossAndStatesWhatWasDrawn) {
  const SimulatedMission base = SimulateScenario("office-loop-1lap", 2);
  int stated_true = 0, stated_absent = 0;
  for (std::uint64_t k = 0; k < 12; ++k) {
    SimulatedMission m = base;
    const Variation v = DrawVariation(VariationFamily::kRadio, k);
    ApplyVariation(v, m);
    if (v.censor_below_dbm) {
      EXPECT_LT(m.data.rssi.size(), base.data.rssi.size());
      for (const auto& p : m.data.rssi) ASSERT_GE(p.rssi_dbm, *v.censor_below_dbm);
    } else {
      ASSERT_EQ(m.data.rssi.size(), base.data.rssi.size());
    }
    if (v.stated_radio == StatedRadio::kTrue) {
      ++stated_true;
      ASSERT_TRUE(m.data.info.radio);
      EXPECT_EQ(m.data.info.radio->alpha_dbm, v.alpha_dbm);
      EXPECT_EQ(m.data.info.radio->path_loss_exponent, v.path_loss_exponent);
    } else if (v.stated_radio == StatedRadio::kAbsent) {
      ++stated_absent;
      EXPECT_FALSE(m.data.info.radio);
    }
  }
  EXPECT_GT(stated_true, 0);
  EXPECT_GT(stated_absent, 0);
}

TEST(Variation, RadioWithoutRandomPartsIsExactlyTheDrawnPathLossChange) {
  // Offsets, extra shadowing and censoring off: a base <-> crumb packet changes by exactly
  // (alpha' - alpha) - 10 (n' - n) log10(d) at the true distance (the reference channel's own
  // shadowing, walls and fading kept).
  Variation v = DrawVariation(VariationFamily::kRadio, 2);
  v.node_offset_max_db = 0;
  v.correlated_shadowing_db = 0;
  v.shadowing_sigma_db = 0;
  v.censor_below_dbm.reset();
  const SimulatedMission base = SimulateScenario("office-loop-1lap", 3);
  SimulatedMission m = base;
  ApplyVariation(v, m);
  ASSERT_EQ(m.data.rssi.size(), base.data.rssi.size());
  const RadioCalibration ref = base.data.info.radio.value_or(RadioCalibration{});
  const Vec2 base_n = base.data.info.Find("base")->position->head<2>();
  std::map<std::string, Vec2> crumb;
  for (const auto& t : base.data.truth)
    if (t.id.rfind("ff", 0) != 0 && t.id != "base") crumb[t.id] = t.position_n.head<2>();
  int checked = 0;
  for (std::size_t i = 0; i < base.data.rssi.size(); ++i) {
    const auto& p = base.data.rssi[i];
    if (p.rx != "base" || !crumb.count(p.tx)) continue;
    const double d = std::max(0.1, (crumb[p.tx] - base_n).norm());
    const double expected = (v.alpha_dbm - ref.alpha_dbm) -
                            10.0 * (v.path_loss_exponent - ref.path_loss_exponent) * std::log10(d);
    EXPECT_NEAR(m.data.rssi[i].rssi_dbm - p.rssi_dbm, expected, 1e-9);
    ++checked;
  }
  EXPECT_GT(checked, 10);
}

TEST(Variation, CorrelatedShadowingIsSpatiallyConsistent) {
  // The same two places give the same extra loss: packets between the base and a crumb that
  // never moves differ only by the reference channel's own fading, not by new draws.
  Variation v = DrawVariation(VariationFamily::kRadio, 5);
  v.node_offset_max_db = 0;
  v.censor_below_dbm.reset();
  v.shadowing_sigma_db = 0;  // no extra per-packet part
  const SimulatedMission base = SimulateScenario("office-loop-1lap", 3);
  SimulatedMission m = base;
  ApplyVariation(v, m);
  std::map<std::pair<std::string, std::string>, std::vector<double>> change;
  for (std::size_t i = 0; i < base.data.rssi.size(); ++i) {
    const auto& p = base.data.rssi[i];
    if (p.rx == "base" && p.tx.rfind("ff", 0) != 0) change[{p.rx, p.tx}].push_back(m.data.rssi[i].rssi_dbm - p.rssi_dbm);
  }
  ASSERT_FALSE(change.empty());
  for (const auto& [link, d] : change) {
    for (double x : d) EXPECT_NEAR(x, d.front(), 1e-9) << link.second;
  }
}

TEST(Variation, RangesGetLongTailedNlosAndNeighbourOnlyLinks) {
  const SimulatedMission base = SimulateScenario("beacon-trail", 2);
  ASSERT_FALSE(base.data.ranges.empty());
  std::uint64_t k = 0;
  while (!DrawVariation(VariationFamily::kRanges, k).neighbour_only_links) ++k;
  SimulatedMission m = base;
  const Variation v = DrawVariation(VariationFamily::kRanges, k);
  ApplyVariation(v, m);
  EXPECT_LT(m.data.ranges.size(), base.data.ranges.size());
  std::map<std::string, int> order;
  for (const auto& e : m.data.events)
    if (e.event == "drop") order.emplace(e.node, static_cast<int>(order.size()));
  for (const auto& r : m.data.ranges) {
    if (order.count(r.a) && order.count(r.b)) ASSERT_LE(std::abs(order[r.a] - order[r.b]), 1);
  }
  // Never shorter than the scaled range: NLOS adds; about the drawn share gets an excess.
  Variation all_links = v;
  all_links.neighbour_only_links = false;
  SimulatedMission n = base;
  ApplyVariation(all_links, n);
  ASSERT_EQ(n.data.ranges.size(), base.data.ranges.size());
  EXPECT_GE(v.ultrasound_range_scale, 0.93);
  EXPECT_LE(v.ultrasound_range_scale, 1.04);
  std::size_t longer = 0;
  for (std::size_t i = 0; i < n.data.ranges.size(); ++i) {
    ASSERT_EQ(base.data.ranges[i].kind, "ultrasound");
    const double scaled = v.ultrasound_range_scale * base.data.ranges[i].range_m;
    ASSERT_GE(n.data.ranges[i].range_m, scaled - 1e-12);
    longer += n.data.ranges[i].range_m > scaled + 1e-12;
  }
  const double share = static_cast<double>(longer) / static_cast<double>(n.data.ranges.size());
  EXPECT_NEAR(share, v.nlos_fraction, 0.05);
}

TEST(Variation, RangesAreTimedAtTheAirsSpeedOfSoundOnlyForUltrasound) {
  // The ranges family's speed of sound scales every ultrasound range alike (a range without
  // NLOS excess by exactly the drawn factor) and leaves radio ranges alone.
  SimulatedMission base = SimulateScenario("beacon-trail", 2);
  base.data.ranges.push_back({base.data.ranges.back().t, "b01", "b02", 4.0, 0.1, "uwb"});
  Variation v = DrawVariation(VariationFamily::kRanges, 3);
  v.nlos_fraction = 0;
  v.neighbour_only_links = false;
  v.ultrasound_range_scale = 1.04;
  SimulatedMission m = base;
  ApplyVariation(v, m);
  ASSERT_EQ(m.data.ranges.size(), base.data.ranges.size());
  for (std::size_t i = 0; i < m.data.ranges.size(); ++i) {
    const double expected =
        base.data.ranges[i].range_m * (base.data.ranges[i].kind == "ultrasound" ? 1.04 : 1.0);
    ASSERT_NEAR(m.data.ranges[i].range_m, expected, 1e-12) << i;
  }
}

TEST(Variation, PdrHeadingDriftsWithTimeAlsoWhileStanding) {
  const SimulatedMission base = SimulateScenario("training-building", 2);  // rooms with pauses
  std::uint64_t k = 0;
  while (!DrawVariation(VariationFamily::kPdr, k).zero_length_steps) ++k;
  const Variation v = DrawVariation(VariationFamily::kPdr, k);
  SimulatedMission m = base;
  ApplyVariation(v, m);
  std::size_t zeros = 0;
  for (const auto& s : m.data.steps) zeros += s.delta_n.head<2>().norm() == 0.0;
  EXPECT_GT(zeros, 10u);
  EXPECT_EQ(m.data.steps.size(), base.data.steps.size() + zeros);
  for (std::size_t i = 1; i < m.data.steps.size(); ++i) ASSERT_LE(m.data.steps[i - 1].t1, m.data.steps[i].t1);
  // The last real step of an agent is turned by offset + drift x its time since its first step.
  const Step& last = base.data.steps.back();
  TimeS first = last.t0;
  for (const auto& s : base.data.steps)
    if (s.agent == last.agent) first = std::min(first, s.t0);
  const Step& moved = m.data.steps.back();
  const double turn = std::atan2(moved.delta_n.y(), moved.delta_n.x()) -
                      std::atan2(last.delta_n.y(), last.delta_n.x());
  EXPECT_NEAR(WrapAngle(turn - v.heading_offset_rad - v.heading_drift_rad_per_s * (last.t1 - first)),
              0.0, 1e-9);
}

TEST(Variation, PhoneStepsTurnWithTheCarryingModeAndMissOrInventSteps) {
  const SimulatedMission base = SimulateScenario("training-building", 2);  // rooms with pauses
  for (std::uint64_t k : {1u, 2u, 3u}) {
    const Variation v = DrawVariation(VariationFamily::kPhone, k);
    ASSERT_TRUE(v.phone);
    EXPECT_GE(v.phone_scale, 0.85);
    EXPECT_LE(v.phone_scale, 1.15);
    SimulatedMission m = base;
    const auto notes = ApplyVariation(v, m);
    ASSERT_FALSE(notes.empty());
    // About 4 % missed, some phantom steps while standing.
    const double ratio = static_cast<double>(m.data.steps.size()) / base.data.steps.size();
    EXPECT_GT(ratio, 0.9) << k;
    EXPECT_LT(ratio, 1.1) << k;
    double walked_base = 0, walked = 0;
    for (const auto& st : base.data.steps) walked_base += st.delta_n.head<2>().norm();
    for (const auto& st : m.data.steps) walked += st.delta_n.head<2>().norm();
    EXPECT_GT(walked / walked_base, 0.85 * v.phone_scale) << k;
    EXPECT_LT(walked / walked_base, 1.05 * v.phone_scale) << k;
    // The first step (if not missed) points off the walking direction by the first mode's offset.
    const Step& b0 = base.data.steps.front();
    const Step& m0 = m.data.steps.front();
    if (m0.t1 == b0.t1) {
      const double turn = std::atan2(m0.delta_n.y(), m0.delta_n.x()) - std::atan2(b0.delta_n.y(), b0.delta_n.x());
      EXPECT_NEAR(WrapAngle(turn - v.phone_first_offset_rad), 0.0, 1e-9) << k;
    }
    for (std::size_t i = 1; i < m.data.steps.size(); ++i) ASSERT_LE(m.data.steps[i - 1].t1, m.data.steps[i].t1);
  }
}

TEST(Variation, AStartOutsideExtendsTheWalkInFrontOfTheEntry) {
  for (const char* scenario : {"office-loop", "house1-search", "landmark-corridor", "beacon-trail"}) {
    const SimulatedMission base = SimulateScenario(scenario, 3);
    std::uint64_t k = 0;
    while (!(DrawVariation(VariationFamily::kStart, k).start_outside_m > 0)) ++k;
    const Variation v = DrawVariation(VariationFamily::kStart, k);
    ASSERT_GE(v.start_outside_m, 2.0);
    ASSERT_LE(v.start_outside_m, 10.0);
    SimulatedMission m = base;
    const auto notes = ApplyVariation(v, m);
    for (std::size_t a = 0; a < base.data.info.nodes.size(); ++a) {
      const NodeInfo& was = base.data.info.nodes[a];
      const NodeInfo& now = m.data.info.nodes[a];
      if (was.kind != NodeKind::kAgent || !was.start) continue;
      // The stated start is the outside point, start_outside_m from where the scenario began.
      const TruthSample* first_before = nullptr;
      const TruthSample* first_now = nullptr;
      for (const auto& t : base.data.truth) if (t.id == was.id && !first_before) first_before = &t;
      for (const auto& t : m.data.truth) if (t.id == was.id && !first_now) first_now = &t;
      ASSERT_TRUE(first_before && first_now) << scenario;
      EXPECT_NEAR((now.start->head<2>() - first_before->position_n.head<2>()).norm(), v.start_outside_m, 1e-9)
          << scenario;
      EXPECT_NEAR((first_now->position_n - *now.start).norm(), 0, 1e-9) << scenario;
      EXPECT_LT(first_now->t, first_before->t);
      // The steps of the way in add up to it (within the PDR's 3 % / 2 degrees).
      Vec2 walked = Vec2::Zero();
      for (const auto& st : m.data.steps) {
        if (st.agent == was.id && st.t1 <= first_before->t + 1e-9) walked += st.delta_n.head<2>();
      }
      EXPECT_NEAR((now.start->head<2>() + walked - first_before->position_n.head<2>()).norm(), 0,
                  0.15 * v.start_outside_m)
          << scenario;
    }
    EXPECT_EQ(m.data.steps.size() > base.data.steps.size(), true) << scenario;
    for (std::size_t i = 1; i < m.data.truth.size(); ++i) ASSERT_LE(m.data.truth[i - 1].t, m.data.truth[i].t);
    EXPECT_FALSE(notes.empty());
  }
}

TEST(Variation, EventsAbsentDeclareTheCrumbsAndNodesGetOneSurveyError) {
  std::uint64_t k = 0;
  while (DrawVariation(VariationFamily::kEvents, k).events != EventsKept::kNone) ++k;
  SimulatedMission m = Varied("office-loop-1lap", 2, VariationFamily::kEvents, k);
  EXPECT_TRUE(m.data.events.empty());
  const SimulatedMission base = SimulateScenario("office-loop-1lap", 2);
  for (const auto& e : base.data.events) {
    if (e.event != "drop") continue;
    const NodeInfo* n = m.data.info.Find(e.node);
    ASSERT_NE(n, nullptr) << e.node;
    EXPECT_EQ(n->kind, NodeKind::kCrumb);
  }
  // Surveyed landmarks: the stated position moves by about its sigma; the truth stays.
  const SimulatedMission lm = SimulateScenario("landmark-corridor", 2);
  const SimulatedMission moved = Varied("landmark-corridor", 2, VariationFamily::kNodes, 1);
  int surveyed = 0;
  for (const NodeInfo& n : lm.data.info.nodes) {
    if (!n.position || !n.position_sigma_m || !(*n.position_sigma_m > 0)) continue;
    ++surveyed;
    const NodeInfo* after = moved.data.info.Find(n.id);
    const double d = (after->position->head<2>() - n.position->head<2>()).norm();
    EXPECT_GT(d, 0.0);
    EXPECT_LT(d, 5.0 * *n.position_sigma_m);
    bool has_truth = false;
    for (const auto& t : moved.data.truth)
      if (t.id == n.id) {
        has_truth = true;
        EXPECT_NEAR((t.position_n - *n.position).norm(), 0.0, 1e-12);
      }
    EXPECT_TRUE(has_truth) << n.id;
  }
  EXPECT_GT(surveyed, 0);
}

// The imu family: the same walks from a foot IMU of a drawn grade and rate, turned on the foot,
// instead of steps.csv; every pipeline then runs the ZUPT INS, which finds the turn. Not part of
// `all`, whose variants keep their steps.
TEST(Variation, TheImuFamilyReplacesTheStepsByAFootImuOfTheDrawnGrade) {
  std::set<std::string> grades;
  std::vector<double> anticipations;
  for (std::uint64_t k = 1; k <= 40; ++k) {
    const Variation v = DrawVariation(VariationFamily::kImu, k);
    ASSERT_TRUE(v.foot_imu);
    grades.insert(v.imu_grade);
    EXPECT_TRUE(v.imu_rate_hz == 100 || v.imu_rate_hz == 200) << k;
    EXPECT_LE(std::abs(v.imu_turn_rad), 30 * std::numbers::pi / 180) << k;
    EXPECT_GE(v.imu_landing_anticipation, 0.0) << k;  // the gait: a pivot ...
    EXPECT_LE(v.imu_landing_anticipation, 0.5) << k;  // ... to half way to the next stride
    anticipations.push_back(v.imu_landing_anticipation);
    EXPECT_FALSE(DrawVariation(VariationFamily::kAll, k).foot_imu) << k;
  }
  EXPECT_EQ(grades, (std::set<std::string>{"tactical", "industrial", "consumer"}));
  EXPECT_LT(*std::min_element(anticipations.begin(), anticipations.end()), 0.1);
  EXPECT_GT(*std::max_element(anticipations.begin(), anticipations.end()), 0.4);
  const testing::TempDir dir;
  int checked = 0;
  for (std::uint64_t k = 1; k <= 8 && checked < 2; ++k) {
    const Variation v = DrawVariation(VariationFamily::kImu, k);
    if (v.imu_grade == "consumer" || std::abs(v.imu_turn_rad) < 5 * std::numbers::pi / 180)
      continue;  // the turn must be worth finding; a consumer gyro's start is another test's
    const SimulatedMission sim = Varied("office-loop-1lap", 4, VariationFamily::kImu, k);
    const SimulatedMission again = Varied("office-loop-1lap", 4, VariationFamily::kImu, k);
    EXPECT_TRUE(sim.data.steps.empty());
    ASSERT_GT(sim.data.imu.size(), 1000u);
    ASSERT_EQ(sim.data.imu.size(), again.data.imu.size());
    EXPECT_EQ(sim.data.imu.back().gyro_b, again.data.imu.back().gyro_b);
    EXPECT_NEAR(sim.data.imu[1].t - sim.data.imu[0].t, 1.0 / v.imu_rate_hz, 1e-9) << k;
    const auto path = dir.path() / ("imu-" + std::to_string(k));
    WriteMissionDirectory(path, sim.data, &sim.plan, v.write);
    VectorSink sink;
    const EstimatorSummary s = RunBatch(RequirePipeline("pdr"), {MissionDirectory(path), {}}, sink);
    ASSERT_TRUE(s.numbers.count("ins.ff1.mount_yaw_turned_deg")) << k;
    EXPECT_NEAR(s.numbers.at("ins.ff1.mount_yaw_turned_deg"),
                v.imu_turn_rad * 180 / std::numbers::pi, 3.0)
        << k;
    ++checked;
  }
  EXPECT_EQ(checked, 2);
}

TEST(Variation, EveryFamilyOfEveryScenarioWritesAValidMissionThatReadsBack) {
  const testing::TempDir dir;
  for (const std::string scenario : {"office-loop-1lap", "landmark-corridor", "beacon-trail", "house1-search"}) {
    for (const auto& [family, name] : VariationFamilies()) {
      const std::uint64_t k = 3;
      SimulatedMission sim = SimulateScenario(scenario, 1);
      if (scenario == "office-loop-1lap") {
        ImuSimOptions imu;
        imu.rate_hz = 50;
        AddFootImu(sim, imu, 5);
      }
      const Variation v = DrawVariation(family, k);
      ApplyVariation(v, sim);
      const auto path = dir.path() / (scenario + "-" + name);
      WriteMissionDirectory(path, sim.data, &sim.plan, v.write);
      const MissionDirectory mission(path);
      const MissionData back = ReadMissionData(mission);
      EXPECT_EQ(back.steps.size(), sim.data.steps.size()) << scenario << " " << name;
      EXPECT_EQ(back.rssi.size(), sim.data.rssi.size()) << scenario << " " << name;
      EXPECT_EQ(back.ranges.size(), sim.data.ranges.size()) << scenario << " " << name;
      EXPECT_EQ(back.imu.size(), sim.data.imu.size()) << scenario << " " << name;
      ASSERT_EQ(back.truth.size(), sim.data.truth.size()) << scenario << " " << name;
      EXPECT_NEAR(back.truth.back().position_n.x(), sim.data.truth.back().position_n.x(), 1e-9);
      const auto plan = mission.LoadFloorPlan(std::nullopt);
      ASSERT_TRUE(plan);
      double solid_written = 0, solid_read = 0;
      for (const auto& w : sim.plan.solid_walls()) solid_written += (w.b - w.a).norm();
      for (const auto& w : plan->solid_walls()) solid_read += (w.b - w.a).norm();
      EXPECT_NEAR(solid_written, solid_read, 1e-6) << scenario << " " << name;
      // Something can run on it (the variant never makes a mission unusable for all).
      EXPECT_FALSE(RunnablePipelines(mission).empty()) << scenario << " " << name;
    }
  }
}

TEST(Variation, CsvStyleReadsBackToTheSameRows) {
  MissionWriteStyle style;
  style.csv_comments = style.csv_shuffled_columns = style.csv_extra_column = true;
  style.seed = 11;
  const std::string text = "t,rx,tx,rssi_dbm\n1,a,b,-50\n2,b,a,-61.5\n";
  const std::string drawn = RestyleCsv(text, style, 3);
  EXPECT_NE(drawn, text);
  EXPECT_EQ(drawn.front(), '#');
  EXPECT_NE(drawn.find("operator_note"), std::string::npos);
  const testing::TempDir dir;
  std::vector<RssiPacket> rows = ReadAll<RssiPacket>(dir.File("rssi.csv", drawn));
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_EQ(rows[1].rx, "b");
  EXPECT_EQ(rows[1].tx, "a");
  EXPECT_DOUBLE_EQ(rows[1].rssi_dbm, -61.5);
}

}  // namespace
}  // namespace trailmark

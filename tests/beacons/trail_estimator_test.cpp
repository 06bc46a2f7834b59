// SPDX-License-Identifier: MIT
// BeaconTrailEstimator: where a dropped beacon's prior lies.

#include "trailmark/beacons/trail_estimator.h"

#include <gtest/gtest.h>

namespace trailmark::beacons {
namespace {

MissionInfo OneDropperOneBeacon() {
  MissionInfo info;
  info.nodes.push_back(NodeInfo::Agent("ff1", Vec3(10, 20, 0), 0.05, 0.0, 0.01));
  NodeInfo b;
  b.id = "b1";
  b.kind = NodeKind::kCrumb;
  info.nodes.push_back(b);
  return info;
}

std::optional<BeaconPosition> MapPosition(const BeaconTrailEstimator& e, const std::string& id) {
  for (int i = 0; i < static_cast<int>(e.map().size()); ++i)
    if (e.map().id(i) == id) return e.map().Position(i);
  return std::nullopt;
}

// Steps of 0.7 m along +x every 0.6 s (their rows at their end) by a dropper whose stated start
// heading is `heading_rad` (the entry fix turns the steps by it), b1 dropped at `drop_t`.
Vec2 DroppedTurned(double heading_rad, double drop_t, bool within_step, Tracker tracker,
                   double* entry_fixes = nullptr, double entry_track_m = 1.0) {
  MissionInfo info = OneDropperOneBeacon();
  info.nodes[0].start_heading_rad = heading_rad;
  BeaconTrailOptions options;
  options.drop_within_step = within_step;
  options.tracker = tracker;
  options.entry_track_m = entry_track_m;
  BeaconTrailEstimator estimator(info, options);
  VectorSink sink;
  bool dropped = false;
  for (int k = 0; k < 8; ++k) {
    Step s;
    s.t0 = 0.6 * k;
    s.t1 = 0.6 * (k + 1);
    s.agent = "ff1";
    s.delta_n = Vec3(0.7, 0, 0);
    s.variance_m2 = Vec3(1e-4, 1e-4, 1e-4);
    if (!dropped && drop_t < s.t1) {
      estimator.Add(MissionEvent{drop_t, "ff1", "drop", "b1"}, sink);
      dropped = true;
    }
    estimator.Add(s, sink);
  }
  estimator.Finish(sink);
  if (entry_fixes) *entry_fixes = estimator.Summary().numbers.at("entry_heading_fixes");
  const auto p = MapPosition(estimator, "b1");
  EXPECT_TRUE(p.has_value());
  return p ? p->position_n : Vec2::Constant(std::nan(""));
}

Vec2 DroppedAt(double drop_t, bool within_step) {
  return DroppedTurned(0.0, drop_t, within_step, BeaconTrailOptions{}.tracker);
}

TEST(BeaconTrailEstimator, ADropIsPlacedWithinTheStepThatSpansIt) {
  // Dropped a quarter into the third step (1.2-1.8 s): 1.575 m from the start. Its row comes
  // before the step's (rows in time order, a step at its end).
  const Vec2 within = DroppedAt(1.35, true);
  EXPECT_NEAR(within.x(), 10 + 1.4 + 0.25 * 0.7, 1e-6);
  EXPECT_NEAR(within.y(), 20, 1e-6);
  // The old placement: where the last step before the drop ended, a quarter step behind.
  const Vec2 at_end = DroppedAt(1.35, false);
  EXPECT_NEAR(at_end.x(), 10 + 1.4, 1e-6);
  // A drop at a step's end (its row after that step's) is the same either way.
  EXPECT_NEAR(DroppedAt(1.8, true).x(), 10 + 2.1, 1e-6);
  EXPECT_NEAR(DroppedAt(1.8, false).x(), 10 + 2.1, 1e-6);
}

TEST(BeaconTrailEstimator, TheEntryFixTurnsTheFirstTrackOfTheDropPriorsToo) {
  // Found by a review (2026-12-06): the first metre's steps went into the drop priors' dead
  // reckoning unturned and every later prior was off by (R(psi) - I) x that metre. The steps
  // along +x by a dropper who faced +y at the start: the walk goes up +y.
  for (const Tracker tracker : {Tracker::kScaat, Tracker::kNone}) {
    // Dropped after the fix (at 1.4 m): a quarter into the third step, 1.575 m up.
    Vec2 p = DroppedTurned(M_PI / 2, 1.35, true, tracker);
    EXPECT_NEAR(p.x(), 10, 1e-6);
    EXPECT_NEAR(p.y(), 20 + 1.575, 1e-6);
    p = DroppedTurned(M_PI / 2, 1.35, false, tracker);
    EXPECT_NEAR(p.x(), 10, 1e-6);
    EXPECT_NEAR(p.y(), 21.4, 1e-6);
    // Dropped on the first track itself (0.35 m), its prior placed again at the fix.
    p = DroppedTurned(M_PI / 2, 0.3, true, tracker);
    EXPECT_NEAR(p.x(), 10, 1e-6);
    EXPECT_NEAR(p.y(), 20.35, 1e-6);
    p = DroppedTurned(M_PI / 2, 0.9, false, tracker);
    EXPECT_NEAR(p.x(), 10, 1e-6);
    EXPECT_NEAR(p.y(), 20.7, 1e-6);
  }
  // Facing the way the steps go, nothing turns.
  const Vec2 straight = DroppedTurned(0.0, 1.35, true, Tracker::kScaat);
  EXPECT_NEAR(straight.x(), 10 + 1.575, 1e-6);
  EXPECT_NEAR(straight.y(), 20, 1e-6);
}

TEST(BeaconTrailEstimator, AnEntryTrackOfZeroNeverFixesTheHeading) {
  // entry_track_m = 0 is documented as "never": it fixed at the first step.
  double fixes = -1;
  DroppedTurned(0.1, 1.35, true, Tracker::kScaat, &fixes, 0.0);
  EXPECT_EQ(fixes, 0.0);
  DroppedTurned(0.1, 1.35, true, Tracker::kScaat, &fixes, 1.0);
  EXPECT_EQ(fixes, 1.0);
}

TEST(BeaconTrailEstimator, TheAssumedHeadingAfterThirtyMetresKeepsItsLeverOnThePosition) {
  // No start heading and no ultrasound: after entry_heading_fallback_m the heading is assumed
  // (0, sigma 0.1 rad) and the filter starts at the end of the 30 m track with the heading's
  // lever perp(track) in its position. The position's correlation with that heading was left
  // out (found by a review, 2026-12-06): walking 12 m further the same way, the cross-track
  // variance grew as (30^2 + 12^2) sigma^2 instead of (30 + 12)^2 sigma^2.
  MissionInfo info;
  info.nodes.push_back(NodeInfo::Agent("ff1", Vec3(0, 0, 0), 0.05));
  NodeInfo lm;  // surveyed, away from the start, never heard: the heading is to be estimated
  lm.id = "lm1";
  lm.kind = NodeKind::kLandmark;
  lm.position = Vec3(50, 50, 0);
  info.nodes.push_back(lm);
  BeaconTrailOptions options;
  options.drop_dead_reckoning.start_heading_sigma_rad = 0.1;
  options.ekf.initial_heading_sigma_rad = 0.1;
  BeaconTrailEstimator estimator(info, options);
  VectorSink sink;
  for (int k = 0; k < 60; ++k) {  // 42 m along +x
    Step s;
    s.t0 = 0.6 * k;
    s.t1 = 0.6 * (k + 1);
    s.agent = "ff1";
    s.delta_n = Vec3(0.7, 0, 0);
    s.variance_m2 = Vec3(1e-6, 1e-6, 1e-6);
    estimator.Add(s, sink);
  }
  estimator.Finish(sink);
  const Estimate* last = nullptr;
  for (const Estimate& e : sink.rows)
    if (e.id == "ff1") last = &e;
  ASSERT_NE(last, nullptr);
  EXPECT_NEAR(last->position_n.x(), 42, 1e-6);
  // (30 + 12)^2 x 0.01 = 17.6 m^2 (plus the white walk's share); the old form 10.4 m^2.
  EXPECT_GT(last->syy, 17.0);
  EXPECT_LT(last->syy, 20.0);
}

TEST(BeaconTrailEstimator, ADropAfterTheLastStepIsPlacedWhereTheDropperStands) {
  BeaconTrailOptions options;
  BeaconTrailEstimator estimator(OneDropperOneBeacon(), options);
  VectorSink sink;
  Step s;
  s.t0 = 0;
  s.t1 = 0.6;
  s.agent = "ff1";
  s.delta_n = Vec3(0.7, 0, 0);
  estimator.Add(s, sink);
  s.t0 = 0.6;
  s.t1 = 1.2;
  estimator.Add(s, sink);
  estimator.Add(MissionEvent{5.0, "ff1", "drop", "b1"}, sink);  // standing since 1.2 s
  estimator.Finish(sink);
  const auto p = MapPosition(estimator, "b1");
  ASSERT_TRUE(p.has_value());
  EXPECT_NEAR(p->position_n.x(), 11.4, 1e-6);
  EXPECT_NEAR(p->position_n.y(), 20, 1e-6);
}

TEST(BeaconTrailEstimator, ADropOfAnAgentIsNotABeacon) {
  // The readers refuse such an event (events.csv, file and line); a live row is left out.
  BeaconTrailEstimator estimator(OneDropperOneBeacon(), BeaconTrailOptions{});
  VectorSink sink;
  estimator.Add(MissionEvent{0.3, "ff1", "drop", "ff1"}, sink);
  Step s;
  s.t0 = 0;
  s.t1 = 0.6;
  s.agent = "ff1";
  s.delta_n = Vec3(0.7, 0, 0);
  estimator.Add(s, sink);
  estimator.Finish(sink);
  EXPECT_EQ(estimator.map().size(), 0u);
  EXPECT_FALSE(MapPosition(estimator, "ff1").has_value());
}

// Out along +x, back along -x (a reversal whose step points at pi - eps or -pi + eps: the steps
// cannot tell a half turn left from one right), 3 m back, then a left turn and 3 m along -y; b1
// dropped at the end of the way out, b2 before the left turn, b3 at the end. The prior of each
// drop (no links: never solved) as its map position.
std::vector<BeaconPosition> ReversalPriors(double eps, const BeaconTrailOptions& options) {
  MissionInfo info;
  info.nodes.push_back(NodeInfo::Agent("ff1", Vec3(0, 0, 0), 0.05, 0.0, 0.01));
  for (const char* id : {"b1", "b2", "b3"}) {
    NodeInfo b;
    b.id = id;
    b.kind = NodeKind::kCrumb;
    info.nodes.push_back(b);
  }
  BeaconTrailEstimator estimator(info, options);
  VectorSink sink;
  TimeS t = 0;
  const auto step = [&](const Vec2& d) {
    Step s;
    s.t0 = t;
    s.t1 = t + 0.5;
    s.agent = "ff1";
    s.delta_n = Vec3(d.x(), d.y(), 0);
    s.variance_m2 = Vec3(1e-4, 1e-4, 1e-4);
    estimator.Add(s, sink);
    t += 0.5;
  };
  for (int k = 0; k < 10; ++k) step(Vec2(0.5, 0));
  estimator.Add(MissionEvent{t, "ff1", "drop", "b1"}, sink);
  step(Vec2(-0.5, eps));  // the reversal: pi - eps (eps > 0) or -pi + |eps|
  for (int k = 0; k < 5; ++k) step(Vec2(-0.5, 0));
  estimator.Add(MissionEvent{t, "ff1", "drop", "b2"}, sink);
  for (int k = 0; k < 6; ++k) step(Vec2(0, -0.5));  // a left turn (from -x to -y)
  estimator.Add(MissionEvent{t, "ff1", "drop", "b3"}, sink);
  estimator.Finish(sink);
  std::vector<BeaconPosition> out;
  for (const char* id : {"b1", "b2", "b3"}) {
    const auto p = MapPosition(estimator, id);
    EXPECT_TRUE(p.has_value()) << id;
    out.push_back(p.value_or(BeaconPosition{}));
  }
  return out;
}

TEST(BeaconTrailEstimator, AReversalsGuessedSignDoesNotTurnTheMapsTurnScaleLever) {
  // The gyro's turn-scale error is a track error of the map: every turn's share of it moves the
  // drops after it (its lever). A reversal's sign is a guess; drawn as +pi or as -pi the same
  // walk must give the same priors. Counted, the two guesses differ by 2 pi in the turn after
  // the reversal, and the last drop's prior by metres of lever x 3 %.
  const double eps = 1e-4;
  for (const double ambiguous : {2.5, 7.0}) {
    BeaconTrailOptions options;
    options.map_turn_ambiguous_rad = ambiguous;
    const auto plus = ReversalPriors(eps, options);
    const auto minus = ReversalPriors(-eps, options);
    for (int i = 0; i < 3; ++i) {
      const double d = (plus[i].position_n - minus[i].position_n).norm();
      EXPECT_LT(d, 1e-3) << i;  // the steps are the same to eps
      const double c = (plus[i].cov - minus[i].cov).norm() / plus[i].cov.norm();
      if (ambiguous < 3 || i < 2)
        EXPECT_LT(c, 1e-3) << "b" << i + 1 << " with the reversal left out: " << ambiguous;
      else
        EXPECT_GT(c, 0.05) << "b3 with the reversal counted";
    }
  }
  // Left out, the reversal's share is a heading error of its own: the drops after it are
  // wider than with no turn-scale error at all.
  BeaconTrailOptions without;
  without.map_turn_scale = false;
  const auto plain = ReversalPriors(eps, without);
  const auto with = ReversalPriors(eps, BeaconTrailOptions{});
  EXPECT_GT(with[2].cov.trace(), plain[2].cov.trace());
}

}  // namespace
}  // namespace trailmark::beacons

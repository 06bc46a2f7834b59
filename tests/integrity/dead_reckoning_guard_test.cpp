// SPDX-License-Identifier: MIT
#include "trailmark/integrity/dead_reckoning_guard.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "trailmark/pipelines/registry.h"

namespace trailmark::integrity {
namespace {

/// Dead reckoning whose estimates of agents are moved by `offset` between two times (an
/// estimator that a wrong source pulls away), and which also emits a crumb.
class Lying : public OnlineEstimator {
 public:
  Lying(const MissionInfo& info, Vec3 offset, TimeS from, TimeS to)
      : dr_(info), offset_(offset), from_(from), to_(to) {}
  void Add(const MissionRow& row, EstimateSink& sink) override {
    VectorSink inner;
    dr_.Add(row, inner);
    for (Estimate e : inner.rows) {
      if (e.t >= from_ && e.t < to_) e.position_n += offset_;
      sink.Add(e);
    }
    if (std::holds_alternative<Step>(row)) sink.Add({RowTime(row), "crumb1", Vec3(100, 0, 0), 1, 0, 1});
  }
  void Finish(EstimateSink&) override {}
  std::optional<Estimate> Current(const std::string& node) const override {
    return dr_.Current(node);
  }
  EstimatorSummary Summary() const override { return {}; }

 private:
  DeadReckoningEstimator dr_;
  Vec3 offset_;
  TimeS from_, to_;
};

MissionInfo OneAgent() {
  MissionInfo info;
  info.nodes.push_back(NodeInfo::Agent("ff1", Vec3(2, 3, 0), 0.5));
  return info;
}

/// 200 steps of 0.7 m east at 2 Hz.
std::vector<Estimate> Walk(OnlineEstimator& estimator) {
  VectorSink sink;
  for (int k = 0; k < 200; ++k) {
    estimator.Add(Step{0.5 * k, 0.5 * (k + 1), "ff1", Vec3(0.7, 0, 0), std::nullopt}, sink);
  }
  estimator.Finish(sink);
  return sink.rows;
}

TEST(DeadReckoningGuard, PassesAnEstimateInsideDeadReckoningsRegionUnchanged) {
  const MissionInfo info = OneAgent();
  // 1 m off: well inside dead reckoning's region after the first metres.
  DeadReckoningGuard guard(info, {}, std::make_unique<Lying>(info, Vec3(0, 1, 0), 20, 1e9));
  Lying reference(info, Vec3(0, 1, 0), 20, 1e9);
  const auto guarded = Walk(guard);
  const auto raw = Walk(reference);
  ASSERT_EQ(guarded.size(), raw.size());
  for (std::size_t i = 0; i < raw.size(); ++i) {
    EXPECT_EQ(guarded[i].position_n, raw[i].position_n) << i;
    EXPECT_EQ(guarded[i].sxx, raw[i].sxx) << i;
  }
  EXPECT_TRUE(guard.Summary().integrity.empty());
  EXPECT_EQ(guard.Summary().numbers.at("integrity.disagreements"), 0.0);
}

GuardOptions Mode(GuardAction action) {
  GuardOptions o;
  o.on_disagreement = action;
  return o;
}

TEST(DeadReckoningGuard, FallbackEmitsDeadReckoningWhileTheEstimateIsOutsideItsRegionAndSaysSo) {
  for (const double offset_m : {40.0, 100.0, 300.0}) {
    const MissionInfo info = OneAgent();
    DeadReckoningGuard guard(info, Mode(GuardAction::kFallback),
                             std::make_unique<Lying>(info, Vec3(-offset_m, offset_m, 0), 30, 60));
    // The guard's dead reckoning: the pdr defaults with their shared-error sigmas x 3.
    PdrOptions overbound;
    overbound.start_heading_sigma_rad *= 3;
    overbound.heading_drift_sigma_rad_per_s *= 3;
    overbound.heading_walk_sigma_rad *= 3;
    overbound.step_scale_sigma *= 3;
    overbound.turn_scale_sigma *= 3;
    DeadReckoningEstimator dr(info, overbound);
    const auto guarded = Walk(guard);
    const auto truth = Walk(dr);
    std::size_t agent_rows = 0;
    for (const Estimate& e : guarded) {
      if (e.id != "ff1") {
        EXPECT_EQ(e.position_n, Vec3(100, 0, 0));  // other nodes pass through
        continue;
      }
      const Estimate& d = truth[agent_rows++];
      ASSERT_EQ(e.t, d.t);
      // Outside the lie the estimate is dead reckoning anyway; during it the guard emits
      // dead reckoning instead of the lie: the output is dead reckoning throughout.
      EXPECT_NEAR((e.position_n - d.position_n).norm(), 0, 1e-12) << offset_m << " t " << e.t;
      if (e.t >= 30 && e.t < 60) EXPECT_NEAR(e.sxx, d.sxx, 1e-12 * d.sxx) << e.t;
    }
    const auto summary = guard.Summary();
    ASSERT_EQ(summary.integrity.size(), 2u) << offset_m;
    EXPECT_EQ(summary.integrity[0].action, "fallback");
    EXPECT_EQ(summary.integrity[0].node, "ff1");
    EXPECT_NEAR(summary.integrity[0].t, 30, 0.5);
    EXPECT_EQ(summary.integrity[1].action, "resumed");
    EXPECT_NEAR(summary.integrity[1].t, 60, 0.5);
    EXPECT_EQ(summary.numbers.at("integrity.disagreements"), 1.0);
    EXPECT_NEAR(summary.numbers.at("integrity.disagreement_share"), 60.0 / 201.0, 0.01);
    EXPECT_FALSE(guard.Disagrees("ff1"));
  }
}

TEST(DeadReckoningGuard, GrowKeepsTheEstimateAndItsEllipseCoversDeadReckoning) {
  // grow_probability 0.95 (the default): the least growth along d that puts dead reckoning on
  // the boundary of the grown 95 % ellipse, d^T C^-1 d = chi2_2(0.95) = -2 ln 0.05; 0: by d d^T,
  // dead reckoning within one sigma.
  const double q95 = -2.0 * std::log(0.05);
  for (const double grow_probability : {0.95, 0.0}) {
    for (const double offset_m : {40.0, 100.0, 300.0}) {
      const MissionInfo info = OneAgent();
      GuardOptions options;
      options.grow_probability = grow_probability;
      DeadReckoningGuard guard(info, options,
                               std::make_unique<Lying>(info, Vec3(offset_m, 0, 0), 30, 60));
      Lying lie(info, Vec3(offset_m, 0, 0), 30, 60);
      const auto grown = Walk(guard);
      const auto raw = Walk(lie);
      ASSERT_EQ(grown.size(), raw.size());
      std::size_t covered = 0, changed = 0;
      for (std::size_t i = 0; i < raw.size(); ++i) {
        const Estimate& e = grown[i];
        EXPECT_EQ(e.position_n, raw[i].position_n);  // the position is the estimator's
        if (e.id != "ff1" || e.sxx == raw[i].sxx) continue;
        ++changed;
        const Vec2 d = Vec2(-offset_m, 0);  // to dead reckoning (the lie removed)
        Mat2 c;
        c << e.sxx, e.sxy, e.sxy, e.syy;
        EXPECT_GT(c.determinant(), 0);
        const double d2 = d.dot(c.inverse() * d);
        if (grow_probability > 0) {
          EXPECT_NEAR(d2, q95, 1e-6 * q95) << offset_m;  // on the boundary, not beyond it
          covered += d2 <= q95 * (1 + 1e-6);
        } else {
          covered += d2 < 1.0 + 1e-9;
        }
        // Only along d: the other axis keeps the estimator's own variance.
        EXPECT_EQ(e.syy, raw[i].syy);
      }
      EXPECT_EQ(changed, 60u) << offset_m;  // the 30 s at 2 Hz of the lie
      EXPECT_EQ(covered, changed);
      ASSERT_EQ(guard.Summary().integrity.size(), 2u);
      EXPECT_EQ(guard.Summary().integrity[0].action, "disagrees");
      EXPECT_EQ(guard.Summary().integrity[1].action, "agrees");
    }
  }
}

TEST(DeadReckoningGuard, CurrentIsWhatTheGuardEmits) {
  const MissionInfo info = OneAgent();
  DeadReckoningGuard guard(info, Mode(GuardAction::kFallback),
                           std::make_unique<Lying>(info, Vec3(50, 50, 0), 0, 1e9));
  Walk(guard);
  EXPECT_TRUE(guard.Disagrees("ff1"));
  DeadReckoningEstimator dr(info);
  Walk(dr);
  // Lying::Current is dead reckoning itself; the guard answers with dead reckoning too.
  EXPECT_EQ(guard.Current("ff1")->position_n, dr.Current("ff1")->position_n);
  EXPECT_FALSE(guard.Current("nobody"));
}

TEST(DeadReckoningGuard, ReportKeepsTheEstimatesAndStillNotes) {
  const MissionInfo info = OneAgent();
  DeadReckoningGuard guard(info, Mode(GuardAction::kReport),
                           std::make_unique<Lying>(info, Vec3(0, 300, 0), 30, 1e9));
  const auto rows = Walk(guard);
  const auto last = std::find_if(rows.rbegin(), rows.rend(), [](const Estimate& e) { return e.id == "ff1"; });
  ASSERT_NE(last, rows.rend());
  EXPECT_NEAR(last->position_n.y(), 303, 1e-9);  // the lie, kept
  ASSERT_EQ(guard.Summary().integrity.size(), 1u);
  EXPECT_NE(guard.Summary().notes.back().find("reported only"), std::string::npos);
}

TEST(DeadReckoningGuard, AnAgentWithoutAStartIsPassedThroughAndNamed) {
  MissionInfo info;
  NodeInfo agent = NodeInfo::Agent("ff1", Vec3::Zero(), 0.0);
  agent.start.reset();
  info.nodes.push_back(agent);
  class Fixed : public OnlineEstimator {
   public:
    void Add(const MissionRow& row, EstimateSink& sink) override {
      sink.Add({RowTime(row), "ff1", Vec3(7, 7, 0), 1, 0, 1});
    }
    void Finish(EstimateSink&) override {}
    std::optional<Estimate> Current(const std::string&) const override { return std::nullopt; }
    EstimatorSummary Summary() const override { return {}; }
  };
  DeadReckoningGuard guard(info, {}, std::make_unique<Fixed>());
  const auto rows = Walk(guard);
  EXPECT_EQ(rows.back().position_n, Vec3(7, 7, 0));
  ASSERT_EQ(guard.Summary().integrity.size(), 1u);
  EXPECT_EQ(guard.Summary().integrity[0].action, "unguarded");
}

TEST(DeadReckoningGuard, RefusesInconsistentOptions) {
  const MissionInfo info = OneAgent();
  GuardOptions options;
  options.return_probability = 0.9999;  // above leave_probability
  EXPECT_THROW(DeadReckoningGuard(info, options, std::make_unique<Lying>(info, Vec3::Zero(), 0, 0)),
               std::invalid_argument);
  for (const double p : {1.0, -0.1, std::nan("")}) {
    GuardOptions bad;
    bad.grow_probability = p;
    EXPECT_THROW(DeadReckoningGuard(info, bad, std::make_unique<Lying>(info, Vec3::Zero(), 0, 0)),
                 std::invalid_argument)
        << p;
  }
}

TEST(DeadReckoningGuard, EveryStepsBasedPipelineButDeadReckoningHasTheIntegrityKeys) {
  for (const PipelineSpec& p : Pipelines()) {
    bool has = false;
    for (const OptionInfo& o : p.options) has = has || o.key == "integrity.on_disagreement";
    EXPECT_EQ(has, p.steps_based && !p.baseline) << p.name;
  }
}

}  // namespace
}  // namespace trailmark::integrity

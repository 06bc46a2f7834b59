// SPDX-License-Identifier: MIT
#include "trailmark/fusion/fusion_estimator.h"

#include <gtest/gtest.h>

#include <cmath>
#include <deque>
#include <functional>
#include <random>

#include "test_util.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/pipelines/batch_run.h"
#include "trailmark/pipelines/registry.h"
#include "trailmark/sim/scenarios.h"

namespace trailmark::fusion {
namespace {

/// A member that answers each step of an agent with an estimate made by `make` (its time, the
/// step count) — at once, or `lag` steps later (a filter that waits) — and may emit a crumb.
class Scripted : public OnlineEstimator {
 public:
  using Make = std::function<Estimate(const std::string& agent, TimeS t, int k)>;
  explicit Scripted(Make make, int lag = 0, bool throws_on_first_step = false)
      : make_(std::move(make)), lag_(lag), throws_(throws_on_first_step) {}
  void Add(const MissionRow& row, EstimateSink& sink) override {
    ++rows;
    const Step* step = std::get_if<Step>(&row);
    if (step == nullptr) return;
    if (throws_ && k_ == 0) {
      ++k_;
      throw std::invalid_argument("scripted: refused");
    }
    queue_.push_back(make_(step->agent, step->t1, k_++));
    while (static_cast<int>(queue_.size()) > lag_) {
      sink.Add(queue_.front());
      queue_.pop_front();
    }
  }
  void Finish(EstimateSink& sink) override {
    for (const Estimate& e : queue_) sink.Add(e);
    queue_.clear();
  }
  std::optional<Estimate> Current(const std::string&) const override { return std::nullopt; }
  EstimatorSummary Summary() const override {
    EstimatorSummary s;
    s.numbers["rows"] = rows;
    return s;
  }
  int rows = 0;

 private:
  Make make_;
  int lag_;
  bool throws_;
  int k_ = 0;
  std::deque<Estimate> queue_;
};

MissionInfo OneAgent() {
  MissionInfo info;
  info.nodes.push_back(NodeInfo::Agent("ff1", Vec3(0, 0, 0), 0.5));
  return info;
}

/// The truth of the scripted walk: 0.7 m east per step.
Vec2 Truth(int k) { return Vec2(0.7 * (k + 1), 0); }

Estimate At(const std::string& id, TimeS t, Vec2 p, double sxx, double sxy, double syy) {
  Estimate e;
  e.t = t;
  e.id = id;
  e.position_n = Vec3(p.x(), p.y(), 0);
  e.sxx = sxx;
  e.sxy = sxy;
  e.syy = syy;
  return e;
}

std::unique_ptr<Scripted> Offset(Vec2 offset, double sxx, double sxy, double syy, int lag = 0) {
  return std::make_unique<Scripted>(
      [=](const std::string& a, TimeS t, int k) {
        return At(a, t, Truth(k) + offset, sxx, sxy, syy);
      },
      lag);
}

std::vector<Estimate> Walk(OnlineEstimator& f, int steps = 100) {
  VectorSink sink;
  for (int k = 0; k < steps; ++k)
    f.Add(Step{0.5 * k, 0.5 * (k + 1), "ff1", Vec3(0.7, 0, 0), std::nullopt}, sink);
  f.Finish(sink);
  return sink.rows;
}

std::vector<FusionMember> Members(std::vector<std::unique_ptr<Scripted>> scripted) {
  std::vector<FusionMember> out;
  int i = 0;
  for (auto& s : scripted) out.push_back({"m" + std::to_string(i++), std::move(s)});
  return out;
}

FusionOptions NoHat() {
  FusionOptions o;
  o.hat_window_s = 0;
  return o;
}

TEST(FusionEstimator, OneMemberIsPassedThrough) {
  std::vector<std::unique_ptr<Scripted>> s;
  s.push_back(Offset(Vec2(0.3, -0.2), 0.5, 0.1, 0.4));
  FusionEstimator f(OneAgent(), {}, Members(std::move(s)));
  const auto rows = Walk(f);
  ASSERT_EQ(rows.size(), 100u);
  for (int k = 0; k < 100; ++k) {
    EXPECT_DOUBLE_EQ(rows[k].t, 0.5 * (k + 1));
    EXPECT_LT((rows[k].position_n.head<2>() - (Truth(k) + Vec2(0.3, -0.2))).norm(), 1e-9);
    EXPECT_NEAR(rows[k].sxx, 0.5, 1e-9);
    EXPECT_NEAR(rows[k].sxy, 0.1, 1e-9);
    EXPECT_NEAR(rows[k].syy, 0.4, 1e-9);
  }
  EXPECT_EQ(f.Current("ff1")->t, 50.0);
}

TEST(FusionEstimator, TwoMembersAreTheirCovarianceIntersection) {
  std::vector<std::unique_ptr<Scripted>> s;
  // Each member is precise along one axis and off by 0.4 m along the other.
  s.push_back(Offset(Vec2(0, 0.4), 0.1, 0, 2.0));
  s.push_back(Offset(Vec2(0.4, 0), 2.0, 0, 0.1));
  FusionEstimator f(OneAgent(), NoHat(), Members(std::move(s)));
  const auto rows = Walk(f);
  ASSERT_EQ(rows.size(), 100u);
  for (int k = 0; k < 100; ++k) {
    const std::vector<PositionGaussian> in{
        {Truth(k) + Vec2(0, 0.4), (Mat2() << 0.1, 0, 0, 2.0).finished()},
        {Truth(k) + Vec2(0.4, 0), (Mat2() << 2.0, 0, 0, 0.1).finished()}};
    const Intersection ci = Intersect(in);
    EXPECT_LT((rows[k].position_n.head<2>() - ci.fused.mean_m).norm(), 1e-9);
    EXPECT_NEAR(rows[k].sxx, ci.fused.cov_m2(0, 0), 1e-9);
    EXPECT_NEAR(rows[k].syy, ci.fused.cov_m2(1, 1), 1e-9);
    // Each member is good along one axis: the fusion is good along both.
    EXPECT_LT((rows[k].position_n.head<2>() - Truth(k)).norm(), 0.1);
  }
  EXPECT_NEAR(f.TypedSummary().members[0].weight_sum / 100, 0.5, 1e-6);
}

TEST(FusionEstimator, AMemberFarFromTheOthersIsLeftOutAndNoted) {
  std::vector<std::unique_ptr<Scripted>> s;
  s.push_back(Offset(Vec2(0.1, 0), 0.04, 0, 0.04));
  s.push_back(Offset(Vec2(-0.1, 0.1), 0.05, 0, 0.05));
  s.push_back(std::make_unique<Scripted>([](const std::string& a, TimeS t, int k) {
    // Wrong by 8 m, sure of itself, from step 40 to 60.
    const Vec2 off = k >= 40 && k < 60 ? Vec2(0, 8) : Vec2(0, 0);
    return At(a, t, Truth(k) + off, 0.04, 0, 0.04);
  }));
  FusionEstimator f(OneAgent(), NoHat(), Members(std::move(s)));
  const auto rows = Walk(f);
  ASSERT_EQ(rows.size(), 100u);
  for (int k = 0; k < 100; ++k)
    EXPECT_LT((rows[k].position_n.head<2>() - Truth(k)).norm(), 0.2) << k;
  EXPECT_EQ(f.TypedSummary().members[2].exclusions, 20);
  EXPECT_EQ(f.TypedSummary().members[0].exclusions, 0);
  const EstimatorSummary summary = f.Summary();
  ASSERT_EQ(summary.integrity.size(), 2u);
  EXPECT_EQ(summary.integrity[0].action, "excluded");
  EXPECT_EQ(summary.integrity[0].source, "m2");
  EXPECT_DOUBLE_EQ(summary.integrity[0].t, 0.5 * 41);
  EXPECT_EQ(summary.integrity[1].action, "readmitted");
  EXPECT_DOUBLE_EQ(summary.integrity[1].t, 0.5 * 61);
  EXPECT_EQ(summary.numbers.at("fusion.m2.exclusions"), 20);
  EXPECT_EQ(summary.numbers.at("m0.rows"), 100);  // members' summaries under their names
}

TEST(FusionEstimator, TwoMembersThatDisagreeAreBothCoveredByTheEllipse) {
  std::vector<std::unique_ptr<Scripted>> s;
  s.push_back(Offset(Vec2(0, 0), 0.04, 0, 0.04));
  s.push_back(Offset(Vec2(5, 0), 0.04, 0, 0.04));
  FusionEstimator f(OneAgent(), NoHat(), Members(std::move(s)));
  const auto rows = Walk(f, 10);
  for (const Estimate& e : rows) {
    Mat2 p;
    p << e.sxx, e.sxy, e.sxy, e.syy;
    // Both members lie within the reported 95 % ellipse (chi-square 2 dof: 5.99).
    const int k = static_cast<int>(std::lround(e.t / 0.5)) - 1;
    for (const Vec2 member : {Truth(k), Vec2(Truth(k) + Vec2(5, 0))}) {
      const Vec2 d = member - e.position_n.head<2>();
      EXPECT_LT(d.dot(p.inverse() * d), 5.99) << e.t;
    }
  }
  EXPECT_EQ(f.TypedSummary().grown_rows, 10);
}

TEST(FusionEstimator, WaitsForAMemberThatLagsAndGivesTheSameEstimates) {
  auto run = [](int lag) {
    std::vector<std::unique_ptr<Scripted>> s;
    s.push_back(Offset(Vec2(0.2, 0), 0.1, 0, 0.3));
    s.push_back(Offset(Vec2(0, 0.2), 0.3, 0, 0.1, lag));
    FusionEstimator f(OneAgent(), NoHat(), Members(std::move(s)));
    VectorSink sink;
    std::vector<std::size_t> emitted_after;
    for (int k = 0; k < 50; ++k) {
      f.Add(Step{0.5 * k, 0.5 * (k + 1), "ff1", Vec3(0.7, 0, 0), std::nullopt}, sink);
      emitted_after.push_back(sink.rows.size());
    }
    f.Finish(sink);
    return std::make_pair(sink.rows, emitted_after);
  };
  const auto [now, now_counts] = run(0);
  const auto [late, late_counts] = run(3);
  ASSERT_EQ(now.size(), 50u);
  ASSERT_EQ(late.size(), 50u);
  for (std::size_t i = 0; i < now.size(); ++i) {
    EXPECT_EQ(now[i].t, late[i].t);
    if (i < 3) {
      // Before its first estimate the lagging member is not known to estimate the agent: the
      // first rows are the other member's alone.
      EXPECT_LT((late[i].position_n.head<2>() - (Truth(static_cast<int>(i)) + Vec2(0.2, 0))).norm(),
                1e-12);
    } else {
      EXPECT_LT((now[i].position_n - late[i].position_n).norm(), 1e-12) << i;
    }
  }
  // The lagging member held each row back by its three steps, not longer.
  EXPECT_EQ(late_counts[10], now_counts[10] - 3);
}

TEST(FusionEstimator, AMemberIsUsedOnlyOnceItsOwnEvidenceArrived) {
  std::vector<FusionMember> m;
  m.push_back({"ranges", Offset(Vec2(3, 0), 0.01, 0, 0.01), StreamSet{Stream::kRanges}});
  m.push_back({"dr", Offset(Vec2(0, 0), 1, 0, 1)});
  m.back().fallback_only = true;  // dead reckoning: only where no other member estimates
  FusionOptions o = NoHat();
  o.predict_fraction = 0;  // the fused rows only (the range would be a time to predict at)
  FusionEstimator f(OneAgent(), o, std::move(m));
  VectorSink sink;
  for (int k = 0; k < 20; ++k) {
    if (k == 10) f.Add(RangeMeasurement{0.5 * k + 0.1, "ff1", "b1", 3.0, 0.05}, sink);
    f.Add(Step{0.5 * k, 0.5 * (k + 1), "ff1", Vec3(0.7, 0, 0), std::nullopt}, sink);
  }
  ASSERT_EQ(sink.rows.size(), 20u);
  for (int k = 0; k < 20; ++k) {
    const double x = sink.rows[k].position_n.x() - Truth(k).x();
    if (k < 10)
      EXPECT_NEAR(x, 0.0, 1e-9) << k;  // the dead reckoning alone
    else
      EXPECT_NEAR(x, 3.0, 1e-9) << k;  // the member with ranges alone
  }
}

TEST(FusionEstimator, DeadReckoningOfAFootInsIsAFullMember) {
  // A member 2 m east of the truth and dead reckoning at the truth, equally confident: with a
  // phone's steps dead reckoning is only a fallback (the member alone); once the front end
  // says the agent's steps come from its foot INS, the two are intersected (half way).
  auto run = [](bool foot_ins) {
    std::vector<FusionMember> m;
    m.push_back({"radio", Offset(Vec2(2, 0), 0.5, 0, 0.5)});
    m.push_back({"dr", Offset(Vec2(0, 0), 0.5, 0, 0.5)});
    m.back().fallback_only = true;
    m.back().full_with_foot_ins = true;
    FusionOptions o = NoHat();
    o.predict_fraction = 0;
    FusionEstimator f(OneAgent(), o, std::move(m));
    f.StepsFromFootIns("ff1", foot_ins);
    const std::vector<Estimate> rows = Walk(f, 10);
    return rows.back().position_n.x() - Truth(9).x();
  };
  EXPECT_NEAR(run(false), 2.0, 1e-9);
  EXPECT_NEAR(run(true), 1.0, 1e-6);
}

TEST(FusionEstimator, ARowOneMemberRefusesStillReachesTheOthersThenThrows) {
  std::vector<FusionMember> m;
  auto refusing = std::make_unique<Scripted>(
      [](const std::string& a, TimeS t, int k) { return At(a, t, Truth(k), 1, 0, 1); }, 0, true);
  auto other = Offset(Vec2(0, 0), 1, 0, 1);
  Scripted* other_ptr = other.get();
  m.push_back({"refusing", std::move(refusing)});
  m.push_back({"other", std::move(other)});
  FusionEstimator f(OneAgent(), {}, std::move(m));
  VectorSink sink;
  EXPECT_THROW(f.Add(Step{0, 0.5, "ff1", Vec3(0.7, 0, 0), std::nullopt}, sink),
               std::invalid_argument);
  EXPECT_EQ(other_ptr->rows, 1);
  EXPECT_NO_THROW(f.Add(Step{0.5, 1.0, "ff1", Vec3(0.7, 0, 0), std::nullopt}, sink));
}

TEST(FusionEstimator, TheHatFindsTheMemberThatIsBetterThanItsCovarianceSays) {
  // Three members claim the same 0.5 m; one is right to 0.05 m, two scatter by 0.7 m. The
  // N-cornered hat learns that from their differences: the fusion follows the good one, and
  // the two that claim too little are inflated.
  std::mt19937 rng(3);
  auto noisy = [&rng](double sigma) {
    return std::make_unique<Scripted>([&rng, sigma](const std::string& a, TimeS t, int k) {
      std::normal_distribution<double> n(0, sigma);
      return At(a, t, Truth(k) + Vec2(n(rng), n(rng)), 0.25, 0, 0.25);
    });
  };
  auto run = [&](bool hat, double power = 1.0) {
    std::vector<std::unique_ptr<Scripted>> s;
    s.push_back(noisy(0.05));
    s.push_back(noisy(0.7));
    s.push_back(noisy(0.7));
    FusionOptions o;
    o.hat_power = power;
    if (!hat) o.hat_window_s = 0;
    FusionEstimator f(OneAgent(), o, Members(std::move(s)));
    const auto rows = Walk(f, 400);
    double sum = 0;
    for (std::size_t k = 100; k < rows.size(); ++k)
      sum += (rows[k].position_n.head<2>() - Truth(static_cast<int>(k))).norm();
    return std::make_pair(sum / 300, f.Summary());
  };
  const auto [with_hat, summary] = run(true);
  const auto [without, ignored] = run(false);
  EXPECT_LT(with_hat, 0.15);
  EXPECT_GT(without, 0.3);
  EXPECT_GT(summary.numbers.at("fusion.m1.mean_inflation"), 1.3);
  EXPECT_NEAR(summary.numbers.at("fusion.m0.mean_inflation"), 1.0, 1e-9);
  // A larger power leans further toward the best member.
  const auto [sharper, unused] = run(true, 3.0);
  EXPECT_LT(sharper, with_hat);
}

/// A member that places crumb c1 at `where` with each step.
class PlacesACrumb : public Scripted {
 public:
  PlacesACrumb(Vec2 where, double var)
      : Scripted([](const std::string& a, TimeS t, int k) { return At(a, t, Truth(k), 1, 0, 1); }),
        where_(where),
        var_(var) {}
  void Add(const MissionRow& row, EstimateSink& sink) override {
    Scripted::Add(row, sink);
    if (std::holds_alternative<Step>(row)) sink.Add(At("c1", RowTime(row), where_, var_, 0, var_));
  }

 private:
  Vec2 where_;
  double var_;
};

TEST(FusionEstimator, AStaticNodeComesFromTheMemberThatMeasuresItMostDirectly) {
  auto run = [](int rank_of_ranges) {
    std::vector<FusionMember> m;
    m.push_back({"radio", std::make_unique<PlacesACrumb>(Vec2(5, 5), 0.01)});
    m.back().static_rank = 2;
    m.push_back({"ranges", std::make_unique<PlacesACrumb>(Vec2(1, 1), 0.04)});
    m.back().static_rank = rank_of_ranges;
    FusionEstimator f(OneAgent(), {}, std::move(m));
    Walk(f, 5);
    return *f.Current("c1");
  };
  EXPECT_LT((run(0).position_n.head<2>() - Vec2(1, 1)).norm(), 1e-12);  // ranges first
  EXPECT_NEAR(run(0).sxx, 0.04, 1e-12);
  EXPECT_LT((run(3).position_n.head<2>() - Vec2(5, 5)).norm(), 1e-12);  // radio first
  // Equal ranks: intersected (the tighter one takes all the weight here).
  EXPECT_LT((run(2).position_n.head<2>() - Vec2(5, 5)).norm(), 1e-3);
}

TEST(FusionEstimator, AStaticNodeComesFromAMemberWhoseEvidenceNamesIt) {
  // A beacon filter (rank 0) keeps the breadcrumb it never ranges where it was dropped; the
  // RSSI network (rank 2) hears it: the crumb is the network's. A beacon the ranges name is the
  // filter's, and a node no evidence names comes from the lowest rank as before.
  auto run = [](const std::string& ranged, const std::string& heard) {
    std::vector<FusionMember> m;
    m.push_back({"ranges", std::make_unique<PlacesACrumb>(Vec2(1, 1), 0.04)});
    m.back().static_rank = 0;
    m.back().evidence = StreamSet{Stream::kRanges};
    m.push_back({"radio", std::make_unique<PlacesACrumb>(Vec2(5, 5), 0.01)});
    m.back().static_rank = 2;
    m.back().evidence = StreamSet{Stream::kRssi};
    FusionEstimator f(OneAgent(), {}, std::move(m));
    VectorSink sink;
    for (int k = 0; k < 5; ++k) {
      if (!ranged.empty())
        f.Add(RangeMeasurement{0.5 * k + 0.1, ranged, "ff1", 2.0, 0.3, "ultrasound"}, sink);
      if (!heard.empty()) f.Add(RssiPacket{0.5 * k + 0.2, "ff1", heard, -70.0}, sink);
      f.Add(Step{0.5 * k, 0.5 * (k + 1), "ff1", Vec3(0.7, 0, 0), std::nullopt}, sink);
    }
    f.Finish(sink);
    return f.Current("c1")->position_n.head<2>().eval();
  };
  EXPECT_LT((run("b1", "c1") - Vec2(5, 5)).norm(), 1e-12);  // only the radio hears c1
  EXPECT_LT((run("c1", "c1") - Vec2(1, 1)).norm(), 1e-12);  // both: the ranges first
  EXPECT_LT((run("b1", "b2") - Vec2(1, 1)).norm(), 1e-12);  // neither: the lowest rank
}

/// A member that answers RSSI packets of ff1 (not steps) with an estimate where it stands.
class OnPackets : public OnlineEstimator {
 public:
  explicit OnPackets(Vec2 where) : where_(where) {}
  void Add(const MissionRow& row, EstimateSink& sink) override {
    if (const auto* r = std::get_if<RssiPacket>(&row)) sink.Add(At("ff1", r->t, where_, 1, 0, 1));
  }
  void Finish(EstimateSink&) override {}
  std::optional<Estimate> Current(const std::string&) const override { return std::nullopt; }
  EstimatorSummary Summary() const override { return {}; }

 private:
  Vec2 where_;
};

TEST(FusionEstimator, AMembersLastEstimateStillCountsWhileTheAgentStands) {
  // Ten steps, then 10 s standing, during which only the other member updates (packets).
  std::vector<FusionMember> m;
  m.push_back({"steps", Offset(Vec2(0, 0), 1, 0, 1)});
  m.push_back({"packets", std::make_unique<OnPackets>(Truth(9) + Vec2(0, 0.4))});
  FusionEstimator f(OneAgent(), NoHat(), std::move(m));
  VectorSink sink;
  for (int k = 0; k < 10; ++k)
    f.Add(Step{0.5 * k, 0.5 * (k + 1), "ff1", Vec3(0.7, 0, 0), std::nullopt}, sink);
  for (int j = 1; j <= 20; ++j) f.Add(RssiPacket{5.0 + 0.5 * j, "ff1", "L1", -60.0}, sink);
  f.Finish(sink);
  EXPECT_EQ(f.TypedSummary().members[0].stale, 0);  // 10 s old, yet current: nothing moved
  const Estimate& last = sink.rows.back();
  EXPECT_DOUBLE_EQ(last.t, 15.0);
  // Both members, equal covariances: halfway between them.
  EXPECT_LT((last.position_n.head<2>() - (Truth(9) + Vec2(0, 0.2))).norm(), 1e-9);
  // Walking again after a gap, the old estimate would be stale: one step later it is.
  FusionOptions o = NoHat();
  std::vector<FusionMember> m2;
  m2.push_back(
      {"steps", std::make_unique<Scripted>([](const std::string& a, TimeS t,
                                              int k) { return At(a, t, Truth(k), 1, 0, 1); },
                                           /*lag=*/100)});  // never emits before Finish
  m2.push_back({"packets", std::make_unique<OnPackets>(Vec2(0, 0))});
  FusionEstimator walking(OneAgent(), o, std::move(m2));
  VectorSink s2;
  walking.Add(Step{0, 0.5, "ff1", Vec3(0.7, 0, 0), std::nullopt}, s2);
  walking.Add(RssiPacket{3.0, "ff1", "L1", -60.0}, s2);
  EXPECT_TRUE(s2.rows.empty() || s2.rows.back().position_n.head<2>().norm() < 1e-9);
}

TEST(FusionEstimator, AMemberThatIsDeadReckoningIsLeftOutBesideTwoWithEvidence) {
  auto run = [](bool two_with_evidence) {
    std::vector<FusionMember> m;
    m.push_back({"like_dr", Offset(Vec2(0, 0), 0.2, 0, 0.2)});
    m.push_back({"a", Offset(Vec2(0.6, 0), 0.5, 0, 0.5)});
    if (two_with_evidence) m.push_back({"b", Offset(Vec2(0.6, 0.1), 0.5, 0, 0.5)});
    m.push_back({"pdr", Offset(Vec2(0, 0), 1, 0, 1)});
    m.back().fallback_only = true;
    FusionEstimator f(OneAgent(), NoHat(), std::move(m));
    const auto rows = Walk(f, 40);
    return std::make_pair(rows.back(), f.TypedSummary());
  };
  const auto [with_two, s2] = run(true);
  // From its eleventh row on: the faded weight of its rows first reaches 10 there.
  EXPECT_EQ(s2.members[0].follows_dr, 30);
  EXPECT_GT(with_two.position_n.x() - Truth(39).x(), 0.55);  // a and b only
  const auto [with_one, s1] = run(false);
  EXPECT_EQ(s1.members[0].follows_dr, 0);  // beside one member it is dead reckoning's voice
  EXPECT_LT(with_one.position_n.x() - Truth(39).x(), 0.3);
}

TEST(FusionEstimator, TwoMembersReadingTheSameEvidenceAreOneOpinion) {
  // The RSSI network reading the ultrasound ranges as well: with no third member to arbitrate,
  // the beacon filter (built for ranges, lower static rank) alone; once the network has RSSI of
  // its own, both again.
  auto run = [](bool rssi) {
    std::vector<FusionMember> m;
    m.push_back(
        {"radio", Offset(Vec2(2, 0), 0.01, 0, 0.01), StreamSet{Stream::kRssi, Stream::kRanges}});
    m.back().static_rank = 2;
    m.push_back({"ranges", Offset(Vec2(0, 0), 0.04, 0, 0.04), StreamSet{Stream::kRanges}});
    m.back().static_rank = 0;
    FusionEstimator f(OneAgent(), NoHat(), std::move(m));
    VectorSink sink;
    f.Add(RangeMeasurement{0.1, "ff1", "b1", 3.0, 0.05}, sink);
    if (rssi) f.Add(RssiPacket{0.2, "ff1", "c1", -60.0}, sink);
    for (int k = 0; k < 10; ++k)
      f.Add(Step{0.5 * k, 0.5 * (k + 1), "ff1", Vec3(0.7, 0, 0), std::nullopt}, sink);
    return std::make_pair(sink.rows.back(), f.TypedSummary());
  };
  const auto [shared, s1] = run(false);
  EXPECT_LT((shared.position_n.head<2>() - Truth(9)).norm(), 1e-9);
  EXPECT_EQ(s1.members[0].shared_evidence, 10);
  const auto [own, s2] = run(true);
  EXPECT_GT((own.position_n.head<2>() - Truth(9)).norm(), 1.0);  // the tighter radio member
  EXPECT_EQ(s2.members[0].shared_evidence, 0);
}

// fusion.shared_evidence_members: with a third member (a map matcher) the two-member rule does
// not apply; `all` and `witness` still make the network reading only the beacon filter's
// ranges give way, so the fused position is that of the other two alone.
TEST(FusionEstimator, AMemberReadingAnothersEvidenceGivesWayAtAnyCountWhenAsked) {
  using SE = FusionOptions::SharedEvidence;
  auto run = [](std::optional<SE> mode, bool with_radio) {
    std::vector<FusionMember> m;
    if (with_radio) {
      m.push_back({"radio", Offset(Vec2(0.6, 0), 0.01, 0, 0.01),
                   StreamSet{Stream::kRssi, Stream::kRanges}});
      m.back().static_rank = 2;
    }
    m.push_back({"ranges", Offset(Vec2(0, 0), 0.04, 0, 0.04), StreamSet{Stream::kRanges}});
    m.back().static_rank = 0;
    m.push_back({"map", Offset(Vec2(0, 0.3), 0.09, 0, 0.09)});
    m.back().static_rank = 3;
    FusionOptions o = NoHat();
    o.disagreement_probability = 1.0 - 1e-12;  // no member left out as disagreeing
    if (mode) o.shared_evidence_members = *mode;
    FusionEstimator f(OneAgent(), o, std::move(m));
    VectorSink sink;
    f.Add(RangeMeasurement{0.1, "ff1", "b1", 3.0, 0.05}, sink);
    for (int k = 0; k < 10; ++k)
      f.Add(Step{0.5 * k, 0.5 * (k + 1), "ff1", Vec3(0.7, 0, 0), std::nullopt}, sink);
    return std::make_pair(sink.rows.back(), f.TypedSummary());
  };
  const auto [two_only, s0] = run(std::nullopt, false);
  const auto [two, s1] = run(SE::kTwo, true);
  EXPECT_GT((two.position_n - two_only.position_n).norm(), 0.2);  // the radio member counts
  EXPECT_EQ(s1.members[0].shared_evidence, 0);
  for (const SE mode : {SE::kAll, SE::kWitness}) {
    const auto [fused, s] = run(mode, true);
    EXPECT_LT((fused.position_n - two_only.position_n).norm(), 1e-9);
    EXPECT_EQ(s.members[0].shared_evidence, 10);
    EXPECT_EQ(s.members[0].rows_used, 0);
  }
}

TEST(FusionEstimator, BetweenFusedRowsTheEstimateIsPredictedAtItsVelocityForHalfTheInterval) {
  // One member at the truth, a step (0.7 m east) every 0.5 s, other rows (a barometer) every
  // 0.05 s in between: a predicted row at most every 0.1 s, on the line at 1.4 m/s, for at most
  // half the interval (0.25 s) after each fused row, its covariance grown by (0.5 m/s x dt)^2.
  // Off: nothing between the fused rows.
  auto run = [](double fraction) {
    FusionOptions o = NoHat();
    o.predict_fraction = fraction;
    std::vector<std::unique_ptr<Scripted>> one;
    one.push_back(Offset(Vec2::Zero(), 0.01, 0, 0.01));
    FusionEstimator f(OneAgent(), o, Members(std::move(one)));
    VectorSink sink;
    for (int k = 0; k < 10; ++k) {
      f.Add(Step{0.5 * k, 0.5 * (k + 1), "ff1", Vec3(0.7, 0, 0), std::nullopt}, sink);
      for (int j = 1; j <= 9; ++j) f.Add(BaroSample{0.5 * (k + 1) + 0.05 * j, "ff1", 1000.0}, sink);
    }
    f.Finish(sink);
    return sink.rows;
  };
  const std::vector<Estimate> held = run(0.0);
  EXPECT_EQ(held.size(), 10u);  // the fused rows only
  const std::vector<Estimate> rows = run(0.5);
  int predicted = 0;
  TimeS last_fused = 0, last_row = -1;
  for (const Estimate& e : rows) {
    EXPECT_GT(e.t, last_row - 1e-9);  // time order
    last_row = e.t;
    const double k = std::round(e.t / 0.5);
    if (std::abs(e.t - 0.5 * k) < 1e-9) {  // a fused row: the member's
      EXPECT_NEAR(e.position_n.x(), 0.7 * k, 1e-9);
      last_fused = e.t;
      continue;
    }
    ++predicted;
    const double ahead = e.t - last_fused;
    EXPECT_GE(ahead, 0.1 - 1e-9);
    EXPECT_LE(ahead, 0.25 + 1e-9);
    EXPECT_NEAR(e.position_n.x(), 0.7 * (last_fused / 0.5) + 1.4 * ahead, 1e-9);
    EXPECT_NEAR(e.position_n.y(), 0.0, 1e-12);
    EXPECT_NEAR(e.sxx, 0.01 + std::pow(0.5 * ahead, 2), 1e-9);
  }
  // Two a step (0.1 and 0.2 s after it) from the second step on (the first has no baseline).
  EXPECT_EQ(predicted, 18);
}

TEST(FusionEstimator, RefusesBadOptionsAndNoMembers) {
  FusionOptions o;
  o.stale_s = -1;
  std::vector<std::unique_ptr<Scripted>> s;
  s.push_back(Offset(Vec2(0, 0), 1, 0, 1));
  EXPECT_THROW(FusionEstimator(OneAgent(), o, Members(std::move(s))), std::invalid_argument);
  EXPECT_THROW(FusionEstimator(OneAgent(), {}, {}), std::invalid_argument);
}

// The registry's fusion builds the members the incident can feed.
TEST(FusionPipeline, BuildsTheMembersTheMissionCanFeed) {
  const SimulatedMission trail = SimulateScenario("beacon-trail", 2);
  EstimatorInputs in{trail.data.info, &trail.plan};
  in.streams = StreamSet{Stream::kSteps, Stream::kRanges, Stream::kEvents};
  auto f = RequirePipeline("fusion").make(in, {}, Feed::kTimeOrdered);
  const EstimatorSummary s = f->Summary();
  EXPECT_EQ(s.numbers.at("fusion.members"), 4);  // breadcrumb, beacons-ekf, mapmatch, pdr
  EXPECT_TRUE(s.numbers.count("fusion.beacons-ekf.mean_weight"));
  EXPECT_FALSE(s.numbers.count("fusion.landmarks-ukf.mean_weight"));
  in.streams = StreamSet{Stream::kSteps};
  in.floor_plan = nullptr;
  EXPECT_EQ(RequirePipeline("fusion")
                .make(in, {}, Feed::kTimeOrdered)
                ->Summary()
                .numbers.at("fusion.members"),
            2);  // the breadcrumb network (no evidence: never used) and dead reckoning
  EXPECT_THROW(RequirePipeline("fusion").make(in, {{"fusion.stale_s", "-2"}}, Feed::kTimeOrdered),
               std::invalid_argument);
}

TEST(FusionPipeline, TakesTheFootImusStepsWhereAMissionAlsoHasAPhones) {
  // The multi-floor building has both imu.csv and steps.csv: the fusion dead-reckons on the
  // foot INS's steps (docs/fusion.md), every single steps-based pipeline on steps.csv, and a
  // note says which file each one did not use.
  const SimulatedMission sim = SimulateScenario("multi-floor", 3);
  testing::TempDir dir;
  WriteMissionDirectory(dir.path(), sim.data, sim.levels);
  const MissionDirectory mission(dir.path());
  std::vector<std::string> notes;
  const StreamSet fusion = BatchFeedStreams(RequirePipeline("fusion"), mission, {}, &notes);
  EXPECT_TRUE(fusion.Has(Stream::kImu));
  EXPECT_FALSE(fusion.Has(Stream::kSteps));
  ASSERT_EQ(notes.size(), 1u);
  EXPECT_NE(notes[0].find("steps.csv not used"), std::string::npos);
  notes.clear();
  const StreamSet mapmatch = BatchFeedStreams(RequirePipeline("mapmatch"), mission, {}, &notes);
  EXPECT_TRUE(mapmatch.Has(Stream::kSteps));
  EXPECT_FALSE(mapmatch.Has(Stream::kImu));
  ASSERT_EQ(notes.size(), 1u);
  EXPECT_NE(notes[0].find("imu.csv not used"), std::string::npos);
}

}  // namespace
}  // namespace trailmark::fusion

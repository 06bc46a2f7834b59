// SPDX-License-Identifier: MIT
// Dead reckoning and the StepFrontEnd (how every steps-based estimator gets its steps and its
// row order) against exact references.
#include "trailmark/ins/step_front_end.h"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <stdexcept>

#include "device_batches.h"
#include "trailmark/core/random.h"
#include "trailmark/ins/dead_reckoning.h"
#include "trailmark/sim/imu_sim.h"
#include "trailmark/sim/scenarios.h"

namespace trailmark {
namespace {

/// Only the white step noise: the covariance is the sum of the step variances.
PdrOptions WhiteOnly() {
  PdrOptions o;
  o.start_heading_sigma_rad = o.heading_drift_sigma_rad_per_s = o.heading_walk_sigma_rad = 0;
  o.track_heading_offset_sigma_rad = 0;
  o.step_scale_sigma = o.turn_scale_sigma = 0;
  return o;
}

TEST(DeadReckoning, SumsStepsAndVariances) {
  DeadReckoning dr(Vec3(1, 2, 0), 0.5, WhiteOnly());
  dr.AddStep({0, 1, "a", Vec3(0.5, 0, 0), Vec3(0.01, 0.02, 0)});
  dr.AddStep({1, 2, "a", Vec3(0, -0.5, 0), Vec3(0.01, 0.02, 0)});
  EXPECT_TRUE(dr.position_n().isApprox(Vec3(1.5, 1.5, 0)));
  EXPECT_NEAR(dr.covariance()(0, 0), 0.25 + 0.02, 1e-15);
  EXPECT_NEAR(dr.covariance()(1, 1), 0.25 + 0.04, 1e-15);
  // Unknown variance: the documented default (5 cm + 3 % of 0.5 m)^2.
  dr.AddStep({2, 3, "a", Vec3(0.5, 0, 0), std::nullopt});
  EXPECT_NEAR(dr.covariance()(0, 0), 0.27 + std::pow(0.05 + 0.015, 2), 1e-15);
}

// A position fix fused by covariance intersection: the exact reference is the information form
// (omega P^-1 + (1 - omega) R^-1)^-1 and its mean, with omega found here by brute force on a
// fine grid of the trace; the shared errors' covariance is untouched and the joint stays
// positive definite; a fix much worse than the estimate is not used.
TEST(DeadReckoning, PositionFixIsACovarianceIntersection) {
  DeadReckoning dr(Vec3(1, 2, 0), 0.3);
  for (int k = 0; k < 40; ++k) dr.AddStep(Step{k * 0.5, k * 0.5 + 0.5, "ff1", Vec3(0.6, 0.2, 0)});
  const Mat2 P = dr.covariance();
  const Vec2 x = dr.position_n().head<2>();
  const auto shared_before =
      dr.error_covariance()
          .bottomRightCorner<DeadReckoning::kSharedErrors, DeadReckoning::kSharedErrors>()
          .eval();
  Mat2 R;
  R << 0.8, -0.3, -0.3, 0.5;
  const Vec2 z = x + Vec2(1.0, -0.7);
  double best = 1e300, best_w = 0;
  for (int k = 0; k <= 100000; ++k) {
    const double w = k / 100000.0;
    const double tr = (w * P.inverse() + (1 - w) * R.inverse()).inverse().trace();
    if (tr < best) best = tr, best_w = w;
  }
  const double omega = dr.FusePosition(z, R);
  EXPECT_NEAR(omega, best_w, 1e-3);
  const Mat2 info = best_w * P.inverse() + (1 - best_w) * R.inverse();
  const Mat2 C = info.inverse();
  const Vec2 mean = C * (best_w * P.inverse() * x + (1 - best_w) * R.inverse() * z);
  EXPECT_LT((dr.covariance() - C).norm(), 1e-6 * C.norm());
  EXPECT_LT((dr.position_n().head<2>() - mean).norm(), 1e-6);
  EXPECT_LT((dr.error_covariance()
                 .bottomRightCorner<DeadReckoning::kSharedErrors, DeadReckoning::kSharedErrors>() -
             shared_before)
                .norm(),
            1e-15);
  const Eigen::SelfAdjointEigenSolver<DeadReckoning::ErrorCovariance> eig(dr.error_covariance());
  EXPECT_GT(eig.eigenvalues().minCoeff(), 0.0);
  // A fix 100 times less certain than the estimate changes nothing.
  const Vec3 before = dr.position_n();
  EXPECT_DOUBLE_EQ(dr.FusePosition(z, dr.covariance() * 100.0), 1.0);
  EXPECT_EQ(dr.position_n(), before);
  // A fix that is not one is refused, and changes nothing.
  EXPECT_THROW(dr.FusePosition(Vec2(NAN, 0), R), std::invalid_argument);
  EXPECT_THROW(dr.FusePosition(z, Mat2::Zero()), std::invalid_argument);
  Mat2 asymmetric = R;
  asymmetric(0, 1) += 0.1;
  EXPECT_THROW(dr.FusePosition(z, asymmetric), std::invalid_argument);
  EXPECT_EQ(dr.position_n(), before);
}

// A fix taken whole (the stop-and-go paper's update): the position and its covariance are the
// fix's, the heading error keeps its variance but no longer its correlation with the position,
// and grows the error again over the walk after the fix. Exact reference (a heading offset
// only): C + sigma_psi^2 perp(D) perp(D)^T + the steps' own variances, D the walk since the fix.
TEST(DeadReckoning, SetPositionKeepsTheSharedErrorsForTheWalkAfter) {
  PdrOptions o = WhiteOnly();
  o.start_heading_sigma_rad = 0.05;
  DeadReckoning dr(Vec3::Zero(), 0.1, o);
  TimeS t = 0;
  for (int k = 0; k < 40; ++k, t += 0.5) dr.AddStep({t, t + 0.5, "a", Vec3(0.7, 0, 0), Vec3(1e-6, 1e-6, 0)});
  EXPECT_GT(dr.covariance()(1, 1), 0.05 * 0.05 * 28 * 28 * 0.99);  // the heading across the walk
  const auto shared_before =
      dr.error_covariance()
          .bottomRightCorner<DeadReckoning::kSharedErrors, DeadReckoning::kSharedErrors>()
          .eval();
  Mat2 C;
  C << 0.2, 0.05, 0.05, 0.1;
  dr.SetPosition(Vec2(27.5, 0.4), C);
  EXPECT_EQ(dr.position_n().head<2>(), Vec2(27.5, 0.4));
  EXPECT_EQ(dr.covariance(), C);
  const auto& P = dr.error_covariance();
  EXPECT_EQ((P.bottomRightCorner<DeadReckoning::kSharedErrors, DeadReckoning::kSharedErrors>() -
             shared_before)
                .norm(),
            0.0);
  const double cross = P.topRightCorner<2, DeadReckoning::kSharedErrors>().norm() +
                       P.bottomLeftCorner<DeadReckoning::kSharedErrors, 2>().norm();
  EXPECT_EQ(cross, 0.0);
  for (int k = 0; k < 20; ++k, t += 0.5) dr.AddStep({t, t + 0.5, "a", Vec3(0, 0.7, 0), Vec3(1e-6, 1e-6, 0)});
  Mat2 expected = C;
  expected(0, 0) += 0.05 * 0.05 * 14 * 14;  // perp((0, 14)) = (-14, 0)
  expected += Mat2::Identity() * 20 * 1e-6;
  EXPECT_LT((dr.covariance() - expected).norm(), 1e-9);
  EXPECT_TRUE(dr.position_n().head<2>().isApprox(Vec2(27.5, 14.4)));
  // A fix that is not one is refused, and changes nothing.
  const Vec3 before = dr.position_n();
  EXPECT_THROW(dr.SetPosition(Vec2(NAN, 0), C), std::invalid_argument);
  EXPECT_THROW(dr.SetPosition(Vec2(1, 0), -C), std::invalid_argument);
  EXPECT_EQ(dr.position_n(), before);
}

TEST(DeadReckoning, AnAddedHeadingVarianceTurnsTheWalkAfterIt) {
  // An extra heading error of variance v (a reversal whose turn's sign is unknown): the walk
  // after it gains v perp(d) perp(d)^T on its position; the position before it is unchanged.
  PdrOptions o = WhiteOnly();
  DeadReckoning dr(Vec3::Zero(), 0.1, o, 0.0);
  TimeS t = 0;
  for (int k = 0; k < 10; ++k, t += 0.5)
    dr.AddStep({t, t + 0.5, "a", Vec3(0.7, 0, 0), Vec3(1e-6, 1e-6, 0)});
  const Mat2 before = dr.covariance();
  dr.AddHeadingVariance(0.01);
  EXPECT_EQ(dr.covariance(), before);
  for (int k = 0; k < 10; ++k, t += 0.5)
    dr.AddStep({t, t + 0.5, "a", Vec3(0, 0.7, 0), Vec3(1e-6, 1e-6, 0)});
  Mat2 expected = before + Mat2::Identity() * 10 * 1e-6;
  expected(0, 0) += 0.01 * 7 * 7;  // perp((0, 7)) = (-7, 0)
  EXPECT_LT((dr.covariance() - expected).norm(), 1e-9);
  EXPECT_THROW(dr.AddHeadingVariance(-1e-3), std::invalid_argument);
  EXPECT_THROW(dr.AddHeadingVariance(NAN), std::invalid_argument);
}

TEST(DeadReckoning, CorrelatedHeadingAndScaleErrorsMatchMonteCarlo) {
  // Exact reference: the covariance of the position over many walks whose steps are turned by
  // a heading offset + drift x time + a turn-scale error x the angle turned + a random walk and
  // stretched by one scale error, all drawn from the options' sigmas. Walk: 40 steps east, 60 s
  // standing, 40 steps north, then a loop of four left turns (20 steps a side, 360 deg more),
  // where the turn-scale error is most of the heading error.
  PdrOptions o;
  o.start_heading_sigma_rad = 0.05;
  o.heading_drift_sigma_rad_per_s = 0.001;
  o.heading_walk_sigma_rad = 0.01;
  o.step_scale_sigma = 0.03;
  o.turn_scale_sigma = 0.02;  // 9 deg over the walk's 450 deg: small angles still
  o.track_heading_offset_sigma_rad = 0.03;
  std::vector<Step> steps;
  TimeS t = 0;
  const std::array<Vec3, 4> sides = {Vec3(0.7, 0, 0), Vec3(0, 0.7, 0), Vec3(-0.7, 0, 0),
                                     Vec3(0, -0.7, 0)};
  for (int i = 0; i < 160; ++i) {
    if (i == 40) t += 60;
    const Vec3 d = i < 40 ? sides[0] : i < 80 ? sides[1] : sides[(2 + (i - 80) / 20) % 4];
    steps.push_back({t, t + 0.5, "a", d, Vec3(1e-4, 1e-4, 0)});
    t += 0.5;
  }
  DeadReckoning dr(Vec3::Zero(), 0.1, o);
  for (const Step& s : steps) dr.AddStep(s);
  Random rng(3);
  const int n = 20000;
  std::vector<Vec2> ends;
  Vec2 mean = Vec2::Zero();
  for (int k = 0; k < n; ++k) {
    // The start heading's error and the track's own offset (two independent draws).
    double heading =
        rng.Normal(0, o.start_heading_sigma_rad) + rng.Normal(0, o.track_heading_offset_sigma_rad);
    const double rate = rng.Normal(0, o.heading_drift_sigma_rad_per_s);
    const double scale = rng.Normal(0, o.step_scale_sigma);
    const double turn_scale = rng.Normal(0, o.turn_scale_sigma);
    Vec2 p(rng.Normal(0, 0.1), rng.Normal(0, 0.1));
    TimeS last = steps.front().t1;
    double direction = 0;  // of the steps as walked (every step here is >= turn_min_step_m)
    for (const Step& s : steps) {
      heading += rate * (s.t1 - last);
      last = s.t1;
      const double now = std::atan2(s.delta_n.y(), s.delta_n.x());
      heading += turn_scale * WrapAngle(now - direction);
      direction = now;
      const Vec2 d = (1 + scale) * (Eigen::Rotation2Dd(heading) * Vec2(s.delta_n.head<2>()));
      p += d + Vec2(rng.Normal(0, 0.01), rng.Normal(0, 0.01));
      heading += rng.Normal(0, o.heading_walk_sigma_rad);
    }
    ends.push_back(p);
    mean += p / n;
  }
  Mat2 empirical = Mat2::Zero();
  for (const Vec2& p : ends) empirical += (p - mean) * (p - mean).transpose() / (n - 1);
  const Mat2 c = dr.covariance();
  // First-order propagation of small angles: within the Monte Carlo's 2-3 % sampling error.
  EXPECT_NEAR(c(0, 0), empirical(0, 0), 0.05 * empirical(0, 0));
  EXPECT_NEAR(c(1, 1), empirical(1, 1), 0.05 * empirical(1, 1));
  EXPECT_NEAR(c(0, 1), empirical(0, 1), 0.05 * std::sqrt(empirical(0, 0) * empirical(1, 1)));
  // Standing 60 s with a drift rate grows the error of the second leg: more than without it
  // (the first 80 steps: east, standing, north).
  PdrOptions no_drift = o;
  no_drift.heading_drift_sigma_rad_per_s = 0;
  DeadReckoning drifting(Vec3::Zero(), 0.1, o), still(Vec3::Zero(), 0.1, no_drift);
  for (int i = 0; i < 80; ++i) drifting.AddStep(steps[i]), still.AddStep(steps[i]);
  EXPECT_GT(drifting.covariance().trace(), 1.5 * still.covariance().trace());
  // The turn-scale error is one more independent source: the covariance with it is the one
  // without it plus that of the turn-scale error alone (linear propagation), which is positive
  // semi-definite of rank one (one scalar error) and metres in size after 450 deg (0.16 rad
  // x a lever of ~20 m); steps shorter than turn_min_step_m (shuffling on the spot)
  // turn nothing.
  PdrOptions no_turn = o, turn_only = WhiteOnly(), none = WhiteOnly();
  no_turn.turn_scale_sigma = 0;
  turn_only.turn_scale_sigma = o.turn_scale_sigma;
  DeadReckoning straight(Vec3::Zero(), 0.1, no_turn), turning(Vec3::Zero(), 0.1, turn_only),
      white(Vec3::Zero(), 0.1, none);
  for (const Step& s : steps) straight.AddStep(s), turning.AddStep(s), white.AddStep(s);
  const Mat2 added = turning.covariance() - white.covariance();
  EXPECT_LT((c - straight.covariance() - added).norm(), 1e-9 * c.norm());
  EXPECT_GT(added.eigenvalues().real().minCoeff(), -1e-9);
  EXPECT_GT(added.trace(), 1.0);
  DeadReckoning shuffle(Vec3::Zero(), 0.1, o), shuffle_none(Vec3::Zero(), 0.1, no_turn);
  for (int k = 0; k < 40; ++k) {
    const double a = k * 2.0;  // scattered directions, 0.1 m steps
    const Step s{k * 0.5, k * 0.5 + 0.5, "a", Vec3(0.1 * std::cos(a), 0.1 * std::sin(a), 0),
                 Vec3(1e-4, 1e-4, 0)};
    shuffle.AddStep(s);
    shuffle_none.AddStep(s);
  }
  EXPECT_EQ(shuffle.covariance(), shuffle_none.covariance());
}

/// Records the rows it is fed.
class Recorder : public OnlineEstimator {
 public:
  explicit Recorder(std::vector<MissionRow>* rows) : rows_(rows) {}
  void Add(const MissionRow& row, EstimateSink&) override { rows_->push_back(row); }
  void Finish(EstimateSink&) override {}
  std::optional<Estimate> Current(const std::string&) const override { return std::nullopt; }
  EstimatorSummary Summary() const override { return {}; }
  void StepsFromFootIns(const std::string& agent, bool foot_ins) override {
    told.emplace_back(agent, foot_ins);
  }
  std::vector<std::pair<std::string, bool>> told;  ///< StepsFromFootIns calls

 private:
  std::vector<MissionRow>* rows_;
};

struct TwoWalkers {
  SimulatedMission sim;
  std::vector<MissionRow> merged;  ///< IMU and RSSI in time order (a batch merge)
  std::vector<MissionRow> expected;  ///< what the inner estimator must see
};

TwoWalkers MakeTwoWalkers() {
  TrainingBuildingOptions o;
  o.rooms_per_side = 1;
  TwoWalkers w{SimulateTrainingBuilding(o, 2), {}, {}};
  ImuSimOptions imu;
  imu.rate_hz = 100;
  AddFootImu(w.sim, imu, 4);
  // Both walks end together (a foot IMU that stops sending holds its last step until the end
  // of data, which a live feed does not wait for).
  std::map<std::string, TimeS> last;
  for (const auto& s : w.sim.data.imu) last[s.agent] = s.t;
  TimeS end = 1e300;
  for (const auto& [agent, t] : last) end = std::min(end, t);
  std::erase_if(w.sim.data.imu, [end](const ImuSample& s) { return s.t > end; });
  std::erase_if(w.sim.data.rssi, [end](const RssiPacket& p) { return p.t > end; });
  for (const auto& p : w.sim.data.rssi) w.merged.emplace_back(p);
  for (const auto& s : w.sim.data.imu) w.merged.emplace_back(s);
  std::stable_sort(w.merged.begin(), w.merged.end(), [](const MissionRow& a, const MissionRow& b) {
    return RowTime(a) != RowTime(b) ? RowTime(a) < RowTime(b) : a.index() < b.index();
  });
  // The reference: the INS over every sample first, its steps in t1 order, merged with the
  // RSSI as if read from steps.csv (what the batch pipelines did before the front end), rows
  // of the same time and stream by node.
  ins::MultiAgentIns reference(w.sim.data.info, {});
  std::vector<Step> steps;
  reference.on_step = [&](const Step& s) { steps.push_back(s); };
  for (const auto& s : w.sim.data.imu) reference.Add(s);
  reference.Finish();
  std::stable_sort(steps.begin(), steps.end(),
                   [](const Step& a, const Step& b) { return a.t1 < b.t1; });
  for (const auto& s : steps) w.expected.emplace_back(s);
  for (const auto& p : w.sim.data.rssi) w.expected.emplace_back(p);
  std::stable_sort(w.expected.begin(), w.expected.end(),
                   [](const MissionRow& a, const MissionRow& b) {
                     if (RowTime(a) != RowTime(b)) return RowTime(a) < RowTime(b);
                     if (a.index() != b.index()) return a.index() < b.index();
                     return RowNode(a) < RowNode(b);
                   });
  return w;
}

void ExpectSameRows(const std::vector<MissionRow>& a, const std::vector<MissionRow>& b) {
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    ASSERT_EQ(a[i].index(), b[i].index()) << i;
    ASSERT_EQ(RowTime(a[i]), RowTime(b[i])) << i;
    ASSERT_EQ(RowNode(a[i]), RowNode(b[i])) << i;
  }
}

TEST(StepFrontEnd, PutsInsStepsInTheirPlaceAmongTheOtherRows) {
  const TwoWalkers w = MakeTwoWalkers();
  ASSERT_GT(w.expected.size(), w.sim.data.rssi.size() + 40);  // 40+ steps
  std::vector<MissionRow> seen;
  StepFrontEnd front(w.sim.data.info, {}, RowOrder::kGlobal, Feed::kTimeOrdered,
                     std::make_unique<Recorder>(&seen));
  NullSink sink;
  std::size_t held_max = 0;
  for (const MissionRow& r : w.merged) {
    front.Add(r, sink);
    held_max = std::max<std::size_t>(held_max, front.Summary().numbers.at("rows_waiting"));
  }
  front.Finish(sink);
  ExpectSameRows(w.expected, seen);
  // It holds rows only while an INS may still emit an earlier step (a stride or so).
  EXPECT_LT(held_max, 200u);
}

TEST(StepFrontEnd, LiveRowsOfInterleavedDevicesComeOutInTimeOrder) {
  const TwoWalkers w = MakeTwoWalkers();
  // One device after the other, 0.3 s at a time: ff2's rows of a period before ff1's.
  std::vector<MissionRow> arrivals = w.merged;
  std::stable_sort(arrivals.begin(), arrivals.end(), [](const MissionRow& a, const MissionRow& b) {
    const long pa = static_cast<long>(std::floor(RowTime(a) / 0.3));
    const long pb = static_cast<long>(std::floor(RowTime(b) / 0.3));
    return pa != pb ? pa < pb : RowNode(a) > RowNode(b);
  });
  std::vector<MissionRow> seen;
  StepFrontEndOptions options;
  options.reorder_s = 0.5;
  StepFrontEnd front(w.sim.data.info, options, RowOrder::kGlobal, Feed::kLive,
                     std::make_unique<Recorder>(&seen));
  NullSink sink;
  for (const MissionRow& r : arrivals) front.Add(r, sink);
  front.Finish(sink);
  EXPECT_EQ(front.Summary().numbers.at("rows_late"), 0.0);
  ExpectSameRows(w.expected, seen);
}

TEST(ReorderWindow, IsTheCapUntilTheFeedHasRunTenSeconds) {
  ReorderWindow w(1.0);
  EXPECT_EQ(w.seconds(), 1.0);
  w.Observe(100.0, -1e300);
  w.Observe(100.1, 100.0);
  w.Observe(109.9, 100.1);
  EXPECT_EQ(w.seconds(), 1.0);
  w.Observe(110.0, 109.9);  // 10 s of feed, no row behind the newest: the least window
  EXPECT_DOUBLE_EQ(w.seconds(), ReorderWindow::kFloorS);
  w.Observe(103.0, 103.0);  // a simultaneous row is not late
  EXPECT_DOUBLE_EQ(w.peak_lateness_s(), 0.0);
}

TEST(ReorderWindow, FollowsTheLargestLatenessOfItsMemoryWithinTheCap) {
  ReorderWindow w(1.0);
  TimeS newest = -1e300;
  auto feed = [&](TimeS t) {
    w.Observe(t, newest);
    newest = std::max(newest, t);
  };
  // Two devices 0.1 s at a time, the second's batch after the first's: rows up to 0.1 s late.
  for (int k = 0; k < 110; ++k) {  // 11 s
    for (int i = 0; i < 10; ++i) feed(0.1 * k + 0.01 * i);
    for (int i = 0; i < 10; ++i) feed(0.1 * k + 0.01 * i);
  }
  EXPECT_NEAR(w.peak_lateness_s(), 0.09, 1e-9);
  EXPECT_NEAR(w.seconds(), 2 * 0.09 + 0.05, 1e-9);
  // Devices 0.2 s at a time: rows up to 0.19 s late.
  for (int k = 0; k < 50; ++k) {  // 10 s
    for (int i = 0; i < 20; ++i) feed(11.0 + 0.2 * k + 0.01 * i);
    for (int i = 0; i < 20; ++i) feed(11.0 + 0.2 * k + 0.01 * i);
  }
  EXPECT_NEAR(w.seconds(), 2 * 0.19 + 0.05, 1e-9);
  // A row 0.4 s late widens the window at once, to the cap at most.
  feed(newest - 0.4);
  EXPECT_NEAR(w.seconds(), 0.85, 1e-9);
  feed(newest - 5.0);
  EXPECT_EQ(w.seconds(), 1.0);
  // 30 s of rows in order later, the memory has forgotten both: the window shrinks.
  const TimeS t0 = newest;
  for (int k = 1; k <= 310; ++k) feed(t0 + 0.1 * k);
  EXPECT_DOUBLE_EQ(w.seconds(), ReorderWindow::kFloorS);
  // A cap of 0 is kept (every row released as it comes); a non-finite time is not a lateness.
  ReorderWindow none(0.0);
  none.Observe(1.0, -1e300);
  none.Observe(10.0, 1.0);
  none.Observe(2.0, 10.0);
  EXPECT_EQ(none.seconds(), 0.0);
  w.Observe(std::numeric_limits<double>::quiet_NaN(), newest);
  EXPECT_DOUBLE_EQ(w.seconds(), ReorderWindow::kFloorS);
}

/// Steps and RSSI of the two walkers in the batch run's order (`merged`) and as devices
/// deliver them: each node's rows of `batch_s` seconds together, the nodes' batches of a period
/// in a shuffled order.
std::vector<MissionRow> StepsAndRssiByDevice(const SimulatedMission& sim, double batch_s,
                                             std::vector<MissionRow>* merged) {
  for (const auto& s : sim.data.steps) merged->emplace_back(s);
  for (const auto& p : sim.data.rssi) merged->emplace_back(p);
  std::stable_sort(merged->begin(), merged->end(), [](const MissionRow& a, const MissionRow& b) {
    if (RowTime(a) != RowTime(b)) return RowTime(a) < RowTime(b);
    if (a.index() != b.index()) return a.index() < b.index();
    return RowNode(a) < RowNode(b);
  });
  return testing::DeviceBatches(*merged, batch_s, 11);
}

TEST(StepFrontEnd, LiveRowsWaitForTheFeedsLatenessNotTheWholeReorderWindow) {
  TrainingBuildingOptions o;
  o.rooms_per_side = 1;
  const SimulatedMission sim = SimulateTrainingBuilding(o, 2);
  std::vector<MissionRow> merged;
  const std::vector<MissionRow> arrivals = StepsAndRssiByDevice(sim, 0.1, &merged);
  ASSERT_GT(merged.size(), 500u);
  // Both streams are in the feed.
  ASSERT_TRUE(std::any_of(arrivals.begin(), arrivals.end(),
                          [](const MissionRow& r) { return std::holds_alternative<Step>(r); }));
  ASSERT_TRUE(std::any_of(arrivals.begin(), arrivals.end(), [](const MissionRow& r) {
    return std::holds_alternative<RssiPacket>(r);
  }));
  // How far the feed had gone past each row while it was still held (the newest row before
  // the one whose arrival released it), after 11 s: the wait in mission time.
  auto run = [&](bool adaptive, double* lag_max, double* late) {
    std::vector<MissionRow> seen;
    StepFrontEndOptions options;
    options.reorder_s = 1.0;
    options.reorder_adaptive = adaptive;
    StepFrontEnd front(sim.data.info, options, RowOrder::kGlobal, Feed::kLive,
                       std::make_unique<Recorder>(&seen));
    NullSink sink;
    TimeS newest = -1e300;
    const TimeS t0 = RowTime(arrivals.front());
    *lag_max = 0;
    for (const MissionRow& r : arrivals) {
      const std::size_t before = seen.size();
      front.Add(r, sink);
      for (std::size_t i = before; i < seen.size(); ++i) {
        if (RowTime(seen[i]) > t0 + 11.0) *lag_max = std::max(*lag_max, newest - RowTime(seen[i]));
      }
      newest = std::max(newest, RowTime(r));
    }
    front.Finish(sink);
    *late = front.Summary().numbers.at("rows_late");
    ExpectSameRows(merged, seen);
  };
  double lag_adaptive = 0, lag_fixed = 0, late_adaptive = -1, late_fixed = -1;
  run(true, &lag_adaptive, &late_adaptive);
  run(false, &lag_fixed, &late_fixed);
  EXPECT_EQ(late_adaptive, 0.0);
  EXPECT_EQ(late_fixed, 0.0);
  // Rows come at most ~0.1 s late here: a window of 2 x 0.1 + 0.05 s, and a batch behind it.
  EXPECT_LT(lag_adaptive, 0.4);
  EXPECT_GT(lag_fixed, 0.95);
}

// What the window that follows the feed costs: a device whose rows once come later than the
// window (a radio stall) has those rows late — counted, and handed on at once, out of order —
// until its first late row widens the window; a fixed window of the whole `reorder_s` has none.
TEST(StepFrontEnd, AStallLongerThanTheLearnedWindowMakesOneBatchLateThenWidensIt) {
  TrainingBuildingOptions o;
  o.rooms_per_side = 1;
  const SimulatedMission sim = SimulateTrainingBuilding(o, 2);
  std::vector<MissionRow> merged;
  std::vector<MissionRow> arrivals = StepsAndRssiByDevice(sim, 0.1, &merged);
  // ff1's rows of [30, 30.6) s come after everyone's rows up to 30.6 s.
  std::vector<MissionRow> stalled, rest;
  for (const MissionRow& r : arrivals) {
    (RowNode(r) == "ff1" && RowTime(r) >= 30.0 && RowTime(r) < 30.6 ? stalled : rest).push_back(r);
  }
  ASSERT_GT(stalled.size(), 3u);
  const auto at = std::find_if(rest.begin(), rest.end(),
                               [](const MissionRow& r) { return RowTime(r) >= 30.6; });
  const std::size_t after_stall = static_cast<std::size_t>(at - rest.begin()) + stalled.size();
  rest.insert(at, stalled.begin(), stalled.end());
  auto late_rows = [&](bool adaptive, double* window_after) {
    std::vector<MissionRow> seen;
    StepFrontEndOptions options;
    options.reorder_adaptive = adaptive;
    StepFrontEnd front(sim.data.info, options, RowOrder::kGlobal, Feed::kLive,
                       std::make_unique<Recorder>(&seen));
    NullSink sink;
    for (std::size_t i = 0; i < rest.size(); ++i) {
      front.Add(rest[i], sink);
      if (i + 1 == after_stall) *window_after = front.Summary().numbers.at("reorder_window_s");
    }
    front.Finish(sink);
    EXPECT_EQ(seen.size(), merged.size());  // late rows are handed on, not lost
    return front.Summary().numbers.at("rows_late");
  };
  double window_adaptive = 0, window_fixed = 0;
  const double late_adaptive = late_rows(true, &window_adaptive);
  EXPECT_EQ(late_rows(false, &window_fixed), 0.0);
  EXPECT_GT(late_adaptive, 0.0);
  EXPECT_LE(late_adaptive, static_cast<double>(stalled.size()));
  // Once the stalled rows are in, the window covers them (2 x ~0.6 + 0.05 s: the cap).
  EXPECT_EQ(window_fixed, 1.0);
  EXPECT_EQ(window_adaptive, 1.0);
}

TEST(StepFrontEnd, AnAgentsFirstSourceWinsAndTheOtherIsCounted) {
  MissionInfo info;
  info.nodes.push_back(NodeInfo::Agent("ff1", Vec3::Zero(), 0.1));
  info.nodes.push_back(NodeInfo::Base("base", Vec3::Zero()));
  info.nodes.push_back(NodeInfo::Agent("ff2", Vec3::Zero(), 0.1));
  std::vector<MissionRow> seen;
  auto recorder = std::make_unique<Recorder>(&seen);
  const Recorder& told = *recorder;
  StepFrontEnd front(info, {}, RowOrder::kPerAgent, Feed::kLive, std::move(recorder));
  NullSink sink;
  front.Add(Step{0, 1, "ff1", Vec3(0.7, 0, 0), std::nullopt}, sink);
  front.Add(ImuSample{1.0, "ff1", Vec3(0, 0, 9.8), Vec3::Zero()}, sink);  // steps came first
  front.Add(ImuSample{1.0, "ff2", Vec3(0, 0, 9.8), Vec3::Zero()}, sink);  // ff2: a foot IMU
  EXPECT_EQ(seen.size(), 1u);
  // The inner estimator is told each agent's source once, when it is chosen.
  ASSERT_EQ(told.told.size(), 2u);
  EXPECT_EQ(told.told[0], std::make_pair(std::string("ff1"), false));
  EXPECT_EQ(told.told[1], std::make_pair(std::string("ff2"), true));
  EXPECT_EQ(front.Summary().numbers.at("rows_ignored"), 1.0);
  EXPECT_THROW(front.Add(Step{1, 2, "base", Vec3(0.7, 0, 0), std::nullopt}, sink),
               std::invalid_argument);
  EXPECT_THROW(front.Add(ImuSample{1.0, "nobody", Vec3(0, 0, 9.8), Vec3::Zero()}, sink),
               std::invalid_argument);
}

// A phone's step detector reads swaying while standing as steps; the agent's declared stop
// (events.csv stop .. go) says it stands. Steps of steps.csv that start in a declared stop are
// not motion: ignored and counted, the step that ends as the stop begins is kept, and the
// option off (or an estimator that takes each agent's rows in its own order) keeps them all.
TEST(StepFrontEnd, StepsOfAPhoneDuringADeclaredStopAreNotMotion) {
  MissionInfo info;
  info.nodes.push_back(NodeInfo::Agent("ff1", Vec3::Zero(), 0.1));
  info.nodes.push_back(NodeInfo::Agent("ff2", Vec3::Zero(), 0.1));
  auto step = [](TimeS t0, TimeS t1, const char* agent) {
    return MissionRow(Step{t0, t1, agent, Vec3(0.6, 0, 0), std::nullopt});
  };
  auto event = [](TimeS t, const char* what) {
    return MissionRow(MissionEvent{t, "ff1", what, ""});
  };
  const std::vector<MissionRow> rows = {
      step(0.0, 0.5, "ff1"), step(0.5, 0.9, "ff1"), event(0.9, "stop"),
      step(0.9, 1.4, "ff1"),  // sway, from the stop on
      step(1.0, 1.5, "ff2"),  // another agent walks on
      step(2.0, 2.5, "ff1"),  // sway
      event(5.0, "go"),      step(5.0, 5.5, "ff1"), step(5.5, 6.0, "ff1")};
  auto run = [&](bool ignore, RowOrder order, double* ignored) {
    std::vector<MissionRow> seen;
    StepFrontEndOptions options;
    options.ignore_steps_in_stops = ignore;
    StepFrontEnd front(info, options, order, Feed::kTimeOrdered, std::make_unique<Recorder>(&seen));
    NullSink sink;
    for (const MissionRow& r : rows) front.Add(r, sink);
    front.Finish(sink);
    const EstimatorSummary summary = front.Summary();
    const auto it = summary.numbers.find("steps_in_declared_stops");
    *ignored = it == summary.numbers.end() ? -1.0 : it->second;
    std::vector<TimeS> ends;  // the steps the inner estimator got, by end time
    for (const MissionRow& r : seen) {
      if (const auto* s = std::get_if<Step>(&r)) ends.push_back(s->t1);
    }
    return ends;
  };
  double ignored = 0;
  EXPECT_EQ(run(true, RowOrder::kGlobal, &ignored), (std::vector<TimeS>{0.5, 0.9, 1.5, 5.5, 6.0}));
  EXPECT_EQ(ignored, 2.0);
  EXPECT_EQ(run(false, RowOrder::kGlobal, &ignored).size(), 7u);
  EXPECT_EQ(run(true, RowOrder::kPerAgent, &ignored).size(), 7u);
}

/// Sums each agent's steps turned and stretched by a fixed M from its start, an estimate at
/// each step's end (cov 0.01 I); says M as its StepTransform.
class TurnedStepSum : public OnlineEstimator {
 public:
  explicit TurnedStepSum(const Mat2& m) : m_(m) {}
  void Add(const MissionRow& row, EstimateSink& sink) override {
    const auto* s = std::get_if<Step>(&row);
    if (s == nullptr) return;
    Vec2& p = position_.try_emplace(s->agent, Vec2::Zero()).first->second;
    p += m_ * s->delta_n.head<2>();
    sink.Add({s->t1, s->agent, Vec3(p.x(), p.y(), 0), 0.01, 0, 0.01});
  }
  void Finish(EstimateSink&) override {}
  std::optional<Estimate> Current(const std::string&) const override { return std::nullopt; }
  EstimatorSummary Summary() const override { return {}; }
  std::optional<Mat2> StepTransform(const std::string&) const override { return m_; }

 private:
  Mat2 m_;
  std::map<std::string, Vec2> position_;
};

// Between rows the walker walks on: the view is the last estimate moved on at the last step's
// velocity as the estimator turns and stretches it — at most a step ahead, back where the step
// ended 1.5 steps' durations after it or from a declared stop — its sigma 0.5 x speed x the time
// ahead; every 0.1 s, from the rows before it only (each agent's own order gives the same rows).
TEST(StepFrontEnd, TheViewBetweenRowsMovesTheLastEstimateOnAtTheTurnedStepVelocity) {
  MissionInfo info;
  info.nodes.push_back(NodeInfo::Agent("ff1", Vec3::Zero(), 0.1));
  info.nodes.push_back(NodeInfo::Agent("ff2", Vec3::Zero(), 0.1));
  const Mat2 m = 1.1 * Eigen::Rotation2Dd(0.5).toRotationMatrix();
  std::vector<MissionRow> rows;
  auto step = [](TimeS t0, TimeS t1, const char* agent) {
    return MissionRow(Step{t0, t1, agent, Vec3(0.6, 0, 0), std::nullopt});
  };
  rows.push_back(step(0.0, 0.5, "ff1"));
  rows.push_back(step(0.5, 1.0, "ff1"));
  rows.push_back(step(3.0, 3.5, "ff1"));
  rows.push_back(step(3.5, 4.0, "ff1"));
  rows.push_back(MissionEvent{4.0, "ff1", "stop", ""});
  rows.push_back(MissionEvent{5.0, "ff1", "go", ""});
  rows.push_back(step(5.0, 5.5, "ff1"));
  for (int k = 1; k < 120; ++k) rows.push_back(RssiPacket{0.05 * k, "ff2", "ff1", -60});
  std::stable_sort(rows.begin(), rows.end(), [](const MissionRow& a, const MissionRow& b) {
    return RowTime(a) != RowTime(b) ? RowTime(a) < RowTime(b) : a.index() < b.index();
  });
  auto run = [&](RowOrder order, double period) {
    StepFrontEndOptions options;
    options.view_period_s = period;
    StepFrontEnd front(info, options, order, Feed::kTimeOrdered,
                       std::make_unique<TurnedStepSum>(m));
    VectorSink sink;
    for (const MissionRow& r : rows) front.Add(r, sink);
    front.Finish(sink);
    return sink.rows;
  };
  const std::vector<Estimate> global = run(RowOrder::kGlobal, 0.1);
  const Vec2 v = m * Vec2(0.6 / 0.5, 0);  // the turned velocity, 1.32 m/s
  // The expected view at t after the step that ended at t1, from the estimate p there.
  auto expected = [&](TimeS t, TimeS t1, const Vec2& p, bool stopped) {
    const double ahead = t - t1;
    const double a = stopped || ahead > 0.75 ? 0.0 : std::min(ahead, 0.5);
    return std::make_pair(Vec2(p + v * a), 0.01 + std::pow(0.5 * v.norm() * a, 2));
  };
  const Vec2 p1 = m * Vec2(1.2, 0), p2 = m * Vec2(2.4, 0);
  std::size_t views = 0;
  TimeS last = -1;
  for (const Estimate& e : global) {
    ASSERT_EQ(e.id, "ff1");
    EXPECT_GE(e.t, last);
    last = e.t;
    const bool at_step = std::abs(e.t - std::round(e.t * 2) / 2) < 1e-9 &&
                         (e.t == 0.5 || e.t == 1.0 || e.t == 3.5 || e.t == 4.0 || e.t == 5.5);
    if (at_step) continue;
    ++views;
    std::pair<Vec2, double> want;
    if (e.t > 1.0 && e.t < 3.5) {
      want = expected(e.t, 1.0, p1, false);
    } else if (e.t > 3.5 && e.t < 4.0) {
      want = expected(e.t, 3.5, Vec2(m * Vec2(1.8, 0)), false);
    } else if (e.t > 4.0 && e.t < 5.5) {
      want = expected(e.t, 4.0, p2, true);  // the stop declared at the step's end
    } else if (e.t > 5.5) {
      want = expected(e.t, 5.5, Vec2(m * Vec2(3.0, 0)), false);  // walking again: the stop is over
    } else {
      ASSERT_GT(e.t, 0.5);
      ASSERT_LT(e.t, 1.0);
      want = expected(e.t, 0.5, m * Vec2(0.6, 0), false);
    }
    EXPECT_NEAR((e.position_n.head<2>() - want.first).norm(), 0.0, 1e-12) << e.t;
    EXPECT_NEAR(e.sxx, want.second, 1e-12) << e.t;
    EXPECT_NEAR(e.syy, want.second, 1e-12) << e.t;
  }
  // 0.6..0.9, 1.1..3.4, 3.6..3.9, 4.1..5.4, and 5.6..5.9 before the last row at 5.95
  EXPECT_EQ(views, 4u + 24u + 4u + 14u + 4u);
  // Each agent's own order: the views come before its next step only, the same rows up to the
  // declared stop (which only global order can read: a device's events may run ahead of its
  // steps).
  const std::vector<Estimate> own = run(RowOrder::kPerAgent, 0.1);
  ASSERT_GE(own.size(), 36u);
  for (std::size_t i = 0; i < own.size() && global[i].t <= 4.0; ++i) {
    EXPECT_EQ(own[i].t, global[i].t) << i;
    EXPECT_EQ(own[i].position_n, global[i].position_n) << i;
  }
  // Off: the estimator's own estimates only.
  EXPECT_EQ(run(RowOrder::kGlobal, 0.0).size(), 5u);
}

// A foot INS ends a step at each landing and half way through each swing: 0.8 s and 0.2 s
// for half a stride each. The view moves on at the walk's speed over the last half second of
// steps (the stride), not at the last one's (the swinging foot's, 4x the walker's), for up to
// the longer step's duration.
TEST(StepFrontEnd, TheViewMovesOnAtTheStridesSpeedNotTheSwingingFoots) {
  MissionInfo info;
  info.nodes.push_back(NodeInfo::Agent("ff1", Vec3::Zero(), 0.1));
  std::vector<MissionRow> rows;
  TimeS t = 0;
  for (int k = 0; k < 6; ++k) {
    const double d = k % 2 == 0 ? 0.8 : 0.2;
    rows.push_back(Step{t, t + d, "ff1", Vec3(0.7, 0, 0), std::nullopt});
    t += d;
  }
  for (int k = 1; k < 80; ++k) rows.push_back(RssiPacket{0.05 * k, "ff1", "x", -60});
  std::stable_sort(rows.begin(), rows.end(), [](const MissionRow& a, const MissionRow& b) {
    return RowTime(a) != RowTime(b) ? RowTime(a) < RowTime(b) : a.index() < b.index();
  });
  StepFrontEnd front(info, {}, RowOrder::kGlobal, Feed::kTimeOrdered,
                     std::make_unique<TurnedStepSum>(Mat2::Identity()));
  VectorSink sink;
  for (const MissionRow& r : rows) front.Add(r, sink);
  front.Finish(sink);
  // After the last step (ends at 3.0 s at x = 4.2 m): 1.4 m a second for up to 0.8 s.
  int checked = 0;
  for (const Estimate& e : sink.rows) {
    if (e.t <= 3.0 + 1e-9) continue;
    EXPECT_NEAR(e.position_n.x(), 4.2 + 1.4 * std::min(e.t - 3.0, 0.8), 1e-9) << e.t;
    ++checked;
  }
  EXPECT_EQ(checked, 9);  // 3.1 .. 3.9, before the last row at 3.95
  // Between the landing step and the next: after the short step (0.2 s) the walker is not
  // taken for stopped at 0.3 s.
  for (const Estimate& e : sink.rows) {
    if (e.t > 1.0 + 1e-9 && e.t < 1.8 - 1e-9) {
      EXPECT_NEAR(e.position_n.x(), 1.4 + 1.4 * (e.t - 1.0), 1e-9) << e.t;
    }
  }
}

// A stop whose go never comes (a lost event) explains away a sway, not a walk: after
// kMaxStepsInStop steps the agent is walking again, and a note says so.
TEST(StepFrontEnd, AStopWithoutGoEndsWhenTheStepsAreMoreThanASway) {
  MissionInfo info;
  info.nodes.push_back(NodeInfo::Agent("ff1", Vec3::Zero(), 0.1));
  std::vector<MissionRow> seen;
  StepFrontEnd front(info, {}, RowOrder::kGlobal, Feed::kTimeOrdered,
                     std::make_unique<Recorder>(&seen));
  NullSink sink;
  front.Add(MissionEvent{1.0, "ff1", "stop", ""}, sink);
  const int n = StepFrontEndOptions::kMaxStepsInStop + 3;
  for (int k = 0; k < n; ++k) {
    front.Add(Step{1.0 + 0.5 * k, 1.5 + 0.5 * k, "ff1", Vec3(0.6, 0, 0), std::nullopt}, sink);
  }
  front.Finish(sink);
  EXPECT_EQ(seen.size(), 4u);  // the stop event and the last 3 steps
  const EstimatorSummary summary = front.Summary();
  EXPECT_EQ(summary.numbers.at("steps_in_declared_stops"),
            static_cast<double>(StepFrontEndOptions::kMaxStepsInStop));
  EXPECT_TRUE(std::any_of(summary.notes.begin(), summary.notes.end(), [](const std::string& n) {
    return n.find("without a go") != std::string::npos;
  }));
}

// A foot INS measures its displacement: its steps are kept in a declared stop.
// The foot is not the walker: every estimate of an agent on foot-INS steps carries the foot's
// offset from the body, along (sigma 0.35 m) the last step's direction and across it (0.1 m);
// an agent on steps.csv keeps its estimator's covariance. Exact, with the view off.
TEST(StepFrontEnd, AnAgentOnFootInsStepsCarriesTheFootsOffsetFromTheWalker) {
  const TwoWalkers w = MakeTwoWalkers();
  StepFrontEndOptions o;
  o.view_period_s = 0;
  const double along = o.foot_offset_along_sigma_m, across = o.foot_offset_across_sigma_m;
  ASSERT_GT(along, across);
  StepFrontEnd front(w.sim.data.info, o, RowOrder::kGlobal, Feed::kTimeOrdered,
                     std::make_unique<TurnedStepSum>(Mat2::Identity()));
  VectorSink sink;
  for (const MissionRow& r : w.merged) front.Add(r, sink);
  front.Finish(sink);
  std::map<std::string, Vec2> last;
  std::size_t checked = 0;
  for (const Estimate& e : sink.rows) {
    const Vec2 p = e.position_n.head<2>();
    const auto it = last.find(e.id);
    const Vec2 step = it == last.end() ? p : Vec2(p - it->second);  // TurnedStepSum starts at 0
    last[e.id] = p;
    if (step.norm() < 0.05) continue;  // the direction is an earlier step's
    Mat2 added;
    added << e.sxx - 0.01, e.sxy, e.sxy, e.syy - 0.01;
    const Vec2 u = step.normalized();
    const Mat2 want = along * along * u * u.transpose() +
                      across * across * (Mat2::Identity() - u * u.transpose());
    ASSERT_NEAR((added - want).norm(), 0.0, 1e-9) << e.id << " at " << e.t;
    ++checked;
  }
  EXPECT_GT(checked, 40u);
  // The same walks as steps.csv rows: no foot, no offset.
  StepFrontEnd phone(w.sim.data.info, o, RowOrder::kGlobal, Feed::kTimeOrdered,
                     std::make_unique<TurnedStepSum>(Mat2::Identity()));
  VectorSink phone_sink;
  for (const MissionRow& r : w.expected) phone.Add(r, phone_sink);
  phone.Finish(phone_sink);
  ASSERT_GT(phone_sink.rows.size(), 40u);
  for (const Estimate& e : phone_sink.rows) {
    ASSERT_EQ(e.sxx, 0.01);
    ASSERT_EQ(e.sxy, 0.0);
    ASSERT_EQ(e.syy, 0.01);
  }
  // Refused: a negative or non-finite sigma.
  o.foot_offset_across_sigma_m = -0.1;
  EXPECT_FALSE(o.IsValid(nullptr));
  o.foot_offset_across_sigma_m = 0.1;
  o.foot_offset_along_sigma_m = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(o.IsValid(nullptr));
}

TEST(StepFrontEnd, AFootInsStepsAreKeptInADeclaredStop) {
  const TwoWalkers w = MakeTwoWalkers();
  std::vector<MissionRow> rows = w.merged;
  const TimeS t_stop = RowTime(rows[rows.size() / 4]), t_go = RowTime(rows[rows.size() / 2]);
  rows.emplace_back(MissionEvent{t_stop, "ff1", "stop", ""});
  rows.emplace_back(MissionEvent{t_go, "ff1", "go", ""});
  std::stable_sort(rows.begin(), rows.end(), [](const MissionRow& a, const MissionRow& b) {
    return RowTime(a) != RowTime(b) ? RowTime(a) < RowTime(b) : a.index() < b.index();
  });
  std::vector<MissionRow> seen;
  StepFrontEnd front(w.sim.data.info, {}, RowOrder::kGlobal, Feed::kTimeOrdered,
                     std::make_unique<Recorder>(&seen));
  NullSink sink;
  for (const MissionRow& r : rows) front.Add(r, sink);
  front.Finish(sink);
  auto steps = [](const std::vector<MissionRow>& v) {
    return std::count_if(v.begin(), v.end(),
                         [](const MissionRow& r) { return std::holds_alternative<Step>(r); });
  };
  const auto in_stop =
      std::count_if(w.expected.begin(), w.expected.end(), [&](const MissionRow& r) {
        const auto* s = std::get_if<Step>(&r);
        return s && s->agent == "ff1" && s->t0 >= t_stop && s->t1 < t_go;
      });
  ASSERT_GT(in_stop, 5);  // the walker does walk in the declared stop
  EXPECT_EQ(steps(seen), steps(w.expected));
  EXPECT_EQ(front.Summary().numbers.at("steps_in_declared_stops"), 0.0);
}

// mission.json states where the responder faced; the device that made the steps may point
// elsewhere (a boot's toe-out, a phone's carrying mode). Exact: the heading's prior variance is
// the stated one plus the track's offset. And what it is for: a straight walk whose steps are
// all turned by 8 deg, stated to 1.1 deg, ends inside the 95 % ellipse only with the offset.
TEST(DeadReckoning, TheTracksOwnHeadingOffsetAddsToTheStatedStartHeading) {
  const double stated = 0.02;
  PdrOptions with;
  ASSERT_GT(with.track_heading_offset_sigma_rad, 0.0);
  PdrOptions without = with;
  without.track_heading_offset_sigma_rad = 0.0;
  DeadReckoning a(Vec3::Zero(), 0.1, with, stated), b(Vec3::Zero(), 0.1, without, stated);
  EXPECT_NEAR(a.error_covariance()(2, 2),
              stated * stated + std::pow(with.track_heading_offset_sigma_rad, 2), 1e-15);
  EXPECT_NEAR(b.error_covariance()(2, 2), stated * stated, 1e-15);
  EXPECT_NEAR(with.StartHeadingSigma(std::nullopt),
              std::hypot(with.start_heading_sigma_rad, with.track_heading_offset_sigma_rad), 1e-15);
  const double offset = 8.0 * M_PI / 180;
  Vec2 truth = Vec2::Zero();
  for (int k = 0; k < 60; ++k) {
    const Vec2 walked(0.7, 0.0);
    truth += walked;
    const Vec2 reported = Eigen::Rotation2Dd(offset) * walked;
    const Step s{k * 0.5, k * 0.5 + 0.5, "ff1", Vec3(reported.x(), reported.y(), 0),
                 Vec3(1e-4, 1e-4, 1e-4)};
    a.AddStep(s);
    b.AddStep(s);
  }
  auto d2 = [&](const DeadReckoning& dr) {
    const Vec2 e = dr.position_n().head<2>() - truth;
    return e.dot(dr.covariance().inverse() * e);
  };
  EXPECT_LT(d2(a), 5.991);  // chi-square, 2 dof, 95 %
  EXPECT_GT(d2(b), 5.991);
}

// The offset as a consider parameter (PdrOptions::track_heading_offset_considered). Without a
// fix it is the state form to rounding (linear propagation); a fix is weighed as if there were
// no offset (estimate and own covariance those of a dead reckoning without it, to the bit), and
// the reported covariance keeps what the fix leaves of the offset: (I - K) s with K the fix's
// gain (the intersection's, from its omega; SetPosition's, given) and s s^T sigma^2 the state
// form's excess before the fix.
TEST(DeadReckoning, AConsideredHeadingOffsetIsReportedButNotWeighed) {
  const double stated = 0.02;
  PdrOptions state;
  PdrOptions considered = state;
  considered.track_heading_offset_considered = true;
  PdrOptions none = state;
  none.track_heading_offset_sigma_rad = 0.0;
  DeadReckoning a(Vec3(1, 2, 0), 0.1, state, stated), c(Vec3(1, 2, 0), 0.1, considered, stated),
      n(Vec3(1, 2, 0), 0.1, none, stated);
  auto walk = [&](int from, int to) {
    for (int k = from; k < to; ++k) {
      const double heading = 0.4 * std::sin(0.2 * k) + (k > 25 ? 1.2 : 0.0);
      const Step s{k * 0.6, k * 0.6 + 0.5, "ff1",
                   Vec3(0.7 * std::cos(heading), 0.7 * std::sin(heading), 0)};
      a.AddStep(s);
      c.AddStep(s);
      n.AddStep(s);
    }
  };
  walk(0, 40);
  EXPECT_EQ(c.position_n(), n.position_n());
  EXPECT_LT((c.covariance() - a.covariance()).norm(), 1e-12 * a.covariance().norm());
  EXPECT_LT((c.own_covariance() - n.covariance()).norm(), 1e-15 * n.covariance().norm());
  EXPECT_GT((a.covariance() - n.covariance()).trace(), 0.05);  // the offset matters here
  // A covariance-intersection fix.
  const Mat2 excess = a.covariance() - n.covariance();  // sigma^2 s s^T
  const Mat2 P = n.covariance();
  const Mat2 R = Mat2::Identity() * 0.09;
  const Vec2 fix(20.0, 9.0);
  const double omega = c.FusePosition(fix, R);
  ASSERT_EQ(n.FusePosition(fix, R), omega);
  ASSERT_LT(omega, 1.0);
  EXPECT_EQ(c.position_n(), n.position_n());
  EXPECT_EQ(c.own_covariance(), n.covariance());
  const Mat2 K = (P / omega) * (P / omega + R / (1 - omega)).inverse();
  const Mat2 kept = Mat2::Identity() - K;
  EXPECT_LT((c.covariance() - n.covariance() - kept * excess * kept.transpose()).norm(),
            1e-12 * excess.norm());
  // Steps on: the offset's share grows again; a fix taken whole with a given kept share.
  walk(40, 60);
  EXPECT_EQ(c.position_n(), n.position_n());
  const Mat2 excess2 = c.covariance() - c.own_covariance();
  EXPECT_GT(excess2.trace(), (kept * excess * kept.transpose()).trace());
  const Mat2 half = Mat2::Identity() * 0.5;
  c.SetPosition(Vec2(3, 4), R, half);
  n.SetPosition(Vec2(3, 4), R);
  EXPECT_EQ(c.own_covariance(), n.covariance());
  EXPECT_LT((c.covariance() - R - 0.25 * excess2).norm(), 1e-12 * excess2.norm());
  c.SetPosition(Vec2(3, 4), R);  // independent of the walk: none is kept
  EXPECT_EQ(c.covariance(), R);
  EXPECT_THROW(c.SetPosition(Vec2(3, 4), R, Mat2::Constant(NAN)), std::invalid_argument);
}

TEST(DeadReckoningEstimator, IsDeadReckoningPerAgent) {
  MissionInfo info;
  info.nodes.push_back(NodeInfo::Agent("ff1", Vec3(1, 1, 0), 0.2));
  info.nodes.push_back(NodeInfo::Agent("ff2", Vec3(5, 0, 0), 0.0));
  DeadReckoningEstimator est(info);
  VectorSink sink;
  est.Add(Step{0, 1, "ff1", Vec3(0.5, 0, 0), Vec3(0.01, 0.01, 0)}, sink);
  est.Add(Step{0, 1.5, "ff2", Vec3(0, 0.5, 0), Vec3(0.01, 0.01, 0)}, sink);
  est.Add(RssiPacket{1.6, "ff1", "ff2", -60}, sink);
  ASSERT_EQ(sink.rows.size(), 4u);  // each start, each step
  EXPECT_EQ(sink.rows[1].position_n, Vec3(1.5, 1, 0));
  // Start + step noise, plus the shared errors of the first step: its length x the scale sigma
  // along it, x the start heading sigma across it.
  const PdrOptions o;
  EXPECT_NEAR(sink.rows[1].sxx, 0.04 + 0.01 + std::pow(0.5 * o.step_scale_sigma, 2), 1e-15);
  // Across it: the heading's sigma at the start, the default one (no start_heading_sigma
  // stated) and the track's own offset in quadrature.
  const double heading_var =
      std::pow(o.start_heading_sigma_rad, 2) + std::pow(o.track_heading_offset_sigma_rad, 2);
  EXPECT_NEAR(sink.rows[1].syy, 0.04 + 0.01 + 0.25 * heading_var, 1e-15);
  EXPECT_EQ(est.Current("ff2")->position_n, Vec3(5, 0.5, 0));
  EXPECT_EQ(est.Current("ff2")->t, 1.5);
  EXPECT_EQ(est.Summary().numbers.at("rows_ignored"), 1.0);
}

TEST(DeadReckoningEstimator, AFootInsAgentMovesWithTheInsOwnErrors) {
  // Told that ff1's steps come from a foot INS (the step front end does, before its first
  // step), the estimator's dead reckoning of ff1 is exactly that of PdrOptions::ForFootIns,
  // each step's own yaw variance as its heading walk; ff2 (a phone) keeps the PDR's errors.
  MissionInfo info;
  info.nodes.push_back(NodeInfo::Agent("ff1", Vec3(0, 0, 0), 0.1, 0.0));  // a stated heading
  info.nodes.push_back(NodeInfo::Agent("ff2", Vec3(0, 0, 0), 0.1, 0.0));
  const PdrOptions o;
  DeadReckoningEstimator est(info, o);
  est.StepsFromFootIns("ff1", true);
  est.StepsFromFootIns("ff2", false);
  DeadReckoning foot(Vec3::Zero(), 0.1, o.ForFootIns()), phone(Vec3::Zero(), 0.1, o);
  VectorSink sink;
  for (int k = 0; k < 40; ++k) {
    const Vec2 d = Eigen::Rotation2Dd(k / 10 * M_PI / 2) * Vec2(0.7, 0.0);  // a square
    Step s{0.6 * k,       0.6 * (k + 1), "ff1", Vec3(d.x(), d.y(), 0), Vec3(1e-4, 1e-4, 1e-4),
           1e-6 * (k % 3)};
    est.Add(s, sink);
    foot.AddStep(s);
    s.agent = "ff2";
    est.Add(s, sink);
    phone.AddStep(s);
  }
  const Estimate a = *est.Current("ff1"), b = *est.Current("ff2");
  EXPECT_NEAR(a.sxx, foot.covariance()(0, 0), 1e-15);
  EXPECT_NEAR(a.syy, foot.covariance()(1, 1), 1e-15);
  EXPECT_NEAR(b.sxx, phone.covariance()(0, 0), 1e-15);
  EXPECT_LT(a.sxx + a.syy, 0.5 * (b.sxx + b.syy));  // the INS's errors are the smaller ones
  // A foot INS outside its noise model (its first step carries no heading variance:
  // ZuptIns::OwnErrorsHold) keeps the PDR's errors.
  DeadReckoningEstimator est_out(info, o);
  est_out.StepsFromFootIns("ff1", true);
  est_out.Add(Step{0, 0.6, "ff1", Vec3(0.7, 0, 0), Vec3(1e-4, 1e-4, 1e-4)}, sink);
  DeadReckoning pdr_out(Vec3::Zero(), 0.1, o);
  pdr_out.AddStep(Step{0, 0.6, "ff1", Vec3(0.7, 0, 0), Vec3(1e-4, 1e-4, 1e-4)});
  EXPECT_NEAR(est_out.Current("ff1")->syy, pdr_out.covariance()(1, 1), 1e-15);
  // Off: the foot INS's steps with the PDR's errors.
  PdrOptions off = o;
  off.foot_ins.own_errors = false;
  DeadReckoningEstimator est_off(info, off);
  est_off.StepsFromFootIns("ff1", true);
  est_off.Add(Step{0, 0.6, "ff1", Vec3(0.7, 0, 0), Vec3(1e-4, 1e-4, 1e-4), 1e-6}, sink);
  DeadReckoning pdr(Vec3::Zero(), 0.1, o);
  pdr.AddStep(Step{0, 0.6, "ff1", Vec3(0.7, 0, 0), Vec3(1e-4, 1e-4, 1e-4)});
  EXPECT_NEAR(est_off.Current("ff1")->syy, pdr.covariance()(1, 1), 1e-15);
}

TEST(DeadReckoning, AnUnknownHeadingsCovarianceIsTheUniformTurnsSecondMomentAndCoversTheCircle) {
  // Against the second moment of R(theta) d - d over theta uniform on the circle, by quadrature,
  // and every point of the circle the truth may be on inside the 95 % ellipse.
  const Vec2 d(3.0, -1.5);
  const Mat2 c = UnknownHeadingCovariance(d);
  Mat2 m = Mat2::Zero();
  const int n = 3600;
  for (int k = 0; k < n; ++k) {
    const Vec2 e = Eigen::Rotation2Dd(2 * M_PI * k / n) * d - d;
    m += e * e.transpose() / n;
  }
  EXPECT_LT((c - m).cwiseAbs().maxCoeff(), 1e-9);
  for (int k = 0; k < 360; ++k) {
    const Vec2 e = Eigen::Rotation2Dd(2 * M_PI * k / 360) * d - d;
    EXPECT_LE(e.dot(c.inverse() * e), 3.0 + 1e-9);  // < 5.99, the 95 % quantile
  }
}

TEST(DeadReckoningEstimator, AFootInsWithoutAStatedHeadingCarriesTheUnknownTurn) {
  // ff1 has a start but no start_heading: its foot INS's steps are in the INS's own frame. The
  // estimate is the sum of the steps; its covariance the dead reckoning's without any heading
  // error at the start plus the unknown turn's. A phone's steps (in the navigation frame by the
  // spec) keep the default heading sigma.
  MissionInfo info;
  info.nodes.push_back(NodeInfo::Agent("ff1", Vec3(1, 0, 0), 0.1));
  info.nodes.back().start_heading_rad.reset();
  info.nodes.back().start_heading_sigma_rad.reset();
  const PdrOptions o;
  DeadReckoningEstimator est(info, o);
  est.StepsFromFootIns("ff1", true);
  PdrOptions ref_options = o.ForFootIns();
  ref_options.track_heading_offset_sigma_rad = 0;
  DeadReckoning ref(Vec3(1, 0, 0), 0.1, ref_options, 0.0);
  VectorSink sink;
  for (int k = 0; k < 10; ++k) {
    const Step s{0.5 * k, 0.5 * (k + 1), "ff1", Vec3(0.6, 0.1, 0), Vec3(1e-4, 1e-4, 1e-4), 1e-6};
    est.Add(s, sink);
    ref.AddStep(s);
  }
  const Estimate e = *est.Current("ff1");
  EXPECT_EQ(e.position_n, ref.position_n());
  const Mat2 expected = ref.covariance() + UnknownHeadingCovariance(Vec2(6.0, 1.0));
  EXPECT_NEAR(e.sxx, expected(0, 0), 1e-9);
  EXPECT_NEAR(e.sxy, expected(0, 1), 1e-9);
  EXPECT_NEAR(e.syy, expected(1, 1), 1e-9);
  bool noted = false;
  for (const auto& note : est.Summary().notes)
    noted |= note.find("without a start_heading") != std::string::npos;
  EXPECT_TRUE(noted);
}

TEST(DeadReckoning, AStepsOwnHeadingVarianceIsItsHeadingWalkWhereLarger) {
  PdrOptions o;
  Step s{0, 0.5, "a", Vec3(0.6, 0, 0), Vec3(1e-4, 1e-4, 1e-4)};
  const double walk = o.heading_walk_sigma_rad * o.heading_walk_sigma_rad;
  EXPECT_EQ(o.HeadingWalkVariance(s), walk);
  s.heading_var_rad2 = 0.1 * walk;
  EXPECT_EQ(o.HeadingWalkVariance(s), walk);
  s.heading_var_rad2 = 10 * walk;
  EXPECT_EQ(o.HeadingWalkVariance(s), 10 * walk);
  s.delta_n.setZero();  // standing: no walk of the PDR's, the source's own growth still counts
  EXPECT_EQ(o.HeadingWalkVariance(s), 10 * walk);
  s.heading_var_rad2.reset();
  EXPECT_EQ(o.HeadingWalkVariance(s), 0.0);
  // The foot INS's options: its sigmas, no walk of its own; overbounding scales them too.
  const PdrOptions f = o.ForFootIns();
  EXPECT_EQ(f.heading_walk_sigma_rad, 0.0);
  EXPECT_EQ(f.heading_drift_sigma_rad_per_s, o.foot_ins.heading_drift_sigma_rad_per_s);
  EXPECT_EQ(f.step_scale_sigma, o.foot_ins.step_scale_sigma);
  EXPECT_EQ(f.turn_scale_sigma, o.foot_ins.turn_scale_sigma);
  EXPECT_EQ(f.start_heading_sigma_rad, o.start_heading_sigma_rad);
  EXPECT_EQ(f.track_heading_offset_sigma_rad, o.track_heading_offset_sigma_rad);
  EXPECT_DOUBLE_EQ(o.SharedErrorsScaled(3).ForFootIns().turn_scale_sigma, 3 * f.turn_scale_sigma);
  PdrOptions bad = o;
  bad.foot_ins.step_scale_sigma = -1;
  EXPECT_FALSE(bad.IsValid(nullptr));
}

}  // namespace
}  // namespace trailmark

// SPDX-License-Identifier: MIT
// The IMU's mounting about the vertical from a foot INS's strides (ins/mount_yaw.h): exact on
// synthetic landings, turns and side steps left out, undecided when the strides disagree; and
// end to end (MultiAgentIns): the same simulated walk with the IMU mounted another way gives the
// same steps and positions, a foot-aligned IMU exactly what it gave before.
#include "trailmark/ins/mount_yaw.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "test_util.h"
#include "trailmark/core/random.h"
#include "trailmark/ins/ins_estimator.h"
#include "trailmark/io/convert_foot_imu.h"
#include "trailmark/sim/imu_sim.h"
#include "trailmark/sim/scenarios.h"

namespace trailmark::ins {
namespace {

constexpr double kDeg = std::numbers::pi / 180;

/// Landings of a foot walking straight along `walk_rad` and then along `turn_to_rad`, its IMU's
/// reference (the body vector along the stated heading at the start) turned `mount_rad` from
/// where the foot points: the attitude at each landing is the foot's heading plus the mount.
struct Landing {
  Vec3 position_n;
  Eigen::Quaterniond q_nb;
};
std::vector<Landing> Walk(double stated_rad, double mount_rad,
                          const std::vector<double>& headings) {
  std::vector<Landing> out;
  Vec3 p = Vec3::Zero();
  for (double h : headings) {
    p += 1.2 * Vec3(std::cos(h), std::sin(h), 0);
    // At the start the INS put the IMU's reference along the stated heading; the foot's heading
    // is h, so the IMU's yaw (as the INS sees it, turned by the mount) is stated + (h - h0) - 0
    // with the INS frame turned by -mount: the stride in the INS frame is along h - mount.
    out.push_back(
        {Vec3(std::cos(-mount_rad) * p.x() - std::sin(-mount_rad) * p.y(),
              std::sin(-mount_rad) * p.x() + std::cos(-mount_rad) * p.y(), 0),
         Eigen::Quaterniond(Eigen::AngleAxisd(stated_rad + h - headings.front(), Vec3::UnitZ()))});
  }
  return out;
}

TEST(MountYaw, TheStridesAngleFromTheReferenceIsTheTurnThatBringsTheWalkOntoTheStatedHeading) {
  for (double mount_deg : {0.0, 7.0, -90.0, 135.0, 180.0}) {
    const double stated = 0.4, mount = mount_deg * kDeg;
    MountYawEstimator m({}, stated);
    m.Start(Eigen::Quaterniond(Eigen::AngleAxisd(stated, Vec3::UnitZ())));
    // The walker walks along the stated heading; the INS's frame is turned by -mount.
    // (A straight stride counts once the next chord is seen straight too: five landings.)
    for (const Landing& l : Walk(stated, mount, {stated, stated, stated, stated, stated})) {
      m.AddLanding(l.position_n, l.q_nb);
    }
    ASSERT_TRUE(m.Decided()) << mount_deg;
    EXPECT_NEAR(WrapAngle(m.CorrectionRad() - mount), 0.0, 1e-9) << mount_deg;
    EXPECT_LT(m.SigmaRad(), 1e-9);
    EXPECT_EQ(m.TurnWorthTakingRad(), std::abs(mount_deg) < 1 ? 0.0 : m.CorrectionRad());
  }
}

TEST(MountYaw, TurningStridesAreLeftOut) {
  const double stated = 0.0, mount = 30 * kDeg;
  MountYawEstimator m({}, stated);
  m.Start(Eigen::Quaterniond::Identity());
  // A turn of 60 deg over one stride (the chord of a turn: not counted), then straight strides.
  const auto landings =
      Walk(stated, mount, {0.0, 0.0, 60 * kDeg, 60 * kDeg, 60 * kDeg, 60 * kDeg, 60 * kDeg});
  for (const Landing& l : landings) m.AddLanding(l.position_n, l.q_nb);
  ASSERT_TRUE(m.Decided());
  EXPECT_NEAR(m.CorrectionRad(), mount, 1e-9);
  // Decided at the third straight stride after the turn: the turning one not counted, nor the
  // one before it (its next chord turned).
  EXPECT_EQ(m.Strides(), 3u);
  EXPECT_EQ(m.Landings(), 7);
}

TEST(MountYaw, StridesThatDisagreeDecideNothingAndSaySo) {
  MountYawOptions o;
  o.max_landings = 8;
  MountYawEstimator m(o, 0.0);
  m.Start(Eigen::Quaterniond::Identity());
  // Strides 50 deg apart each way with the foot facing the same way (side steps, crawling).
  Vec3 p = Vec3::Zero();
  for (int k = 0; k < 8; ++k) {
    const double a = (k % 2 == 0 ? 50.0 : -50.0) * kDeg;
    p += Vec3(std::cos(a), std::sin(a), 0);
    m.AddLanding(p, Eigen::Quaterniond::Identity());
  }
  ASSERT_TRUE(m.Decided());
  EXPECT_EQ(m.CorrectionRad(), 0.0);
  EXPECT_NE(m.Note().find("not found"), std::string::npos);
  MountYawOptions bad;
  bad.max_spread_rad = -1;
  std::string why;
  EXPECT_FALSE(bad.IsValid(&why));
  EXPECT_NE(why.find("mount_yaw_max_spread"), std::string::npos);
}

/// Landings of a foot whose heading at the k-th landing is `foot[k]` (foot[0] the stated heading,
/// the INS's start), its IMU's reference turned `mount_rad` from the foot. The stride to landing
/// k points along the foot's landing heading (`chord_along_mean` false: a foot that turns as it
/// lifts, as the simulator's walker) or along the mean of its lift-off and landing headings
/// (true: the chord of a circular arc).
std::vector<Landing> TurningWalk(double mount_rad, const std::vector<double>& foot,
                                 bool chord_along_mean) {
  std::vector<Landing> out;
  Vec2 p = Vec2::Zero();
  for (std::size_t k = 0; k < foot.size(); ++k) {
    const double along = chord_along_mean && k > 0 ? 0.5 * (foot[k - 1] + foot[k]) : foot[k];
    p += 1.2 * Vec2(std::cos(along), std::sin(along));
    const Vec2 p_ins = Eigen::Rotation2Dd(-mount_rad) * p;
    out.push_back({Vec3(p_ins.x(), p_ins.y(), 0),
                   Eigen::Quaterniond(Eigen::AngleAxisd(foot[k], Vec3::UnitZ()))});
  }
  return out;
}

/// A search's foot headings: a turn at every stride, both ways, 20-50 deg (none straight).
std::vector<double> SearchHeadings(double stated_rad, int landings) {
  const double turns_deg[] = {35, -50, 20, -30, 45, -25, 30, -40, 25, -35, 50, -20};
  std::vector<double> h = {stated_rad};
  for (int k = 1; k < landings; ++k) h.push_back(h.back() + turns_deg[(k - 1) % 12] * kDeg);
  return h;
}

/// The turning strides' bounds (session 44; off by default since the gait's regression) alone.
MountYawOptions BoundsOnly() {
  MountYawOptions o;
  o.interval_max_turn_rad = 1.5708;
  o.gait_min_strides = 0;
  return o;
}

/// Landings of a walk along `chords` (the first the stated heading: the foot rests along it)
/// whose foot lands turned toward its next stride by `a` of the turn to it (0: a pivot, the
/// stride along the landing heading), its IMU's reference turned `mount_rad` from the foot.
std::vector<Landing> AnticipatingWalk(double mount_rad, const std::vector<double>& chords,
                                      double a) {
  std::vector<Landing> out;
  Vec2 p = Vec2::Zero();
  for (std::size_t k = 0; k < chords.size(); ++k) {
    p += 1.2 * Vec2(std::cos(chords[k]), std::sin(chords[k]));
    const double next = k + 1 < chords.size() ? chords[k + 1] : chords[k];
    const double foot = chords[k] + a * WrapAngle(next - chords[k]);
    const Vec2 p_ins = Eigen::Rotation2Dd(-mount_rad) * p;
    out.push_back({Vec3(p_ins.x(), p_ins.y(), 0),
                   Eigen::Quaterniond(Eigen::AngleAxisd(foot, Vec3::UnitZ()))});
  }
  return out;
}

TEST(MountYaw, TheGaitsRegressionFindsTheMountingWhateverTheGait) {
  // A search that turns at every stride, both ways, 20-50 deg (no straight stride): a foot that
  // pivots (lands along its stride), one that lands a quarter and one that lands half way
  // turned toward its next stride, and an arc's chord (along the mean of the foot's headings).
  // The turning strides' bounds put the anticipating ones 8-12 deg off on simulated searches;
  // the regression alpha = mu - a dnext - b tau fits each, within 9 landings.
  for (const double mount_deg : {25.0, -18.0, 150.0}) {
    const double mount = mount_deg * kDeg;
    const auto decide = [&](const std::vector<Landing>& walk) {
      MountYawEstimator m({}, 0.0);
      m.Start(Eigen::Quaterniond::Identity());
      for (const Landing& l : walk) {
        m.AddLanding(l.position_n, l.q_nb);
        if (m.Decided()) break;
      }
      return m;
    };
    for (const double a : {0.0, 0.25, 0.5}) {
      const MountYawEstimator m = decide(AnticipatingWalk(mount, SearchHeadings(0.0, 30), a));
      ASSERT_TRUE(m.Decided()) << mount_deg << " " << a;
      EXPECT_TRUE(m.DecidedByGait());
      EXPECT_LE(m.Landings(), 9);  // six strides (not the first, from standing), each with its next
      EXPECT_NEAR(WrapAngle(m.CorrectionRad() - mount), 0.0, 0.2 * kDeg) << mount_deg << " " << a;
      EXPECT_NEAR(m.GaitShares().first, a, 0.02);
      // The bounds alone on the same walk: right for the pivot, off for the others.
      MountYawEstimator bounds(BoundsOnly(), 0.0);
      bounds.Start(Eigen::Quaterniond::Identity());
      for (const Landing& l : AnticipatingWalk(mount, SearchHeadings(0.0, 30), a)) {
        bounds.AddLanding(l.position_n, l.q_nb);
        if (bounds.Decided()) break;
      }
      if (a > 0 && bounds.Decided()) {
        EXPECT_GT(std::abs(WrapAngle(bounds.CorrectionRad() - mount)), 1 * kDeg) << a;
      }
    }
    const MountYawEstimator arc = decide(TurningWalk(mount, SearchHeadings(0.0, 30), true));
    ASSERT_TRUE(arc.Decided()) << mount_deg;
    EXPECT_TRUE(arc.DecidedByGait());
    EXPECT_NEAR(WrapAngle(arc.CorrectionRad() - mount), 0.0, 0.2 * kDeg) << mount_deg;
    EXPECT_NEAR(arc.GaitShares().second, 0.5, 0.02);
  }
  // A walk circling one way (30 deg a stride): every stride's turns the same, so the mounting
  // and the gait's shares cannot be told apart — not decided by the regression.
  std::vector<double> circle = {0.0};
  for (int k = 1; k < 30; ++k) circle.push_back(circle.back() + 30 * kDeg);
  MountYawOptions gait_only;
  gait_only.strides = 3;
  MountYawEstimator m(gait_only, 0.0);
  m.Start(Eigen::Quaterniond::Identity());
  for (const Landing& l : AnticipatingWalk(40 * kDeg, circle, 0.3)) {
    m.AddLanding(l.position_n, l.q_nb);
    EXPECT_FALSE(m.DecidedByGait());
  }
  MountYawOptions bad;
  bad.gait_max_sigma_rad = 0;
  std::string why;
  EXPECT_FALSE(bad.IsValid(&why));
  EXPECT_NE(why.find("mount_yaw_gait_max_sigma"), std::string::npos);
}

TEST(MountYaw, TurningStridesBoundTheMountingOnASearchWalk) {
  // A foot that turns as it lifts (the stride along its landing heading, the simulator's
  // walker): each stride's angle from the reference at lift-off and at landing bound the
  // mounting, and a walk that turns both ways pins it to the landing end. No stride is
  // straight: the median never decides.
  for (const double mount_deg : {25.0, -18.0, 40.0, 150.0}) {
    const double stated = 0.3, mount = mount_deg * kDeg;
    MountYawEstimator m(BoundsOnly(), stated);
    m.Start(Eigen::Quaterniond(Eigen::AngleAxisd(stated, Vec3::UnitZ())));
    int landings = 0;
    for (const Landing& l : TurningWalk(mount, SearchHeadings(stated, 30), false)) {
      m.AddLanding(l.position_n, l.q_nb);
      ++landings;
      if (m.Decided()) break;
    }
    ASSERT_TRUE(m.Decided()) << mount_deg;
    EXPECT_TRUE(m.DecidedByBounds());
    EXPECT_EQ(m.Strides(), 0u);
    // Four strides after the first landing (the fewest), where house searches took 13-34.
    EXPECT_LE(landings, 6) << mount_deg;
    EXPECT_NEAR(WrapAngle(m.CorrectionRad() - mount), 0.0, 1e-9) << mount_deg;
    EXPECT_EQ(m.TurnWorthTakingRad(), m.CorrectionRad());
    EXPECT_GT(m.SigmaRad(), 0.0);
  }
  // The chord of an arc (along the mean of the two headings): every stride's bounds are
  // centred on the mounting and as wide as its turn (20-50 deg here), so they share no stretch
  // as narrow as a straight stride's bounds and decide nothing — never a wrong turn; such a
  // walk waits for straight strides, as before.
  for (const double mount_deg : {25.0, -40.0}) {
    MountYawEstimator wide(BoundsOnly(), 0.0);
    wide.Start(Eigen::Quaterniond::Identity());
    for (const Landing& l : TurningWalk(mount_deg * kDeg, SearchHeadings(0.0, 30), true))
      wide.AddLanding(l.position_n, l.q_nb);
    EXPECT_FALSE(wide.Decided()) << mount_deg;
  }
}

TEST(MountYaw, BoundsLeaveAMountingAboutTheFootsAndACircleUndecided) {
  // Mounted 3 deg off the foot: zero lies in the shared stretch, so the bounds decide nothing
  // (a toe-out waits for the straight strides' median, as before).
  {
    MountYawEstimator m(BoundsOnly(), 0.0);
    m.Start(Eigen::Quaterniond::Identity());
    for (const Landing& l : TurningWalk(3 * kDeg, SearchHeadings(0.0, 30), false))
      m.AddLanding(l.position_n, l.q_nb);
    EXPECT_FALSE(m.Decided());
  }
  // A walk circling one way (30 deg a stride) with the IMU turned 40 deg: every stride's bounds
  // are the same 40 deg wide stretch, whose centre depends on the gait (the landing heading's
  // end or the middle): not decided by them.
  {
    std::vector<double> circle = {0.0};
    for (int k = 1; k < 30; ++k) circle.push_back(circle.back() + 30 * kDeg);
    MountYawEstimator m(BoundsOnly(), 0.0);
    m.Start(Eigen::Quaterniond::Identity());
    for (const Landing& l : TurningWalk(40 * kDeg, circle, false))
      m.AddLanding(l.position_n, l.q_nb);
    EXPECT_FALSE(m.Decided());
  }
  // Off (interval_max_turn_rad = 0): the search walk of the test above decides nothing.
  MountYawOptions off = BoundsOnly();
  off.interval_max_turn_rad = 0;
  MountYawEstimator m(off, 0.0);
  m.Start(Eigen::Quaterniond::Identity());
  for (const Landing& l : TurningWalk(25 * kDeg, SearchHeadings(0.0, 30), false))
    m.AddLanding(l.position_n, l.q_nb);
  EXPECT_FALSE(m.Decided());
  MountYawOptions bad;
  bad.interval_margin_rad = -0.1;
  std::string why;
  EXPECT_FALSE(bad.IsValid(&why));
  EXPECT_NE(why.find("mount_yaw_interval_margin"), std::string::npos);
}

/// The IMU's samples as read by one mounted turned by R (foot frame -> IMU frame: v_imu = R^T v).
std::vector<ImuSample> Mounted(std::vector<ImuSample> imu, const Eigen::Matrix3d& R) {
  for (auto& s : imu) {
    s.accel_b = R.transpose() * s.accel_b;
    s.gyro_b = R.transpose() * s.gyro_b;
  }
  return imu;
}

struct InsRun {
  std::vector<Step> steps;
  std::vector<InsState> states;
  EstimatorSummary summary;
};
InsRun RunIns(const MissionInfo& info, const std::vector<ImuSample>& imu, InsOptions o = {}) {
  InsRun r;
  MultiAgentIns ins(info, o);
  ins.on_step = [&](const Step& s) { r.steps.push_back(s); };
  ins.on_state = [&](const std::string&, const InsState& s) { r.states.push_back(s); };
  for (const auto& s : imu) ins.Add(s);
  ins.Finish();
  r.summary = ins.Summary();
  return r;
}

/// The largest distance between the two runs' sums of steps so far, from the k-th step on.
double WorstAlongTheWalk(const InsRun& x, const InsRun& y, std::size_t from_step) {
  Vec2 a = Vec2::Zero(), b = Vec2::Zero();
  double worst = 0;
  for (std::size_t k = 0; k < std::min(x.steps.size(), y.steps.size()); ++k) {
    a += x.steps[k].delta_n.head<2>();
    b += y.steps[k].delta_n.head<2>();
    if (k >= from_step) worst = std::max(worst, (a - b).norm());
  }
  return worst;
}

Vec2 SumOfSteps(const InsRun& r) {
  Vec2 sum = Vec2::Zero();
  for (const Step& s : r.steps) sum += s.delta_n.head<2>();
  return sum;
}

/// A simulated scenario's first walker and a 200 Hz foot IMU of its walk.
struct SimulatedFootImu {
  SimulatedMission sim;
  std::string id;
  std::vector<ImuSample> imu;
};
SimulatedFootImu FootImuOf(const std::string& scenario, std::uint64_t seed,
                           std::uint64_t imu_seed) {
  SimulatedFootImu out{SimulateScenario(scenario, seed), {}, {}};
  const auto& [id, walk] = out.sim.walks.front();
  ImuSimOptions io;
  io.rate_hz = 200;
  out.id = id;
  out.imu = SimulateFootImu(walk, id, io, Random(imu_seed)).samples;
  return out;
}

TEST(MountYaw, TheSameWalkWithTheImuMountedAnotherWayGivesTheSameSteps) {
  const SimulatedFootImu foot = FootImuOf("office-loop-1lap", 7, 8);
  const std::string& id = foot.id;
  const std::vector<ImuSample>& imu = foot.imu;
  const MissionInfo& info = foot.sim.data.info;
  const InsRun aligned = RunIns(info, imu);
  // Mounted as the foot: exactly what the INS gave without looking for the mounting.
  InsOptions off;
  off.mount_yaw.strides = 0;
  const InsRun before = RunIns(info, imu, off);
  ASSERT_EQ(aligned.steps.size(), before.steps.size());
  for (std::size_t k = 0; k < aligned.steps.size(); ++k) {
    ASSERT_EQ(aligned.steps[k].delta_n, before.steps[k].delta_n) << k;
  }
  ASSERT_GT(aligned.steps.size(), 100u);
  const Vec2 start = info.AgentStart(*info.Find(id))->head<2>();
  double walked = 0;
  for (const Step& s : aligned.steps) walked += s.delta_n.head<2>().norm();
  ASSERT_GT(walked, 50.0);
  // Turned 90 deg (another axis forward), 10 deg (a toe-out, below the hold: made up after),
  // and upside down and turned 120 deg: the same walk.
  const std::vector<Eigen::Matrix3d> mounts = {
      Eigen::AngleAxisd(90 * kDeg, Vec3::UnitZ()).toRotationMatrix(),
      Eigen::AngleAxisd(10 * kDeg, Vec3::UnitZ()).toRotationMatrix(),
      (Eigen::AngleAxisd(120 * kDeg, Vec3::UnitZ()) * Eigen::AngleAxisd(M_PI, Vec3::UnitX()))
          .toRotationMatrix()};
  for (const auto& R : mounts) {
    const InsRun turned = RunIns(info, Mounted(imu, R));
    ASSERT_FALSE(turned.states.empty());
    // The steps add up to where the turned INS ends (the catch-up), and both where the aligned
    // IMU's walk ends, within the INS's own differences (noise in another frame).
    const Vec2 sum = SumOfSteps(turned);
    const Vec2 last_state = turned.states.back().position_n.head<2>() - start;
    EXPECT_LT((sum - SumOfSteps(aligned)).norm(), 0.3) << R;
    EXPECT_LT((last_state - (aligned.states.back().position_n.head<2>() - start)).norm(), 0.3);
    // Along the walk, after the first metres: the sums of the steps so far within 0.3 m (from
    // the 24th step: the 10 deg toe-out is not held, and its catch-up ends a few steps after
    // the decision at the fifth landing — a straight stride counts once the next chord is seen).
    ASSERT_EQ(turned.steps.size(), aligned.steps.size());
    EXPECT_LT(WorstAlongTheWalk(turned, aligned, 24), 0.3) << R;
  }
  // Without looking for the mounting the 90 deg IMU walks off sideways (what it did before).
  const InsRun blind = RunIns(info, Mounted(imu, mounts[0]), off);
  EXPECT_GT(WorstAlongTheWalk(blind, aligned, 20), 5.0);
}

TEST(MountYaw, AHouseSearchsTurnedImuIsDecidedWithinTheFirstStepsHold) {
  // The simulator's house search turns at nearly every stride: its straight strides came 3 in
  // 13-34 landings, beyond the 12 landings the step consumers' INS holds its first steps for,
  // so those went out turned and a catch-up followed. The gait's regression (the turning
  // strides' bounds in session 44) decides within the hold, and the walk is the aligned IMU's from
  // the first steps on.
  const SimulatedFootImu foot = FootImuOf("house1-search", 3, 4);
  const std::string& id = foot.id;
  const std::vector<ImuSample>& imu = foot.imu;
  const MissionInfo& info = foot.sim.data.info;
  InsOptions held;
  held.mount_yaw.hold_first_landings = 12;
  InsOptions median_only = held;
  median_only.mount_yaw.interval_max_turn_rad = 0;
  median_only.mount_yaw.gait_min_strides = 0;
  const InsRun aligned = RunIns(info, imu, held);
  const Eigen::Matrix3d R = Eigen::AngleAxisd(25 * kDeg, Vec3::UnitZ()).toRotationMatrix();
  for (const InsOptions& o : {held, median_only}) {
    MultiAgentIns ins(info, o);
    InsRun r;
    ins.on_step = [&](const Step& s) { r.steps.push_back(s); };
    for (const auto& s : Mounted(imu, R)) ins.Add(s);
    ins.Finish();
    const auto numbers = ins.Summary().numbers;
    const double landings = numbers.at(id + ".mount_yaw_landings");
    const bool by_gait = numbers.at(id + ".mount_yaw_by_gait") > 0;
    ASSERT_EQ(r.steps.size(), aligned.steps.size());
    if (o.mount_yaw.gait_min_strides > 0) {
      EXPECT_TRUE(by_gait);
      EXPECT_LE(landings, 12);
      EXPECT_NEAR(numbers.at(id + ".mount_yaw_turned_deg"), 25.0, 1.0);
      EXPECT_LT(WorstAlongTheWalk(r, aligned, 0), 0.3);
    } else {
      EXPECT_FALSE(by_gait);
      EXPECT_GT(landings, 12);  // the hold ran out: the first steps went out turned
      EXPECT_GT(WorstAlongTheWalk(r, aligned, 0), 1.0);
    }
  }
}

TEST(MountYaw, TheRecordedFigureEightTurnedOnTheFootIsDecidedByItsGait) {
  // Recorded gait, not the simulator's walker: OpenShoe's figure-8 turns all the way (its foot
  // lands about two thirds of the way toward its next stride). Its IMU read turned by +25 and
  // -40 degrees about its z axis (a metamorphic copy of the same walk) must give the same
  // mounting plus that turn. Its straight strides decide at the eighth landing, the gait's
  // regression alone at the ninth; both within a degree of the median of all the walk's
  // straight strides.
  const auto dir = testing::SharedData("openshoe-figure8");
  if (dir.empty()) GTEST_SKIP() << "../shared/data not present";
  const MissionData fig8 = ReadOpenShoeFigure8(dir / "imu_820hz.txt");
  const std::string id = fig8.imu.front().agent;
  auto decide = [&](double turn_deg, int gait_min_strides, int strides = 3) {
    InsOptions o;
    o.mount_yaw.gait_min_strides = gait_min_strides;
    o.mount_yaw.strides = strides;
    o.mount_yaw.max_landings = std::max(40, strides);
    MultiAgentIns ins(fig8.info, o);
    ins.on_step = [](const Step&) {};
    for (const auto& s :
         Mounted(fig8.imu, Eigen::AngleAxisd(turn_deg * kDeg, Vec3::UnitZ()).toRotationMatrix()))
      ins.Add(s);
    ins.Finish();
    return ins.Summary().numbers;
  };
  const int gait = MountYawOptions{}.gait_min_strides;
  // Against the median of every straight stride of the walk (decided at its end).
  const auto all = decide(0, 0, 1000);
  EXPECT_GT(all.at(id + ".mount_yaw_strides"), 15.0);
  const double reference = all.at(id + ".mount_yaw_turned_deg");
  // The defaults: its straight strides decide first (the eighth landing).
  const auto base = decide(0, gait);
  EXPECT_LE(base.at(id + ".mount_yaw_landings"), 8.0);
  EXPECT_NEAR(base.at(id + ".mount_yaw_turned_deg"), reference, 1.0);
  // The gait's regression alone (no straight stride decides before the walk's end): the ninth.
  const auto by_gait = decide(0, gait, 1000);
  EXPECT_EQ(by_gait.at(id + ".mount_yaw_by_gait"), 1.0);
  EXPECT_LE(by_gait.at(id + ".mount_yaw_landings"), 9.0);
  EXPECT_NEAR(by_gait.at(id + ".mount_yaw_turned_deg"), reference, 1.0);
  EXPECT_GT(by_gait.at(id + ".mount_yaw_gait_a"), 0.2);  // not a pivot
  for (const double turn : {25.0, -40.0}) {
    for (const auto& [strides, one] : {std::pair(3, &base), std::pair(1000, &by_gait)}) {
      const auto n = decide(turn, gait, strides);
      EXPECT_EQ(n.at(id + ".mount_yaw_by_gait"), one->at(id + ".mount_yaw_by_gait")) << turn;
      EXPECT_NEAR(WrapAngle((n.at(id + ".mount_yaw_turned_deg") -
                             one->at(id + ".mount_yaw_turned_deg") - turn) *
                            kDeg),
                  0.0, 0.5 * kDeg)
          << turn << " " << strides;
    }
  }
}

}  // namespace
}  // namespace trailmark::ins

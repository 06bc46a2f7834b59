// SPDX-License-Identifier: MIT
#include "trailmark/sim/imu_sim.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

#include <Eigen/Geometry>

namespace trailmark {

namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
constexpr double kUg = 9.80665e-6;

/// Minimum-jerk progress s(tau) and its first two derivatives in tau.
void MinimumJerk(double tau, double* s, double* ds, double* dds) {
  const double t2 = tau * tau, t3 = t2 * tau;
  *s = 10 * t3 - 15 * t3 * tau + 6 * t3 * t2;
  *ds = 30 * t2 - 60 * t3 + 30 * t3 * tau;
  *dds = 60 * tau - 180 * t2 + 120 * t3;
}

Vec3 LogMap(const Eigen::Matrix3d& R) {
  const Eigen::AngleAxisd aa(R);
  return aa.angle() * aa.axis();
}

struct FootPose {
  Vec3 p = Vec3::Zero(), v = Vec3::Zero();
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  bool stance = true;
};

}  // namespace

ImuGrade ImuGrade::Perfect() { return {"perfect"}; }

ImuGrade ImuGrade::Tactical() {
  ImuGrade g;
  g.name = "tactical";
  g.accel_noise_density = 0.012 / 60.0;  // VRW 0.012 m/s/sqrt(h)
  g.gyro_noise_density = 0.12 * kDeg / 60.0;  // ARW 0.12 deg/sqrt(h)
  g.accel_turn_on_bias = 50 * kUg;
  g.gyro_turn_on_bias = 5.0 * kDeg / 3600.0;
  g.accel_bias_instability = 3.2 * kUg;
  g.gyro_bias_instability = 0.8 * kDeg / 3600.0;
  g.accel_scale_sigma = 5e-4;
  g.gyro_scale_sigma = 5e-4;
  g.misalignment_sigma_rad = 2e-4;
  return g;
}

ImuGrade ImuGrade::Industrial() {
  ImuGrade g;
  g.name = "industrial";
  g.accel_noise_density = 100 * kUg;      // 3DM-GX5-25: 100 ug/sqrt(Hz)
  g.gyro_noise_density = 0.005 * kDeg;    // 0.005 deg/s/sqrt(Hz)
  g.accel_turn_on_bias = 2e-3 * 9.80665;  // 2 mg
  g.gyro_turn_on_bias = 0.05 * kDeg;      // 0.05 deg/s (after factory calibration)
  g.accel_bias_instability = 40 * kUg;
  g.gyro_bias_instability = 8.0 * kDeg / 3600.0;
  g.accel_scale_sigma = 1e-3;
  g.gyro_scale_sigma = 1e-3;
  g.misalignment_sigma_rad = 1e-3;
  return g;
}

ImuGrade ImuGrade::Consumer() {
  ImuGrade g;
  g.name = "consumer";
  g.accel_noise_density = 300 * kUg;
  g.gyro_noise_density = 0.01 * kDeg;
  g.accel_turn_on_bias = 60e-3 * 9.80665 / 3.0;  // +-60 mg read as 3 sigma
  g.gyro_turn_on_bias = 5.0 * kDeg / 3.0;        // +-5 deg/s as 3 sigma
  g.accel_bias_instability = 0.5e-3 * 9.80665;
  g.gyro_bias_instability = 30.0 * kDeg / 3600.0;
  g.accel_scale_sigma = 1e-2;
  g.gyro_scale_sigma = 1e-2;
  g.misalignment_sigma_rad = 5e-3;
  return g;
}

ImuGrade ImuGrade::ByName(const std::string& name) {
  if (name == "perfect") return Perfect();
  if (name == "tactical") return Tactical();
  if (name == "industrial") return Industrial();
  if (name == "consumer") return Consumer();
  throw std::invalid_argument("unknown IMU grade '" + name +
                              "' (known: perfect, tactical, industrial, consumer)");
}

SimulatedImu SimulateFootImu(const Walk& walk, const std::string& agent, const ImuSimOptions& o,
                             Random rng, std::optional<double> start_yaw_rad) {
  if (walk.steps.empty()) throw std::invalid_argument("SimulateFootImu: a walk without steps");
  if (!(o.rate_hz > 0)) throw std::invalid_argument("SimulateFootImu: rate must be > 0");
  // The instrumented foot's strides: it rests during even steps and swings during odd ones,
  // from its footprint to the footprint two steps ahead.
  // A swing shorter than a normal one (the shuffle into a stop) lifts and pitches the foot
  // proportionally less and turns it at most kMaxSwingYawRate: the motion stays within what a
  // foot does and a MEMS gyro measures; the heading left over is caught up by the next strides.
  constexpr double kFullSwingS = 0.35;
  // A foot's swing lasts about 0.4 s whatever the walking speed: a slower walker lengthens the
  // stance, not the swing (e.g. Winter, The Biomechanics and Motor Control of Human Gait;
  // swing ~0.35-0.45 s from slow to fast walking, ~0.3 s running). A swing is kept within
  // [kMinSwingS, kMaxSwingS] of the time its step allows; the foot rests the rest of it. (Before
  // 2026-12-05 a swing took its whole step: a slow search's 1.1 s steps swung for 1.1 s, and
  // the pitch profile's rate stood still at a third and two thirds of such a swing while the
  // foot moved at ~1 m/s, which a ZUPT detector takes for a stance; and a step cut short before
  // a stop swung in 0.13 s, at up to 22 g.)
  constexpr double kMinSwingS = 0.3;
  constexpr double kMaxSwingS = 0.6;
  constexpr double kMaxSwingYawRate = 8.0;  // rad/s, mean over the swing
  constexpr double kMaxMeanSwingSpeed = 4.0;  // m/s: a walking stride's swing averages 2-3 m/s
  struct Stride {
    double t0, t1;
    Vec3 from, to;
    double yaw_from, yaw_to;
    double amplitude;  ///< scale of lift and pitch, (0, 1]
  };
  std::vector<Stride> strides;
  const double lift = o.motion == FootMotion::kCrawl ? std::min(o.lift_m, 0.03) : o.lift_m;
  const double pitch = o.motion == FootMotion::kCrawl ? 0.3 * o.pitch_amplitude_rad
                                                      : o.pitch_amplitude_rad;
  const double climb = o.motion == FootMotion::kStairs ? 2 * o.riser_m : 0.0;
  // The foot's height: the walk's own (stairs along the route) plus, in the stairs motion, two
  // risers per stride.
  Vec3 foot(walk.steps.front().from.x(), walk.steps.front().from.y(), walk.steps.front().z0);
  double climbed = 0;
  const Vec2 first_dir = walk.steps.front().to - walk.steps.front().from;
  // The stated start heading, which an INS aligns its yaw to (a search's walk sets off up to
  // ~30 deg from the direction it entered by: the foot faced the first step before, and the
  // INS of an --imu-only house search ran 30 deg off).
  double yaw = start_yaw_rad ? *start_yaw_rad : std::atan2(first_dir.y(), first_dir.x());
  // The instrumented foot's footprints (every second one of the walk, and the last), so that a
  // stride knows the direction of the next (landing_anticipation).
  std::vector<Vec2> footprints{walk.steps.front().from};
  for (std::size_t k = 1; k < walk.steps.size(); k += 2) footprints.push_back(walk.steps[k].to);
  if (walk.steps.size() % 2 == 1 && walk.steps.size() > 1)
    footprints.push_back(walk.steps.back().to);
  auto add_stride = [&](const TrueStep& s, double rise_m) {
    climbed += rise_m;
    const Vec3 to(s.to.x(), s.to.y(), s.z1 + climbed);
    const Vec2 d = (to - foot).head<2>();
    double yaw_to = d.norm() > 1e-6 ? std::atan2(d.y(), d.x()) : yaw;
    // Turned on toward the next stride's direction by the gait's share of the turn between them.
    const std::size_t i = strides.size() + 1;  // this stride ends at footprints[i]
    if (o.landing_anticipation > 0 && d.norm() > 1e-6 && i + 1 < footprints.size()) {
      const Vec2 next = footprints[i + 1] - footprints[i];
      if (next.norm() > 1e-6) {
        yaw_to += o.landing_anticipation * WrapAngle(std::atan2(next.y(), next.x()) - yaw_to);
      }
    }
    // A step cut short before a stop can last milliseconds while this foot's stride spans the
    // step before it too: the swing then starts earlier, in this foot's rest, so that its mean
    // speed stays a foot's (the g-forces of a real stride, not thousands of g).
    const double min_swing_s = std::max(kMinSwingS, (to - foot).norm() / kMaxMeanSwingSpeed);
    double t0 = std::max(s.t0, s.t1 - kMaxSwingS);
    if (s.t1 - t0 < min_swing_s) {
      t0 = std::max(s.t1 - min_swing_s, strides.empty() ? s.t0 - min_swing_s : strides.back().t1);
    }
    const double swing_s = s.t1 - t0;
    const double max_turn = kMaxSwingYawRate * swing_s;
    const double turn = std::clamp(WrapAngle(yaw_to - yaw), -max_turn, max_turn);
    strides.push_back({t0, s.t1, foot, to, yaw, yaw + turn,
                       std::clamp(swing_s / kFullSwingS, 0.0, 1.0)});
    foot = to;
    yaw = strides.back().yaw_to;
  };
  for (std::size_t k = 1; k < walk.steps.size(); k += 2) add_stride(walk.steps[k], climb);
  if (walk.steps.size() % 2 == 1 && walk.steps.size() > 1) {  // join the last footprint
    add_stride(walk.steps.back(), climb / 2);
  }

  auto pose_at = [&](double t) {
    FootPose f;
    // The stride in progress or the last one completed.
    auto it = std::upper_bound(strides.begin(), strides.end(), t,
                               [](double v, const Stride& s) { return v < s.t0; });
    if (it == strides.begin()) {
      f.p = strides.front().from;
      f.R = Eigen::AngleAxisd(strides.front().yaw_from, Vec3::UnitZ()).toRotationMatrix();
      return f;
    }
    const Stride& s = *(it - 1);
    if (t >= s.t1) {
      f.p = s.to;
      f.R = Eigen::AngleAxisd(s.yaw_to, Vec3::UnitZ()).toRotationMatrix();
      return f;
    }
    const double T = s.t1 - s.t0, tau = (t - s.t0) / T;
    double m, dm, ddm;
    MinimumJerk(tau, &m, &dm, &ddm);
    const double sp = std::sin(std::numbers::pi * tau);
    const double lift_m = s.amplitude * lift;
    f.p = s.from + (s.to - s.from) * m + Vec3(0, 0, lift_m * sp * sp);
    f.v = (s.to - s.from) * (dm / T) +
          Vec3(0, 0, lift_m * std::numbers::pi * std::sin(2 * std::numbers::pi * tau) / T);
    const double yaw_t = s.yaw_from + (s.yaw_to - s.yaw_from) * m;
    const double theta = s.amplitude * pitch * std::sin(2 * std::numbers::pi * tau) * sp * sp;
    f.R = (Eigen::AngleAxisd(yaw_t, Vec3::UnitZ()) * Eigen::AngleAxisd(theta, Vec3::UnitY()))
              .toRotationMatrix();
    f.stance = false;
    return f;
  };

  SimulatedImu out;
  for (const Stride& s : strides) out.landings.push_back({s.t1, s.to.head<2>(), s.yaw_to});
  // Sensor errors.
  const ImuGrade& g = o.grade;
  const double dt = 1.0 / o.rate_hz;
  auto draw3 = [&](double sigma) { return Vec3(rng.Normal(0, sigma), rng.Normal(0, sigma), rng.Normal(0, sigma)); };
  const Vec3 ba0 = draw3(g.accel_turn_on_bias), bg0 = draw3(g.gyro_turn_on_bias);
  const Vec3 sa = draw3(g.accel_scale_sigma), sg = draw3(g.gyro_scale_sigma);
  const Vec3 mis = draw3(g.misalignment_sigma_rad);
  const Eigen::Matrix3d M = Eigen::AngleAxisd(mis.norm(), mis.norm() > 0 ? Vec3(mis.normalized()) : Vec3::UnitX())
                                .toRotationMatrix();
  const double rho = std::exp(-dt / g.bias_correlation_s);
  const double gm = std::sqrt(std::max(0.0, 1 - rho * rho));
  Vec3 ba_gm = draw3(g.accel_bias_instability), bg_gm = draw3(g.gyro_bias_instability);
  const double sigma_a = g.accel_noise_density * std::sqrt(o.rate_hz);
  const double sigma_g = g.gyro_noise_density * std::sqrt(o.rate_hz);

  const double t_begin = walk.truth.empty() ? walk.steps.front().t0 - o.rest_before_s
                                            : std::min(walk.truth.front().t, walk.steps.front().t0) -
                                                  o.rest_before_s;
  const double t_end = std::max(walk.steps.back().t1, walk.truth.empty() ? 0.0 : walk.truth.back().t) + 0.5;
  const auto n = static_cast<std::size_t>(std::floor((t_end - t_begin) * o.rate_hz)) + 1;
  out.samples.reserve(n);
  FootPose prev = pose_at(t_begin - dt);
  const Vec3 up(0, 0, o.gravity_mps2);
  for (std::size_t k = 0; k < n; ++k) {
    const double t = t_begin + k * dt;
    const FootPose cur = pose_at(t);
    // Consistent with the INS's mechanization: the rotation from the previous sample by the
    // exponential map, and the mean acceleration over the interval in the mean attitude.
    const Vec3 w_true = LogMap(prev.R.transpose() * cur.R) / dt;
    const Eigen::Matrix3d R_mid = 0.5 * (prev.R + cur.R);
    const Vec3 f_true = R_mid.inverse() * ((cur.v - prev.v) / dt + up);
    ba_gm = rho * ba_gm + gm * draw3(g.accel_bias_instability);
    bg_gm = rho * bg_gm + gm * draw3(g.gyro_bias_instability);
    ImuSample s;
    s.t = t;
    s.agent = agent;
    s.accel_b = (Vec3::Ones() + sa).cwiseProduct(M * f_true) + ba0 + ba_gm + draw3(sigma_a);
    s.gyro_b = (Vec3::Ones() + sg).cwiseProduct(M * w_true) + bg0 + bg_gm + draw3(sigma_g);
    out.samples.push_back(s);
    out.foot_truth.push_back({t, agent, cur.p});
    out.stance.push_back(cur.stance);
    prev = cur;
  }
  return out;
}

void AddFootImu(SimulatedMission& sim, const ImuSimOptions& options, std::uint64_t seed) {
  Random rng(seed);
  for (const auto& [id, walk] : sim.walks) {
    const NodeInfo* node = sim.data.info.Find(id);
    const SimulatedImu s = SimulateFootImu(walk, id, options, rng.Fork(),
                                           node ? node->start_heading_rad : std::nullopt);
    sim.data.imu.insert(sim.data.imu.end(), s.samples.begin(), s.samples.end());
  }
  std::stable_sort(sim.data.imu.begin(), sim.data.imu.end(),
                   [](const ImuSample& a, const ImuSample& b) { return a.t < b.t; });
}

void MountImu(std::vector<ImuSample>& samples, const Eigen::Matrix3d& imu_in_foot) {
  for (ImuSample& s : samples) {
    s.accel_b = imu_in_foot.transpose() * s.accel_b;
    s.gyro_b = imu_in_foot.transpose() * s.gyro_b;
  }
}

Eigen::Matrix3d ImuMounting(double yaw_rad, double roll_rad, double pitch_rad) {
  return (Eigen::AngleAxisd(yaw_rad, Vec3::UnitZ()) * Eigen::AngleAxisd(pitch_rad, Vec3::UnitY()) *
          Eigen::AngleAxisd(roll_rad, Vec3::UnitX()))
      .toRotationMatrix();
}

}  // namespace trailmark

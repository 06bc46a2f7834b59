// SPDX-License-Identifier: MIT
// Consistency of the ZUPT INS's position covariance (issue 21, item 4; STYLE.md): the normalized
// estimation error squared (NEES) of the horizontal position over Monte Carlo runs of the foot-IMU
// simulator on the office loop.
//  - Exact model: an IMU with white noise only, of the per-sample sigmas the filter assumes, the
//    true stance labels, biases neither simulated nor estimated: the mean NEES must be the
//    degrees of freedom (2), within the two-sided 99 % chi-square interval of the runs.
//  - The default filter on the industrial-grade IMU (biases, scale errors, misalignment, its own
//    stance detector): it must not claim more than it has (NEES below the upper 99 % bound).
// One NEES per run (at its last sample), so that the runs are independent.
#include <gtest/gtest.h>

#include <boost/math/distributions/chi_squared.hpp>
#include <cmath>
#include <cstdio>
#include <functional>

#include "trailmark/ins/zupt_ins.h"
#include "trailmark/sim/imu_sim.h"
#include "trailmark/sim/scenarios.h"

namespace trailmark::ins {
namespace {

struct NeesRun {
  double nees = 0;   ///< horizontal position, at the last sample
  double error_m = 0;
};

NeesRun RunOnce(std::uint64_t seed, const ImuGrade& grade, InsOptions io, bool true_stance,
                std::function<void(ImuSample&)> perturb = {}) {
  const SimulatedMission sim = SimulateScenario("office-loop-1lap", seed);
  ImuSimOptions o;
  o.rate_hz = 100;
  o.grade = grade;
  const auto& [id, walk] = sim.walks.front();
  SimulatedImu imu = SimulateFootImu(walk, id, o, Random(seed + 1000));
  if (perturb) for (auto& smp : imu.samples) perturb(smp);
  io.initial_yaw_rad = sim.data.info.Find(id)->start_heading_rad.value_or(0.0);
  io.initial_position_n = imu.foot_truth.front().position_n;
  ZuptIns ins(io);
  std::vector<InsState> states;
  ins.on_state = [&](const InsState& s) { states.push_back(s); };
  for (std::size_t k = 0; k < imu.samples.size(); ++k) {
    if (true_stance) {
      ins.AddWithStance(imu.samples[k], imu.stance[k]);
    } else {
      ins.Add(imu.samples[k]);
    }
  }
  ins.Finish();
  EXPECT_EQ(states.size(), imu.samples.size());
  const InsState& last = states.back();
  const Vec2 e = (last.position_n - imu.foot_truth.back().position_n).head<2>();
  const Eigen::Matrix2d P = last.position_cov.topLeftCorner<2, 2>();
  EXPECT_NEAR(P(0, 1), P(1, 0), 1e-12);
  EXPECT_GT(P.determinant(), 0.0);
  return {e.dot(P.ldlt().solve(e)), e.norm()};
}

/// Mean NEES of `runs` independent runs and its two-sided 99 % interval for 2 degrees of freedom.
struct NeesCheck {
  double mean = 0, low = 0, high = 0, mean_error_m = 0;
};
NeesCheck Check(int runs, const ImuGrade& grade, const InsOptions& io, bool true_stance) {
  NeesCheck c;
  for (int r = 0; r < runs; ++r) {
    const NeesRun run = RunOnce(static_cast<std::uint64_t>(r + 1), grade, io, true_stance);
    c.mean += run.nees / runs;
    c.mean_error_m += run.error_m / runs;
  }
  const boost::math::chi_squared chi2(2.0 * runs);
  c.low = boost::math::quantile(chi2, 0.005) / runs;
  c.high = boost::math::quantile(chi2, 0.995) / runs;
  std::printf("mean NEES %.3f (99 %% interval %.3f-%.3f), mean error %.3f m over %d runs\n", c.mean,
              c.low, c.high, c.mean_error_m, runs);
  return c;
}

TEST(ZuptInsNees, ExactModelGivesTheDegreesOfFreedom) {
  InsOptions io;
  io.accel_noise_mps2 = 0.05;   // per sample at 100 Hz
  io.gyro_noise_radps = 0.002;
  io.zaru = false;
  // What the model knows of the start: the simulated IMU has no bias, the filter estimates the
  // gyro bias from the resting alignment (0.5 s, 51 samples: its error sigma_g / sqrt(51)) and
  // takes the start position and heading as given (they are exact here).
  io.alignment_s = 0.5;
  io.gyro_bias_sigma0 = io.gyro_noise_radps / std::sqrt(51.0);
  io.accel_bias_sigma0 = 1e-5;
  io.accel_bias_rw = 1e-9;
  io.gyro_bias_rw = 1e-9;
  io.initial_yaw_sigma_rad = 1e-4;
  ImuGrade grade = ImuGrade::Perfect();
  grade.name = "white";
  grade.accel_noise_density = io.accel_noise_mps2 / std::sqrt(100.0);
  grade.gyro_noise_density = io.gyro_noise_radps / std::sqrt(100.0);
  const NeesCheck c = Check(40, grade, io, /*true_stance=*/true);
  EXPECT_GT(c.mean, c.low) << "conservative: mean NEES " << c.mean << " (error " << c.mean_error_m
                           << " m)";
  EXPECT_LT(c.mean, c.high) << "overconfident: mean NEES " << c.mean << " (error "
                            << c.mean_error_m << " m)";
}

TEST(ZuptInsNees, DefaultFilterOnAnIndustrialImuIsNotOverconfident) {
  const NeesCheck c = Check(40, ImuGrade::Industrial(), InsOptions{}, /*true_stance=*/false);
  EXPECT_LT(c.mean, c.high) << "overconfident: mean NEES " << c.mean << " (error "
                            << c.mean_error_m << " m)";
  // And not useless: the 95 % radius is not orders of magnitude above the error.
  EXPECT_GT(c.mean, 0.01) << "mean NEES " << c.mean;
}

}  // namespace
}  // namespace trailmark::ins

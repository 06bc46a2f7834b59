// SPDX-License-Identifier: MIT
#include "trailmark/io/trajectory_formats.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "test_util.h"
#include "trailmark/core/error.h"

namespace trailmark {
namespace {

using testing::TempDir;

TEST(Tum, OneNodesRowsAsTumLinesWithAnIdentityQuaternion) {
  std::vector<Estimate> rows(3);
  rows[0].t = 0.5;
  rows[0].id = "ff1";
  rows[0].position_n = Vec3(1.25, -2, 0.1);
  rows[1].t = 0.75;
  rows[1].id = "c1";
  rows[2].t = 1.0 / 3.0;
  rows[2].id = "ff1";
  rows[2].position_n = Vec3(3, 4, 1e-9);
  EXPECT_EQ(TumTrajectory(rows, "ff1"),
            "# timestamp tx ty tz qx qy qz qw (trailmark: no attitude, identity quaternion)\n"
            "0.5 1.25 -2 0.1 0 0 0 1\n"
            "0.3333333333333333 3 4 1e-09 0 0 0 1\n");
  std::vector<TruthSample> truth{{2.0, "c1", Vec3(5, 6, 7), 1}};
  EXPECT_EQ(TumTrajectory(truth, "c1").substr(TumTrajectory(truth, "c1").find('\n') + 1),
            "2 5 6 7 0 0 0 1\n");
}

constexpr const char* kGroundTruthHeader =
    "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], "
    "q_RS_z [], v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1]\n";

TEST(Euroc, GroundTruthAndImuOfAMav0Folder) {
  TempDir dir;
  std::filesystem::create_directories(dir.path() / "mav0" / "state_groundtruth_estimate0");
  std::filesystem::create_directories(dir.path() / "mav0" / "imu0");
  // Yaw 90 degrees: q = (cos 45, 0, 0, sin 45).
  const double c = std::cos(std::numbers::pi / 4);
  dir.File("mav0/state_groundtruth_estimate0/data.csv",
           std::string(kGroundTruthHeader) +
               "1403636579763555584,4.688319,-1.786938,0.783338," + std::to_string(c) + ",0,0," +
               std::to_string(c) + ",0,0,0\n"
               "1403636579768555520,4.688177,-1.786770,0.787350,1,0,0,0,0,0,0\n");
  dir.File("mav0/imu0/data.csv",
           "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
           "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]\n"
           "1403636579758555392,-0.099134701513277898,0.14730578886832138,0.02722713633111154,"
           "8.1476917083333333,-0.37592158333333331,-2.4026292499999999\n"
           "1403636579763555584,-0.1,0.1,0.02,8.1,-0.3,-2.4\n");
  const MissionData m = ReadEuroc(dir.path(), "mav");
  ASSERT_EQ(m.truth.size(), 2u);
  ASSERT_EQ(m.imu.size(), 2u);
  // t = 0 at the earliest timestamp of both files (the IMU's), nanoseconds kept exactly.
  EXPECT_EQ(m.imu[0].t, 0.0);
  EXPECT_NEAR(m.truth[0].t, 0.005000192, 1e-12);
  EXPECT_NEAR(m.truth[1].t, 0.010000128, 1e-12);
  EXPECT_EQ(m.truth[1].position_n, Vec3(4.688177, -1.786770, 0.787350));
  EXPECT_EQ(m.imu[0].gyro_b, Vec3(-0.099134701513277898, 0.14730578886832138, 0.02722713633111154));
  EXPECT_EQ(m.imu[0].accel_b, Vec3(8.1476917083333333, -0.37592158333333331, -2.4026292499999999));
  ASSERT_EQ(m.info.nodes.size(), 1u);
  EXPECT_EQ(m.info.nodes[0].id, "mav");
  EXPECT_EQ(*m.info.nodes[0].start, Vec3(4.688319, -1.786938, 0.783338));
  EXPECT_NEAR(*m.info.nodes[0].start_heading_rad, std::numbers::pi / 2, 1e-6);
  // The ground-truth file alone: no IMU, time from its own first row.
  const MissionData gt = ReadEuroc(dir.path() / "mav0/state_groundtruth_estimate0/data.csv");
  EXPECT_TRUE(gt.imu.empty());
  EXPECT_EQ(gt.truth[0].t, 0.0);
  EXPECT_EQ(gt.truth[0].id, "body");
}

void ExpectRefused(const std::string& rows, std::size_t line, const std::string& problem) {
  testing::ExpectFileRefused("data.csv", std::string(kGroundTruthHeader) + rows, line, problem,
                             [](const std::string& path) { ReadEuroc(path); });
}

TEST(Euroc, BadRowsAreRefusedWithTheirLine) {
  ExpectRefused("1,0,0,0,1,0,0\n", 2, "expected at least 8 fields, found 7");
  ExpectRefused("1,0,0,0,1,0,0,0\n2,0,nan,0,1,0,0,0\n", 3, "'nan' is not a finite number");
  ExpectRefused("5,0,0,0,1,0,0,0\n4,0,0,0,1,0,0,0\n", 3, "time goes backwards");
  ExpectRefused("1.5,0,0,0,1,0,0,0\n", 2, "not integer nanoseconds");
  ExpectRefused("", 0, "no rows");
  ExpectRefused(std::string(3u << 20, '1'), 2, "line longer than");
  TempDir dir;
  EXPECT_THROW(ReadEuroc(dir.path()), InputError);  // a folder without ground truth
}

}  // namespace
}  // namespace trailmark

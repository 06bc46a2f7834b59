// SPDX-License-Identifier: MIT
#include "trailmark/io/convert_ipin.h"

#include <GeographicLib/Geodesic.hpp>
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "test_util.h"
#include "trailmark/core/error.h"
#include "trailmark/io/geo.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/io/streams.h"

namespace trailmark {
namespace {

using testing::TempDir;

// A logfile written from the public format description (GetSensorData's header comments):
// every record type we convert, in its variants, and two we do not.
constexpr const char* kLogfile =
    "% LogFile data created by the GetSensorData App for Android.\n"
    "% ACCE;AppTimestamp(s);SensorTimestamp(s);Acc_X(m/s^2);Acc_Y(m/s^2);Acc_Z(m/s^2);Accuracy(integer)\n"
    "\n"
    "GYRO;0.010;1000.010;0.10;0.20;0.30;3\n"
    "ACCE;0.005;1000.005;9.0;0.0;0.5;3\n"  // before the first gyro sample: left out
    "ACCE;0.015;1000.015;9.1;0.1;0.6;3\n"
    "GYRO;0.020;1000.020;0.30;0.40;0.50;3\n"
    "ACCE;0.020;1000.020;9.2;0.2;0.7;3\n"
    "MAGN;0.021;1000.021;12.5;-3.0;40.0;3\n"
    "PRES;0.030;1000.030;1013.25;0\n"
    "POSI;0.040;1;40.31320000;-3.48310000;0;0\n"
    "POSI;0.050;2;0.0;0.0;0;0\n"
    "AHRS;0.055;1000.055;1.0;2.0;3.0;0.1;0.2;0.3;3\n"
    "WIFI;0.060;1000.060;eduroam;00:0b:86:27:36:c1;2412;-55\n"
    "WIFI;0.060;1000.060;a;b;c;11:22:33:44:55:66;-70;\n"  // an SSID with ';', no frequency
    "BLE4;0.070;iBeacon;F4:B8:5E:DE:4D:F1;-79;-59;1;2;e2c56db5-dffb-48d2-b060-d0f5a71096e0\n"
    "BLE4;0.080;Eddystone;C8:FD:19:44:EB:36;-81;0x0d;3.1;22.5;100;7\n"
    "BLE4;0.090;2;15;-90\n"
    "GNSS;0.095;1000.095;40.3;-3.4;600;0;10;0;10;8\n"
    "POSI;0.100;3;40.31320000;-3.48200000;1;0\n";

TEST(IpinLogfile, EveryRecordTypeIntoTheMissionFormat) {
  TempDir dir;
  const IpinLogfile log = ReadIpinLogfile(dir.File("log.txt", kLogfile));
  const MissionData& m = log.mission;
  // IMU: the ACCE samples inside the gyro's span, gyro interpolated linearly at their times.
  ASSERT_EQ(m.imu.size(), 2u);
  EXPECT_EQ(m.imu[0].t, 0.015);
  EXPECT_EQ(m.imu[0].accel_b, Vec3(9.1, 0.1, 0.6));
  EXPECT_TRUE(m.imu[0].gyro_b.isApprox(Vec3(0.2, 0.3, 0.4), 1e-12)) << m.imu[0].gyro_b.transpose();
  EXPECT_TRUE(m.imu[1].gyro_b.isApprox(Vec3(0.3, 0.4, 0.5), 1e-12));
  EXPECT_EQ(m.imu[0].agent, "phone");
  ASSERT_EQ(m.baro.size(), 1u);
  EXPECT_EQ(m.baro[0].pressure_hpa, 1013.25);
  ASSERT_EQ(log.magnetometer.size(), 1u);
  EXPECT_EQ(log.magnetometer[0].field_ut, Vec3(12.5, -3.0, 40.0));
  // Truth: metres east of the first POSI; the geodesic distance is the reference.
  ASSERT_EQ(m.truth.size(), 2u);
  ASSERT_TRUE(m.info.geo_origin);
  EXPECT_EQ(m.info.geo_origin->lat_deg, 40.3132);
  EXPECT_EQ(m.truth[0].position_n, Vec3(0, 0, 0));
  double s12 = 0;
  GeographicLib::Geodesic::WGS84().Inverse(40.3132, -3.4831, 40.3132, -3.4820, s12);
  EXPECT_NEAR(m.truth[1].position_n.x(), s12, 1e-3);
  EXPECT_NEAR(m.truth[1].position_n.y(), 0.0, 0.01);  // a parallel bends north of the chord by mm
  EXPECT_EQ(m.truth[1].position_n.z(), 3.0);
  EXPECT_EQ(m.truth[1].floor, 1);
  EXPECT_EQ(m.info.nodes[0].start, Vec3(0, 0, 0));
  // BLE: one landmark node per transmitter; WiFi with and without a frequency.
  ASSERT_EQ(m.rssi.size(), 3u);
  EXPECT_EQ(m.rssi[0].tx, "ble-f4-b8-5e-de-4d-f1");
  EXPECT_EQ(m.rssi[0].rssi_dbm, -79);
  EXPECT_EQ(m.rssi[1].tx, "ble-c8-fd-19-44-eb-36");
  EXPECT_EQ(m.rssi[2].tx, "ble-2-15");
  ASSERT_EQ(m.info.nodes.size(), 4u);
  EXPECT_EQ(m.info.nodes[3].kind, NodeKind::kLandmark);
  EXPECT_FALSE(m.info.nodes[3].position);
  ASSERT_EQ(log.wifi.size(), 2u);
  EXPECT_EQ(log.wifi[0].bssid, "00:0b:86:27:36:c1");
  EXPECT_EQ(log.wifi[0].frequency_mhz, 2412);
  EXPECT_EQ(log.wifi[1].bssid, "11:22:33:44:55:66");
  EXPECT_FALSE(log.wifi[1].frequency_mhz);
  // What was not converted is counted and said.
  EXPECT_EQ(log.unknown_records.at("AHRS"), 1u);
  EXPECT_EQ(log.unknown_records.at("GNSS"), 1u);
  EXPECT_EQ(log.records.at("POSI"), 2u);
  std::string notes;
  for (const auto& n : log.notes) notes += n + "\n";
  EXPECT_NE(notes.find("1 of 3 ACCE samples left out"), std::string::npos) << notes;
  EXPECT_NE(notes.find("1 POSI records at (0, 0)"), std::string::npos) << notes;
  EXPECT_NE(notes.find("AHRS"), std::string::npos) << notes;

  // Written and read back: every stream passes the readers, the origin survives.
  WriteIpinMission(log, dir.path() / "m");
  const MissionDirectory mission(dir.path() / "m");
  ASSERT_TRUE(mission.info().geo_origin);
  EXPECT_EQ(mission.info().geo_origin->lon_deg, -3.4831);
  EXPECT_EQ(ReadAll<TruthSample>(mission.Path("truth.csv").string(), &mission.registry()).size(), 2u);
  EXPECT_EQ(ReadAll<RssiPacket>(mission.Path("rssi.csv").string(), &mission.registry()).size(), 3u);
  EXPECT_EQ(ReadAll<ImuSample>(mission.Path("imu.csv").string(), &mission.registry()).size(), 2u);
  EXPECT_TRUE(mission.Has("wifi.csv"));
  EXPECT_TRUE(mission.Has("magnetometer.csv"));
}

TEST(IpinLogfile, AGivenOriginAndAgent) {
  TempDir dir;
  IpinOptions options;
  options.agent = "ff7";
  options.origin = GeoOrigin{40.3132, -3.4820, 0};
  const IpinLogfile log = ReadIpinLogfile(dir.File("log.txt", kLogfile), options);
  EXPECT_NEAR(log.mission.truth[1].position_n.x(), 0.0, 1e-9);
  EXPECT_LT(log.mission.truth[0].position_n.x(), -90);
  EXPECT_EQ(log.mission.rssi[0].rx, "ff7");
}

void ExpectRefused(const std::string& text, std::size_t line, const std::string& problem) {
  testing::ExpectFileRefused("log.txt", text, line, problem,
                             [](const std::string& path) { ReadIpinLogfile(path); });
}

// An ACCE sample after the last GYRO sample has no gyro bracket: left out and counted, never
// read past the gyro samples' end (the fuzzer's find, 2026-12-04: ACCE at 10.5 s, GYRO to 0.02 s).
TEST(IpinLogfile, AnAccelerometerSampleAfterTheLastGyroSampleIsLeftOut) {
  TempDir dir;
  const IpinLogfile log =
      ReadIpinLogfile(dir.File("log.txt",
                               "GYRO;0.01;1.01;0.1;0.2;0.3;3\nACCE;10.5;1.015;9.1;0.1;0.6;3\n"
                               "GYRO;0.02;1.02;0.3;0.4;0.5;3\n"));
  EXPECT_EQ(log.mission.imu.size(), 0u);
  ASSERT_FALSE(log.notes.empty());
  EXPECT_NE(log.notes.front().find("1 of 1 ACCE samples left out"), std::string::npos)
      << log.notes.front();
}

TEST(IpinLogfile, BadRecordsAreRefusedWithTheirLine) {
  ExpectRefused("% header\nACCE;0.1;0.1;9.8\n", 2, "ACCE record: expected at least 6 fields");
  ExpectRefused("ACCE;0.1;0.1;9.8;x;0\n", 1, "field 5 (Y): 'x' is not a finite number");
  ExpectRefused("GYRO;0.2;0;0;0;0\nGYRO;0.1;0;0;0;0\n", 2, "time goes backwards");
  ExpectRefused("POSI;0.1;1;95.0;-3.4;0;0\n", 1, "not a WGS 84 latitude, longitude");
  ExpectRefused("POSI;0.1;1;40.3;-3.4;0.5;0\n", 1, "FloorID '0.5' is not a level");
  // 0.05 deg of latitude is 5.5 km: outside the venue.
  ExpectRefused("POSI;0.1;1;40.30;-3.4;0;0\nPOSI;0.2;2;40.35;-3.4;0;0\n", 2, "outside the venue");
  ExpectRefused("PRES;0.1;0.1;10132.5;0\n", 1, "not a plausible pressure");
  // What baro.csv's and imu.csv's readers would refuse is refused here, naming the line (the
  // fuzzer found a converted 1,130 hPa that the mission's own reader refused).
  ExpectRefused("PRES;0.03;1.0;1130.25;0\n", 1, "not a plausible pressure");
  ExpectRefused("PRES;0.03;1.0;250;0\n", 1, "not a plausible pressure");
  ExpectRefused("ACCE;0.1;0.1;9.8;0;2e4;3\n", 1, "acceleration of 20000");
  ExpectRefused("GYRO;0.1;0.1;0;300;0;3\n", 1, "angular rate of 300");
  ExpectRefused("BLE4;0.1;iBeacon;;-70;-59;1;2;u\n", 1, "empty MAC");
  ExpectRefused("WIFI;0.1;0.1;ssid;a,b;2412;-50\n", 1, "is not a MAC address");
  ExpectRefused("", 0, "no records");
  ExpectRefused("AHRS;0.1;0.1;1;2;3\nSOUN;0.2;1;2;3\n", 0, "found only AHRS: 1, SOUN: 1");
  ExpectRefused(std::string("ACCE;0.1;0.1;9.8;0;0\n\0\n", 24), 2, "binary data");
  // A huge line (a binary file, no line breaks) is refused before it is held whole.
  ExpectRefused("ACCE;0.1;0.1;9.8;0;0\n" + std::string(3u << 20, '7'), 2, "line longer than");
}

TEST(LocalFrame, ExactOnTheEllipsoidWhereASphereIsNot) {
  // At 56 deg N a degree of longitude is longer on the ellipsoid than on the mean sphere: the
  // hand-written equirectangular formula this replaced was 0.34 % short in the east.
  const LocalFrame frame(GeoOrigin{56.0, -3.0, 0});
  const Vec3 east = frame.ToEnu(56.0, -2.99, 0);
  double s12 = 0;
  GeographicLib::Geodesic::WGS84().Inverse(56.0, -3.0, 56.0, -2.99, s12);
  EXPECT_NEAR(east.x(), s12, 1e-3);
  const double sphere = 6371008.8 * std::cos(56.0 * std::numbers::pi / 180) * 0.01 * std::numbers::pi / 180;
  EXPECT_NEAR(east.x() / sphere - 1, 0.0034, 0.0002);
  const GeoOrigin back = frame.ToGeodetic(east);
  EXPECT_NEAR(back.lat_deg, 56.0, 1e-12);
  EXPECT_NEAR(back.lon_deg, -2.99, 1e-12);
  EXPECT_THROW(LocalFrame(GeoOrigin{-3.0, 181.0, 0}), std::invalid_argument);
}

}  // namespace
}  // namespace trailmark

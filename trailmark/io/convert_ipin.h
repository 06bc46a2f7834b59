// SPDX-License-Identifier: MIT
#pragma once
/// Converter: an IPIN competition logfile (the GetSensorData Android app's text format, used by
/// the IPIN smartphone tracks) into a mission directory. One record per line, fields separated
/// by ';', '%' lines are comments. The records read:
///
///   ACCE;AppTimestamp(s);SensorTimestamp(s);Acc_X;Acc_Y;Acc_Z[;Accuracy]     m/s^2
///   GYRO;AppTimestamp(s);SensorTimestamp(s);Gyr_X;Gyr_Y;Gyr_Z[;Accuracy]     rad/s
///   MAGN;AppTimestamp(s);SensorTimestamp(s);Mag_X;Mag_Y;Mag_Z[;Accuracy]     uT
///   PRES;AppTimestamp(s);SensorTimestamp(s);Pres(mbar)[;Accuracy]
///   POSI;Timestamp(s);Counter;Latitude(deg);Longitude(deg);FloorID[;BuildingID]
///   WIFI;AppTimestamp(s);SensorTimestamp(s);SSID;BSSID[;Frequency(MHz)];RSS(dBm)
///   BLE4;AppTimestamp(s);iBeacon;MAC;RSSI(dBm);Power;MajorID;MinorID;UUID
///   BLE4;AppTimestamp(s);Eddystone;MAC;RSSI(dBm);InstanceID[;telemetry...]
///   BLE4;AppTimestamp(s);MajorID;MinorID;RSS(dBm)                (the early format)
///
/// Into: imu.csv (each ACCE sample with the gyro interpolated linearly at its time; samples
/// outside the gyro's span are left out and counted), baro.csv (PRES: 1 mbar = 1 hPa),
/// truth.csv (POSI: metres east/north of the geo origin through GeographicLib, z = FloorID x
/// 3 m by the spec's default storeys, the `floor` column = FloorID), rssi.csv (BLE4: each
/// transmitter a landmark node of unknown position, `ble-` and its MAC or major-minor), and two
/// extra streams the pipelines do not read: wifi.csv (t, rx, bssid, frequency_mhz, rssi_dbm)
/// and magnetometer.csv (t, agent, mx_ut, my_ut, mz_ut). Times are AppTimestamp, the app's one
/// clock for every sensor. Other record types (AHRS, GNSS, LIGH, PROX, SOUN, ...) are counted
/// and reported, not converted.

#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "trailmark/core/mission.h"

namespace trailmark {

struct IpinOptions {
  std::string agent = "phone";
  /// The frame's origin; default: the first POSI with coordinates.
  std::optional<GeoOrigin> origin;
  /// A POSI farther than this from the origin is refused as outside the venue, m.
  double max_venue_m = 2000.0;
};

struct WifiReading {
  double t = 0;
  std::string bssid;
  std::optional<double> frequency_mhz;
  double rssi_dbm = 0;
};

struct MagnetometerSample {
  double t = 0;
  Vec3 field_ut = Vec3::Zero();
};

struct IpinLogfile {
  MissionData mission;
  std::vector<WifiReading> wifi;
  std::vector<MagnetometerSample> magnetometer;
  std::map<std::string, std::size_t> records;          ///< converted, by record type
  std::map<std::string, std::size_t> unknown_records;  ///< not converted, by record type
  std::vector<std::string> notes;                      ///< what was left out, and why
};

/// Throws InputError naming the file and line: a record with too few fields, a cell that is not
/// a finite number, a time going backwards within a record type, a POSI that is not a WGS 84
/// position or lies outside the venue, a file with no record at all.
IpinLogfile ReadIpinLogfile(const std::filesystem::path& logfile, const IpinOptions& options = {});

/// mission.json (with geo_origin), the streams, wifi.csv and magnetometer.csv.
void WriteIpinMission(const IpinLogfile& log, const std::filesystem::path& out_dir);

}  // namespace trailmark

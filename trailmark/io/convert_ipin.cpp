// SPDX-License-Identifier: MIT
#include "trailmark/io/convert_ipin.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <set>
#include <string_view>

#include "trailmark/core/error.h"
#include "trailmark/io/csv.h"
#include "trailmark/io/geo.h"
#include "trailmark/io/json_input.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/io/streams.h"

namespace trailmark {
namespace {

/// One record of the logfile being read: its fields and where it is, for errors.
struct Record {
  std::vector<std::string_view> fields;
  const std::string* file;
  std::size_t line;

  [[noreturn]] void Fail(const std::string& problem) const {
    throw InputError(*file, line, fmt::format("{} record: {}", fields[0], problem));
  }
  void Require(std::size_t n, std::string_view layout) const {
    if (fields.size() < n) {
      Fail(fmt::format("expected at least {} fields ({}), found {}", n, layout, fields.size()));
    }
  }
  double Number(std::size_t i, std::string_view name) const {
    const std::optional<double> x = ParseFiniteDouble(fields[i]);
    if (!x) {
      Fail(fmt::format("field {} ({}): '{}' is not a finite number", i + 1, name,
                       std::string(fields[i].substr(0, 40))));
    }
    return *x;
  }
};

std::vector<std::string_view> SplitFields(std::string_view line) {
  std::vector<std::string_view> fields;
  std::size_t start = 0;
  while (true) {
    const std::size_t semi = line.find(';', start);
    std::string_view f = line.substr(start, semi == line.npos ? line.npos : semi - start);
    while (!f.empty() && (f.front() == ' ' || f.front() == '\t')) f.remove_prefix(1);
    while (!f.empty() && (f.back() == ' ' || f.back() == '\t')) f.remove_suffix(1);
    fields.push_back(f);
    if (semi == line.npos) break;
    start = semi + 1;
  }
  if (fields.size() > 1 && fields.back().empty()) fields.pop_back();  // a trailing ';'
  return fields;
}

/// A node id from a MAC address or beacon ids: `ble-` and the text lowercased, ':' as '-',
/// other characters outside the spec's [A-Za-z0-9_.-] as '_'.
std::string BleNodeId(std::string_view text) {
  std::string id = "ble-";
  for (char c : text) {
    const auto u = static_cast<unsigned char>(c);
    if (c == ':') {
      id += '-';
    } else if (std::isalnum(u) || c == '_' || c == '.' || c == '-') {
      id += static_cast<char>(std::tolower(u));
    } else {
      id += '_';
    }
  }
  return id;
}

/// Non-decreasing time per record type.
class Clocks {
 public:
  double Check(const Record& r, double t) {
    auto [it, fresh] = last_.try_emplace(std::string(r.fields[0]), t);
    if (!fresh) {
      if (t < it->second) {
        r.Fail(fmt::format("time goes backwards ({} s after {} s)", t, it->second));
      }
      it->second = t;
    }
    return t;
  }

 private:
  std::map<std::string, double> last_;
};

/// "ACCE: 3, GYRO: 2".
std::string Counts(const std::map<std::string, std::size_t>& counts) {
  std::string out;
  for (const auto& [type, n] : counts) out += fmt::format("{}{}: {}", out.empty() ? "" : ", ", type, n);
  return out;
}

struct RawPosition {
  double t, lat_deg, lon_deg;
  int floor;
  long building;
  std::size_t line;
};

}  // namespace

IpinLogfile ReadIpinLogfile(const std::filesystem::path& logfile, const IpinOptions& options) {
  const std::string file = logfile.string();
  std::ifstream in(logfile, std::ios::binary);
  if (!in) throw InputError(file, 0, "cannot open");
  if (!IsValidNodeId(options.agent)) {
    throw std::invalid_argument("agent '" + options.agent + "' is not a node id");
  }
  IpinLogfile log;
  MissionData& m = log.mission;
  const std::string& agent = options.agent;
  std::vector<std::pair<double, Vec3>> accel, gyro;
  std::vector<RawPosition> positions;
  std::vector<std::string> transmitters;
  std::set<std::string> known_transmitters;
  std::size_t unlabelled_positions = 0;
  Clocks clocks;
  std::string line;
  std::size_t n = 0;
  while (io_detail::ReadBoundedLine(in, line, file, n + 1)) {
    ++n;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty() || line.front() == '%') continue;
    if (line.find('\0') != std::string::npos) throw InputError(file, n, "binary data: not a logfile");
    Record r{SplitFields(line), &file, n};
    const std::string_view type = r.fields[0];
    if (type == "ACCE" || type == "GYRO" || type == "MAGN") {
      r.Require(6, "type;AppTimestamp;SensorTimestamp;X;Y;Z");
      const double t = clocks.Check(r, r.Number(1, "AppTimestamp"));
      const Vec3 v(r.Number(3, "X"), r.Number(4, "Y"), r.Number(5, "Z"));
      // The limits imu.csv's reader checks (the samples are interpolated between these).
      if (type == "ACCE" && v.cwiseAbs().maxCoeff() > plausible::kMaxAccelMps2)
        r.Fail(fmt::format("an acceleration of {:g} m/s^2 is not plausible (|a| <= {:g})",
                           v.cwiseAbs().maxCoeff(), plausible::kMaxAccelMps2));
      if (type == "GYRO" && v.cwiseAbs().maxCoeff() > plausible::kMaxGyroRadps)
        r.Fail(fmt::format("an angular rate of {:g} rad/s is not plausible (|w| <= {:g}; deg/s?)",
                           v.cwiseAbs().maxCoeff(), plausible::kMaxGyroRadps));
      if (type == "ACCE") {
        accel.emplace_back(t, v);
      } else if (type == "GYRO") {
        gyro.emplace_back(t, v);
      } else {
        log.magnetometer.push_back({t, v});
      }
    } else if (type == "PRES") {
      r.Require(4, "PRES;AppTimestamp;SensorTimestamp;Pres(mbar)");
      const double t = clocks.Check(r, r.Number(1, "AppTimestamp"));
      const double hpa = r.Number(3, "Pres");
      if (hpa < plausible::kMinPressureHpa || hpa > plausible::kMaxPressureHpa) {
        r.Fail(fmt::format("{} mbar is not a plausible pressure ({:g} to {:g}, as baro.csv)", hpa,
                           plausible::kMinPressureHpa, plausible::kMaxPressureHpa));
      }
      m.baro.push_back({t, agent, hpa});
    } else if (type == "POSI") {
      r.Require(6, "POSI;Timestamp;Counter;Latitude;Longitude;FloorID");
      const double t = clocks.Check(r, r.Number(1, "Timestamp"));
      const double lat = r.Number(3, "Latitude"), lon = r.Number(4, "Longitude");
      const double floor = r.Number(5, "FloorID");
      if (floor != std::round(floor) || std::abs(floor) > 200) {
        r.Fail(fmt::format("FloorID '{}' is not a level", std::string(r.fields[5])));
      }
      const double building = r.fields.size() > 6 && !r.fields[6].empty() ? r.Number(6, "BuildingID") : 0;
      if (lat == 0 && lon == 0) {  // the app's placeholder before a position is labelled
        ++unlabelled_positions;
        continue;
      }
      if (!IsGeodetic(lat, lon)) {
        r.Fail(fmt::format("({}, {}) is not a WGS 84 latitude, longitude", lat, lon));
      }
      positions.push_back({t, lat, lon, static_cast<int>(floor), static_cast<long>(building), n});
    } else if (type == "WIFI") {
      r.Require(6, "WIFI;AppTimestamp;SensorTimestamp;SSID;BSSID[;Frequency];RSS");
      const double t = clocks.Check(r, r.Number(1, "AppTimestamp"));
      const std::size_t k = r.fields.size();
      WifiReading w{t, "", std::nullopt, r.Number(k - 1, "RSS")};
      // With a frequency (MHz) before the RSS, the BSSID is the field before it. An SSID may
      // itself hold ';': the BSSID and what follows are counted from the end.
      const std::optional<double> freq = k >= 7 ? ParseFiniteDouble(r.fields[k - 2]) : std::nullopt;
      if (freq && *freq >= 1000) {
        w.frequency_mhz = *freq;
        w.bssid = std::string(r.fields[k - 3]);
      } else {
        w.bssid = std::string(r.fields[k - 2]);
      }
      if (w.bssid.empty() || w.bssid.find_first_of(",\"") != std::string::npos) {
        r.Fail("BSSID '" + w.bssid.substr(0, 40) + "' is not a MAC address");
      }
      if (w.rssi_dbm < -150 || w.rssi_dbm > 20) r.Fail(fmt::format("RSS {} dBm is not plausible", w.rssi_dbm));
      log.wifi.push_back(std::move(w));
    } else if (type == "BLE4") {
      r.Require(5, "BLE4;AppTimestamp;iBeacon|Eddystone;MAC;RSSI... or BLE4;AppTimestamp;MajorID;MinorID;RSS");
      const double t = clocks.Check(r, r.Number(1, "AppTimestamp"));
      std::string tx;
      double rssi = 0;
      if (r.fields[2] == "iBeacon" || r.fields[2] == "Eddystone") {
        if (r.fields[3].empty()) r.Fail("empty MAC");
        tx = BleNodeId(r.fields[3]);
        rssi = r.Number(4, "RSSI");
      } else {  // the early format: major and minor ids
        r.Number(2, "MajorID");
        r.Number(3, "MinorID");
        tx = BleNodeId(fmt::format("{}-{}", r.fields[2], r.fields[3]));
        rssi = r.Number(4, "RSS");
      }
      if (rssi < -150 || rssi > 20) r.Fail(fmt::format("RSSI {} dBm is not plausible", rssi));
      if (known_transmitters.insert(tx).second) transmitters.push_back(tx);
      m.rssi.push_back({t, agent, tx, rssi});
    } else {
      ++log.unknown_records[std::string(type.substr(0, 16))];
      continue;
    }
    ++log.records[std::string(type)];
  }
  if (log.records.empty()) {
    throw InputError(file, 0,
                     log.unknown_records.empty()
                         ? "no records: not an IPIN logfile"
                         : fmt::format("no record to convert (ACCE, GYRO, MAGN, PRES, POSI, WIFI, "
                                       "BLE4); found only {}",
                                       Counts(log.unknown_records)));
  }

  // IMU: each accelerometer sample with the gyro interpolated at its time.
  std::size_t outside = 0, j = 0;
  for (const auto& [t, a] : accel) {
    while (j + 1 < gyro.size() && gyro[j + 1].first < t) ++j;
    // After the last GYRO sample j is the last index: no bracket (the fuzzer found the read
    // past the end, 2026-12-04).
    if (j + 1 >= gyro.size() || t < gyro[j].first || t > gyro[j + 1].first) {
      ++outside;
      continue;
    }
    const double span = gyro[j + 1].first - gyro[j].first;
    const double w = span > 0 ? (t - gyro[j].first) / span : 0.0;
    m.imu.push_back({t, agent, a, (1 - w) * gyro[j].second + w * gyro[j + 1].second});
  }
  if (outside > 0) {
    log.notes.push_back(fmt::format(
        "{} of {} ACCE samples left out of imu.csv: outside the span of the GYRO samples", outside,
        accel.size()));
  }

  // Truth: POSI in metres of the local frame at the origin.
  if (!positions.empty() || options.origin) {
    const GeoOrigin origin = options.origin.value_or(
        GeoOrigin{positions.front().lat_deg, positions.front().lon_deg, 0.0});
    const LocalFrame frame(origin);
    m.info.geo_origin = origin;
    std::set<long> buildings;
    for (const RawPosition& p : positions) {
      const Vec3 enu = frame.ToEnu(p.lat_deg, p.lon_deg, origin.height_m);
      const double d = std::hypot(enu.x(), enu.y());
      if (d > options.max_venue_m) {
        throw InputError(file, p.line,
                         fmt::format("POSI record: ({}, {}) is {:.0f} m from the origin ({}, {}): "
                                     "outside the venue (max {:.0f} m)",
                                     p.lat_deg, p.lon_deg, d, origin.lat_deg, origin.lon_deg,
                                     options.max_venue_m));
      }
      m.truth.push_back({p.t, agent, Vec3(enu.x(), enu.y(), p.floor * kDefaultStoreyM), p.floor});
      buildings.insert(p.building);
    }
    if (buildings.size() > 1) {
      log.notes.push_back(fmt::format("POSI in {} buildings ({}): one frame for all",
                                      buildings.size(), fmt::join(buildings, ", ")));
    }
  }
  if (unlabelled_positions > 0) {
    log.notes.push_back(fmt::format(
        "{} POSI records at (0, 0) left out: the app's placeholder for an unlabelled position",
        unlabelled_positions));
  }
  if (!log.unknown_records.empty()) {
    log.notes.push_back("record types not converted: " + Counts(log.unknown_records));
  }

  m.info.name = logfile.stem().string();
  m.info.description = fmt::format(
      "IPIN logfile {} (GetSensorData): {}; times are the app's timestamps", logfile.filename().string(),
      Counts(log.records));
  NodeInfo phone;
  phone.id = agent;
  phone.kind = NodeKind::kAgent;
  if (!m.truth.empty()) {
    phone.start = m.truth.front().position_n;
    phone.start_sigma_m = 2.0;  // a labelled point, read off a map
  }
  m.info.nodes.push_back(phone);
  for (const std::string& tx : transmitters) {
    NodeInfo beacon;
    beacon.id = tx;
    beacon.kind = NodeKind::kLandmark;
    m.info.nodes.push_back(beacon);
  }
  return log;
}

void WriteIpinMission(const IpinLogfile& log, const std::filesystem::path& out_dir) {
  WriteMissionDirectory(out_dir, log.mission, nullptr);
  if (!log.wifi.empty()) {
    CsvWriter w((out_dir / "wifi.csv").string(), {"t", "rx", "bssid", "frequency_mhz", "rssi_dbm"});
    for (const WifiReading& r : log.wifi) {
      w.Add(r.t).Add(log.mission.info.nodes.front().id).Add(r.bssid).Add(r.frequency_mhz).Add(r.rssi_dbm);
      w.EndRow();
    }
    w.Close();
  }
  if (!log.magnetometer.empty()) {
    CsvWriter w((out_dir / "magnetometer.csv").string(), {"t", "agent", "mx_ut", "my_ut", "mz_ut"});
    for (const MagnetometerSample& s : log.magnetometer) {
      w.Add(s.t).Add(log.mission.info.nodes.front().id).Add(s.field_ut.x()).Add(s.field_ut.y()).Add(s.field_ut.z());
      w.EndRow();
    }
    w.Close();
  }
}

}  // namespace trailmark

// SPDX-License-Identifier: MIT
#include "trailmark/io/streams.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <type_traits>

#include "trailmark/core/error.h"

namespace trailmark {
namespace {

// Per row kind: header, required/optional columns, parse and format. Columns are looked up
// once per file; `cols` holds their indices in the order of kColumns (-1 when optional and
// absent).
struct ColumnSpec {
  const char* name;
  bool required;
};

template <class Row>
struct Layout;

/// A row's node ids (one or two), without an allocation per row.
struct RowIds {
  std::array<std::string_view, 2> id;
  std::size_t n = 0;
  RowIds(std::string_view a) : id{a, {}}, n(1) {}
  RowIds(std::string_view a, std::string_view b) : id{a, b}, n(2) {}
  std::string_view front() const { return id[0]; }
  const std::string_view* begin() const { return id.data(); }
  const std::string_view* end() const { return id.data() + n; }
};

// Plausibility bounds: values outside them are a wrong unit or a corrupted row, not data.
constexpr double kMaxAbsTimeS = 1e10;        // ~317 years: Unix-epoch seconds still fit
constexpr double kMinRssiDbm = -200.0;       // far below any receiver's sensitivity
constexpr double kMaxRssiDbm = 60.0;         // above any transmitter's power (1 kW)
constexpr double kMaxStepLengthM = 100.0;    // one row of steps.csv
using plausible::kMaxAccelMps2;              // (high-g accelerometers: 400 g)
using plausible::kMaxGyroRadps;
using plausible::kMaxPressureHpa;
using plausible::kMinPressureHpa;
constexpr double kMaxStepVarianceM2 = kMaxStepLengthM * kMaxStepLengthM;  // a step's own scale
constexpr double kMaxRangeM = 1e5;           // 100 km: beyond any ranging radio or ultrasound
constexpr double kMaxRangeSigmaM = 1e4;      // a range known to 10 km says nothing
constexpr double kMaxAbsAngleRad = 1e3;      // as mission.json's headings
constexpr double kMaxAngleSigmaRad = 100.0;  // beyond a full turn many times: not radians
constexpr double kMaxDeviceGapS = kMaxDeviceTimeGapS;  // one device's rows a day apart

// The events of the spec (mission-format.md, events.csv).
constexpr std::string_view kEventNames[] = {"drop", "wake", "enter", "exit", "stop", "go"};
// The range kinds of the spec (mission-format.md, ranges.csv); empty: not said.
constexpr std::string_view kRangeKinds[] = {"ultrasound", "uwb", "rssi"};

std::string_view TrimCell(std::string_view v) {
  const auto first = v.find_first_not_of(" \t");
  if (first == std::string_view::npos) return {};
  return v.substr(first, v.find_last_not_of(" \t") - first + 1);
}

// A name that must be one of the spec's (`names`, listed as `listed`): refused with the line,
// and the lowercase name suggested when only the case differs.
template <std::size_t N>
void CheckName(const CsvReader& c, const char* column, const std::string& name,
               const std::string_view (&names)[N], const char* what) {
  if (std::find(std::begin(names), std::end(names), name) != std::end(names)) return;
  std::string lower = name;
  for (char& ch : lower) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
  const bool case_only = std::find(std::begin(names), std::end(names), lower) != std::end(names);
  std::string listed;
  for (const std::string_view n : names) listed += (listed.empty() ? "" : ", ") + std::string(n);
  c.Fail(fmt::format("column '{}': '{}' is not {} of the mission format ({}){}", column, name, what,
                     listed, case_only ? fmt::format("; names are lowercase: '{}'?", lower) : ""));
}

void CheckAtMost(const CsvReader& c, const char* what, double value, double max,
                 const char* unit) {
  if (!(value <= max)) {
    c.Fail(fmt::format("column '{}': {:g} is not plausible (at most {:g} {})", what, value, max,
                       unit));
  }
}

void CheckTime(const CsvReader& c, double t) {
  if (std::abs(t) > kMaxAbsTimeS) {
    c.Fail(fmt::format("time {} is not plausible (|t| > {:g} s; times are seconds)", t,
                       kMaxAbsTimeS));
  }
}

template <>
struct Layout<ImuSample> {
  static constexpr ColumnSpec kColumns[] = {{"t", true},  {"agent", true}, {"ax", true},
                                            {"ay", true}, {"az", true},    {"gx", true},
                                            {"gy", true}, {"gz", true}};
  static double Time(const ImuSample& r) { return r.t; }
  static void Parse(const CsvReader& c, const std::vector<int>& k, ImuSample& r) {
    r.t = c.Double(k[0]);
    r.agent.assign(c.NodeId(k[1]));
    r.accel_b = Vec3(c.Double(k[2]), c.Double(k[3]), c.Double(k[4]));
    r.gyro_b = Vec3(c.Double(k[5]), c.Double(k[6]), c.Double(k[7]));
    if (r.accel_b.cwiseAbs().maxCoeff() > kMaxAccelMps2) {
      c.Fail(fmt::format("an acceleration of {:g} m/s^2 is beyond any foot IMU (|a| <= {:g})",
                         r.accel_b.cwiseAbs().maxCoeff(), kMaxAccelMps2));
    }
    if (r.gyro_b.cwiseAbs().maxCoeff() > kMaxGyroRadps) {
      c.Fail(fmt::format("an angular rate of {:g} rad/s is beyond any gyro (|w| <= {:g}; deg/s?)",
                         r.gyro_b.cwiseAbs().maxCoeff(), kMaxGyroRadps));
    }
  }
  static RowIds Ids(const ImuSample& r) { return {r.agent}; }
  static void Format(CsvWriter& w, const ImuSample& r) {
    w.Add(r.t).Add(r.agent).Add(r.accel_b.x()).Add(r.accel_b.y()).Add(r.accel_b.z());
    w.Add(r.gyro_b.x()).Add(r.gyro_b.y()).Add(r.gyro_b.z());
  }
};

template <>
struct Layout<Step> {
  static constexpr ColumnSpec kColumns[] = {{"t0", true},  {"t1", true},  {"agent", true},
                                            {"dx", true},  {"dy", true},  {"dz", false},
                                            {"sxx", false}, {"syy", false}, {"szz", false}};
  static double Time(const Step& r) { return r.t1; }
  static void Parse(const CsvReader& c, const std::vector<int>& k, Step& r) {
    r.t0 = c.Double(k[0]);
    r.t1 = c.Double(k[1]);
    CheckTime(c, r.t0);
    if (r.t1 < r.t0) c.Fail(fmt::format("t1 = {} is before t0 = {}", r.t1, r.t0));
    r.agent.assign(c.NodeId(k[2]));
    r.delta_n = Vec3(c.Double(k[3]), c.Double(k[4]), c.OptionalDouble(k[5]).value_or(0.0));
    if (r.delta_n.norm() > kMaxStepLengthM) {
      c.Fail(fmt::format("a step of {:g} m is not a plausible foot displacement (> {:g} m)",
                         r.delta_n.norm(), kMaxStepLengthM));
    }
    auto sxx = c.OptionalDouble(k[6]);
    auto syy = c.OptionalDouble(k[7]);
    const auto szz = c.OptionalDouble(k[8]);
    // One horizontal variance given and the other empty (unknown): the step's error taken as
    // round, the given one for both, rather than both dropped for the pipeline's default.
    if (sxx && !syy) syy = sxx;
    if (syy && !sxx) sxx = syy;
    if (sxx && syy) {
      if (*sxx < 0 || *syy < 0 || (szz && *szz < 0)) c.Fail("negative variance");
      CheckAtMost(c, "sxx", *sxx, kMaxStepVarianceM2, "m^2");
      CheckAtMost(c, "syy", *syy, kMaxStepVarianceM2, "m^2");
      if (szz) CheckAtMost(c, "szz", *szz, kMaxStepVarianceM2, "m^2");
      r.variance_m2 = Vec3(*sxx, *syy, szz.value_or(0.0));
    } else {
      r.variance_m2.reset();
    }
  }
  static RowIds Ids(const Step& r) { return {r.agent}; }
  static void Format(CsvWriter& w, const Step& r) {
    w.Add(r.t0).Add(r.t1).Add(r.agent).Add(r.delta_n.x()).Add(r.delta_n.y()).Add(r.delta_n.z());
    if (r.variance_m2) {
      w.Add(r.variance_m2->x()).Add(r.variance_m2->y()).Add(r.variance_m2->z());
    } else {
      w.Add(std::nullopt).Add(std::nullopt).Add(std::nullopt);
    }
  }
};

template <>
struct Layout<RssiPacket> {
  static constexpr ColumnSpec kColumns[] = {
      {"t", true}, {"rx", true}, {"tx", true}, {"rssi_dbm", true}};
  static double Time(const RssiPacket& r) { return r.t; }
  static void Parse(const CsvReader& c, const std::vector<int>& k, RssiPacket& r) {
    r.t = c.Double(k[0]);
    r.rx.assign(c.NodeId(k[1]));
    r.tx.assign(c.NodeId(k[2]));
    r.rssi_dbm = c.Double(k[3]);
    if (r.rssi_dbm < kMinRssiDbm || r.rssi_dbm > kMaxRssiDbm) {
      c.Fail(fmt::format("column 'rssi_dbm': {} is not a received power in dBm (expected {:g} "
                         "to {:g})",
                         r.rssi_dbm, kMinRssiDbm, kMaxRssiDbm));
    }
  }
  static RowIds Ids(const RssiPacket& r) { return {r.rx, r.tx}; }
  static void Format(CsvWriter& w, const RssiPacket& r) {
    w.Add(r.t).Add(r.rx).Add(r.tx).Add(r.rssi_dbm);
  }
};

template <>
struct Layout<RangeMeasurement> {
  static constexpr ColumnSpec kColumns[] = {{"t", true},     {"a", true},     {"b", true},
                                            {"range", true}, {"sigma", false}, {"kind", false}};
  static double Time(const RangeMeasurement& r) { return r.t; }
  static void Parse(const CsvReader& c, const std::vector<int>& k, RangeMeasurement& r) {
    r.t = c.Double(k[0]);
    r.a.assign(c.NodeId(k[1]));
    r.b.assign(c.NodeId(k[2]));
    r.range_m = c.Double(k[3]);
    if (r.range_m < 0) c.Fail(fmt::format("column 'range': negative range {}", r.range_m));
    CheckAtMost(c, "range", r.range_m, kMaxRangeM, "m");
    r.sigma_m = c.OptionalDouble(k[4]);
    if (r.sigma_m && *r.sigma_m <= 0) c.Fail("column 'sigma': must be positive");
    if (r.sigma_m) CheckAtMost(c, "sigma", *r.sigma_m, kMaxRangeSigmaM, "m");
    r.kind = k[5] >= 0 ? std::string(TrimCell(c.Field(k[5]))) : std::string();
    if (!r.kind.empty()) CheckName(c, "kind", r.kind, kRangeKinds, "a range kind");
  }
  static RowIds Ids(const RangeMeasurement& r) { return {r.a, r.b}; }
  static void Format(CsvWriter& w, const RangeMeasurement& r) {
    w.Add(r.t).Add(r.a).Add(r.b).Add(r.range_m).Add(r.sigma_m).Add(r.kind);
  }
};

template <>
struct Layout<BearingMeasurement> {
  static constexpr ColumnSpec kColumns[] = {
      {"t", true}, {"a", true}, {"b", true}, {"bearing", true}, {"sigma", false}};
  static double Time(const BearingMeasurement& r) { return r.t; }
  static void Parse(const CsvReader& c, const std::vector<int>& k, BearingMeasurement& r) {
    r.t = c.Double(k[0]);
    r.a.assign(c.NodeId(k[1]));
    r.b.assign(c.NodeId(k[2]));
    r.bearing_rad = c.Double(k[3]);
    CheckAtMost(c, "bearing", std::abs(r.bearing_rad), kMaxAbsAngleRad, "rad in magnitude");
    r.sigma_rad = c.OptionalDouble(k[4]);
    if (r.sigma_rad && *r.sigma_rad <= 0) c.Fail("column 'sigma': must be positive");
    if (r.sigma_rad) CheckAtMost(c, "sigma", *r.sigma_rad, kMaxAngleSigmaRad, "rad");
  }
  static RowIds Ids(const BearingMeasurement& r) { return {r.a, r.b}; }
  static void Format(CsvWriter& w, const BearingMeasurement& r) {
    w.Add(r.t).Add(r.a).Add(r.b).Add(r.bearing_rad).Add(r.sigma_rad);
  }
};

template <>
struct Layout<MissionEvent> {
  static constexpr ColumnSpec kColumns[] = {
      {"t", true}, {"agent", true}, {"event", true}, {"node", false}};
  static double Time(const MissionEvent& r) { return r.t; }
  static void Parse(const CsvReader& c, const std::vector<int>& k, MissionEvent& r) {
    r.t = c.Double(k[0]);
    r.agent.assign(c.NodeId(k[1]));
    r.event.assign(TrimCell(c.Field(k[2])));
    if (r.event.empty()) c.Fail("column 'event': empty");
    CheckName(c, "event", r.event, kEventNames, "an event");
    r.node.clear();
    if (k[3] >= 0 && !TrimCell(c.Field(k[3])).empty()) r.node.assign(c.NodeId(k[3]));
    if (r.event == "drop" && r.node.empty()) c.Fail("a 'drop' event needs the dropped node id");
  }
  static RowIds Ids(const MissionEvent& r) {
    if (r.node.empty()) return RowIds(r.agent);
    return RowIds(r.agent, r.node);
  }
  static void Format(CsvWriter& w, const MissionEvent& r) {
    w.Add(r.t).Add(r.agent).Add(r.event).Add(r.node);
  }
};

template <>
struct Layout<BaroSample> {
  static constexpr ColumnSpec kColumns[] = {{"t", true}, {"agent", true}, {"pressure_hpa", true}};
  static double Time(const BaroSample& r) { return r.t; }
  static void Parse(const CsvReader& c, const std::vector<int>& k, BaroSample& r) {
    r.t = c.Double(k[0]);
    r.agent.assign(c.NodeId(k[1]));
    r.pressure_hpa = c.Double(k[2]);
    if (r.pressure_hpa < kMinPressureHpa || r.pressure_hpa > kMaxPressureHpa) {
      c.Fail(fmt::format("column 'pressure_hpa': {} is not an air pressure in hPa (expected {:g} "
                         "to {:g}; Pa or kPa?)",
                         r.pressure_hpa, kMinPressureHpa, kMaxPressureHpa));
    }
  }
  static RowIds Ids(const BaroSample& r) { return {r.agent}; }
  static void Format(CsvWriter& w, const BaroSample& r) {
    w.Add(r.t).Add(r.agent).Add(r.pressure_hpa);
  }
};

/// A level in a `floor` cell: an integer (spec 1.1).
std::optional<int> OptionalLevel(const CsvReader& c, int col) {
  const std::optional<double> v = c.OptionalDouble(col);
  if (!v) return std::nullopt;
  if (std::floor(*v) != *v || std::abs(*v) > 1000) {
    c.Fail(fmt::format("column 'floor': {:g} is not a level (an integer)", *v));
  }
  return static_cast<int>(*v);
}

void AddLevel(CsvWriter& w, const std::optional<int>& level) {
  w.Add(level ? std::optional<double>(*level) : std::nullopt);
}

template <>
struct Layout<TruthSample> {
  static constexpr ColumnSpec kColumns[] = {
      {"t", true}, {"id", true}, {"x", true}, {"y", true}, {"z", false}, {"floor", false}};
  static constexpr std::size_t kFloorColumns = 1;  ///< the trailing 1.1 columns
  static double Time(const TruthSample& r) { return r.t; }
  static void Parse(const CsvReader& c, const std::vector<int>& k, TruthSample& r) {
    r.t = c.Double(k[0]);
    r.id.assign(c.NodeId(k[1]));
    r.position_n = Vec3(c.Double(k[2]), c.Double(k[3]), c.OptionalDouble(k[4]).value_or(0.0));
    r.floor = OptionalLevel(c, k[5]);
  }
  static RowIds Ids(const TruthSample& r) { return {r.id}; }
  static void Format(CsvWriter& w, const TruthSample& r) {
    w.Add(r.t).Add(r.id).Add(r.position_n.x()).Add(r.position_n.y()).Add(r.position_n.z());
  }
  static void FormatFloor(CsvWriter& w, const TruthSample& r) { AddLevel(w, r.floor); }
};

template <>
struct Layout<Estimate> {
  static constexpr ColumnSpec kColumns[] = {
      {"t", true},     {"id", true},      {"x", true},   {"y", true},   {"z", false},
      {"sxx", false},  {"sxy", false},    {"syy", false}, {"szz", false}, {"floor", false}};
  static constexpr std::size_t kFloorColumns = 2;
  static double Time(const Estimate& r) { return r.t; }
  static void Parse(const CsvReader& c, const std::vector<int>& k, Estimate& r) {
    r.t = c.Double(k[0]);
    r.id.assign(c.NodeId(k[1]));
    r.position_n = Vec3(c.Double(k[2]), c.Double(k[3]), c.OptionalDouble(k[4]).value_or(0.0));
    // Empty = unknown (spec): a covariance with any of its cells empty is not known.
    const auto sxx = c.OptionalDouble(k[5]), sxy = c.OptionalDouble(k[6]),
               syy = c.OptionalDouble(k[7]);
    r.covariance_known = sxx && sxy && syy;
    r.sxx = r.covariance_known ? *sxx : 0.0;
    r.sxy = r.covariance_known ? *sxy : 0.0;
    r.syy = r.covariance_known ? *syy : 0.0;
    r.szz = c.OptionalDouble(k[8]);
    r.floor = OptionalLevel(c, k[9]);
    if (r.sxx < 0 || r.syy < 0 || (r.szz && *r.szz < 0)) c.Fail("negative variance");
  }
  static RowIds Ids(const Estimate& r) { return {r.id}; }
  static void Format(CsvWriter& w, const Estimate& r) {
    w.Add(r.t).Add(r.id).Add(r.position_n.x()).Add(r.position_n.y()).Add(r.position_n.z());
    if (r.covariance_known) {
      w.Add(r.sxx).Add(r.sxy).Add(r.syy);
    } else {
      const std::optional<double> unknown;
      w.Add(unknown).Add(unknown).Add(unknown);
    }
  }
  static void FormatFloor(CsvWriter& w, const Estimate& r) {
    w.Add(r.szz);
    AddLevel(w, r.floor);
  }
};

/// Rows whose first id is the agent column (spec: steps, IMU, events, barometer).
template <class Row>
constexpr bool HasAgentColumn() {
  return std::is_same_v<Row, Step> || std::is_same_v<Row, ImuSample> ||
         std::is_same_v<Row, MissionEvent> || std::is_same_v<Row, BaroSample>;
}

template <class Row>
constexpr std::size_t FloorColumns() {
  if constexpr (requires { Layout<Row>::kFloorColumns; }) {
    return Layout<Row>::kFloorColumns;
  } else {
    return 0;
  }
}

template <class Row>
std::vector<std::string> Header(bool floor_columns) {
  std::vector<std::string> h;
  for (const auto& c : Layout<Row>::kColumns) h.emplace_back(c.name);
  if (!floor_columns) h.resize(h.size() - FloorColumns<Row>());
  return h;
}

}  // namespace

template <class Row>
RowReader<Row>::RowReader(std::string path, const NodeRegistry* registry,
                          CsvReader::Options options)
    : csv_(std::move(path), options), registry_(registry) {
  for (const auto& c : Layout<Row>::kColumns) {
    columns_.push_back(c.required ? csv_.RequireColumn(c.name) : csv_.Column(c.name));
  }
}

template <class Row>
RowReader<Row>::RowReader(std::string name, std::string_view content,
                          const NodeRegistry* registry, CsvReader::Options options)
    : csv_(std::move(name), content, options), registry_(registry) {
  for (const auto& c : Layout<Row>::kColumns) {
    columns_.push_back(c.required ? csv_.RequireColumn(c.name) : csv_.Column(c.name));
  }
}

template <class Row>
RowReader<Row>::~RowReader() = default;

template <class Row>
bool RowReader<Row>::Next(Row& row) {
  if (!csv_.Next()) return false;
  Layout<Row>::Parse(csv_, columns_, row);
  const double t = Layout<Row>::Time(row);
  CheckTime(csv_, t);
  if (t < last_t_) {
    csv_.Fail(fmt::format("row out of time order: t = {} comes after t = {} (line {}); rows "
                          "must be in non-decreasing time",
                          t, last_t_, last_t_line_));
  }
  last_t_ = t;
  last_t_line_ = csv_.line();
  // One device's rows: a jump of more than a day is a stray time (a clock reset, a unit slip),
  // not a pause of an incident; refused with both lines, never integrated over.
  const std::string_view device = Layout<Row>::Ids(row).front();
  auto it = last_device_ != device_.end() && last_device_->first == device ? last_device_
                                                                          : device_.find(device);
  if (it == device_.end()) {
    last_device_ =
        device_.emplace(std::string(device), std::pair<double, std::size_t>{t, csv_.line()}).first;
  } else {
    last_device_ = it;
    if (t - it->second.first > kMaxDeviceGapS) {
      csv_.Fail(fmt::format("'{}' jumps from t = {} (line {}) to t = {}: more than {:g} s between "
                            "one device's rows is a stray time, not data",
                            device, it->second.first, it->second.second, t, kMaxDeviceGapS));
    }
    it->second = {t, csv_.line()};
  }
  if (registry_ != nullptr) {
    for (std::string_view id : Layout<Row>::Ids(row)) {
      if (!registry_->Contains(id)) {
        csv_.Fail(fmt::format("unknown node id '{}': not declared in mission.json nor dropped "
                              "in events.csv",
                              id));
      }
    }
    // The agent column (steps, IMU, barometer, events) names a moving person.
    if constexpr (HasAgentColumn<Row>()) {
      const std::string_view agent = Layout<Row>::Ids(row).front();
      if (const auto kind = registry_->Kind(agent); kind && *kind != NodeKind::kAgent) {
        csv_.Fail(fmt::format("'{}' is a {} in mission.json: the agent column names an agent",
                              agent, ToString(*kind)));
      }
    }
  }
  ++rows_;
  return true;
}

template <class Row>
RowWriter<Row>::RowWriter(std::string path, bool floor_columns)
    : floor_columns_(floor_columns && FloorColumns<Row>() > 0),
      csv_(std::move(path), Header<Row>(floor_columns_)) {}

template <class Row>
RowWriter<Row>::RowWriter(std::string name, std::vector<std::string>* lines, bool floor_columns)
    : floor_columns_(floor_columns && FloorColumns<Row>() > 0),
      csv_(std::move(name), Header<Row>(floor_columns_), lines) {}

template <class Row>
void RowWriter<Row>::Write(const Row& row) {
  Layout<Row>::Format(csv_, row);
  if constexpr (FloorColumns<Row>() > 0) {
    if (floor_columns_) Layout<Row>::FormatFloor(csv_, row);
  }
  csv_.EndRow();
}

#define TRAILMARK_INSTANTIATE(Row) \
  template class RowReader<Row>;   \
  template class RowWriter<Row>;
TRAILMARK_INSTANTIATE(ImuSample)
TRAILMARK_INSTANTIATE(Step)
TRAILMARK_INSTANTIATE(RssiPacket)
TRAILMARK_INSTANTIATE(RangeMeasurement)
TRAILMARK_INSTANTIATE(BearingMeasurement)
TRAILMARK_INSTANTIATE(MissionEvent)
TRAILMARK_INSTANTIATE(BaroSample)
TRAILMARK_INSTANTIATE(TruthSample)
TRAILMARK_INSTANTIATE(Estimate)
#undef TRAILMARK_INSTANTIATE

}  // namespace trailmark

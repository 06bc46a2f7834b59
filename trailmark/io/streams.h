// SPDX-License-Identifier: MIT
#pragma once
/// Typed, streaming readers and writers for every CSV stream of the mission format.
///
///   RowReader<Step> reader(dir / "steps.csv", &registry);
///   Step step;
///   while (reader.Next(step)) { ... }
///
/// Each row is checked as it is read: required columns present, numbers finite, node ids
/// well formed and (when a registry is given) declared, rows in non-decreasing time.

#include <algorithm>
#include <functional>
#include <map>
#include <set>
#include <stdexcept>
#include <string>
#include <string_view>
#include <type_traits>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "trailmark/core/measurements.h"
#include "trailmark/io/csv.h"

namespace trailmark {

/// The readers' plausibility limits that a converter writing these streams keeps to as well: a
/// converted mission that our own readers refuse is a converter's bug (the fuzzer found an IPIN
/// logfile's 1,130 hPa, 2026-12-05).
namespace plausible {
inline constexpr double kMaxAccelMps2 = 1e4;      ///< ~1,000 g: beyond every accelerometer
inline constexpr double kMaxGyroRadps = 200.0;    ///< beyond any MEMS range (2000 deg/s = 35 rad/s)
inline constexpr double kMinPressureHpa = 300.0;  ///< above the summit of Everest (~330 hPa)
inline constexpr double kMaxPressureHpa = 1100.0;  ///< below the deepest mine's air (~1080 hPa)
}  // namespace plausible

/// Hashes strings and string views alike (look-ups by std::string_view without a copy).
struct StringHash {
  using is_transparent = void;
  std::size_t operator()(std::string_view s) const { return std::hash<std::string_view>{}(s); }
};

/// Ids a stream may use: those declared in mission.json plus crumbs introduced by drops.
class NodeRegistry {
 public:
  void Add(std::string id) { ids_.insert(std::move(id)); }
  /// With its kind: a row's agent column (steps, IMU, barometer, events) must then name an agent.
  void Add(std::string id, NodeKind kind) {
    kinds_[id] = kind;
    ids_.insert(std::move(id));
  }
  bool Contains(std::string_view id) const { return ids_.find(id) != ids_.end(); }
  /// The kind it was added with; nullopt when added without one.
  std::optional<NodeKind> Kind(std::string_view id) const {
    const auto it = kinds_.find(id);
    return it == kinds_.end() ? std::nullopt : std::optional<NodeKind>(it->second);
  }
  std::size_t size() const { return ids_.size(); }

 private:
  std::unordered_set<std::string, StringHash, std::equal_to<>> ids_;
  std::unordered_map<std::string, NodeKind, StringHash, std::equal_to<>> kinds_;
};

/// Column layout and parsing of one row kind (specialised in streams.cpp).
/// One device's rows more than this apart (s) are a stray time (a clock reset, a unit slip),
/// not a pause of an incident: refused by the readers and by the live journal (issue 30).
inline constexpr double kMaxDeviceTimeGapS = 86400.0;

template <class Row>
struct StreamTraits;

template <class Row>
class RowReader {
 public:
  /// `registry` may be null (then ids are only checked for their syntax).
  explicit RowReader(std::string path, const NodeRegistry* registry = nullptr,
                     CsvReader::Options options = {});
  /// A document held in memory (see CsvReader); `content` must outlive the reader.
  RowReader(std::string name, std::string_view content, const NodeRegistry* registry,
            CsvReader::Options options);
  ~RowReader();
  /// Reads the next row into `row`; false at end of file. Throws InputError on bad input.
  bool Next(Row& row);
  std::size_t rows() const { return rows_; }
  const CsvReader& csv() const { return csv_; }

 private:
  CsvReader csv_;
  const NodeRegistry* registry_;
  std::vector<int> columns_;
  double last_t_ = -std::numeric_limits<double>::infinity();
  std::size_t last_t_line_ = 0;
  std::size_t rows_ = 0;
  /// Per device (the row's first id): its latest time and line.
  std::unordered_map<std::string, std::pair<double, std::size_t>, StringHash, std::equal_to<>>
      device_;
  decltype(device_)::iterator last_device_ = device_.end();  ///< the previous row's device
};

/// Whether rows need the 1.1 columns (truth: `floor`; estimates: `szz,floor`): some row has them.
inline bool NeedsFloorColumns(const std::vector<TruthSample>& rows) {
  return std::any_of(rows.begin(), rows.end(), [](const TruthSample& r) { return r.floor.has_value(); });
}
inline bool NeedsFloorColumns(const std::vector<Estimate>& rows) {
  return std::any_of(rows.begin(), rows.end(),
                     [](const Estimate& r) { return r.szz.has_value() || r.floor.has_value(); });
}
template <class Row>
bool NeedsFloorColumns(const std::vector<Row>&) {
  return false;
}

template <class Row>
class RowWriter {
 public:
  /// `floor_columns`: also the 1.1 columns of truth (`floor`) and estimates (`szz,floor`),
  /// empty cells where a row has none; other streams have none.
  explicit RowWriter(std::string path, bool floor_columns = false);
  /// Canonical lines (header first, no newlines) into `lines` instead of a file.
  RowWriter(std::string name, std::vector<std::string>* lines, bool floor_columns = false);
  void Write(const Row& row);
  void Close() { csv_.Close(); }
  std::size_t rows() const { return csv_.rows(); }

 private:
  bool floor_columns_;
  CsvWriter csv_;
};

/// Reads a whole (small) stream into memory; use RowReader for large ones.
template <class Row>
std::vector<Row> ReadAll(const std::string& path, const NodeRegistry* registry = nullptr) {
  RowReader<Row> reader(path, registry);
  std::vector<Row> rows;
  Row row;
  while (reader.Next(row)) rows.push_back(row);
  return rows;
}

/// Parses a whole CSV document held in memory (e.g. a request body) named `name` in errors;
/// `lines` (when not null) receives each row's 1-based line in the document.
template <class Row>
std::vector<Row> ParseAll(const std::string& name, std::string_view content,
                          const NodeRegistry* registry = nullptr,
                          std::vector<std::size_t>* lines = nullptr) {
  CsvReader::Options options;
  // No line is longer than the document: a buffer of its size suffices.
  options.chunk_bytes = std::min<std::size_t>(options.chunk_bytes, content.size() + 1);
  options.max_line_bytes = std::min<std::size_t>(options.max_line_bytes, content.size() + 1);
  RowReader<Row> reader(name, content, registry, options);
  std::vector<Row> rows;
  Row row;
  while (reader.Next(row)) {
    rows.push_back(row);
    if (lines) lines->push_back(reader.csv().line());
  }
  return rows;
}

/// The canonical CSV lines of rows (first the header), as WriteAll would write them.
template <class Row>
std::vector<std::string> FormatAll(const std::vector<Row>& rows) {
  std::vector<std::string> lines;
  RowWriter<Row> writer("(memory)", &lines, NeedsFloorColumns(rows));
  for (const auto& r : rows) writer.Write(r);
  return lines;
}

template <class Row>
void WriteAll(const std::string& path, const std::vector<Row>& rows) {
  RowWriter<Row> writer(path, NeedsFloorColumns(rows));
  for (const auto& r : rows) writer.Write(r);
  writer.Close();
}

/// The file name of each stream in a mission directory ("steps.csv", ...).
template <class Row>
const char* StreamFileName() {
  return StreamTraits<Row>::kFileName;
}

template <>
struct StreamTraits<ImuSample> {
  static constexpr const char* kFileName = "imu.csv";
};
template <>
struct StreamTraits<Step> {
  static constexpr const char* kFileName = "steps.csv";
};
template <>
struct StreamTraits<RssiPacket> {
  static constexpr const char* kFileName = "rssi.csv";
};
template <>
struct StreamTraits<RangeMeasurement> {
  static constexpr const char* kFileName = "ranges.csv";
};
template <>
struct StreamTraits<BearingMeasurement> {
  static constexpr const char* kFileName = "bearings.csv";
};
template <>
struct StreamTraits<MissionEvent> {
  static constexpr const char* kFileName = "events.csv";
};
template <>
struct StreamTraits<BaroSample> {
  static constexpr const char* kFileName = "baro.csv";
};
template <>
struct StreamTraits<TruthSample> {
  static constexpr const char* kFileName = "truth.csv";
};
template <>
struct StreamTraits<Estimate> {
  static constexpr const char* kFileName = "estimates.csv";
};

/// Calls `f(std::type_identity<Row>{})` with the row type of a stream file: the measurement
/// streams ("steps.csv", "imu.csv", "rssi.csv", "ranges.csv", "bearings.csv", "events.csv",
/// "baro.csv") and, when `kOutputs`, "truth.csv" and "estimates.csv". Throws
/// std::invalid_argument naming the known files for any other name.
template <bool kOutputs = false, class F>
decltype(auto) WithStreamRowType(std::string_view file, F&& f) {
  if (file == "steps.csv") return f(std::type_identity<Step>{});
  if (file == "imu.csv") return f(std::type_identity<ImuSample>{});
  if (file == "rssi.csv") return f(std::type_identity<RssiPacket>{});
  if (file == "ranges.csv") return f(std::type_identity<RangeMeasurement>{});
  if (file == "bearings.csv") return f(std::type_identity<BearingMeasurement>{});
  if (file == "events.csv") return f(std::type_identity<MissionEvent>{});
  if (file == "baro.csv") return f(std::type_identity<BaroSample>{});
  if constexpr (kOutputs) {
    if (file == "truth.csv") return f(std::type_identity<TruthSample>{});
    if (file == "estimates.csv") return f(std::type_identity<Estimate>{});
  }
  throw std::invalid_argument(
      "unknown stream '" + std::string(file) +
      "' (steps.csv, imu.csv, rssi.csv, ranges.csv, bearings.csv, events.csv, baro.csv" +
      (kOutputs ? ", truth.csv, estimates.csv)" : ")"));
}

}  // namespace trailmark

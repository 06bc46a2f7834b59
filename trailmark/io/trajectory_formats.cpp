// SPDX-License-Identifier: MIT
#include "trailmark/io/trajectory_formats.h"

#include <fmt/format.h>

#include <charconv>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <optional>
#include <string_view>

#include "trailmark/core/error.h"
#include "trailmark/io/csv.h"
#include "trailmark/io/json_input.h"

namespace trailmark {
namespace {

template <class Row>
std::string Tum(const std::vector<Row>& rows, const std::string& id) {
  std::string out = "# timestamp tx ty tz qx qy qz qw (trailmark: no attitude, identity quaternion)\n";
  for (const Row& r : rows) {
    if (r.id != id) continue;
    fmt::format_to(std::back_inserter(out), "{} {} {} {} 0 0 0 1\n", r.t, r.position_n.x(),
                   r.position_n.y(), r.position_n.z());
  }
  return out;
}

/// The numbers of an ASL (EuRoC) CSV row: comma-separated, at least `min_fields`.
std::vector<double> AslFields(std::string_view line, std::size_t min_fields, const std::string& file,
                              std::size_t line_no) {
  std::vector<double> v;
  std::size_t start = 0;
  while (start <= line.size()) {
    const std::size_t comma = line.find(',', start);
    std::string_view cell = line.substr(start, comma == line.npos ? line.npos : comma - start);
    while (!cell.empty() && cell.front() == ' ') cell.remove_prefix(1);
    while (!cell.empty() && (cell.back() == ' ' || cell.back() == '\r')) cell.remove_suffix(1);
    const std::optional<double> x = ParseFiniteDouble(cell);
    if (!x) {
      throw InputError(file, line_no, fmt::format("field {}: '{}' is not a finite number",
                                                  v.size() + 1, std::string(cell).substr(0, 40)));
    }
    v.push_back(*x);
    if (comma == line.npos) break;
    start = comma + 1;
  }
  if (v.size() < min_fields) {
    throw InputError(file, line_no,
                     fmt::format("expected at least {} fields, found {}", min_fields, v.size()));
  }
  return v;
}

/// Rows of an ASL data.csv: (timestamp ns, the other fields). '#' lines are headers.
std::vector<std::pair<std::int64_t, std::vector<double>>> ReadAsl(const std::filesystem::path& path,
                                                                  std::size_t min_fields) {
  std::ifstream in(path);
  if (!in) throw InputError(path.string(), 0, "cannot open");
  std::vector<std::pair<std::int64_t, std::vector<double>>> rows;
  std::string line;
  std::size_t n = 0;
  std::int64_t last = INT64_MIN;
  while (io_detail::ReadBoundedLine(in, line, path.string(), n + 1)) {
    ++n;
    if (line.empty() || line == "\r" || line.front() == '#') continue;
    std::vector<double> v = AslFields(line, min_fields, path.string(), n);
    // Timestamps are integers of nanoseconds (~1.4e18): parse the first cell as an integer, not
    // through a double (which keeps only ~256 ns).
    const std::string_view cell(line.data(), line.find(','));
    std::int64_t ns = 0;
    const auto [end, ec] = std::from_chars(cell.data(), cell.data() + cell.size(), ns);
    if (ec != std::errc() || (end != cell.data() + cell.size() && *end != ' ')) {
      throw InputError(path.string(), n, "timestamp '" + std::string(cell) + "' is not integer nanoseconds");
    }
    if (ns < last) throw InputError(path.string(), n, "time goes backwards");
    last = ns;
    v.erase(v.begin());
    rows.emplace_back(ns, std::move(v));
  }
  if (rows.empty()) throw InputError(path.string(), 0, "no rows");
  return rows;
}

}  // namespace

std::string TumTrajectory(const std::vector<Estimate>& rows, const std::string& id) {
  return Tum(rows, id);
}
std::string TumTrajectory(const std::vector<TruthSample>& rows, const std::string& id) {
  return Tum(rows, id);
}

MissionData ReadEuroc(const std::filesystem::path& source, const std::string& agent) {
  namespace fs = std::filesystem;
  fs::path gt = source, imu;
  if (fs::is_directory(source)) {
    const fs::path mav = fs::exists(source / "mav0") ? source / "mav0" : source;
    gt = mav / "state_groundtruth_estimate0" / "data.csv";
    if (!fs::exists(gt)) {
      throw InputError(source.string(), 0,
                       "no state_groundtruth_estimate0/data.csv (a EuRoC mav0 folder expected)");
    }
    if (fs::exists(mav / "imu0" / "data.csv")) imu = mav / "imu0" / "data.csv";
  }
  const auto truth = ReadAsl(gt, 8);  // timestamp, p xyz, q wxyz
  std::vector<std::pair<std::int64_t, std::vector<double>>> imu_rows;
  if (!imu.empty()) imu_rows = ReadAsl(imu, 7);  // timestamp, w xyz, a xyz
  std::int64_t t0 = truth.front().first;
  if (!imu_rows.empty()) t0 = std::min(t0, imu_rows.front().first);
  auto seconds = [t0](std::int64_t ns) { return static_cast<double>(ns - t0) * 1e-9; };

  MissionData m;
  m.info.name = "euroc";
  m.info.description = fmt::format(
      "EuRoC MAV sequence ({}): ground truth of the body frame S in the world frame R (z up){}; "
      "t = 0 at timestamp {} ns",
      source.filename().string(), imu_rows.empty() ? "" : ", IMU in S", t0);
  const std::vector<double>& q = truth.front().second;  // p xyz, then q w x y z
  const double qw = q[3], qx = q[4], qy = q[5], qz = q[6];
  const double yaw = std::atan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz));
  m.info.nodes.push_back(NodeInfo::Agent(agent, Vec3(q[0], q[1], q[2]), 0.01, yaw, 0.01));
  for (const auto& [ns, v] : truth) m.truth.push_back({seconds(ns), agent, Vec3(v[0], v[1], v[2])});
  for (const auto& [ns, v] : imu_rows) {
    m.imu.push_back({seconds(ns), agent, Vec3(v[3], v[4], v[5]), Vec3(v[0], v[1], v[2])});
  }
  return m;
}

}  // namespace trailmark

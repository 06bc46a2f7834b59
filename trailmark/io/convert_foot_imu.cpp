// SPDX-License-Identifier: MIT
#include "trailmark/io/convert_foot_imu.h"

#include <fstream>

#include "trailmark/core/error.h"
#include "trailmark/io/csv.h"

namespace trailmark {

namespace {

std::vector<ImuSample> ReadImuCsv(const std::filesystem::path& file, const char* t, const char* ax,
                                  const char* ay, const char* az, const char* gx, const char* gy,
                                  const char* gz, double index_rate_hz, const std::string& agent) {
  CsvReader r(file.string());
  const int ct = r.RequireColumn(t);
  const int c[6] = {r.RequireColumn(ax), r.RequireColumn(ay), r.RequireColumn(az),
                    r.RequireColumn(gx), r.RequireColumn(gy), r.RequireColumn(gz)};
  std::vector<ImuSample> out;
  double last = -1e300;
  while (r.Next()) {
    const double time = index_rate_hz > 0 ? r.Double(ct) / index_rate_hz : r.Double(ct);
    if (time < last) r.Fail("time goes backwards");
    last = time;
    out.push_back({time, agent, Vec3(r.Double(c[0]), r.Double(c[1]), r.Double(c[2])),
                   Vec3(r.Double(c[3]), r.Double(c[4]), r.Double(c[5]))});
  }
  return out;
}

}  // namespace

MissionData ReadOpenShoeFigure8(const std::filesystem::path& txt) {
  std::ifstream in(txt);
  if (!in) throw InputError(txt.string(), 0, "cannot open");
  MissionData m;
  m.info.name = "openshoe-figure8";
  m.info.description =
      "OpenShoe foot IMU, 820 Hz, closed figure-eight walk of ~81 m (Nilsson et al.); no truth: "
      "the walk ends where it started";
  m.info.nodes.push_back(NodeInfo::Agent("foot", Vec3::Zero(), 0.01, 0.0, 0.01));
  std::string line;
  std::size_t n = 0;
  while (std::getline(in, line)) {
    ++n;
    while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.pop_back();
    if (line.empty()) continue;
    double v[6];
    std::size_t start = 0;
    for (int i = 0; i < 6; ++i) {
      const auto comma = line.find(',', start);
      if ((comma == std::string::npos) != (i == 5)) throw InputError(txt.string(), n, "expected 6 columns");
      const std::string cell = line.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
      const auto x = ParseFiniteDouble(cell);
      if (!x) throw InputError(txt.string(), n, "'" + cell + "' is not a finite number");
      v[i] = *x;
      start = comma + 1;
    }
    m.imu.push_back({static_cast<double>(m.imu.size()) / 820.0, "foot", Vec3(v[0], v[1], v[2]),
                     Vec3(v[3], v[4], v[5])});
  }
  if (m.imu.empty()) throw InputError(txt.string(), 0, "no samples");
  return m;
}

MissionData ReadLlioWalk(const std::filesystem::path& imu_csv) {
  const std::string stem = imu_csv.filename().string();
  const auto pos = stem.rfind("_imu.csv");
  if (pos == std::string::npos) throw InputError(imu_csv.string(), 0, "expected a <walk>_imu.csv file");
  const auto gcp_csv = imu_csv.parent_path() / (stem.substr(0, pos) + "_gcp.csv");
  MissionData m;
  m.info.name = stem.substr(0, pos);
  m.info.description = "LLIO footprint walk " + m.info.name +
                       " (Koroglu/Cetin et al. 2025): foot IMU at 200 Hz, truth = measured "
                       "footprints (stride 0 at the origin); heading unknown";
  m.imu = ReadImuCsv(imu_csv, "t_s", "ax_mps2", "ay_mps2", "az_mps2", "gx_radps", "gy_radps",
                     "gz_radps", 0, "foot");
  CsvReader g(gcp_csv.string());
  const int ct = g.RequireColumn("t_s"), cx = g.RequireColumn("x_m"), cy = g.RequireColumn("y_m");
  while (g.Next()) m.truth.push_back({g.Double(ct), "foot", Vec3(g.Double(cx), g.Double(cy), 0)});
  std::stable_sort(m.truth.begin(), m.truth.end(),
                   [](const TruthSample& a, const TruthSample& b) { return a.t < b.t; });
  m.info.nodes.push_back(NodeInfo::Agent("foot", Vec3::Zero(), 0.01));
  return m;
}

MissionData ReadDualFoot(const std::filesystem::path& dir) {
  MissionData m;
  m.info.name = "zupt-dualfoot-60hz";
  m.info.description = "Two foot IMUs at 60 Hz with per-foot position truth (Hu & Hu, PLANS 2025)";
  for (const char* side : {"left", "right"}) {
    const std::string file = std::string("imuMeas") + (side[0] == 'l' ? "Left" : "Right") + ".csv";
    auto imu = ReadImuCsv(dir / file, "time_index", "acc_x", "acc_y", "acc_z", "gyro_x", "gyro_y",
                          "gyro_z", 60.0, side);
    m.imu.insert(m.imu.end(), imu.begin(), imu.end());
  }
  std::stable_sort(m.imu.begin(), m.imu.end(),
                   [](const ImuSample& a, const ImuSample& b) { return a.t < b.t; });
  CsvReader g((dir / "positionGt.csv").string());
  const int ci = g.RequireColumn("time_index");
  const int l[3] = {g.RequireColumn("pos_left_x"), g.RequireColumn("pos_left_y"), g.RequireColumn("pos_left_z")};
  const int r[3] = {g.RequireColumn("pos_right_x"), g.RequireColumn("pos_right_y"), g.RequireColumn("pos_right_z")};
  while (g.Next()) {
    const double t = g.Double(ci) / 60.0;
    m.truth.push_back({t, "left", Vec3(g.Double(l[0]), g.Double(l[1]), g.Double(l[2]))});
    m.truth.push_back({t, "right", Vec3(g.Double(r[0]), g.Double(r[1]), g.Double(r[2]))});
  }
  if (m.truth.empty()) throw InputError((dir / "positionGt.csv").string(), 0, "no rows");
  m.info.nodes.push_back(NodeInfo::Agent("left", m.truth[0].position_n, 0.01));
  m.info.nodes.push_back(NodeInfo::Agent("right", m.truth[1].position_n, 0.01));
  return m;
}

}  // namespace trailmark

// SPDX-License-Identifier: MIT
#include "trailmark/io/convert_pyshoe.h"

#include <fmt/format.h>

#include <fstream>

#include "trailmark/io/csv.h"
#include "trailmark/io/mission_io.h"

namespace trailmark {

PyShoeTrial ReadPyShoeTrial(const std::filesystem::path& csv) {
  CsvReader r(csv.string());
  const int t = r.RequireColumn("t_s");
  const int ax = r.RequireColumn("ax_mps2"), ay = r.RequireColumn("ay_mps2"),
            az = r.RequireColumn("az_mps2");
  const int gx = r.RequireColumn("gx_radps"), gy = r.RequireColumn("gy_radps"),
            gz = r.RequireColumn("gz_radps");
  const int px = r.RequireColumn("gt_x_m"), py = r.RequireColumn("gt_y_m"),
            pz = r.RequireColumn("gt_z_m");
  const int zv = r.Column("zv_best");
  PyShoeTrial trial;
  trial.name = csv.stem().string();
  double last_t = -1e300;
  while (r.Next()) {
    ImuSample s;
    s.t = r.Double(t);
    if (s.t < last_t) r.Fail("time goes backwards");
    last_t = s.t;
    s.agent = "foot";
    s.accel_b = Vec3(r.Double(ax), r.Double(ay), r.Double(az));
    s.gyro_b = Vec3(r.Double(gx), r.Double(gy), r.Double(gz));
    trial.imu.push_back(s);
    trial.truth_n.emplace_back(r.Double(px), -r.Double(py), r.Double(pz));
    trial.stance_label.push_back(zv >= 0 && r.Double(zv) > 0.5);
  }
  if (trial.imu.size() < 10) r.Fail("fewer than 10 samples");
  return trial;
}

void WritePyShoeMission(const PyShoeTrial& trial, const std::filesystem::path& out_dir) {
  MissionData m;
  m.info.name = "pyshoe-" + trial.name;
  m.info.description =
      "PyShoe VICON trial " + trial.name +
      " (Wagstaff et al. 2019): foot IMU at 200 Hz, Vicon truth with y negated (handedness)";
  NodeInfo foot = NodeInfo::Agent("foot", trial.truth_n.front(), 0.01);
  m.info.nodes.push_back(foot);
  m.imu = trial.imu;
  for (std::size_t k = 0; k < trial.imu.size(); ++k) {
    m.truth.push_back({trial.imu[k].t, "foot", trial.truth_n[k]});
  }
  WriteMissionDirectory(out_dir, m, nullptr);
  std::ofstream labels(out_dir / "stance.csv");
  labels << "t,stance\n";
  for (std::size_t k = 0; k < trial.imu.size(); ++k) {
    labels << fmt::format("{:.6f},{}\n", trial.imu[k].t, trial.stance_label[k] ? 1 : 0);
  }
}

}  // namespace trailmark

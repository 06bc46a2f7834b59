// SPDX-License-Identifier: MIT
#pragma once
/// Converter: one trial of the PyShoe VICON set (../shared/data/pyshoe-vicon/<trial>.csv: t_s,
/// accel, gyro, Vicon position per sample, zv_best) into the mission format: imu.csv (agent
/// "foot"), truth.csv (Vicon, y negated — the Vicon xy plane is mirrored relative to a
/// right-handed z-up INS, see the folder README), mission.json (the agent starts at the first
/// Vicon position; heading unknown). The stance labels are kept as an extra column-free file
/// `stance.csv` (t,stance) for detector evaluation.

#include <filesystem>
#include <vector>

#include "trailmark/core/mission.h"

namespace trailmark {

struct PyShoeTrial {
  std::string name;
  std::vector<ImuSample> imu;
  std::vector<Vec3> truth_n;      ///< per IMU sample, y already negated
  std::vector<bool> stance_label; ///< zv_best
};

/// Throws InputError with file:line on malformed input.
PyShoeTrial ReadPyShoeTrial(const std::filesystem::path& csv);
/// Writes the trial as a mission directory.
void WritePyShoeMission(const PyShoeTrial& trial, const std::filesystem::path& out_dir);

}  // namespace trailmark

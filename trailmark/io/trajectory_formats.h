// SPDX-License-Identifier: MIT
#pragma once
/// Standard trajectory formats of the evaluation tools researchers use (evo, the TUM and EuRoC
/// benchmarks), for `trailmark export tum` and `trailmark convert euroc`.
///
/// TUM RGB-D trajectory: one line per pose, `t x y z qx qy qz qw` separated by spaces, `#`
/// comments; t in seconds. Our rows carry no attitude: the quaternion is the identity (yaw 0),
/// so compare positions (`evo_ape tum truth.tum est.tum --pose_relation trans_part`).
///
/// EuRoC MAV (ASL format): `mav0/state_groundtruth_estimate0/data.csv` (`#timestamp [ns],
/// p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], ...`)
/// and `mav0/imu0/data.csv` (`#timestamp [ns], w_RS_S_x [rad s^-1], ..., a_RS_S_x [m s^-2],
/// ...`): the body S's position in the world frame R (z up) and the IMU in S.

#include <filesystem>
#include <string>
#include <vector>

#include "trailmark/core/mission.h"

namespace trailmark {

/// The TUM lines of one node's rows (estimates or truth), in their order; a `#` header line
/// first. Times and positions in shortest round-trip form.
std::string TumTrajectory(const std::vector<Estimate>& rows, const std::string& id);
std::string TumTrajectory(const std::vector<TruthSample>& rows, const std::string& id);

/// A EuRoC sequence as a mission of one agent `agent`: `source` is a ground-truth data.csv, or
/// a folder holding it (mav0/, or the sequence folder above it) and, when present, imu0/data.csv
/// (then imu.csv too). Times are seconds from the earliest timestamp of the files read (its
/// nanoseconds are kept in the description); the start and its heading are the first ground
/// truth pose's (yaw of q_RS). Throws InputError with file and line: a row with fewer fields
/// than the format's, a cell that is not a finite number, time going backwards.
MissionData ReadEuroc(const std::filesystem::path& source, const std::string& agent = "body");

}  // namespace trailmark

// SPDX-License-Identifier: MIT
#pragma once
/// The recorded BLE flat (../shared/data/ble-rss-flat, its README): one reader of its files for
/// the experiments that use it (reproduce landmarks, reproduce landmark-tracking).

#include <filesystem>
#include <optional>
#include <vector>

#include "trailmark/core/types.h"

namespace trailmark::experiments {

/// One row of a session file: time (s), the LiDAR-SLAM position when the file has one, and the
/// RSSI (dBm) of each anchor in anchors.csv order (empty: not heard).
struct BleFlatRow {
  double t_s = 0;
  std::optional<Vec2> xy;
  std::vector<std::optional<double>> rssi_dbm;
};

/// anchors.csv: the anchors' positions (x, y, z; m).
std::vector<Vec3> ReadBleFlatAnchors(const std::filesystem::path& dir);
/// A session file (calibration_df.csv, test_robot_df.csv, test_walk_df.csv): `ts` in ns, `x`/`y`
/// when present, `rssi_1`..`rssi_N` for N anchors (a pandas index column allowed).
std::vector<BleFlatRow> ReadBleFlatRows(const std::filesystem::path& file, std::size_t anchors);

}  // namespace trailmark::experiments

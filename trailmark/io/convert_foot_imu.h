// SPDX-License-Identifier: MIT
#pragma once
/// Converters of the other recorded foot-IMU sets of ../shared/data into missions (see each
/// folder's README for source, license and format). Throw InputError with file:line.
///  - openshoe-figure8/imu_820hz.txt: 6 columns, no header, 820 Hz; a closed walk, no truth
///    (the loop closes: the evaluation is the end-to-start distance).
///  - llio-gcp-walks/<walk>_imu.csv + <walk>_gcp.csv: 200 Hz IMU, truth = measured footprints
///    (sparse truth rows at the footprints' IMU times).
///  - zupt-dualfoot-60hz/: imuMeasLeft.csv, imuMeasRight.csv, positionGt.csv; two agents
///    "left" and "right", 60 Hz from the sample index, truth per sample and foot.

#include <filesystem>

#include "trailmark/core/mission.h"

namespace trailmark {

MissionData ReadOpenShoeFigure8(const std::filesystem::path& txt);
MissionData ReadLlioWalk(const std::filesystem::path& imu_csv);  ///< finds the _gcp.csv beside it
MissionData ReadDualFoot(const std::filesystem::path& dir);

}  // namespace trailmark

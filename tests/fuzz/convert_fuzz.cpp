// SPDX-License-Identifier: MIT
// libFuzzer target (issue 30, item 6): arbitrary bytes as the recorded sets the converters read
// — OpenShoe's figure-eight text, a PyShoe trial, an LLIO walk and its footprints, the dual-foot
// set's three files, a WRLD building's main.json and one level, a EuRoC sequence's ground truth
// and IMU, an IPIN logfile, an IMDF venue (folder and zip) — split into files at each
// "\n==\n". Any outcome but an InputError (or a clean read) is a bug: crashes, hangs, UB, an
// exception of another type. A WRLD building that reads is turned into a floor plan, which our
// own reader must then accept.
#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>
#include <vector>

#include "trailmark/core/error.h"
#include "trailmark/io/convert_foot_imu.h"
#include "trailmark/io/convert_imdf.h"
#include "trailmark/io/convert_ipin.h"
#include "trailmark/io/convert_pyshoe.h"
#include "trailmark/io/convert_wrld.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/io/streams.h"
#include "trailmark/io/trajectory_formats.h"

namespace {

namespace fs = std::filesystem;

std::vector<std::string> Parts(std::string_view text) {
  std::vector<std::string> parts;
  constexpr std::string_view kSeparator = "\n==\n";
  while (true) {
    const auto at = text.find(kSeparator);
    parts.emplace_back(text.substr(0, at));
    if (at == std::string_view::npos) break;
    text.remove_prefix(at + kSeparator.size());
  }
  while (parts.size() < 3) parts.emplace_back();
  return parts;
}

void Write(const fs::path& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
}

template <class F>
void Expect(F&& read) {
  try {
    read();
  } catch (const trailmark::InputError&) {
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const fs::path dir = fs::temp_directory_path() /
                              ("trailmark-convert-fuzz-" + std::to_string(getpid()));
  fs::create_directories(dir);
  const std::string text(reinterpret_cast<const char*>(data), size);
  const auto parts = Parts(text);

  Write(dir / "figure8.txt", text);
  Expect([&] { trailmark::ReadOpenShoeFigure8(dir / "figure8.txt"); });
  Write(dir / "trial.csv", text);
  Expect([&] { trailmark::ReadPyShoeTrial(dir / "trial.csv"); });
  Write(dir / "walk_imu.csv", parts[0]);
  Write(dir / "walk_gcp.csv", parts[1]);
  Expect([&] { trailmark::ReadLlioWalk(dir / "walk_imu.csv"); });
  Write(dir / "imuMeasLeft.csv", parts[0]);
  Write(dir / "imuMeasRight.csv", parts[1]);
  Write(dir / "positionGt.csv", parts[2]);
  Expect([&] { trailmark::ReadDualFoot(dir); });
  Write(dir / "euroc.csv", text);
  Expect([&] { trailmark::ReadEuroc(dir / "euroc.csv"); });
  fs::create_directories(dir / "mav0" / "state_groundtruth_estimate0");
  fs::create_directories(dir / "mav0" / "imu0");
  Write(dir / "mav0" / "state_groundtruth_estimate0" / "data.csv", parts[0]);
  Write(dir / "mav0" / "imu0" / "data.csv", parts[1]);
  Expect([&] { trailmark::ReadEuroc(dir); });
  // An IMDF venue (level, unit and opening files; and the bytes as a zip archive): one that
  // reads is written as a floor plan our own reader must accept.
  fs::create_directories(dir / "imdf");
  Write(dir / "imdf" / "level.geojson", parts[0]);
  Write(dir / "imdf" / "unit.geojson", parts[1]);
  Write(dir / "imdf" / "opening.geojson", parts[2]);
  Write(dir / "venue.zip", text);
  for (const fs::path& venue_source : {dir / "imdf", dir / "venue.zip"}) {
    try {
      const trailmark::ImdfVenue venue = trailmark::ReadImdfVenue(venue_source);
      fs::remove_all(dir / "imdf-mission");
      trailmark::WriteImdfMission(venue, dir / "imdf-mission");
      try {
        trailmark::MissionDirectory mission(dir / "imdf-mission");
        std::vector<int> levels;
        mission.LoadFloorPlan(std::nullopt, &levels);
        for (int l : levels) mission.LoadFloorPlan(l);
      } catch (const trailmark::InputError&) {
        std::abort();  // the converter wrote a plan our own reader refuses
      }
    } catch (const trailmark::InputError&) {
    }
  }
  // An IPIN logfile that reads is written as a mission our own readers must accept.
  Write(dir / "ipin.txt", text);
  try {
    const trailmark::IpinLogfile log = trailmark::ReadIpinLogfile(dir / "ipin.txt");
    fs::remove_all(dir / "ipin-mission");
    trailmark::WriteIpinMission(log, dir / "ipin-mission");
    try {
      const trailmark::MissionDirectory mission(dir / "ipin-mission");
      const auto* registry = &mission.registry();
      const auto path = [&](const char* f) { return mission.Path(f).string(); };
      if (mission.Has("imu.csv")) trailmark::ReadAll<trailmark::ImuSample>(path("imu.csv"), registry);
      if (mission.Has("baro.csv")) trailmark::ReadAll<trailmark::BaroSample>(path("baro.csv"), registry);
      if (mission.Has("rssi.csv")) trailmark::ReadAll<trailmark::RssiPacket>(path("rssi.csv"), registry);
      if (mission.Has("truth.csv")) trailmark::ReadAll<trailmark::TruthSample>(path("truth.csv"), registry);
    } catch (const trailmark::InputError&) {
      std::abort();  // the converter wrote a mission our own readers refuse
    }
  } catch (const trailmark::InputError&) {
  }
  Write(dir / "main.json", parts[0]);
  Write(dir / "level.json", parts[1]);
  try {
    const trailmark::WrldBuilding building = trailmark::ReadWrldBuilding(dir);
    const std::string plan = trailmark::WrldFloorPlanGeoJson(building);
    try {
      trailmark::ParseFloorPlanGeoJson(plan, "converted.geojson");
    } catch (const trailmark::InputError&) {
      std::abort();  // the converter wrote a plan our own reader refuses
    }
  } catch (const trailmark::InputError&) {
  }
  return 0;
}

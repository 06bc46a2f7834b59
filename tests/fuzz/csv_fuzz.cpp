// SPDX-License-Identifier: MIT
// libFuzzer target: arbitrary bytes as every stream kind and as mission.json / GeoJSON. Any
// outcome but an InputError (or a clean read) is a bug: crashes, hangs, leaks, UB.
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <string>
#include <unistd.h>

#include "trailmark/core/error.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/io/streams.h"

namespace {

template <class Row>
void ReadAllRows(const std::string& path) {
  try {
    trailmark::RowReader<Row> reader(path, nullptr, {.max_line_bytes = 4096, .chunk_bytes = 512});
    Row row;
    while (reader.Next(row)) {
    }
  } catch (const trailmark::InputError&) {
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::string path = "/tmp/trailmark-fuzz-" + std::to_string(getpid()) + ".csv";
  const std::string text(reinterpret_cast<const char*>(data), size);
  {
    std::ofstream out(path, std::ios::binary);
    out << text;
  }
  ReadAllRows<trailmark::ImuSample>(path);
  ReadAllRows<trailmark::Step>(path);
  ReadAllRows<trailmark::RssiPacket>(path);
  ReadAllRows<trailmark::RangeMeasurement>(path);
  ReadAllRows<trailmark::MissionEvent>(path);
  ReadAllRows<trailmark::Estimate>(path);
  try {
    trailmark::ParseMissionInfo(text, "mission.json");
  } catch (const trailmark::InputError&) {
  }
  try {
    trailmark::ParseFloorPlanGeoJson(text, "plan.geojson");
  } catch (const trailmark::InputError&) {
  }
  return 0;
}

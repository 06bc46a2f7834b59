// SPDX-License-Identifier: MIT
#include "experiments/ble_flat.h"

#include <string>

#include "trailmark/io/csv.h"

namespace trailmark::experiments {

std::vector<Vec3> ReadBleFlatAnchors(const std::filesystem::path& dir) {
  std::vector<Vec3> anchors;
  CsvReader r((dir / "anchors.csv").string());
  const int cx = r.RequireColumn("x"), cy = r.RequireColumn("y"), cz = r.RequireColumn("z");
  while (r.Next()) anchors.emplace_back(r.Double(cx), r.Double(cy), r.Double(cz));
  return anchors;
}

std::vector<BleFlatRow> ReadBleFlatRows(const std::filesystem::path& file, std::size_t anchors) {
  CsvReaderOptions unnamed;
  unnamed.allow_unnamed_columns = true;  // a pandas index column
  CsvReader r(file.string(), unnamed);
  const int ct = r.RequireColumn("ts"), cx = r.Column("x"), cy = r.Column("y");
  std::vector<int> cr;
  for (std::size_t k = 0; k < anchors; ++k) cr.push_back(r.RequireColumn("rssi_" + std::to_string(k + 1)));
  std::vector<BleFlatRow> rows;
  while (r.Next()) {
    BleFlatRow row;
    row.t_s = r.Double(ct) * 1e-9;
    if (cx >= 0 && cy >= 0) row.xy = Vec2(r.Double(cx), r.Double(cy));
    for (int c : cr) row.rssi_dbm.push_back(r.OptionalDouble(c));
    rows.push_back(std::move(row));
  }
  return rows;
}

}  // namespace trailmark::experiments

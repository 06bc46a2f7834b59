// SPDX-License-Identifier: MIT
#pragma once
/// mission.json and the mission directory (spec: ../shared/spec/mission-format.md).

#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "trailmark/core/measurements.h"
#include "trailmark/core/mission.h"
#include "trailmark/geometry/floor_plan.h"
#include "trailmark/io/streams.h"

namespace trailmark {

/// Parses mission.json text; `source` names it in errors. Throws InputError.
MissionInfo ParseMissionInfo(const std::string& json_text, const std::string& source);
MissionInfo ReadMissionInfo(const std::filesystem::path& path);
std::string MissionInfoToJson(const MissionInfo& info);
void WriteMissionInfo(const std::filesystem::path& path, const MissionInfo& info);

/// Throws InputError naming `source` when the walls span less than 5 cm: a plan drawn in degrees
/// (longitude/latitude) or in the wrong unit; the message says which it looks like.
void RequirePlanInMetres(const std::vector<Segment2>& walls, const std::string& source);

/// Floor plan GeoJSON (spec: "Floor plans"). `level` selects one floor (any integer, a
/// basement's -1 too; nullopt = every level's features in one plan);
/// `levels_present` (optional) receives the levels its walls, doors and rooms use, sorted
/// (a feature without "level" is on level 0).
FloorPlan ParseFloorPlanGeoJson(const std::string& json_text, const std::string& source,
                                std::optional<int> level = std::nullopt,
                                std::vector<int>* levels_present = nullptr);
FloorPlan ReadFloorPlanGeoJson(const std::filesystem::path& path,
                               std::optional<int> level = std::nullopt,
                               std::vector<int>* levels_present = nullptr);
/// The floor a single-floor consumer uses when not told: level 0 when the plan has it (the
/// floor the responders enter on), else the lowest.
int DefaultFloorPlanLevel(const std::vector<int>& levels_present);
/// One floor of a floor-plan file: `level`, or when not given DefaultFloorPlanLevel (floors are
/// never merged into one plan). A `level` the plan does not have is an InputError naming the
/// file and the levels it has. `levels_present` (optional) receives the plan's levels.
FloorPlan ReadFloorPlanFloor(const std::filesystem::path& path,
                             std::optional<int> level = std::nullopt,
                             std::vector<int>* levels_present = nullptr);
/// `polyline_walls`: walls that continue one another as one multi-vertex LineString (spec 1.1).
std::string FloorPlanToGeoJson(const FloorPlan& plan, bool polyline_walls = false);
/// Several floors in one file: every feature of a floor carries its `level`.
std::string FloorPlanToGeoJson(const std::vector<std::pair<int, FloorPlan>>& floors,
                               bool polyline_walls = false);

/// Writes mission.json, every non-empty stream and (when given) the floor plan into `dir`,
/// creating it; the file of an empty stream is removed (a directory written twice holds the
/// second mission only). Streams are written in the order held; the caller keeps them
/// time-sorted.
/// `style`: another of the ways the spec allows to draw the same mission.
void WriteMissionDirectory(const std::filesystem::path& dir, const MissionData& data,
                           const FloorPlan* plan = nullptr, const MissionWriteStyle& style = {});

/// The same, with a multi-floor plan: every level's plan in one file (each feature with its
/// `level`), named by data.info.floorplan (default floorplan.geojson).
void WriteMissionDirectory(const std::filesystem::path& dir, const MissionData& data,
                           const std::vector<std::pair<int, FloorPlan>>& levels,
                           const MissionWriteStyle& style = {});

/// The same CSV text drawn another way the spec allows: comment lines, the columns in another
/// order, an extra (quoted) column. Cells are taken as written by CsvWriter (no quotes).
std::string RestyleCsv(const std::string& text, const MissionWriteStyle& style,
                       std::uint64_t stream_seed);

/// Reads every stream of a (small) mission into memory.
class MissionDirectory;
MissionData ReadMissionData(const MissionDirectory& mission);

/// A mission directory opened for reading: mission.json parsed and validated, the ids that
/// streams may use collected (declared nodes plus crumbs dropped in events.csv).
class MissionDirectory {
 public:
  explicit MissionDirectory(std::filesystem::path dir);

  const std::filesystem::path& dir() const { return dir_; }
  const MissionInfo& info() const { return info_; }
  const NodeRegistry& registry() const { return registry_; }
  /// Crumb ids introduced by drop events, in drop order.
  const std::vector<std::string>& dropped_crumbs() const { return dropped_; }

  bool Has(const std::string& file) const;
  std::filesystem::path Path(const std::string& file) const { return dir_ / file; }
  /// Throws InputError naming the missing file and who needs it.
  void Require(const std::string& file, const std::string& needed_by) const;

  template <class Row>
  bool HasStream() const {
    return Has(StreamFileName<Row>());
  }
  template <class Row>
  RowReader<Row> OpenStream() const {
    return RowReader<Row>(Path(StreamFileName<Row>()).string(), &registry_);
  }
  /// The floor plan named in mission.json, if any: one floor of it (ReadFloorPlanFloor).
  std::optional<FloorPlan> LoadFloorPlan(std::optional<int> level = std::nullopt,
                                         std::vector<int>* levels_present = nullptr) const;

 private:
  std::filesystem::path dir_;
  MissionInfo info_;
  NodeRegistry registry_;
  std::vector<std::string> dropped_;
};

}  // namespace trailmark

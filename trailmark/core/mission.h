// SPDX-License-Identifier: MIT
#pragma once
/// The in-memory description of a mission (mission.json of the spec). No I/O here.

#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "trailmark/core/types.h"

namespace trailmark {

struct NodeInfo {
  std::string id;
  NodeKind kind = NodeKind::kAgent;
  std::optional<Vec3> position;           ///< known a priori (anchors, surveyed landmarks)
  std::optional<double> position_sigma_m;
  std::optional<Vec3> start;              ///< agent position at its first sample
  std::optional<double> start_sigma_m;
  std::optional<double> start_heading_rad;  ///< radians from +x, counter-clockwise
  std::optional<double> start_heading_sigma_rad;

  /// A base station at a known position.
  static NodeInfo Base(std::string id, const Vec3& position) {
    NodeInfo n;
    n.id = std::move(id);
    n.kind = NodeKind::kBase;
    n.position = position;
    return n;
  }
  /// An agent with a known start (and optionally heading).
  static NodeInfo Agent(std::string id, const Vec3& start, double start_sigma_m,
                        std::optional<double> heading_rad = std::nullopt,
                        std::optional<double> heading_sigma_rad = std::nullopt) {
    NodeInfo n;
    n.id = std::move(id);
    n.kind = NodeKind::kAgent;
    n.start = start;
    n.start_sigma_m = start_sigma_m;
    n.start_heading_rad = heading_rad;
    n.start_heading_sigma_rad = heading_sigma_rad;
    return n;
  }
};

/// Log-distance path-loss calibration: rssi = alpha - 10 n log10(d / 1 m) + N(0, sigma^2).
/// mission.json may give only some of the values (spec: "`radio` holds calibration if known");
/// the others keep these defaults and are flagged as not given.
struct RadioCalibration {
  std::string model = "log-distance";
  double alpha_dbm = -40.0;
  double path_loss_exponent = 2.3;
  double shadowing_sigma_db = 4.0;
  bool alpha_given = true;
  bool exponent_given = true;
  bool sigma_given = true;
  /// A calibration the estimators can use as it is: alpha and the exponent both known (a
  /// missing sigma takes the default). Otherwise the path loss is fitted, with the given sigma
  /// where there is one.
  bool Complete() const { return alpha_given && exponent_given; }
};

/// One level of the building (spec 1.1, "Floors"): the elevation of its floor surface in the
/// navigation frame's z.
struct FloorLevel {
  int level = 0;
  double elevation_m = 0;
};

/// Spec 1.1: a person's z is on the level with the highest elevation at or below z + 1.0 m;
/// below every level, the lowest. Without levels, storeys of kDefaultStoreyM with level 0 at
/// z = 0. `floors` sorted by elevation (MissionInfo keeps them so).
inline constexpr double kFloorTolerance_m = 1.0;
inline constexpr double kDefaultStoreyM = 3.0;
int LevelAt(const std::vector<FloorLevel>& floors, double z_m);
/// Ours: the storey a mounted device (a landmark on the ceiling, a beacon on a wall) is in:
/// the level whose floor is at or below its z, within kMountedTolerance_m (a survey's error).
/// The spec's 1 m tolerance is for a person's z at the feet or belt; with it a ceiling device
/// 2.7 m above a 3 m storey's floor would be on the level above.
inline constexpr double kMountedTolerance_m = 0.1;
int MountedLevelAt(const std::vector<FloorLevel>& floors, double z_m);
/// The z interval [lower, upper) of heights that LevelAt maps to `level` (infinite at the ends;
/// empty, lower == upper, for a level not in `floors`).
std::pair<double, double> LevelHeightInterval(const std::vector<FloorLevel>& floors, int level);
/// The elevation of `level`'s floor surface (default storeys without floors); nullopt for a
/// level not in `floors`.
std::optional<double> LevelElevation(const std::vector<FloorLevel>& floors, int level);

/// Where the navigation frame lies on the Earth, for data converted from or exported to
/// geographic coordinates: x east, y north, z up of the WGS 84 local tangent frame at this
/// point (io/geo.h projects through GeographicLib's LocalCartesian). mission.json "geo_origin"
/// (a trailmark extension of the format; docs/mission-format-notes.md).
struct GeoOrigin {
  double lat_deg = 0;
  double lon_deg = 0;
  double height_m = 0;  ///< ellipsoidal height of the frame's origin
};

struct MissionInfo {
  std::string format = "trailmark-mission/1";
  std::string name;
  std::string description;
  std::vector<NodeInfo> nodes;
  std::optional<RadioCalibration> radio;
  std::optional<std::string> floorplan;  ///< path relative to the mission directory
  /// The building's levels (1.1), sorted by elevation; empty: 3 m storeys, level 0 at z = 0.
  std::vector<FloorLevel> floors;
  /// Where the frame lies on the Earth (converted geographic data); empty: not known.
  std::optional<GeoOrigin> geo_origin;

  const NodeInfo* Find(const std::string& id) const;
  /// The single base node, or nullptr when there is none or more than one.
  const NodeInfo* SingleBase() const;
  /// The agent's start: its own `start`, else the single base's position (spec).
  std::optional<Vec3> AgentStart(const NodeInfo& agent) const;
};

/// How a mission is drawn on disk, among the ways the spec allows ("Conventions: CSV", "Floor
/// plans"); a reader must accept all of them. Plain data: io/mission_io's writer applies it.
struct MissionWriteStyle {
  bool csv_comments = false;          ///< '#' comment lines at the top and between rows
  bool csv_shuffled_columns = false;  ///< each stream's columns in another order
  bool csv_extra_column = false;      ///< an extra column that readers ignore
  bool polyline_walls = false;        ///< connected walls as one multi-vertex LineString
  std::uint64_t seed = 0;             ///< for the column order and where comments go
};

}  // namespace trailmark

#include <vector>

#include "trailmark/core/measurements.h"

namespace trailmark {

/// A whole mission held in memory (simulator output, small recorded sets). Large recorded
/// missions are read stream by stream instead (io/streams.h).
struct MissionData {
  MissionInfo info;
  std::vector<ImuSample> imu;
  std::vector<Step> steps;
  std::vector<RssiPacket> rssi;
  std::vector<RangeMeasurement> ranges;
  std::vector<BearingMeasurement> bearings;
  std::vector<MissionEvent> events;
  std::vector<BaroSample> baro;
  std::vector<TruthSample> truth;
};

}  // namespace trailmark

#pragma once
/// `mapmatch`: the map-aided search paper's navigation filter on a mission (sec. IV): odometry
/// (steps.csv, or the INS on imu.csv) and the floor plan (walls cannot be crossed), with
/// pseudo observations from comparing the last 20 m of odometry with the directional-search
/// patterns of the map every 2 m walked. Works without an initial position.
///
/// Options (the four configurations of Figs. 7-8): `init=auto|known|uniform` (auto: known
/// when the agent has a start in mission.json), `pseudo=true|false`, `resample=true|false`;
/// and `particles`, `seed`, `grid_m`, `pattern_length_m`, `compare_every_m`,
/// `point_spacing_m`, `sigma`, `tracking_sigma` (ours: sigma once the track is found),
/// `outlier_weight`, `new_particle_weight`, `variance_alarm_m2`
/// (map-error indicator, sec. V-E: 3 m^2) and `variance_alarm_min_s` (how long it must last);
/// ours: the wall-following model (`wall_follow`, `wall_follow_*`), `stay_inside`, the wall
/// alarm and recovery (`wall_alarm_k`, `wall_alarm_h`, `recover*`), `map_error_wall_alarms`
/// (docs/mapmatch.md lists them all with their defaults and where they were chosen).
/// Diagnostics: the extracted sequences, floor-plan problems, the periods when the estimated
/// variance exceeded the alarm level, the wall alarms, and the map-error verdict
/// (`<agent>.map_error_suspected`).

#include <map>
#include <memory>
#include <optional>
#include <string>

#include "trailmark/geometry/floor_plan.h"
#include "trailmark/pipelines/pipeline.h"

namespace trailmark {

/// The filter set up for an incident (floor plan, search sequences, options) and fed step by
/// step (each agent's steps in time order; agents independent), emitting each agent's estimate
/// at every step: the batch pipeline and its live form share it.
class MapMatchSession {
 public:
  /// `options`: the pipeline's keys without the "ins." ones. Throws std::invalid_argument on
  /// bad options, InputError naming `plan_file` for a floor plan that encloses nothing.
  MapMatchSession(const MissionInfo& info, FloorPlan plan, const std::string& plan_file,
                  const std::map<std::string, std::string>& options, PipelineSummary& summary);
  ~MapMatchSession();
  /// One step; throws std::invalid_argument for steps of a node that is not an agent, or of an
  /// agent without a start when init=known. Notes (an agent's initial state) go to `summary`.
  void AddStep(const Step& step, EstimateSink& sink, PipelineSummary& summary);
  /// Per agent: the filter's counters, the variance and wall-crossing alarms.
  void Summarize(PipelineSummary& summary);

 private:
  struct Impl;
  const MissionInfo& info_;
  std::unique_ptr<Impl> impl_;
};

/// The mapmatch option `level` (which floor of a multi-floor plan; a whole number), taken out
/// of `options`; nullopt when absent (the plan's default floor: level 0, else the lowest).
/// Throws std::invalid_argument when it is not a whole number. The batch pipeline, its live
/// form and `trailmark serve` (which draws that floor) read it the same way.
std::optional<int> TakeMapMatchLevel(std::map<std::string, std::string>& options);

class MapMatchPipeline : public Pipeline {
 public:
  std::string name() const override { return "mapmatch"; }
  std::string description() const override {
    return "map-aided search paper: particle filter on odometry and the floor plan with pseudo "
           "observations from "
           "directional-search patterns (ICP); no initial position needed";
  }
  std::vector<std::string> required_files() const override {
    return {"steps.csv or imu.csv", "floorplan.geojson (mission.json \"floorplan\")"};
  }
  bool CanRun(const MissionDirectory& mission) const override;
  PipelineSummary Run(const PipelineContext& context, EstimateSink& sink) const override;
};

}  // namespace trailmark

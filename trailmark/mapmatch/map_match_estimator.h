// SPDX-License-Identifier: MIT
#pragma once
/// `mapmatch`: the map-aided search paper's navigation filter (sec. IV) as an online estimator:
/// odometry (steps) and the floor plan (walls cannot be crossed), with pseudo observations from
/// comparing the last 20 m of odometry with the directional-search patterns of the map every
/// 2 m walked; works without an initial position. In a multi-level building each agent's
/// filter works on the plan of the level its height channel puts it on (UseLevels); when the
/// level changes, the belief moves to the new level's plan with the particles that are in a
/// stairwell (every particle when none is: the change is noted; refused while the belief is
/// confident, see stairwell_veto_variance_m2). The estimates of a multi-level filter carry its
/// level. Map-error evidence per agent (ours and sec.
/// V-E): periods when the estimated variance stayed above the alarm level, wall alarms (the
/// walk kept crossing the map's walls), and the verdict. Agents are independent: each agent's
/// steps in time order is all it needs. No I/O.

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "trailmark/core/mission.h"
#include "trailmark/core/online_estimator.h"
#include "trailmark/core/options.h"
#include "trailmark/geometry/floor_plan.h"
#include "trailmark/integrity/dead_reckoning_first.h"
#include "trailmark/mapmatch/particle_filter.h"
#include "trailmark/mapmatch/pattern_comparison.h"
#include "trailmark/mapmatch/search_map.h"

namespace trailmark::mapmatch {

/// How each agent's filter starts: known (its start from the mission), uniform over the
/// building, or auto (known when the agent has a start).
enum class StartMode { kAuto, kKnown, kUniform };

struct MapMatchEstimatorOptions {
  StartMode init = StartMode::kAuto;
  /// Ours: 2,000 particles (the paper: N = 500, `particles=500`); with the wall-following
  /// model the belief stays sharp, and more particles keep second hypotheses alive through
  /// furniture (docs/mapmatch.md: measured on held-out searches).
  MapParticleFilterOptions filter = [] {
    MapParticleFilterOptions o;
    o.particles = 2000;
    return o;
  }();
  SearchSequenceOptions sequences;
  PatternComparisonOptions comparison;
  double compare_every_m = 2.0;       ///< m walked between pattern comparisons (sec. IV)
  double variance_alarm_m2 = 3.0;     ///< m^2; map-error indicator level (sec. V-E)
  double variance_alarm_min_s = 10.0; ///< s; how long the variance must stay above it
  int map_error_wall_alarms = 5;      ///< wall alarms that make the verdict (docs/mapmatch.md)
  double walking_direction_m = 1.0;   ///< m of odometry that give the walking direction
  /// Ours, multi-level plans: a level change of the height channel while none of the belief
  /// is in a stairwell (of a plan that marks stairwells) is refused as long as the position
  /// variance (trace) is at most this — a confident belief on one level's corridor says the
  /// barometer drifted across a level boundary; the change is made once the particles reach
  /// a stairwell. The estimates then carry the map's level. 0: never refuse. Off: on the
  /// multi-floor building (seeds 1-10) it fixed the barometer's brief flips at a level's
  /// boundary once, and twice kept a filter that was confidently lost on the wrong level
  /// (right floor 97.9 % with 4 m^2, 98.1 % without; docs/floors.md).
  double stairwell_veto_variance_m2 = 0.0;
  /// Ours (issues 21 and 23, off: the other estimators' `dr_first`): an agent whose steps come
  /// from a foot INS within its noise model (steps with their heading variance) and that has a
  /// known start and start heading is written as its dead reckoning while that lies inside the
  /// filter's own 99 % region, the filter's estimate beyond 99.99 % (an integrity note), a blend
  /// between (integrity/dead_reckoning_first.h). On a good foot INS the particles' spread is
  /// the estimate's noise (the `imu` family's house searches: dead reckoning 0.48-0.50 m p75,
  /// the filter 0.51 m, with it 0.47-0.48 m); but the particles' region is wide (in95 100 %),
  /// and a gyro a few percent off the INS's model leaves the dead reckoning a metre off and
  /// still inside it, where the filter alone halves the error (docs/mapmatch.md). With
  /// stated_steps the filter's ellipse is about as tight as its error (in95 97-99 %) and the
  /// filter alone near dead reckoning on a good INS, but the trade stays (0.47-0.71 m against
  /// the filter's 0.47-0.53 m off the INS's model): off.
  bool dr_first = false;
  integrity::DeadReckoningFirstOptions dr_test;
  /// Ours (issue 23): the steps of a foot INS within its noise model (steps with their heading
  /// variance) move the particles by their own statement instead of the paper's white noise
  /// (0.12 m a step and 2 deg/m: a PDR's): each step's own position noise and heading-variance
  /// growth, and per particle the dead reckoning's shared errors of a foot INS (step-length
  /// scale 1 %, gyro scale over turns 1 %, heading drift 1 deg/min: PdrOptions::foot_ins), drawn
  /// once and carried (docs/mapmatch.md). Other steps keep the paper's noise.
  bool stated_steps = true;
  double default_start_sigma_m = 0.2;           ///< a known start without start_sigma
  double min_start_sigma_m = 0.05;              ///< the particle cloud is never narrower
  double default_start_heading_sigma_rad = 0.09;
  double min_start_heading_sigma_rad = 0.01;
  bool IsValid(std::string* why) const;
  /// Whether the agents' starts of mission.json are used (not with init=uniform): the
  /// dead-reckoning guard (integrity/) only checks estimators that trust the same start.
  bool UsesMissionStart() const { return init != StartMode::kUniform; }
};
/// The `--option` keys (docs/pipeline-options.md).
const OptionTable<MapMatchEstimatorOptions>& MapMatchOptionTable();

struct AgentMapEvidence {
  std::vector<std::pair<TimeS, TimeS>> variance_alarms;  ///< periods above the level
  std::vector<std::string> wall_alarms;                  ///< when and where
  bool map_error_suspected = false;
};

class MapMatchEstimator : public OnlineEstimator {
 public:
  /// The filter set up for one floor `plan` (search sequences from the first agent's start,
  /// else the single base, else the building's corner). `plan_source` names the plan in
  /// errors. Throws std::invalid_argument on invalid options, InputError naming `plan_source`
  /// for a floor plan that encloses nothing.
  MapMatchEstimator(const MissionInfo& info, FloorPlan plan, std::string plan_source,
                    MapMatchEstimatorOptions options);
  /// Every level of a building (at least one; levels as LevelAt numbers them from
  /// info.floors). An agent starts on its start's level (else the level source's, else level
  /// 0, else the lowest); the search sequences of a level start at the first agent's start
  /// when it is on that level, else at the centre of the level's first stairwell.
  MapMatchEstimator(const MissionInfo& info, LevelPlans levels, std::string plan_source,
                    MapMatchEstimatorOptions options);
  ~MapMatchEstimator() override;
  /// Steps (others are counted and ignored). Throws std::invalid_argument for steps of a node
  /// that is not an agent, or of an agent without a start when init is known.
  void Add(const MissionRow& row, EstimateSink& sink) override;
  void Finish(EstimateSink&) override {}
  void UseLevels(const LevelSource* levels) override;
  std::optional<Estimate> Current(const std::string& node) const override;
  /// R of the particles' mean heading offset (odometry frame -> map frame); none while the
  /// agent's dead reckoning is written (dr_first): the steps as they come.
  std::optional<Mat2> StepTransform(const std::string& agent) const override;
  /// Per agent: the filter's counters, the variance and wall alarms, the verdict, the level
  /// changes (and those made with no particle in a stairwell).
  EstimatorSummary Summary() const override;
  /// The map-error evidence of an agent so far (nullopt for an agent not seen).
  std::optional<AgentMapEvidence> Evidence(const std::string& agent) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace trailmark::mapmatch

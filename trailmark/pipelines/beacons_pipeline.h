#pragma once
/// The ultrasound-beacons paper's estimators on mission directories.
///  - `beacons-mds`: beacon positions online from the beacon-to-beacon ultrasound ranges
///    (ranges.csv between two non-agent nodes): MDS with shortest-path completion + SMACOF,
///    anchored to surveyed beacons or to where the responder's dead reckoning dropped them.
///  - `beacons-ekf`: the responder tracked by the SCAAT EKF (u, v, psi, scale) on PDR steps (or
///    the INS on imu.csv) and every ultrasound range/bearing from a beacon (ranges.csv /
///    bearings.csv between a beacon and an agent); beacons surveyed or from the online MDS,
///    anchored by the tracker's own estimates at the drops. `--option filter=us-only` runs the
///    paper's ultrasound-only Kalman filter instead. Agents without a start are initialized
///    from their first ultrasound measurements. Diagnostics carry the way back out.
/// Beacons: every crumb, and every landmark or base that appears in an ultrasound range;
/// their order (for the way out) is the order of the drop events, else of mission.json.

#include <optional>
#include <string>
#include <vector>

#include "trailmark/pipelines/pipeline.h"

namespace trailmark {

class BeaconsPipeline : public Pipeline {
 public:
  explicit BeaconsPipeline(bool track) : track_(track) {}
  std::string name() const override { return track_ ? "beacons-ekf" : "beacons-mds"; }
  std::string description() const override {
    return track_ ? "ultrasound-beacons paper: SCAAT EKF (position, PDR heading and scale "
                    "corrections) on PDR steps and ultrasound range/bearing (sec. 6)"
                  : "ultrasound-beacons paper: beacon positions by MDS with shortest-path "
                    "completion and SMACOF refinement, anchored online (sec. 5)";
  }
  std::vector<std::string> required_files() const override {
    if (track_) return {"steps.csv or imu.csv", "ranges.csv"};
    return {"ranges.csv"};
  }
  std::vector<std::string> optional_files() const override {
    return {"bearings.csv", "events.csv"};
  }
  bool CanRun(const MissionDirectory& mission) const override;
  PipelineSummary Run(const PipelineContext& context, EstimateSink& sink) const override;

 private:
  bool track_;
};

/// The way back out for one agent at time `at_s` (default: the end of the mission): the
/// beacons heard in the last `window_s` seconds, the route by the smallest-id rule, and where
/// the next beacon is (when the beacon positions can be estimated).
struct WayOutReport {
  std::vector<std::string> heard;
  std::vector<std::string> route;     ///< beacon ids to follow, ending at the entry beacon
  std::optional<std::string> broken;  ///< why the route does not reach the entry
  std::vector<std::optional<Vec2>> route_positions_n;
};
WayOutReport ComputeWayOut(const MissionDirectory& mission, const std::string& agent,
                           std::optional<TimeS> at_s, double window_s = 3.0);

}  // namespace trailmark

#pragma once
/// The radio-landmarks paper's estimators on mission directories.
///  - `landmarks-stopgo`: dead reckoning between stops; at every stop (events stop/go) the RSSI
///    of each landmark is averaged; after each stop the stop-and-go problem (landmarks/
///    stop_and_go.h) is solved over all stops so far with the standing positions from the PDR,
///    giving the unknown landmarks; the handheld is then re-localized at the stop with the
///    landmarks (sec. 6.2) and dead reckoning continues from that fix.
///  - `landmarks-ukf`: the same landmark estimation, plus the UKF (landmarks/landmark_ukf.h)
///    with the steps (or the INS on imu.csv) as motion model and every RSSI answer of a
///    localized landmark as an update (sec. 5.4, with the ZUPT INS as motion model: ours).
/// Landmarks with `position` (and `position_sigma`) are known; without, they are estimated.
/// The radio calibration comes from mission.json (else the default model, noted).

#include "trailmark/pipelines/pipeline.h"

namespace trailmark {

class LandmarksPipeline : public Pipeline {
 public:
  explicit LandmarksPipeline(bool ukf) : ukf_(ukf) {}
  std::string name() const override { return ukf_ ? "landmarks-ukf" : "landmarks-stopgo"; }
  std::string description() const override {
    return ukf_ ? "radio-landmarks paper: landmarks from stop-and-go, responder by a UKF of PDR/INS "
                  "motion and every RSSI answer (sec. 5.4)"
                : "radio-landmarks paper: stop-and-go localization of landmarks and stops, dead "
                  "reckoning re-anchored at each stop (sec. 5.3, 6.2)";
  }
  std::vector<std::string> required_files() const override {
    return {"steps.csv or imu.csv", "rssi.csv", "3+ landmarks in mission.json"};
  }
  std::vector<std::string> optional_files() const override { return {"events.csv"}; }
  bool CanRun(const MissionDirectory& mission) const override;
  PipelineSummary Run(const PipelineContext& context, EstimateSink& sink) const override;

 private:
  bool ukf_;
};

}  // namespace trailmark

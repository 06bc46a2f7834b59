// SPDX-License-Identifier: MIT
#pragma once
/// The zero-velocity INS (zupt_ins.h) for every agent of an incident, and the `ins` estimator:
/// one ZuptIns per agent, created at its first IMU sample with the agent's start and heading
/// from the mission (else the origin and heading 0). Its steps feed every steps-based
/// estimator through the StepFrontEnd (step_front_end.h); its positions are the `ins`
/// pipeline's estimates. No I/O.

#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>

#include "trailmark/core/mission.h"
#include "trailmark/core/online_estimator.h"
#include "trailmark/core/options.h"
#include "trailmark/ins/dead_reckoning.h"
#include "trailmark/ins/height.h"
#include "trailmark/ins/zupt_ins.h"

namespace trailmark::ins {

/// The INS's settings as `--option` keys (docs/pipeline-options.md).
const OptionTable<InsOptions>& InsOptionTable();

/// One ZuptIns per agent.
class MultiAgentIns {
 public:
  MultiAgentIns(MissionInfo info, InsOptions options);
  ~MultiAgentIns();
  MultiAgentIns(const MultiAgentIns&) = delete;
  MultiAgentIns& operator=(const MultiAgentIns&) = delete;
  /// A sample of its agent (each agent's samples in time order). Throws std::invalid_argument
  /// for a sample the INS refuses (units, NaN) or a node that is not an agent of the mission.
  void Add(const ImuSample& sample);
  /// End of data: every agent's INS processes what it still holds.
  void Finish();
  /// Every processed sample: (agent, state).
  std::function<void(const std::string&, const InsState&)> on_state;
  /// Every step.
  std::function<void(const Step&)> on_step;
  /// The agent's latest state (nullopt before its INS is aligned).
  std::optional<InsState> State(const std::string& agent) const;
  /// The earliest end time of a step the agent's INS may still emit (ZuptIns::
  /// EarliestNextStepEnd), and the time of its newest sample; nullopt for an agent not seen.
  std::optional<TimeS> EarliestNextStepEnd(const std::string& agent) const;
  std::optional<TimeS> NewestSample(const std::string& agent) const;
  /// Whether the agent's INS holds its noise model (ZuptIns::OwnErrorsHold); true before it is
  /// aligned and for an agent not seen.
  bool OwnErrorsHold(const std::string& agent) const;
  /// Whether the IMU's mounting about the vertical was searched for and not found (a walk
  /// without straight strides: a search along walls, a crawl): its walk is turned about the
  /// start by an angle nobody knows, and its steps no longer claim the INS's own heading
  /// variance (MountYawEstimator::NotFound).
  bool MountNotFound(const std::string& agent) const;
  /// The earliest EarliestNextStepEnd of the agents whose newest sample is at or after
  /// `active_since` (a device further behind does not hold the others back); nullopt if none.
  std::optional<TimeS> EarliestNextStepEndOfActive(TimeS active_since) const;
  /// The agents seen so far.
  std::vector<std::string> Agents() const;
  /// Per agent: samples, steps, stance fraction, distance, gaps, saturation, gyro bias,
  /// warnings; and the detector.
  EstimatorSummary Summary() const;
  const InsOptions& options() const { return options_; }

 private:
  struct Agent;
  /// A state, or a step with its end state, given out turned; every waiting one given out.
  void Give(Agent& a, const std::string& id, const InsState& st);
  void Give(Agent& a, const Step& step, const InsState& end);
  void Release(Agent& a, const std::string& id);
  MissionInfo info_;
  InsOptions options_;
  std::map<std::string, std::unique_ptr<Agent>> agents_;
};

/// Which INS states become estimates.
enum class InsOutput {
  kRate,   ///< at most `output_hz` per agent (0: every sample), and every step end
  kSteps,  ///< every step end only (the foot at rest, ZUPT-corrected), and the last state
};

struct InsEstimatorOptions {
  InsOptions ins;
  InsOutput output = InsOutput::kRate;
  /// Hz; estimates at most this often per agent (0: every sample). 50 Hz: a foot moves at most
  /// ~10 cm between two (swing ~5 m/s), a tenth of the INS's error after a minute's walk, and a
  /// 820 Hz IMU writes 16x fewer rows than samples. Step ends are written whatever the rate.
  double output_hz = 50;
  /// The foot's own heading offset from the stated start heading (a boot's toe-out: the IMU's
  /// yaw is aligned with where the responder faced, the foot points a few degrees off), added to
  /// the start heading's variance in the covariance written (as dead reckoning's,
  /// PdrOptions::track_heading_offset_sigma_rad); rad. 0: the foot points as stated.
  double track_heading_offset_sigma_rad = PdrOptions{}.track_heading_offset_sigma_rad;
  /// The walker is not the foot the INS tracks: the foot is within half a stride of the walker
  /// along the walk (uniform over +-0.65 m for a 1.3 m stride: sigma 0.375 m) and a foot's width
  /// beside (0.1 m); isotropic 0.35 m in the covariance written, a priori (m). 0: the foot is
  /// what is tracked (the recorded sets' truth is the foot's).
  double foot_offset_sigma_m = 0.35;
  /// The height channel (`height.` keys): z, szz and floor from the steps and baro.csv.
  HeightOptions height;
  bool IsValid(std::string* why) const;
};
const OptionTable<InsEstimatorOptions>& InsEstimatorOptionTable();

/// `ins`: each agent's INS position (with its horizontal covariance) at `output_hz` (or every
/// sample) and at every step end, or at the step ends only; each agent's last state at the end
/// of data. Agents are independent: each agent's samples in time order is all it needs.
/// The covariance written is the filter's plus what mission.json says of the start, which the
/// filter leaves out (its position starts exact, its yaw at `initial_yaw_sigma_rad`): the start
/// position's variance, and a start heading error beyond the filter's own, which turns the
/// whole walk about the start — the variance (sigma_h^2 - sigma_filter^2) u u^T with
/// u = (-(y - y0), x - x0) (the steps it emits are differences: neither enters them). Without a
/// stated start_heading the filter's frame is its own: the covariance carries
/// UnknownHeadingCovariance of the walk since the start instead (dead_reckoning.h).
/// An agent whose INS does not hold its noise model (ZuptIns::OwnErrorsHold: a gyro bias at rest
/// far beyond the stated one, an uncalibrated consumer unit) has a filter covariance that is not
/// this device's: its estimates carry instead the dead reckoning of its own steps with a PDR's
/// errors (the `pdr` estimator's covariance on the same steps: start, heading drift, step and
/// turn scale) on top of the filter's, and a note says so.
class InsEstimator : public OnlineEstimator {
 public:
  InsEstimator(MissionInfo info, InsEstimatorOptions options);
  void Add(const MissionRow& row, EstimateSink& sink) override;
  void Finish(EstimateSink& sink) override;
  std::optional<Estimate> Current(const std::string& node) const override;
  EstimatorSummary Summary() const override;

 private:
  InsEstimatorOptions options_;
  MultiAgentIns ins_;
  HeightChannel height_;
  void Write(const std::string& agent, const InsState& state);
  /// The estimate of `agent` in state `st`, its covariance with the start's uncertainty.
  Estimate ToEstimate(const std::string& agent, const InsState& st) const;
  /// Per agent: the start (x, y), its variance (m^2) and the start heading's variance beyond
  /// the filter's initial yaw variance (rad^2).
  struct StartPrior {
    Vec2 start = Vec2::Zero();
    double position_var_m2 = 0;
    double extra_yaw_var_rad2 = 0;
    bool unknown_heading = false;  ///< no start_heading stated (UnknownHeadingCovariance)
    bool known_start = false;      ///< the mission states it (else the origin)
  };
  std::map<std::string, StartPrior> start_prior_;
  /// The dead reckoning of every agent's steps (a PDR's errors for an INS outside its model).
  DeadReckoningEstimator steps_dr_;
  std::set<std::string> outside_model_;  ///< agents whose INS does not hold its noise model
  EstimateSink* sink_ = nullptr;
  std::map<std::string, TimeS> written_;  ///< per agent: the time of the last state written
  std::size_t ignored_ = 0;
};

}  // namespace trailmark::ins

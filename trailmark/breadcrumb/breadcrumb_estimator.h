// SPDX-License-Identifier: MIT
#pragma once
/// `breadcrumb`: the collaborative localization of the breadcrumb paper (the GEN estimator,
/// localizer.h) as an online estimator over an incident: PDR steps, RSSI between all nodes,
/// direct ranges, drop events. Output: each agent at every step; static nodes (base, landmarks,
/// crumbs) when their estimate changed (checked every `static_period_s` of mission time) and
/// at the end. Needs every row in global time order (the registry feeds it through a
/// StepFrontEnd). No I/O.

#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "trailmark/breadcrumb/localizer.h"
#include "trailmark/core/latency_histogram.h"
#include "trailmark/core/mission.h"
#include "trailmark/core/online_estimator.h"
#include "trailmark/core/options.h"
#include "trailmark/ins/dead_reckoning.h"
#include "trailmark/integrity/dead_reckoning_first.h"

namespace trailmark::breadcrumb {

struct BreadcrumbEstimatorOptions {
  LocalizerOptions localizer;
  double static_period_s = 1.0;  ///< s; how often static estimates are checked for output
  /// Ours (issue 26): RSSI and ranges between nodes on different levels are not used — the
  /// path-loss model has no floors, and a floor costs 10-20 dB (a packet from the floor below
  /// reads as metres farther away). A node's level: the height channel's (an agent now, a
  /// crumb its dropper's at the drop), a node of known position its z's.
  bool gate_other_floors = true;
  /// Ours (issues 21 and 25: never worse than dead reckoning): an agent on a foot INS within
  /// its noise model, with a known start and a stated heading, is written as its dead
  /// reckoning (`pdr`'s estimate of the same steps) while that is inside the network's own
  /// 99 % region (the agent's marginal without the heading offsets' consider terms), the
  /// network's estimate beyond 99.99 %, a blend between (integrity/dead_reckoning_first.h; the
  /// landmark tracker's and the beacon filter's `dr_first`). Measured on the `imu` family:
  /// docs/breadcrumb.md.
  bool dr_first = true;
  integrity::DeadReckoningFirstOptions dr_test;
  bool IsValid(std::string* why) const;
};
/// The `--option` keys (docs/pipeline-options.md).
const OptionTable<BreadcrumbEstimatorOptions>& BreadcrumbOptionTable();

class BreadcrumbEstimator : public OnlineEstimator {
 public:
  /// The localizer set up for the incident's nodes; mission.json's radio calibration replaces
  /// the options' model. Throws std::invalid_argument on invalid options.
  BreadcrumbEstimator(const MissionInfo& info, BreadcrumbEstimatorOptions options);
  ~BreadcrumbEstimator() override;
  /// Rows in global time order (steps by t1). Throws std::invalid_argument for steps of a node
  /// that is not an agent.
  void Add(const MissionRow& row, EstimateSink& sink) override;
  /// Every agent's and static node's final estimate.
  void Finish(EstimateSink& sink) override;
  void UseLevels(const LevelSource* levels) override { levels_ = levels; }
  /// A foot INS's agent moves with the INS's own errors (BreadcrumbLocalizer::UseFootInsMotion)
  /// from its first step on, where that step carries its heading variance (an INS that holds its
  /// noise model, ZuptIns::OwnErrorsHold).
  void StepsFromFootIns(const std::string& agent, bool foot_ins) override {
    if (foot_ins) foot_ins_.insert(agent);
  }
  /// The node's latest estimate as emitted (agents at their latest step, static nodes at their
  /// latest change).
  std::optional<Estimate> Current(const std::string& node) const override;
  /// The agent's heading and scale node's (1 + s) R(psi), once the network has one.
  std::optional<Mat2> StepTransform(const std::string& agent) const override;
  /// The localizer's counters, calibration, range offsets, latency percentiles and notes.
  EstimatorSummary Summary() const override;
  const BreadcrumbLocalizer& localizer() const { return *loc_; }

 private:
  void Emit(const Estimate& e, EstimateSink& sink);
  void EmitAgent(const std::string& id, EstimateSink& sink);
  void EmitStatic(TimeS t, bool all, EstimateSink& sink);
  /// dr_first, decided at the agent's first step (a foot INS within its noise model, a known
  /// start, a stated heading): its dead reckoning and the network's verdict on it.
  void DecideDeadReckoningFirst(const Step& step);
  struct DeadReckoningFirstState {
    DeadReckoning dr;
    integrity::DeadReckoningFirst verdict;
  };
  std::map<std::string, DeadReckoningFirstState> dr_first_;
  std::vector<IntegrityNote> dr_notes_;
  std::vector<std::string> agents_;
  BreadcrumbEstimatorOptions options_;
  std::unique_ptr<BreadcrumbLocalizer> loc_;
  std::map<std::string, double> agent_z_;
  std::set<std::string> foot_ins_;  ///< foot INS agents not yet stepped
  std::vector<std::string> known_starts_;
  std::vector<std::string> setup_notes_;
  std::map<std::string, Vec2> last_static_;
  std::map<std::string, Estimate> current_;
  LatencyHistogram latency_us_;                   ///< per-row processing time (µs)
  TimeS t_last_ = -1e300, next_static_ = -1e300;  ///< t_last_: the latest row's time
  bool any_ = false;
  std::size_t ignored_ = 0;
  /// Whether the two ends of a radio measurement are known to be on different levels.
  bool OnOtherFloors(const std::string& a, const std::string& b) const;
  const LevelSource* levels_ = nullptr;
  MissionInfo info_;
  MissionLevels mission_levels_;  ///< mission.json's levels by id (every packet asks)
  std::size_t other_floor_ = 0;
};

}  // namespace trailmark::breadcrumb

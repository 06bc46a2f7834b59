// SPDX-License-Identifier: MIT
#pragma once
/// The `fusion` estimator (issue 27), first part: track-to-track fusion of the project's
/// estimators. Every member (the breadcrumb network, the beacon trail's EKF, the landmark
/// filter, the map-matching particle filter, dead reckoning: whatever the mission can feed) is
/// fed every row; at each step of an agent, and whenever a member updates it, the members'
/// estimates of that agent at that time are fused by covariance intersection
/// (covariance_intersection.h) — the members dead-reckon the same steps, so their errors are
/// correlated by an amount no one knows, and covariance intersection is consistent for every such
/// correlation. Static nodes (crumbs, beacons, landmarks) come from the member that measures them
/// most directly (FusionMember::static_rank) among those whose evidence rows name the node,
/// whenever it updates one.
///
/// Integrity between members: with three or more members at a step, a member whose estimate
/// lies outside the fusion of the others (squared Mahalanobis distance under the sum of both
/// covariances beyond the 2-dof chi-square quantile of `disagreement_probability`) is left
/// out, the worst first, while three remain; when the last two disagree, both are kept and the
/// fused covariance grows to cover both (the commander sees the doubt). Each change is an
/// integrity note.
///
/// Members that lag (a filter that waits for a stop or for other agents' rows) are waited for
/// at most `max_wait_s` of mission time; a member's estimate older than `stale_s` at the step's
/// time is left out. No I/O.
///
/// What this is not yet: one joint graph of every source and node (the goal); see
/// docs/fusion.md for what the track-level fusion can and cannot gain.

#include <deque>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <unordered_set>
#include <vector>

#include "trailmark/core/mission.h"
#include "trailmark/core/online_estimator.h"
#include "trailmark/core/options.h"
#include "trailmark/fusion/covariance_intersection.h"

namespace trailmark::fusion {

struct FusionOptions {
  /// A fused row waits at most this long (mission time) for members still behind it, s.
  double max_wait_s = 3.0;
  /// A member's last estimate of an agent before t still counts at t when the agent has not
  /// stepped since (standing: nothing moved); else only when at most this old, s.
  double stale_s = 1.0;
  /// A member whose estimates of an agent stay this close to dead reckoning's (rms over the
  /// hat's window, m) uses no evidence of its own for that agent (the RSSI network on a mission
  /// without crumbs is dead reckoning). Where two or more other members do, it is left out: it
  /// would make the hat take dead reckoning's error for theirs. Needs the `pdr` fallback
  /// member. 0: off.
  double follows_dr_m = 0.2;
  /// The region a member's estimate must lie in around the fusion of the others (2-dof
  /// chi-square probability; 99.9 %: a consistent member leaves it one time in a thousand).
  double disagreement_probability = 0.999;
  /// Each member's actual error variance, estimated from the members' pairwise differences
  /// (the N-cornered hat: with independent errors, the mean squared difference of members i
  /// and j is s_i^2 + s_j^2; three or more members determine every s_i^2), averaged over this
  /// time constant, s. A member whose estimated variance exceeds its stated one has its
  /// covariance inflated by the ratio before the intersection (never deflated). 0: off.
  double hat_window_s = 120.0;
  /// Once the hat knows every member's error variance, the fused position weighs the members
  /// by its inverse (the minimum-variance combination) instead of by their stated covariances;
  /// the reported covariance stays the intersection's, grown to cover the shift.
  bool hat_weights = true;
  /// Where only two members count (the hat cannot arbitrate) and every evidence stream one of
  /// them has seen is evidence of the other, of lower static rank, too (the RSSI network and
  /// the beacon filter both reading the ultrasound ranges), they are not two opinions: the one
  /// built for that evidence is used alone.
  bool shared_evidence_to_owner = true;
  /// Which counts the rule above applies at. kTwo: only where two members count (the hat
  /// cannot arbitrate). kAll: a member whose evidence seen is all another's (of lower static
  /// rank) gives way to it whenever both count. kWitness: as kAll for the fused position, but
  /// the member still takes part in the hat's pairwise differences (a third opinion of the
  /// others' errors, not of its own).
  enum class SharedEvidence { kTwo, kAll, kWitness };
  SharedEvidence shared_evidence_members = SharedEvidence::kTwo;
  /// The hat's weights are (1/s_i^2)^hat_power: 1 is the minimum-variance combination of
  /// independent errors; the members' errors share dead reckoning's, and a larger power leans
  /// toward the best member alone.
  double hat_power = 1.0;
  /// Between an agent's fused rows (a foot IMU's steps come once a stride, ~1.1 s), the
  /// estimate predicted to the time of every row the fusion gets, at most every
  /// `predict_period_s`: the last fused position moved on at the velocity since the fused row
  /// at least `predict_baseline_s` before it (taken only when at most 2 s before), for at most
  /// `predict_fraction` of that interval — a walker who stops overshoots by at most that part
  /// of a stride. The covariance grows by (predict_speed_sigma_mps x time ahead)^2 on each
  /// axis. 0: off (an estimate is held until the next fused row). Off by default since
  /// 2026-12-07: the step front end's view between rows (view_period_s, ins/step_front_end.h)
  /// moves the fused estimate on at the last step's velocity as its largest member turns it
  /// (StepTransform): corridor p75 0.82 -> 0.72 m, house 1 0.58 -> 0.51 m (docs/robustness.md).
  double predict_fraction = 0.0;
  double predict_period_s = 0.1;
  double predict_baseline_s = 0.5;
  double predict_speed_sigma_mps = 0.5;
  bool IsValid(std::string* why) const;
};

/// The fusion's own keys (`fusion.`).
const OptionTable<FusionOptions>& FusionOptionTable();

/// One member: a name (its pipeline's) and the estimator, fed without a step front end.
struct FusionMember {
  std::string name;
  std::unique_ptr<OnlineEstimator> estimator;
  /// The streams that carry the member's own evidence (ranges for the beacon filter, RSSI for
  /// the landmark filter): until a row of one arrives, the member only dead-reckons like the
  /// others and its estimates are not used. Empty: used from the start (map matching). The
  /// fusion's output thus never depends on which members were built for streams a mission
  /// lacks: live (members for every stream) equals batch (members for the mission's streams).
  StreamSet evidence{};
  /// Used only at times no other member has an estimate (dead reckoning: before any member's
  /// evidence arrives, or for an agent no other member estimates).
  bool fallback_only = false;
  /// Static nodes (crumbs, beacons, landmarks) come from the member of lowest rank that
  /// estimates them and whose evidence rows name them (any member that estimates them when
  /// none does) — the one whose source measures them most directly (ultrasound ranges
  /// before RSSI to landmarks before RSSI to crumbs); members of equal rank are intersected.
  /// A beacon filter's crumbs, which no range names, are only where they were dropped.
  /// Two members' estimates of a node are not independent evidence of it, and an RSSI network
  /// that treats beacons as crumbs is far from the ranges' map (measured in docs/fusion.md).
  int static_rank = 0;
  /// A fallback member that is a full member for an agent whose steps come from its foot IMU
  /// through the ZUPT INS (OnlineEstimator::StepsFromFootIns): dead reckoning of a foot INS is
  /// a good and honest opinion of its own; of a phone's PDR it is neither.
  bool full_with_foot_ins = false;
};

/// What the fusion did, per member.
struct FusionMemberSummary {
  std::string name;
  long long rows_used = 0;     ///< fused agent rows it took part in
  double weight_sum = 0.0;     ///< sum of its covariance-intersection weights over those rows
  long long exclusions = 0;    ///< rows it was left out of as disagreeing with the others
  long long stale = 0;         ///< rows it had no recent estimate for
  long long follows_dr = 0;    ///< rows it was left out of as no different from dead reckoning
  long long shared_evidence = 0;  ///< rows it gave way to the member built for its evidence
  double inflation_sum = 0.0;  ///< sum of its covariance inflation over the rows it was used in
};

struct FusionSummary {
  long long agent_rows = 0;   ///< fused agent estimates emitted
  long long static_rows = 0;  ///< fused estimates of static nodes emitted
  long long grown_rows = 0;   ///< rows whose covariance grew over two disagreeing members
  long long predicted_rows = 0;  ///< rows predicted between fused rows
  std::vector<FusionMemberSummary> members;
};

class FusionEstimator : public OnlineEstimator {
 public:
  /// `notes`: what the caller has to say of the members (e.g. one it could not build, and why).
  FusionEstimator(MissionInfo info, FusionOptions options, std::vector<FusionMember> members,
                  std::vector<std::string> notes = {});
  ~FusionEstimator() override;
  void UseLevels(const LevelSource* levels) override;
  void StepsFromFootIns(const std::string& agent, bool foot_ins) override;
  /// Every row goes to every member; a step of an agent asks for a fused row at its t1.
  /// A row a member cannot use (std::invalid_argument) still reaches the others; the first
  /// such error is thrown after all have seen the row.
  void Add(const MissionRow& row, EstimateSink& sink) override;
  void Finish(EstimateSink& sink) override;
  std::optional<Estimate> Current(const std::string& node) const override;
  /// The StepTransform of the member with the largest share of the agent's estimate.
  std::optional<Mat2> StepTransform(const std::string& agent) const override;
  /// The members of the agent's latest fused row and their weights ("pdr" alone where dead
  /// reckoning stood in); a static node's: the member it came from.
  std::vector<SourceShare> Sources(const std::string& node) const override;
  /// fusion.* numbers (rows, each member's mean weight, share used, exclusions), and every
  /// member's summary under its name ("breadcrumb.…"), notes and integrity notes included.
  EstimatorSummary Summary() const override;
  const FusionSummary& TypedSummary() const { return summary_; }
  /// The members' names, in order.
  std::vector<std::string> MemberNames() const;

 private:
  class MemberSink;
  struct Pending {
    std::string agent;
    TimeS t = 0;
  };
  void OnMemberEstimate(std::size_t member, const Estimate& e);
  /// Emits the pending agent rows that are due (all of them when `all`).
  void Resolve(EstimateSink& sink, bool all);
  /// Whether p's row is due now. When not: *blocking_latest is the earliest latest estimate of
  /// the members it waits for (the row cannot become due before one of them falls behind, at
  /// now_ - max_wait_s > *blocking_latest, or the wait ends, unless a member estimates more).
  bool Due(const Pending& p, TimeS* blocking_latest = nullptr) const;
  void EmitAgent(const Pending& p, EstimateSink& sink);
  void EmitStatic(const std::string& node, TimeS t, EstimateSink& sink);
  /// Predicted rows at now_ for agents between fused rows (FusionOptions::predict_fraction).
  void Predict(EstimateSink& sink);
  /// The agent's last fused row moved on to t at its velocity; none beyond the prediction's
  /// reach (or before the last fused row, or without a baseline).
  std::optional<Estimate> PredictedAt(const std::string& agent, TimeS t) const;
  /// The member's estimate of the agent at t: its own at t, else interpolated between its
  /// estimates before and after t, else its latest before t unless older than `stale_s`.
  std::optional<Estimate> MemberAt(std::size_t member, const std::string& agent, TimeS t) const;
  void Note(TimeS t, const std::string& agent, std::size_t member, bool excluded, double d2);

  MissionInfo info_;
  FusionOptions options_;
  std::vector<FusionMember> members_;
  std::vector<std::unique_ptr<MemberSink>> sinks_;
  std::vector<bool> active_;  ///< per member: its evidence has arrived
  std::set<std::string> foot_ins_agents_;  ///< agents whose steps come from a foot INS
  /// Whether member m is used only as a fallback for this agent.
  bool FallbackFor(std::size_t m, const std::string& agent) const;
  std::vector<StreamSet> seen_evidence_;  ///< per member: which of its evidence streams came
  /// Per member: the nodes its evidence rows named (a range's or RSSI packet's ends).
  std::vector<std::unordered_set<std::string>> measured_;
  double gate_d2_ = 0.0;
  TimeS now_ = -1e300;
  /// Per agent, the times a fused row is asked for (its steps' ends, and every time a member
  /// used estimates it), resolved in time order.
  struct PendingTimes {
    std::set<TimeS> times;
    /// Resolve skips the agent while nothing of it changed and now_ has not passed this
    /// (Due's blocking_latest of its first time); -inf: check.
    TimeS blocked_until_behind = -std::numeric_limits<double>::infinity();
    void Touch() { blocked_until_behind = -std::numeric_limits<double>::infinity(); }
  };
  std::map<std::string, PendingTimes> pending_;
  /// Per member, per agent: its recent estimates (time order).
  std::vector<std::map<std::string, std::deque<Estimate>>> agent_history_;
  /// Per member, per static node: its latest estimate.
  std::vector<std::map<std::string, Estimate>> static_latest_;
  std::vector<std::string> static_dirty_;
  std::map<std::string, Estimate> current_;
  /// Per agent: its recent fused rows (time, position; the prediction's baseline) and the time
  /// of its last row written (fused or predicted).
  std::map<std::string, std::deque<std::pair<TimeS, Vec2>>> fused_track_;
  struct Written {
    TimeS t = 0;                 ///< of the agent's last row written (fused or predicted)
    bool no_prediction = false;  ///< none possible until its next fused row (PredictedAt)
  };
  std::map<std::string, Written> last_written_t_;
  std::map<std::string, std::vector<SourceShare>> sources_;  ///< of each node's latest row
  /// The N-cornered hat of one agent: time-averaged squared differences of each pair of
  /// members (per axis, m^2) and each member's stated variance (per axis, m^2).
  struct Hat {
    TimeS t = 0;
    std::map<std::pair<std::size_t, std::size_t>, std::pair<double, double>> pair;  // weight, mean
    std::map<std::size_t, std::pair<double, double>> stated;                        // weight, mean
  };
  /// What the hat says of each member now: its covariance inflation (>= 1) and, once every
  /// pair has history, its estimated error variance (per axis, m^2).
  struct HatEstimate {
    std::vector<double> inflation;
    std::optional<std::vector<double>> variance_m2;
  };
  /// Updates the agent's hat with the members' estimates.
  HatEstimate UpdateHat(const std::string& agent, TimeS t, const std::vector<std::size_t>& members,
                        const std::vector<Estimate>& inputs);
  std::map<std::string, Hat> hats_;
  /// Per agent: its recent steps (t0, t1), to tell standing from walking.
  std::map<std::string, std::deque<std::pair<TimeS, TimeS>>> steps_;
  /// Whether the agent stepped between two times (a step overlaps (from, to)).
  bool MovedBetween(const std::string& agent, TimeS from, TimeS to) const;
  /// Per (agent, member): time-averaged squared distance from dead reckoning (weight, mean).
  std::map<std::pair<std::string, std::size_t>, std::pair<double, double>> from_dr_;
  std::map<std::string, TimeS> from_dr_t_;
  /// (agent, member) pairs left out at the last row.
  std::map<std::pair<std::string, std::size_t>, bool> excluded_;
  std::vector<std::string> member_notes_;
  std::vector<IntegrityNote> notes_;
  long long notes_dropped_ = 0;
  FusionSummary summary_;
};

}  // namespace trailmark::fusion

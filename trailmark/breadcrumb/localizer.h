// SPDX-License-Identifier: MIT
#pragma once
/// Collaborative localization of firefighters and breadcrumbs (breadcrumb paper, sections
/// IV-E and IV-F) on top of the GEN (gen_network.h).
///
/// Mobile nodes, IV-E: each agent is one state of the extended graph at a time. A measurement
/// involving the agent at time t moves the agent to a new state: AddNode(new), AddMeasurement
/// (new - old = PDR displacement, covariance from the PDR), DeleteNode(old) (marginalization).
/// Measurements closer in time than `state_period_s` share a state; the small PDR displacement
/// between the measurement time and the state time is applied as a known offset and its
/// variance added to the measurement's. Radio measurements wait (at most `max_latency_s`) until
/// the agent's PDR covers their time, so they are attached to an interpolated position.
///
/// Static nodes: anchors and surveyed landmarks (a prior), dropped crumbs (a `drop` event: the
/// crumb is where the dropping agent's foot is, within drop_sigma_m), and nodes of unknown
/// position (landmarks without `position`, crumbs heard before any drop): those are initialized
/// after enough ranges from distinct positions (grid search + Gauss-Newton, the mirror ambiguity
/// checked) and then enter the GEN with that prior.
///
/// Radio: agent<->node RSSI packets are scalar edges in the dB domain,
///   z = alpha - 10 n log10 |x_i - x_j| + e,   e ~ N(0, sigma_db^2)
/// which is the range measurement with the distance-dependent variance of the log-distance
/// model. Node<->node links are persistent edges (averaged, re-linearized). Encounters (a local
/// RSSI maximum above -40 dBm, sec. V-A) are relative-position edges of ~1 m. A lasting jump
/// on a crumb's links marks the crumb as moved (sec. V-C): it gets a new state tied to the old
/// one by a kick-sized covariance, so it can move.
///
/// Outliers, IV-F: steps faster than max_speed_mps are dropped; every scalar measurement is
/// gated on its normalized innovation and down-weighted (Huber) beyond huber_k sigma.

#include <deque>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "trailmark/breadcrumb/gen_network.h"
#include "trailmark/core/measurements.h"
#include "trailmark/integrity/consistency.h"
#include "trailmark/radio/path_loss.h"

namespace trailmark::breadcrumb {

struct LocalizerOptions {
  GenOptions gen;
  // PDR
  double default_step_sigma_m = 0.03;        ///< steps without variance: sigma = a + b * length
  double default_step_relative_sigma = 0.05;
  double min_step_variance_m2 = 1e-6;
  /// Floor of a step's per-axis sigma: floor_a + floor_b * length. PDR heading error is a
  /// drift (gyro bias and scale factor), not white noise; a positions-only graph can only cover
  /// it by not trusting short-term PDR beyond this (IV-F: lessen the effect of noisy data).
  double step_sigma_floor_m = 0.03;
  double step_sigma_floor_relative = 0.15;
  double max_speed_mps = 5.0;                ///< IV-F: a firefighter never exceeds 5 m/s
  // heading/scale correction of the PDR (beyond the paper; the ultrasound paper's EKF does the
  // same with psi and scale): each agent carries a node theta = (psi, s) and every PDR edge is
  // x_new - x_old = (1 + s) R(psi) delta_pdr + e. psi is a random walk (gyro bias drift plus a
  // gyro scale-factor error that accrues with every turn), s nearly constant.
  bool estimate_heading_scale = true;
  double heading_sigma0_rad = 0.05;          ///< when mission.json gives no start_heading_sigma
  /// The steps' own heading offset from the stated start heading (a boot's toe-out, a phone's
  /// carrying mode; PdrOptions::track_heading_offset_sigma_rad, 5 deg): a consider parameter
  /// per agent (GenNetwork::AddConsider), not in the heading node's prior. Every edge that
  /// carries the agent's PDR displacement says how it turns with it; each node's sensitivity
  /// to it, through every solve, adds sigma^2 s s^T to the reported covariance only: the
  /// estimates are those without it. As the heading node's prior it made right walks worse
  /// (plain families p75 1.67 -> 1.98 m, docs/breadcrumb.md). 0: none (no extra solves).
  double track_heading_offset_sigma_rad = 0.087;
  /// A stated start_heading_sigma below this is raised to it (0: taken as stated).
  double start_heading_sigma_floor_rad = 0.0;
  /// The entry heading (issue 25, item 1; as the beacon filter's, docs/beacons.md): for an
  /// agent with a start_heading, the steps' rotation into the navigation frame is measured once,
  /// m = the stated start heading minus the direction of its first entry_track_m of PDR (a
  /// responder walks in facing forward), sigma_m = hypot(start sigma, entry_track_heading_sigma)
  /// (the first metre's own direction noise). The stated start_heading_sigma is a claim about
  /// the steps' alignment; m checks it (issue 21: a source checked against its stated noise):
  ///  - m within entry_gate_sigma of hypot(start sigma, sigma_m): the claim holds; the heading
  ///    node gets the stated prior and m;
  ///  - beyond that, but within entry_gate_sigma of hypot(start sigma, the steps' own offset
  ///    track_heading_offset_sigma_rad, sigma_m): the claim is refuted (the steps are turned by
  ///    more than stated, e.g. a magnetometer's alignment); m alone, and a note;
  ///  - further still: the walk did not start along the stated heading; the stated prior
  ///    widened by the steps' offset, and a note.
  /// Until then the heading node's prior is weak (entry_prior_sigma_rad); the steps' offset is
  /// estimated, not a consider parameter. An agent that walks 3 entry_track_m without getting
  /// that far from its start gets the widened prior.
  bool entry_heading = true;
  /// A start_heading given without its sigma: its value's accuracy is unknown, so the
  /// measurement takes this sigma (a magnetometer's indoor heading, ~10 deg), while the steps'
  /// alignment prior stays heading_sigma0_rad.
  double entry_unstated_sigma_rad = 0.17;
  double entry_track_m = 1.0;
  double entry_track_heading_sigma_rad = 0.05;
  double entry_gate_sigma = 3.0;
  double entry_prior_sigma_rad = 1.0;
  double scale_sigma0 = 0.05;
  double heading_rw_rad_per_sqrt_s = 0.003;
  double heading_per_turn_sigma = 0.01;      ///< random part per turn, fraction of its angle
  double scale_rw_per_sqrt_s = 1e-4;
  /// The gyro scale-factor error as a constant per agent (a node (k, -)): every turn of Delta
  /// (rad, signed, as the PDR measured it) adds k Delta to psi. MEMS gyros: 1-3 % (sigma0 5 %).
  bool estimate_gyro_scale = true;
  double gyro_scale_sigma0 = 0.05;
  /// Ours (issue 24 item 2, for the RSSI network too): an agent whose steps come from a foot
  /// INS (UseFootInsMotion) moves with the INS's own errors, not a phone PDR's: its heading's
  /// random walk is each step's own yaw variance growth (Step::heading_var_rad2) instead of
  /// heading_rw, and these instead of the PDR's (set a priori, as PdrOptions::FootIns: step
  /// and turn scale 1 %; the step floor a fifth of the PDR's — the INS measures each step;
  /// the random part of a turn half of it).
  struct FootIns {
    bool own_errors = true;  ///< false: a foot INS's steps with the PDR's errors
    double step_sigma_floor_m = 0.01;
    double step_sigma_floor_relative = 0.02;
    double heading_per_turn_sigma = 0.005;
    double scale_sigma0 = 0.01;
    double gyro_scale_sigma0 = 0.01;
    double scale_rw_per_sqrt_s = 1e-5;
  } foot_ins{};
  /// The PDR heading's drift rate as a constant per agent (issue 25, item 1): the gyro bias a
  /// foot or phone PDR leaves, which turns its heading at b rad/s whether the agent walks or
  /// stands (the second component of the gyro node (k, b)): psi_new - psi_old = k Delta + b dt
  /// + w. A random walk alone (heading_rw) cannot follow a drift over minutes, least of all
  /// across a standstill, where no step says anything. sigma0: a MEMS PDR's residual heading
  /// drift of a few degrees per minute (1e-3 rad/s = 3.4 deg/min). Off by default: better
  /// ellipses but mixed accuracy on held-out variants (docs/breadcrumb.md).
  bool estimate_heading_rate = false;
  double heading_rate_sigma0_rad_per_s = 1e-3;
  /// With the rate: a new agent state at least this often (s) at a step's start, so that dead
  /// reckoning between radio measurements turns with the drift (3 deg/min: 0.25 deg in 5 s).
  double heading_rate_state_period_s = 5.0;
  // mobile states, IV-E
  double state_period_s = 0.4;
  double max_latency_s = 2.0;
  // radio
  radio::LogDistanceModel radio;             ///< replaced by mission.json's calibration
  double min_rssi_dbm = -65.0;  ///< weaker packets are mostly NLOS (walls): biased, dropped
  bool use_agent_rssi = true;
  /// Per-packet sigma of agent<->node RSSI edges = factor x the calibrated sigma: packets of one
  /// link are correlated over the shadowing correlation distance (a few metres, ~10 packets at
  /// walking speed), so each carries far less than sigma_db's information. > 0 overrides.
  double agent_rssi_sigma_db = 0;
  double agent_rssi_sigma_factor = 4.0;
  /// Online calibration of the log-distance model with body shadowing (issue 8, item 3): the
  /// effective channel (walls, the wearer's body, antennas on the floor) differs from a
  /// line-of-sight calibration. Pairs come from local geometry only: packets within
  /// calibration_window_s of a drop or an encounter of that node, whose distance and bearing
  /// are the agent's PDR displacement since/until then (precise over seconds, and the heading
  /// error cancels). Until the first fit agent RSSI only feeds encounters; then the pairs are
  /// re-fitted every period (trimmed least squares, radio/path_loss.h).
  bool calibrate_online = true;
  std::size_t calibration_min_pairs = 150;
  double calibration_period_s = 30.0;
  double calibration_window_s = 15.0;
  double calibration_min_distance_m = 1.0;
  /// The fit (radio/path_loss.h): 5 % trimmed per 1 m bin, with the body-shadowing term.
  radio::PathLossCalibrationOptions calibration = {0.05, 1.0, true};
  /// The packets kept are those >= min_rssi_dbm only: a truncated sample. Calibrated as one
  /// (the likelihood fit of path_loss.h), and an RSSI edge predicts the mean of the kept packets
  /// (ScalarModel::truncation_dbm), not the channel's mean (issue 25: least squares fitted an
  /// exponent of 1.97 where the truth was 2.8).
  bool model_rssi_truncation = false;
  /// > 0: without enough local pairs after this long (no encounters, say), the given model is
  /// used. 0 (default): agent RSSI ranges wait for a fit (a mission.json model made in line of
  /// sight misleads in walled rooms: measured on training-building).
  double calibration_timeout_s = 0.0;
  bool use_static_rssi = true;
  bool use_encounters = true;
  radio::EncounterOptions encounter;
  double encounter_sigma_m = 1.0;
  /// Encounters beyond IV-F's Huber constant down-weighted, as every other measurement is (its
  /// 2-D radius: the tail probability of huber_k, 2.0 for 1.5); false: each at
  /// encounter_sigma_m whatever its innovation (the paper's).
  bool robust_encounters = true;
  /// A dropper's peak from its own crumb within this long after the drop is not an encounter:
  /// the drop's edge and the steps since (precise over seconds) already say where the crumb is,
  /// and walking away its near field peaks 2-4 m behind (measured on BLE channels of 6-8 dB;
  /// taking those within 2.45 sigma by the steps instead measured worse on the office loop's
  /// families, docs/breadcrumb.md). 0: every peak counts. A return later counts.
  double own_drop_encounter_after_s = 10.0;
  /// A crumb that no drop named and its packets have not yet placed enters the network at its
  /// first encounter, tied to the agent's state by encounter_sigma_m (as a drop by drop_sigma_m).
  /// On since 2026-12-07 (with robust encounters; docs/breadcrumb.md).
  bool encounter_places_crumbs = true;
  /// min_rssi_dbm and encounter.threshold_dbm are the paper's, for its channel (868 MHz: about
  /// -40 dBm at 1 m, sec. V-A). With relative_rssi_thresholds they move with this channel's
  /// level at 1 m (a BLE channel reads ~20 dB lower: every packet fell below -65 dBm, no
  /// encounter passed -40 dBm, and the radio was never used): the given model's alpha
  /// (radio_given), else the paper's, unless the packets contradict it. The check: the median
  /// of the packets a dropper hears from its crumb within reference_window_s of the drop and
  /// reference_max_distance_m of it (PDR), brought to 1 m with the model's exponent. The crumb
  /// is then behind its dropper, whose body takes 0 to reference_body_loss_max_db (an assumed
  /// bound) off every packet: half of it is added, and the level contradicts the stated one
  /// when they differ by more than that half plus 3 standard errors of the median (over the
  /// drops: the packets of one drop share their shadowing); from then on
  /// the thresholds follow the packets' level (a summary note says when and by how much).
  bool relative_rssi_thresholds = true;
  double paper_reference_dbm = -40.0;
  double reference_window_s = 3.0;
  double reference_max_distance_m = 2.5;
  int reference_min_samples = 5;
  double reference_body_loss_max_db = 10.0;
  /// Set by the caller when `radio` is the mission's stated model (not the default).
  bool radio_given = false;
  double drop_sigma_m = 0.5;
  double default_range_sigma_m = 0.5;        ///< ranges.csv rows without sigma
  /// Range offset and scale per range kind (UWB antenna/hardware delay and clock: the recorded
  /// Plaza ranges are ~1.05 d + 0.8 m), estimated as a node (offset, scale) of the network.
  bool estimate_range_bias = true;
  double range_bias_sigma0_m = 5.0;
  /// 0 keeps the scale at 0: with a PDR scale also estimated (heading/scale node) the two trade
  /// off and are poorly observable; enable it when the odometry scale is trusted.
  double range_scale_sigma0 = 0.0;
  /// Per-node RSSI offset (issue 25, item 3): each crumb's (or landmark's) transmit power and
  /// antenna differ — ±3-4 dB between beacons of one make on recorded BLE — so every agent
  /// packet from it is z = h(d) + o_node + e, o_node with a prior N(0, rssi_node_offset_sigma_db)
  /// (a priori: the spread quoted above). kInnovations (default): o_node is the prior-shrunk,
  /// information-weighted mean of the node's packet innovations before it, subtracted from each
  /// packet (the network stays as sparse as without); kNetwork: o_node a state of the network,
  /// estimated jointly (the crumbs' offsets couple through the agent states: 4.5x the time of
  /// the 20-firefighter benchmark); kOff: none.
  enum class RssiOffsets { kOff, kInnovations, kNetwork };
  RssiOffsets rssi_offsets = RssiOffsets::kInnovations;
  double rssi_node_offset_sigma_db = 4.0;
  // robustness
  double gate_sigma = 5.0;                   ///< reject when |innovation| > gate * sigma_S
  double huber_k = 1.5;                      ///< variance x (|nu| / (k sigma_S)) beyond k
  /// A range edge of an agent is linearized once, at the estimates of that moment, and folded
  /// into the network when the agent's state leaves. With this, the edge carries the
  /// second-order terms of its model at the two nodes' uncertainty (ScalarModel::
  /// SecondOrderTerms: the expected range is longer than the estimates' distance by about
  /// sigma_t^2 / 2d, and less certain), so that edges to a beacon still poorly placed do not
  /// all pull one way (issue 25, item 2; ours). RSSI edges stay first-order (localizer.cpp).
  bool second_order = true;
  /// A fixed-lag window (issue 25, item 2; ours): an agent's states of the last fixed_lag_s
  /// stay in the network, and its range edges (and RSSI edges with fixed_lag_rssi) are
  /// persistent (GenNetwork::AddScalarPersistent): re-linearized at every solve until their
  /// state leaves the window, then folded at the estimates of that moment. An edge added while
  /// the agent or the node was far from the truth (a loop closure, a beacon just placed) is
  /// thus taken again at the better estimates the next measurements give, before it is
  /// committed. 0: off (the paper's mobile node, IV-E: a state is marginalized as soon as the
  /// next one exists).
  double fixed_lag_s = 0.0;
  bool fixed_lag_rssi = false;
  /// The PDR checked against its stated noise (issue 21; ours). Each agent's radio and range
  /// edges' innovations, normalized by one measurement's noise plus the position uncertainty
  /// the network states (not the edges' correlation-inflated variance; refused and gated
  /// edges count too, capped at the gate), are averaged per node it hears; the median over the
  /// nodes heard in the last 30 s (at least 3) is the agent's: one node that lies moves its
  /// own mean, an agent whose motion lies moves every node's. While that median is above 1
  /// the agent's step and heading noise for new states are scaled up (integral control toward
  /// 1, between 1 and motion_noise_scale_max, in variance). A phone's steps claiming a foot's
  /// noise, a drift beyond the a-priori sigmas.
  bool adapt_motion_noise = true;
  double motion_noise_scale_max = 100.0;
  /// RSSI is attenuated by walls, bodies and smoke, seldom amplified: a packet weaker than
  /// predicted (nu < 0) is down-weighted beyond this many sigma (one-sided NLOS robustness).
  double rssi_nlos_k = 0.5;
  /// Static links: slow shadowing does not average out (variance floor, dB^2 = sigma^2 x this).
  double static_link_floor_fraction = 0.75;
  // moved crumbs, sec. V-C
  bool detect_moved = true;
  /// The link shift test; min_z 5: a shift of 5 of the link's own standard errors as well as
  /// 3 dB (issue 25, item 4: 322 false detections in 58 unkicked runs with the dB test alone).
  radio::LinkChangeOptions link_change = {8, 5, 3.0, 5.0};
  double moved_sigma_m = 1.5;                ///< "within 1 to 2 meters"
  // delayed initialization of nodes with unknown positions
  int init_min_measurements = 8;
  double init_min_spread_m = 3.0;            ///< measuring positions must span this (2nd axis)
  double init_ambiguity_chi2 = 10.0;         ///< mirror solution must be this much worse
  double init_covariance_inflation = 4.0;
  double init_grid_m = 1.0;
  // throttling for large incidents (0 = exact online behaviour: solve at every request)
  double solve_period_s = 0.25;       ///< re-solve L x = b at most this often (mission time)
  double covariance_period_s = 0.25;  ///< refresh a node's marginal covariance this often
  // agents
  double known_start_sigma_m = 0.01;         ///< `start` without `start_sigma`
  double unknown_start_sigma_m = 1000.0;
  /// Each static node's RSSI and ranges from agents checked against their stated noise
  /// (issue 21, integrity/consistency.h): an inconsistent crumb, landmark or anchor (moved,
  /// offset, surveyed wrong) is left out until it agrees again.
  integrity::ConsistencyOptions integrity;
};

struct LocalizerSummary {
  std::size_t steps = 0, steps_rejected = 0;
  std::size_t rssi_packets = 0, rssi_weak = 0, rssi_agent_used = 0, rssi_static_used = 0;
  std::size_t near_field_samples = 0;
  double rssi_threshold_shift_db = 0;  ///< the thresholds' shift from the paper's (last)
  std::size_t ranges_used = 0;
  std::size_t gated = 0, downweighted = 0;
  std::size_t refused = 0;  ///< by the integrity check (a static node inconsistent with its noise)
  std::size_t refusals_blamed_on_motion = 0;  ///< flagged nodes used anyway (BlameMotion)
  std::size_t encounters = 0, drops = 0, moved_detected = 0;
  std::size_t encounters_after_own_drop = 0;  ///< peaks of a crumb its dropper was leaving, refused
  std::size_t crumbs_placed_by_encounters = 0;
  std::size_t encounters_downweighted = 0;  ///< beyond Huber's 2-D radius (robust_encounters)
  std::size_t agent_states = 0, delayed_initializations = 0, pending_uninitialized = 0;
  /// entry_heading: claims held, refuted (the measurement alone), entries not along the
  /// stated heading (the widened prior).
  std::size_t entry_headings = 0, entry_headings_refuted = 0, entry_headings_refused = 0;
  std::size_t unusable = 0;  ///< measurements that could not be attached (with reasons in notes)
  std::size_t solves = 0, factorizations = 0, symbolic_analyses = 0, dense_factorizations = 0;
  std::size_t sensitivity_solves =
      0;  ///< track_heading_offset_sigma_rad's, C right-hand sides each
  int max_dimension = 0;                ///< of the network's largest system
  std::size_t max_factor_nonzeros = 0;  ///< of its LDL^T factor
  std::size_t calibrations = 0, calibration_pairs = 0;
  std::optional<radio::PathLossFit> calibration;  ///< the latest online fit
  std::vector<std::string> notes;
};

struct NodeEstimate {
  std::string id;
  Vec2 position_n = Vec2::Zero();
  Mat2 covariance = Mat2::Identity();
  /// The network's own covariance: `covariance` without the agents' heading offsets'
  /// consider terms (track_heading_offset_sigma_rad), which dead reckoning shares.
  Mat2 own_covariance = Mat2::Identity();
};

class BreadcrumbLocalizer {
 public:
  explicit BreadcrumbLocalizer(LocalizerOptions options = {});

  /// Base stations and surveyed landmarks. Declared only: a node enters the network when a
  /// measurement first names it (issue 30: the cost follows the nodes used, not the declared).
  void AddKnownNode(const std::string& id, const Vec2& position_n, double sigma_m);
  struct DeclaredNode {
    Vec2 position_n = Vec2::Zero();
    double sigma_m = 0;  ///< as used (at least 1 mm)
  };
  /// Known nodes declared and never named by a measurement (not in the network).
  const std::map<std::string, DeclaredNode>& DeclaredOnly() const { return declared_known_; }
  /// A static node whose position is unknown (initialized from ranges).
  void AddUnknownNode(const std::string& id);
  /// An agent; `start` empty when unknown; heading sigma for the heading/scale node (empty:
  /// options.heading_sigma0_rad).
  void AddAgent(const std::string& id, const std::optional<Vec2>& start, double start_sigma_m,
                std::optional<double> start_heading_sigma_rad = std::nullopt,
                std::optional<double> start_heading_rad = std::nullopt);
  /// The agent's steps come from a foot INS: from now on it moves with the INS's own errors
  /// (LocalizerOptions::FootIns; unless `foot_ins.own_errors` is off). Its scale and gyro
  /// nodes' priors are tightened to the INS's sigmas by a second prior each (information adds:
  /// exact for independent Gaussian priors). Call it before the agent's first step. Unknown
  /// agents are ignored.
  void UseFootInsMotion(const std::string& id);
  /// The agent's steps come from a foot INS (any grade), before its first step: no entry
  /// heading is measured from its first metre (the INS aligned its yaw to the stated heading and
  /// finds its mounting from its strides, ins/mount_yaw.h; the steps before that decision are
  /// not in the stated frame): the heading node gets the stated prior at once, as when the
  /// entry heading's claim holds, without the measurement.
  void NoEntryHeading(const std::string& id);
  /// Estimated PDR heading correction (rad) and scale error of an agent.
  std::optional<Vec2> HeadingScale(const std::string& id) const;
  /// Estimated gyro scale-factor error and PDR heading drift rate (rad/s) of an agent.
  std::optional<Vec2> GyroScaleRate(const std::string& id) const;
  /// The factor on the agent's step and heading noise (adapt_motion_noise; 1: as stated).
  std::optional<double> MotionNoiseScale(const std::string& id) const;
  /// How the network moves the agent's next step: (1 + s) R(psi) of its heading and scale
  /// node (nullopt: an unknown agent, or none: heading_scale off).
  std::optional<Mat2> StepTransform(const std::string& id) const;
  /// The agents, by id.
  std::vector<std::string> AgentIds() const;

  /// Inputs, each stream in non-decreasing time (steps by t1); streams interleaved by time.
  void AddStep(const Step& step);
  void AddRssi(const RssiPacket& packet);
  void AddRange(const RangeMeasurement& range);
  void AddEvent(const MissionEvent& event);
  /// Processes every buffered measurement the PDR now covers (or that waited max_latency_s).
  void AdvanceTo(TimeS t);
  /// End of data: processes everything still buffered.
  void Finish();

  bool IsAgent(const std::string& id) const { return agents_.count(id) != 0; }
  /// Latest estimate: agents at their latest PDR time; static nodes once they exist.
  std::optional<NodeEstimate> Estimate(const std::string& id);
  /// Time of an agent's latest PDR knot.
  TimeS AgentTime(const std::string& id) const;
  /// Static nodes that exist in the network (known, dropped, initialized), in creation order.
  const std::vector<std::string>& StaticNodes() const { return static_order_; }
  /// Estimated (offset m, scale) of a range kind (empty when not estimated).
  std::optional<Vec2> RangeBias(const std::string& kind) const;
  /// The estimated RSSI offset of a crumb or landmark (dB; rssi_offsets), when it has one.
  std::optional<double> RssiOffsetDb(const std::string& id) const;
  /// Ids of crumbs detected as moved, with the detection time.
  const std::vector<std::pair<TimeS, std::string>>& MovedNodes() const { return moved_; }

  LocalizerSummary summary() const;
  /// The integrity check of the static nodes (integrity notes, counts).
  const integrity::ConsistencyMonitor& node_integrity() const { return node_integrity_; }
  const GenNetwork& network() const { return gen_; }
  const LocalizerOptions& options() const { return options_; }

 private:
  struct Knot {
    TimeS t;
    Vec2 cum;      ///< PDR displacement since the agent's first knot
    Vec2 cum_var;  ///< accumulated per-axis variance
    double cum_turn = 0;  ///< accumulated |turn| of the step directions, rad
    double heading = 0;   ///< raw PDR direction of the step ending here
    double cum_turn_signed = 0;
    double cum_heading_var = 0;  ///< the steps' own heading variance growth (rad^2)
  };
  enum class Kind { kRssi, kRange, kEncounter, kDrop };
  struct Pending {
    TimeS t;
    Kind kind;
    std::string other;  ///< the other node
    double value = 0;   ///< rssi_dbm or range_m
    double sigma = 0;   ///< range sigma
    std::string range_kind;
    bool weak = false;  ///< RSSI below the threshold when heard: a near-field sample only
  };
  struct Agent {
    std::string id;
    /// fixed_lag_s: the earlier states still in the network (position, heading/scale node or
    /// -1, and their time), oldest first.
    struct Lagged {
      NodeIndex state = -1, theta = -1;
      TimeS t = 0;
      std::vector<int> edges;  ///< its persistent range edges (second-order terms at the fold)
    };
    std::deque<Lagged> window;
    std::vector<int> state_edges;  ///< the current state's persistent range edges
    NodeIndex state = -1;
    NodeIndex theta = -1;  ///< heading/scale node (-1 when not estimated)
    NodeIndex gyro = -1;   ///< gyro node (scale factor k, heading rate b); -1 when neither
    std::optional<double> last_heading;
    double state_cum_turn = 0;
    double state_cum_turn_signed = 0;
    double state_cum_heading_var = 0;
    bool foot_ins = false;  ///< the steps come from a foot INS (UseFootInsMotion)
    TimeS state_t = 0;
    Vec2 state_cum = Vec2::Zero();      ///< PDR displacement at the state's time
    Vec2 state_cum_var = Vec2::Zero();
    bool started = false;
    std::deque<Knot> knots;
    /// entry_heading: the stated start heading and its sigma, until the entry track is walked
    /// (then empty).
    std::optional<double> entry_heading_rad;
    double entry_heading_sigma_rad = 0;  ///< the stated start heading sigma (the claim)
    double entry_value_sigma_rad = 0;    ///< the start heading value's sigma (the measurement)
    double entry_walked_m = 0;           ///< path length walked while waiting
    std::deque<Pending> pending;  ///< sorted by t
    /// Calibration: recent packets per static node, and the last drop/encounter time.
    std::map<std::string, std::deque<std::pair<TimeS, double>>> link_history;
    std::map<std::string, TimeS> link_anchor;
    std::map<std::string, TimeS> dropped;  ///< this agent's drops: node -> time
    Mat2 cached_cov = Mat2::Identity() * 100.0;
    /// With a heading/scale node: the cross-covariance of the state and theta and theta's own,
    /// for the PDR walked since the state (its displacement turns with the heading's error).
    Mat2 cached_cross = Mat2::Zero();
    Mat2 cached_theta = Mat2::Zero();
    TimeS cov_t = -1e300;  ///< when cached_cov was computed
    Vec2 cov_cum_var = Vec2::Zero();  ///< PDR variance at that time
    /// track_heading_offset_sigma_rad: this agent's consider parameter, and at the last
    /// refresh the state's and theta's sensitivities to every parameter and the state's PDR
    /// displacement (the walk since turns with the parameter).
    int consider = -1;
    std::vector<Vec2> cached_sens_state, cached_sens_theta;
    Vec2 sens_state_cum = Vec2::Zero();
    /// adapt_motion_noise: per node heard, its edges' normalized innovations' running mean;
    /// the agent's edges counted, the factor on its step and heading noise and the median.
    struct NodeNis {
      double mean = 0;  ///< running mean of the normalized innovations (about 10 edges)
      std::size_t edges = 0;
      TimeS t = 0;  ///< the latest
    };
    std::map<std::string, NodeNis> motion_nis;
    std::size_t motion_edges = 0;
    double motion_noise_scale = 1.0;
    double motion_median = 0;  ///< the latest median over the nodes (0: fewer than 3 heard)
  };
  struct InitObservation {
    Vec2 from;
    double range_m;
    double sigma_m;
    bool biased = false;  ///< a range whose kind has an estimated offset
  };
  struct StaticNode {
    std::string id;
    NodeIndex index = -1;  ///< -1 while uninitialized
    bool known = false;
    Mat2 cached_cov = Mat2::Identity() * 100.0;
    Mat2 cached_consider = Mat2::Zero();  ///< the agents' heading offsets' share, reported only
    TimeS cov_t = -1e300;
    std::vector<InitObservation> init;
    int next_try = 0;
    NodeIndex rssi_offset = -1;  ///< (offset dB, 0): RssiOffsets::kNetwork
    /// RssiOffsets::kInnovations: sum of innovation / S and of 1 / S over the node's packets.
    double offset_sum = 0, offset_info = 0;
  };
  struct Link {
    int edge = -1;
    radio::LinkChangeDetector change;
  };

  Agent& StartedAgent(const std::string& id, TimeS t);
  /// Into the agent's time-ordered queue of measurements waiting for its PDR.
  static void Enqueue(Agent& a, const Pending& q);
  Vec2 CumAt(const Agent& a, TimeS t, Vec2* cum_var, double* cum_turn = nullptr,
             double* cum_turn_signed = nullptr, double* cum_heading_var = nullptr) const;
  /// The PDR displacement `raw` corrected by the agent's current heading/scale estimate.
  Vec2 Corrected(const Agent& a, const Vec2& raw) const;
  /// How a displacement v of agent a's PDR turns with its heading offset (empty: none).
  std::vector<ConsiderRate> Turned(const Agent& a, const Vec2& v) const;
  /// The heading offsets' share of an agent's reported covariance at PDR displacement cum.
  Mat2 ConsiderCovariance(const Agent& a, const Vec2& cum) const;
  /// Walking direction: the last step's direction corrected by the heading estimate.
  double AgentHeading(const Agent& a) const;
  void ProcessAgent(Agent& a, TimeS covered);
  void AttachState(Agent& a, TimeS t);
  /// entry_heading: once the agent's PDR has walked entry_track_m, the measurement of its
  /// heading node.
  /// `measured` false: the stated prior only (NoEntryHeading).
  void EntryHeading(Agent& a, bool measured = true);
  /// fixed_lag_s: marginalizes the agent's states older than the window (their persistent
  /// edges folded at the current estimates).
  void RetireLagged(Agent& a, TimeS t);
  void ApplyPending(Agent& a, const Pending& p);
  /// `source` (a static node's id, may be null) and `t`: the integrity check of that node.
  /// An edge's innovation and its variance's position part (slope^2 u^T (cov_i + cov_j) u),
  /// whether the edge was added or refused or gated.
  struct EdgeInnovation {
    double nu = 0;
    double position_variance = 0;
  };
  /// Empty when the innovation is not finite.
  std::optional<EdgeInnovation> AddScalarRobust(NodeIndex i, NodeIndex j, const Mat2& cov_i,
                                                const Mat2& cov_j, double z, double variance,
                                                const ScalarModel& model, const Vec2& offset,
                                                double k_negative, NodeIndex bias = -1,
                                                const std::string* source = nullptr, TimeS t = 0,
                                                const Agent* agent = nullptr,
                                                const std::vector<ConsiderRate>& rates = {});
  /// Whether the node check's verdict on `node` is the agent's motion, not the node's: the
  /// agent's median over the nodes it hears is above 1 and this node's mean is like its peers'
  /// (within kMotionPeerFactor of the median): then its edges are not refused.
  bool BlameMotion(const Agent& a, const std::string& node) const;
  /// Feeds an agent-to-static packet (weak ones too) to the link's encounter detector and
  /// enqueues a confirmed encounter (not one of a crumb its dropper is leaving).
  void DetectEncounter(Agent& a, const std::string& other, const RssiPacket& p);
  /// adapt_motion_noise: one edge of agent `a` to `node` at t, with the variance of one
  /// measurement.
  void ObserveMotion(Agent& a, const std::string& node, TimeS t,
                     const std::optional<EdgeInnovation>& edge, double measurement_variance);
  NodeIndex RangeBiasNode(const std::string& kind);
  /// The node's RSSI offset state (created with its prior on first use); -1 when not estimated.
  NodeIndex RssiOffsetNode(StaticNode& node);
  double InnovationOffsetDb(const StaticNode& node) const;
  void ObserveUninitialized(StaticNode& node, const Vec2& from, double range_m, double sigma_m,
                            bool biased = false);
  void TryInitialize(StaticNode& node);
  void StaticPacket(const RssiPacket& packet);
  void MarkMoved(const std::string& id, TimeS t);
  StaticNode* FindStatic(const std::string& id);
  ScalarModel RssiModel() const;
  double AgentRssiVariance() const;

  LocalizerOptions options_;
  GenNetwork gen_;
  std::map<std::string, Agent> agents_;
  std::map<std::string, StaticNode> static_;
  std::vector<std::string> static_order_;
  std::map<std::string, DeclaredNode> declared_known_;
  std::map<std::pair<std::string, std::string>, Link> links_;
  std::map<std::pair<std::string, std::string>, radio::EncounterDetector> encounter_;
  std::vector<std::pair<TimeS, std::string>> moved_;
  /// Near-field levels at 1 m (relative_rssi_thresholds) and the thresholds' shift from them.
  struct NearField {
    double dbm_at_1m;    ///< without the body term
    double body_factor;  ///< radio::BodyFactor of the crumb seen from its dropper
  };
  /// The (dropper, crumb) pairs the samples come from: a drop's packets share one shadowing.
  std::set<std::pair<std::string, std::string>> near_field_drops_;
  std::vector<NearField> near_field_;
  double stated_alpha_dbm_ = -40.0;  ///< the reference the thresholds move from
  bool stated_contradicted_ = false;
  double rssi_shift_db_ = 0;
  /// min_rssi_dbm moved with the channel (relative_rssi_thresholds).
  double MinRssiDbm() const { return options_.min_rssi_dbm + rssi_shift_db_; }
  void UpdateRssiShift();
  /// A packet from a crumb heard by its dropper shortly after the drop: a near-field sample.
  void NearFieldPacket(const Agent& a, const std::string& node, TimeS t, double rssi_dbm);
  TimeS now_ = -1e300;
  TimeS last_solve_t_ = -1e300;
  /// When the heading offsets' sensitivities were last solved for (at most once per
  /// covariance_period_s of mission time: C more right-hand sides with the factor).
  TimeS last_sensitivity_t_ = -1e300;
  /// Whether the sensitivities may be read now (computing them if due).
  bool SensitivitiesDue();
  /// Solves unless throttled; true when the factor matches the current network.
  bool SolveThrottled();
  LocalizerSummary summary_;
  integrity::ConsistencyMonitor node_integrity_;
  std::vector<double> motion_means_;  ///< ObserveMotion's scratch (no allocation per edge)
  std::vector<radio::CalibrationPair> calibration_pairs_;
  std::map<std::string, NodeIndex> range_bias_;
  bool calibrated_ = false;
  TimeS next_calibration_ = -1e300;
  TimeS first_agent_rssi_t_ = 1e300;
  void MaybeCalibrate(TimeS t);
  void CalibrationPacket(Agent& a, const std::string& node, TimeS t, double rssi_dbm);
  void SetCalibrationAnchor(Agent& a, const std::string& node, TimeS t);
  double HeadingAt(const Agent& a, TimeS t) const;
};

}  // namespace trailmark::breadcrumb

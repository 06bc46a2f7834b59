// SPDX-License-Identifier: MIT
#include "trailmark/ins/ins_estimator.h"

#include <fmt/format.h>

#include <cmath>
#include <deque>
#include <numbers>
#include <stdexcept>

namespace trailmark::ins {

const OptionTable<InsOptions>& InsOptionTable() {
  static const OptionTable<InsOptions> table = [] {
    using O = InsOptions;
    OptionTable<O> t;
    t.Choice("detector", [](O& o) -> DetectorKind& { return o.detector.kind; },
             std::vector<std::pair<std::string, DetectorKind>>{{"shoe", DetectorKind::kShoe},
                                                               {"are", DetectorKind::kAre},
                                                               {"mv", DetectorKind::kMv},
                                                               {"mag", DetectorKind::kMag},
                                                               {"adaptive", DetectorKind::kAdaptive}},
             "zero-velocity detector (Skog et al. 2010; adaptive: ours, docs/ins.md)");
    t.Integer("window", [](O& o) -> int& { return o.detector.window; },
              OptionBounds::Between(1, 100000),
              "detector window in samples (setting it clears window_s)")
        .AlsoSets([](O& o) { o.detector.window_s = 0; });
    t.Real("window_s", [](O& o) -> double& { return o.detector.window_s; }, "s",
           OptionBounds::NonNegative(),
           "detector window in seconds, one setting for every sample rate (0: use window)");
    t.Real("gamma", [](O& o) -> std::optional<double>& { return o.detector.gamma; }, "",
           OptionBounds::Positive(), "detector threshold", "auto (per detector, docs/ins.md)");
    t.Real("detector_sigma_a", [](O& o) -> double& { return o.detector.sigma_a_mps2; }, "m/s^2",
           OptionBounds::Positive(), "accelerometer noise normalizing the detector statistic");
    t.Real("detector_sigma_g", [](O& o) -> double& { return o.detector.sigma_g_radps; }, "rad/s",
           OptionBounds::Positive(), "gyro noise normalizing the detector statistic");
    t.Real("adaptive_reference", [](O& o) -> double& { return o.detector.adaptive_reference; },
           "", OptionBounds::Positive(), "adaptive: swing energy of normal walking (E_ref)");
    t.Real("adaptive_power", [](O& o) -> double& { return o.detector.adaptive_power; }, "",
           OptionBounds::Any(), "adaptive: exponent p of the threshold scaling");
    t.Real("adaptive_min_scale", [](O& o) -> double& { return o.detector.adaptive_min_scale; },
           "", OptionBounds::Positive(), "adaptive: smallest threshold scale");
    t.Real("adaptive_max_scale", [](O& o) -> double& { return o.detector.adaptive_max_scale; },
           "", OptionBounds::Positive(), "adaptive: largest threshold scale");
    t.Real("adaptive_tau_s", [](O& o) -> double& { return o.detector.adaptive_tau_s; }, "s",
           OptionBounds::Positive(), "adaptive: time constant of the swing-energy tracker");
    t.Real("accel_noise", &O::accel_noise_mps2, "m/s^2", OptionBounds::Positive(),
           "accelerometer process noise per sample (PyShoe)");
    t.Real("gyro_noise", &O::gyro_noise_radps, "rad/s", OptionBounds::Positive(),
           "gyro process noise per sample (PyShoe)");
    t.Flag("biases", &O::estimate_biases,
           "estimate accelerometer and gyro biases (false: the IMU is taken as unbiased)");
    t.Flag("zaru", &O::zaru, "zero angular rate updates in stance (gated)");
    t.Flag("mid_swing_steps", &O::mid_swing_steps,
           "also a step half way through each swing (two a stride, as the walker's)");
    t.Flag("step_at_landing", &O::step_at_landing,
           "a step ends when the foot lands (false: when it lifts off, a step behind the walker)");
    t.Real("zaru_sigma", &O::zaru_sigma_radps, "rad/s", OptionBounds::Positive(),
           "ZARU measurement sigma");
    t.Real("zupt_sigma", &O::zupt_sigma_mps, "m/s", OptionBounds::Positive(),
           "ZUPT measurement sigma");
    t.Real("zaru_gate", &O::zaru_gate_chi2, "", OptionBounds::Positive(),
           "ZARU chi-square gate (3 degrees of freedom)");
    t.Integer(
        "mount_yaw_strides", [](O& o) -> int& { return o.mount_yaw.strides; },
        OptionBounds::Between(0, 1000),
        "forward strides that find the IMU's mounting about the vertical (0: its forward "
        "axis is the foot's)");
    t.Real(
        "mount_yaw_min_stride_m", [](O& o) -> double& { return o.mount_yaw.min_stride_m; }, "m",
        OptionBounds::Positive(), "the shortest stride counted for the mounting");
    t.Real(
        "mount_yaw_max_spread", [](O& o) -> double& { return o.mount_yaw.max_spread_rad; }, "rad",
        OptionBounds::Positive(),
        "a stride further than this from the strides' median is a side step (decided when "
        "three in four lie within it)");
    t.Real(
        "mount_yaw_hold_above", [](O& o) -> double& { return o.mount_yaw.hold_above_rad; }, "rad",
        OptionBounds::NonNegative(),
        "a straight stride this far off the reference holds the INS's output until the mounting "
        "is decided");
    t.Real(
        "mount_yaw_max_turn", [](O& o) -> double& { return o.mount_yaw.max_turn_rad; }, "rad",
        OptionBounds::Positive(), "a stride whose foot turned more than this is not counted");
    t.Real(
        "mount_yaw_min_turn", [](O& o) -> double& { return o.mount_yaw.min_turn_rad; }, "rad",
        OptionBounds::NonNegative(),
        "a mounting found within this of the foot's is not turned for");
    t.Integer(
        "mount_yaw_max_landings", [](O& o) -> int& { return o.mount_yaw.max_landings; },
        OptionBounds::Between(1, 100000),
        "landings after which the mounting is decided with what there is");
    t.Integer(
        "mount_yaw_hold_first_landings",
        [](O& o) -> int& { return o.mount_yaw.hold_first_landings; },
        OptionBounds::Between(0, 100000),
        "from the first step the INS's output waits for the mounting, at most this many "
        "landings (0: only a stride beyond mount_yaw_hold_above holds it)");
    t.Real(
        "mount_yaw_hold_first_release",
        [](O& o) -> double& { return o.mount_yaw.hold_first_release_rad; }, "rad",
        OptionBounds::NonNegative(),
        "the first steps' hold ends at a straight stride within this of the reference (a "
        "mounting about the foot's)");
    t.Real(
        "mount_yaw_interval_max_turn",
        [](O& o) -> double& { return o.mount_yaw.interval_max_turn_rad; }, "rad",
        OptionBounds::NonNegative(),
        "a stride that turned up to this bounds the mounting between its lift-off and landing "
        "headings (0: straight strides only)");
    t.Real(
        "mount_yaw_interval_margin",
        [](O& o) -> double& { return o.mount_yaw.interval_margin_rad; }, "rad",
        OptionBounds::NonNegative(), "each stride's bounds widened by this each way");
    t.Integer(
        "mount_yaw_interval_min_strides",
        [](O& o) -> int& { return o.mount_yaw.interval_min_strides; },
        OptionBounds::Between(1, 100000),
        "strides whose bounds must share one stretch (three in four of all) to decide by them");
    t.Integer(
        "mount_yaw_gait_min_strides", [](O& o) -> int& { return o.mount_yaw.gait_min_strides; },
        OptionBounds::Between(0, 100000),
        "strides the gait's regression needs to decide the mounting (0: off; straight strides "
        "only)");
    t.Real(
        "mount_yaw_gait_max_turn", [](O& o) -> double& { return o.mount_yaw.gait_max_turn_rad; },
        "rad", OptionBounds::Positive(),
        "the gait's regression takes strides whose foot and next chord turned up to this");
    t.Real(
        "mount_yaw_gait_max_sigma", [](O& o) -> double& { return o.mount_yaw.gait_max_sigma_rad; },
        "rad", OptionBounds::Positive(),
        "the gait's regression decides once the mounting's standard error is at most this");
    t.Real(
        "mount_yaw_gait_noise_floor",
        [](O& o) -> double& { return o.mount_yaw.gait_noise_floor_rad; }, "rad",
        OptionBounds::Positive(), "the least scale of the gait regression's residuals");
    t.Real("zaru_recover_s", &O::zaru_recover_s, "s", OptionBounds::NonNegative(),
           "stance over which every ZARU refused grows the gyro bias's covariance to take it "
           "(0: never)");
    t.Real("alignment_s", &O::alignment_s, "s", OptionBounds::NonNegative(),
           "stationary start used for roll, pitch and gyro bias");
    t.Real("gravity", &O::gravity_mps2, "m/s^2", OptionBounds::Positive(), "local gravity");
    return t;
  }();
  return table;
}

struct MultiAgentIns::Agent {
  std::unique_ptr<ZuptIns> ins;
  TimeS newest = -1e300;
  Vec2 start_n = Vec2::Zero();
  /// The IMU's mounting about the vertical (a stated start heading only). Nothing waits for it:
  /// until it is decided the INS's frame is given out as it is; from then on everything is turned
  /// about the start by its correction (when it is worth a turn, `turn_rad`), and the steps after
  /// it also make up, kCatchUpPerStepM at a time (within a walker's speed, for consumers that gate
  /// a step's speed), what the earlier steps were turned short by: a consumer's sum of the steps
  /// lands where the turned INS is.
  std::optional<MountYawEstimator> mount;
  double turn_rad = 0;
  bool turned_any_step = false;
  Vec2 catch_up_n = Vec2::Zero();              ///< still to make up (m)
  double catch_up_m = 0, catch_up_var_m2 = 0;  ///< its length and variance when it began
  static constexpr double kCatchUpPerStepM = 0.3;
  /// Waiting for the mounting (a stride far off the reference): states and steps (with their
  /// end state) in the order the INS gave them; the last one given out.
  bool holding = false;
  bool holding_first = false;  ///< the hold from the first step (hold_first_landings)
  bool stepped = false;
  bool releasing = false;  ///< giving out what waited
  struct Waiting {
    std::optional<Step> step;
    InsState state;  ///< the state, or the step's end
  };
  std::deque<Waiting> waiting;
  std::optional<InsState> given;
  /// A lower bound on t1 of every step still to be given: a waiting step's, else the INS's.
  std::optional<TimeS> EarliestNextStepEnd() const {
    const std::optional<TimeS> own = ins->EarliestNextStepEnd();
    for (const Waiting& w : waiting) {
      if (w.step) return own ? std::min(*own, w.step->t1) : w.step->t1;
    }
    return own;
  }
  InsState Turned(InsState st) const {
    if (turn_rad == 0.0) return st;
    const Eigen::Matrix3d R = Eigen::AngleAxisd(turn_rad, Vec3::UnitZ()).toRotationMatrix();
    st.position_n.head<2>() =
        start_n + R.topLeftCorner<2, 2>() * (st.position_n.head<2>() - start_n);
    st.velocity_n = R * st.velocity_n;
    st.q_nb = Eigen::Quaterniond(R) * st.q_nb;
    st.position_cov = R * st.position_cov * R.transpose();
    return st;
  }
  /// The step turned; `end_n`: where it ends in the INS's frame.
  Step Turned(Step step, const Vec3& end_n) {
    if (turn_rad == 0.0) return step;
    const Eigen::Matrix2d R = Eigen::Rotation2Dd(turn_rad).toRotationMatrix();
    const Vec2 delta = step.delta_n.head<2>();
    step.delta_n.head<2>() = R * delta;
    if (step.variance_m2) {  // the turned covariance's marginal variances
      const Vec3 v = *step.variance_m2;
      const double c = R(0, 0), s = R(1, 0);
      step.variance_m2 = Vec3(c * c * v.x() + s * s * v.y(), s * s * v.x() + c * c * v.y(), v.z());
    }
    if (!turned_any_step) {
      // The steps before were in the INS's frame: their sum ends at start + from, the turned INS
      // at start + R from.
      turned_any_step = true;
      const Vec2 from = end_n.head<2>() - delta - start_n;
      catch_up_n = (R - Eigen::Matrix2d::Identity()) * from;
      catch_up_m = catch_up_n.norm();
      catch_up_var_m2 = std::pow(mount->SigmaRad() * from.norm(), 2);
    }
    if (catch_up_m > 0 && catch_up_n.norm() > 0) {
      // A share f of the catch-up carries f of its variance (the shares' errors are one error).
      const double take = std::min(kCatchUpPerStepM, catch_up_n.norm());
      const Vec2 part = catch_up_n * (take / catch_up_n.norm());
      catch_up_n -= part;
      step.delta_n.head<2>() += part;
      if (step.variance_m2) {
        step.variance_m2->head<2>() += Vec2::Constant(catch_up_var_m2 * take / catch_up_m);
      }
    }
    return step;
  }
};

MultiAgentIns::MultiAgentIns(MissionInfo info, InsOptions options)
    : info_(std::move(info)), options_(options) {}

MultiAgentIns::~MultiAgentIns() = default;

void MultiAgentIns::Give(Agent& a, const std::string& id, const InsState& st) {
  if (on_state) on_state(id, a.Turned(st));
}

void MultiAgentIns::Give(Agent& a, const Step& step, const InsState& end) {
  a.given = a.Turned(end);  // State() while the step is given: its end
  if (!on_step) return;
  Step out = a.Turned(step, end.position_n);
  // A mounting not found leaves the walk turned by what the IMU's forward axis is off the
  // foot's (up to the hold's 15 degrees, more for steps that waited): the INS's own heading
  // variance is not these steps' error, and they no longer claim it (consumers take them with
  // a PDR's errors; house 1, imu family K 250: turned 28.7 degrees, dead reckoning 4.1 m off).
  if (a.mount && a.mount->NotFound()) out.heading_var_rad2.reset();
  on_step(out);
}

void MultiAgentIns::Release(Agent& a, const std::string& id) {
  a.holding = false;
  a.releasing = true;  // State() is each released one's while it is given
  if (a.mount->Decided()) a.turn_rad = a.mount->TurnWorthTakingRad();
  while (!a.waiting.empty()) {
    const Agent::Waiting w = std::move(a.waiting.front());
    a.waiting.pop_front();
    if (w.step) {
      Give(a, *w.step, w.state);
    } else {
      a.given = a.Turned(w.state);
      Give(a, id, w.state);
    }
  }
  a.releasing = false;
}

void MultiAgentIns::Add(const ImuSample& sample) {
  auto it = agents_.find(sample.agent);
  if (it == agents_.end()) {
    const NodeInfo* node = info_.Find(sample.agent);
    if (node == nullptr || node->kind != NodeKind::kAgent) {
      throw std::invalid_argument(
          fmt::format("'{}' has IMU samples but is not an agent in mission.json", sample.agent));
    }
    InsOptions o = options_;
    if (auto start = info_.AgentStart(*node)) o.initial_position_n = *start;
    if (node->start_heading_rad) o.initial_yaw_rad = *node->start_heading_rad;
    it = agents_.emplace(sample.agent, std::make_unique<Agent>()).first;
    Agent* a = it->second.get();
    a->ins = std::make_unique<ZuptIns>(o);
    a->start_n = o.initial_position_n.head<2>();
    // Without a stated heading the INS's frame is its own (any turn of it is as good).
    if (node->start_heading_rad && o.mount_yaw.strides > 0) {
      a->mount.emplace(o.mount_yaw, o.initial_yaw_rad);
    }
    const std::string id = sample.agent;
    a->ins->on_state = [this, a, id](const InsState& st) {
      if (a->mount) a->mount->Start(st.q_nb);
      if (a->holding) {
        a->waiting.push_back({std::nullopt, st});
      } else {
        Give(*a, id, st);
      }
    };
    a->ins->on_step = [this, a, id](const Step& step) {
      const InsState end = *a->ins->LastState();  // the step's end (ZuptIns::EmitStep)
      if (a->mount && !a->mount->Decided() && !a->stepped &&
          options_.mount_yaw.hold_first_landings > 0) {
        a->holding = a->holding_first = true;
      }
      a->stepped = true;
      bool release_first = false;
      if (a->mount && !a->mount->Decided() && end.stance) {
        a->mount->AddLanding(end.position_n, end.q_nb);
        const auto last = a->mount->LastStrideRad();
        if (!a->mount->Decided() && last && std::abs(*last) > options_.mount_yaw.hold_above_rad) {
          a->holding = true;
          a->holding_first = false;  // turned: it waits for the decision
        } else if (a->holding_first && last &&
                   std::abs(*last) <= options_.mount_yaw.hold_first_release_rad) {
          release_first = true;  // mounted about as the foot: no need to wait for the decision
        }
        if (a->mount->Decided()) a->turn_rad = a->mount->TurnWorthTakingRad();
      }
      if (a->holding) {
        a->waiting.push_back({step, end});
      } else {
        Give(*a, step, end);
      }
      if (a->mount && a->mount->Decided() && a->holding) {
        Release(*a, id);
      } else if (a->holding_first && a->holding &&
                 (release_first ||
                  a->mount->Landings() >= options_.mount_yaw.hold_first_landings)) {
        Release(*a, id);  // as they are: the decision's catch-up follows
      }
      if (!a->holding) a->holding_first = false;
    };
  }
  it->second->newest = std::max(it->second->newest, sample.t);
  it->second->ins->Add(sample);
}

void MultiAgentIns::Finish() {
  for (auto& [id, a] : agents_) {
    try {
      a->ins->Finish();
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(id + ": " + e.what());
    }
    if (a->mount) {
      a->mount->Settle();
      Release(*a, id);
    }
  }
}

std::optional<InsState> MultiAgentIns::State(const std::string& agent) const {
  const auto it = agents_.find(agent);
  if (it == agents_.end()) return std::nullopt;
  const Agent& a = *it->second;
  if (a.holding || a.releasing) return a.given;
  const auto st = a.ins->LastState();
  return st ? std::optional<InsState>(a.Turned(*st)) : std::nullopt;
}

std::optional<TimeS> MultiAgentIns::EarliestNextStepEnd(const std::string& agent) const {
  const auto it = agents_.find(agent);
  return it == agents_.end() ? std::nullopt : it->second->EarliestNextStepEnd();
}

bool MultiAgentIns::OwnErrorsHold(const std::string& agent) const {
  const auto it = agents_.find(agent);
  return it == agents_.end() || it->second->ins->OwnErrorsHold();
}

bool MultiAgentIns::MountNotFound(const std::string& agent) const {
  const auto it = agents_.find(agent);
  return it != agents_.end() && it->second->mount && it->second->mount->NotFound();
}

std::optional<TimeS> MultiAgentIns::NewestSample(const std::string& agent) const {
  const auto it = agents_.find(agent);
  return it == agents_.end() ? std::nullopt : std::optional<TimeS>(it->second->newest);
}

std::optional<TimeS> MultiAgentIns::EarliestNextStepEndOfActive(TimeS active_since) const {
  std::optional<TimeS> earliest;
  for (const auto& [id, a] : agents_) {
    if (a->newest < active_since) continue;
    if (const auto b = a->EarliestNextStepEnd()) {
      earliest = earliest ? std::min(*earliest, *b) : *b;
    }
  }
  return earliest;
}

std::vector<std::string> MultiAgentIns::Agents() const {
  std::vector<std::string> out;
  for (const auto& [id, a] : agents_) out.push_back(id);
  return out;
}

EstimatorSummary MultiAgentIns::Summary() const {
  EstimatorSummary summary;
  for (const auto& [id, a] : agents_) {
    const auto& s = a->ins->summary();
    summary.numbers[id + ".samples"] = static_cast<double>(s.samples);
    summary.numbers[id + ".steps"] = static_cast<double>(s.steps);
    summary.numbers[id + ".stance_fraction"] =
        s.samples ? static_cast<double>(s.stance_samples) / s.samples : 0.0;
    summary.numbers[id + ".distance_m"] = s.distance_m;
    summary.numbers[id + ".gaps"] = static_cast<double>(s.gaps);
    summary.numbers[id + ".saturated_samples"] = static_cast<double>(s.saturated);
    summary.numbers[id + ".gyro_bias_z_deg_per_h"] =
        s.gyro_bias.z() * 180 / std::numbers::pi * 3600;
    summary.numbers[id + ".zaru_recoveries"] = static_cast<double>(s.zaru_recoveries);
    if (a->mount) {
      summary.numbers[id + ".mount_yaw_deg"] = a->mount->CorrectionRad() * 180 / std::numbers::pi;
      summary.numbers[id + ".mount_yaw_turned_deg"] = a->turn_rad * 180 / std::numbers::pi;
      summary.numbers[id + ".mount_yaw_sigma_deg"] = a->mount->SigmaRad() * 180 / std::numbers::pi;
      summary.numbers[id + ".mount_yaw_strides"] = static_cast<double>(a->mount->Strides());
      summary.numbers[id + ".mount_yaw_landings"] = static_cast<double>(a->mount->Landings());
      summary.numbers[id + ".mount_yaw_by_bounds"] = a->mount->DecidedByBounds() ? 1.0 : 0.0;
      summary.numbers[id + ".mount_yaw_by_gait"] = a->mount->DecidedByGait() ? 1.0 : 0.0;
      if (a->mount->DecidedByGait()) {
        summary.numbers[id + ".mount_yaw_gait_a"] = a->mount->GaitShares().first;
        summary.numbers[id + ".mount_yaw_gait_b"] = a->mount->GaitShares().second;
      }
      if (!a->mount->Note().empty()) summary.notes.push_back(id + ": " + a->mount->Note());
    }
    for (const auto& w : s.warnings) summary.notes.push_back(id + ": " + w);
  }
  summary.notes.push_back("detector: " + ToString(options_.detector.kind));
  return summary;
}

bool InsEstimatorOptions::IsValid(std::string* why) const {
  if (!ins.IsValid(why) || !height.IsValid(why)) return false;
  if (!(output_hz >= 0) || !std::isfinite(output_hz)) {
    if (why) *why = "output_hz must be >= 0 and finite";
    return false;
  }
  if (!(foot_offset_sigma_m >= 0) || !std::isfinite(foot_offset_sigma_m)) {
    if (why) *why = "foot_offset_sigma_m must be >= 0 and finite";
    return false;
  }
  if (!(track_heading_offset_sigma_rad >= 0) || !std::isfinite(track_heading_offset_sigma_rad)) {
    if (why) *why = "track_heading_offset_sigma_rad must be >= 0 and finite";
    return false;
  }
  return true;
}

const OptionTable<InsEstimatorOptions>& InsEstimatorOptionTable() {
  static const OptionTable<InsEstimatorOptions> table = [] {
    OptionTable<InsEstimatorOptions> t;
    t.Include("", &InsEstimatorOptions::ins, InsOptionTable());
    t.Choice("output", &InsEstimatorOptions::output,
             std::vector<std::pair<std::string, InsOutput>>{{"rate", InsOutput::kRate},
                                                            {"steps", InsOutput::kSteps}},
             "which states become estimates: rate (output_hz and every step end) or steps "
             "(every step end only)");
    t.Real("output_hz", &InsEstimatorOptions::output_hz, "Hz", OptionBounds::NonNegative(),
           "output=rate: estimates per agent per second, step ends besides (0: every sample)");
    t.Real("track_heading_offset_sigma_rad", &InsEstimatorOptions::track_heading_offset_sigma_rad,
           "rad", OptionBounds::NonNegative(),
           "the foot's own heading offset from the stated start heading (toe-out), in the "
           "covariance written");
    t.Real("foot_offset_sigma_m", &InsEstimatorOptions::foot_offset_sigma_m, "m",
           OptionBounds::NonNegative(),
           "the foot's distance from the walker, in the covariance written (0: the foot is what "
           "is tracked)");
    t.Include("height.", &InsEstimatorOptions::height, HeightOptionTable());
    return t;
  }();
  return table;
}

InsEstimator::InsEstimator(MissionInfo info, InsEstimatorOptions options)
    : options_(options), ins_(info, options.ins), height_(info, options.height), steps_dr_(info) {
  std::string why;
  if (!options_.IsValid(&why)) throw std::invalid_argument("ins: " + why);
  for (const NodeInfo& n : info.nodes) {
    if (n.kind != NodeKind::kAgent) continue;
    StartPrior prior;
    if (const auto start = info.AgentStart(n)) {
      prior.start = start->head<2>();
      prior.known_start = true;
    }
    if (n.start_sigma_m) prior.position_var_m2 = *n.start_sigma_m * *n.start_sigma_m;
    // The filter starts its yaw at the stated heading with its own sigma (MultiAgentIns); the
    // stated sigma (the filter's own when none is stated) and the foot's offset are beyond it.
    if (n.start_heading_rad) {
      const double own = options_.ins.initial_yaw_sigma_rad;
      const double stated = n.start_heading_sigma_rad.value_or(own);
      const double offset = options_.track_heading_offset_sigma_rad;
      prior.extra_yaw_var_rad2 = std::max(0.0, stated * stated + offset * offset - own * own);
    } else {
      // No heading stated: the filter's yaw starts at 0 in a frame nobody aligned — the walk is
      // turned about the start by an unknown angle (UnknownHeadingCovariance).
      prior.unknown_heading = true;
    }
    start_prior_[n.id] = prior;
  }
  ins_.on_state = [this](const std::string& id, const InsState& st) {
    if (sink_ == nullptr || options_.output != InsOutput::kRate) return;
    const auto written = written_.find(id);
    // At least 1/output_hz after the last one written, to a microsecond: the choice does not
    // depend on the clock's origin (a sample exactly on the period is taken in every frame).
    if (options_.output_hz > 0 && written != written_.end() &&
        st.t < written->second + 1.0 / options_.output_hz - 1e-6) {
      return;
    }
    Write(id, st);
  };
  // A step is emitted when its stance has ended: the agent's latest state is the stance end.
  ins_.on_step = [this](const Step& step) {
    height_.Add(step);
    if (!ins_.OwnErrorsHold(step.agent) && start_prior_.count(step.agent) != 0 &&
        start_prior_.at(step.agent).known_start) {
      if (outside_model_.insert(step.agent).second) steps_dr_.StepsFromFootIns(step.agent, true);
      NullSink none;
      steps_dr_.Add(step, none);
    }
    if (sink_ == nullptr) return;
    if (const auto st = ins_.State(step.agent); st && st->t == step.t1) Write(step.agent, *st);
  };
}

void InsEstimator::Write(const std::string& agent, const InsState& st) {
  auto [it, fresh] = written_.emplace(agent, st.t);
  if (!fresh) {
    if (st.t <= it->second) return;  // (a step end the rate wrote already)
    it->second = st.t;
  }
  sink_->Add(ToEstimate(agent, st));
}

Estimate InsEstimator::ToEstimate(const std::string& agent, const InsState& st) const {
  Mat2 c = st.position_cov.topLeftCorner<2, 2>();
  if (const auto it = start_prior_.find(agent); it != start_prior_.end()) {
    const StartPrior& prior = it->second;
    // A start heading error turns the walk about the start: d(p) = dpsi * u.
    const Vec2 from = st.position_n.head<2>() - prior.start;
    const Vec2 u(-from.y(), from.x());
    c += prior.position_var_m2 * Mat2::Identity() + prior.extra_yaw_var_rad2 * u * u.transpose();
    // No heading stated, or the IMU's mounting not found: turned by an unknown angle.
    if (prior.unknown_heading || ins_.MountNotFound(agent)) c += UnknownHeadingCovariance(from);
  }
  if (outside_model_.count(agent) != 0) {
    // The filter's covariance is not this device's: its steps' dead reckoning with a PDR's
    // errors (start and heading included) on top of the filter's own, whose start terms above
    // that one carries already.
    if (const auto dr = steps_dr_.Current(agent)) {
      c = st.position_cov.topLeftCorner<2, 2>() + Mat2{{dr->sxx, dr->sxy}, {dr->sxy, dr->syy}};
    }
  }
  // The foot is not the walker: within half a stride of it along the walk, a foot's width
  // beside it (foot_offset_sigma_m).
  c += options_.foot_offset_sigma_m * options_.foot_offset_sigma_m * Mat2::Identity();
  Estimate e{st.t, agent, st.position_n, c(0, 0), c(0, 1), c(1, 1)};
  height_.Annotate(e);
  return e;
}

void InsEstimator::Add(const MissionRow& row, EstimateSink& sink) {
  const auto* imu = std::get_if<ImuSample>(&row);
  if (imu == nullptr) {
    if (std::holds_alternative<BaroSample>(row)) {
      height_.Add(row);
    } else {
      ++ignored_;
    }
    return;
  }
  sink_ = &sink;
  ins_.Add(*imu);
}

void InsEstimator::Finish(EstimateSink& sink) {
  sink_ = &sink;
  ins_.Finish();
  for (const std::string& agent : ins_.Agents()) {  // where each agent's data ended
    if (const auto st = ins_.State(agent)) Write(agent, *st);
  }
}

std::optional<Estimate> InsEstimator::Current(const std::string& node) const {
  const auto st = ins_.State(node);
  if (!st) return std::nullopt;
  return ToEstimate(node, *st);
}

EstimatorSummary InsEstimator::Summary() const {
  EstimatorSummary s = ins_.Summary();
  height_.AddToSummary(s);
  for (const std::string& agent : outside_model_) {
    s.notes.push_back(agent +
                      ": covariance from its steps' dead reckoning with a PDR's errors "
                      "(the INS's own is not this device's)");
  }
  s.numbers["rows_ignored"] = static_cast<double>(ignored_);
  return s;
}

}  // namespace trailmark::ins

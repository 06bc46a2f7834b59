// SPDX-License-Identifier: MIT
#include "trailmark/landmarks/landmark_estimator.h"

#include <fmt/format.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace trailmark::landmarks {

namespace {

/// Added to solved covariances so that they stay positive definite: (1 cm)^2.
constexpr double kCovarianceFloorM2 = 1e-4;
/// Added to a step's drift variance so that it is never zero: (0.1 mm)^2.
constexpr double kStepVarianceFloorM2 = 1e-8;
/// Unknown landmarks placed by the trackers are written at most this often (s).
constexpr double kLandmarkEmitPeriodS = 5.0;
/// The error-state tracker writes an agent's estimate after radio updates at most this often (s).
constexpr double kRadioEmitPeriodS = 0.5;
/// Periods are compared with this slack: packets exactly a period apart must count as such
/// whatever the mission's time origin (round-off; the time-shift test).
constexpr double kTimeTolS = 1e-6;
/// A position fix needs ranges to three landmarks (two leave a mirror ambiguity).
constexpr int kRangesForFix = 3;
/// FixFusion::kJoint: an error of each stop that no other shares, (1 mm)^2 per axis (keeps the
/// stops' prior positive definite when two stops have no step between them).
constexpr double kStopOwnVarianceM2 = 1e-6;

}  // namespace

bool LandmarkEstimatorOptions::IsValid(std::string* why) const {
  if (!(drift_per_m > 0) || !(rssi_sigma_db > 0)) {
    if (why) *why = "drift_per_m and rssi_sigma_db must be > 0";
    return false;
  }
  if (!(min_range_sigma_m > 0) || !(known_start_sigma_m > 0) || !(unknown_start_sigma_m > 0) ||
      !(surveyed_sigma_m > 0) || min_stops_heard < 1 || !(regrid_growth >= 1) ||
      joint_window_stops < 1 || !(joint_false_alarm > 0 && joint_false_alarm < 1)) {
    if (why) {
      *why =
          "sigmas must be > 0, min_stops_heard >= 1, regrid_growth >= 1, "
          "joint_window_stops >= 1, 0 < joint_false_alarm < 1";
    }
    return false;
  }
  if (tracking == Tracking::kUkf && fix_fusion != FixFusion::kIndependent) {
    if (why) {
      *why =
          "fix_fusion=intersection and fix_fusion=joint are for stop-and-go tracking "
          "(landmarks-stopgo); continuous tracking takes fix_fusion=independent";
    }
    return false;
  }
  if (tracking != Tracking::kUkf && filter != TrackingFilter::kPaper) {
    if (why) *why = "filter=error-state is the continuous tracker of landmarks-ukf";
    return false;
  }
  return calibration.IsValid(why) && integrity.IsValid(why) && tracker.IsValid(why) &&
         dr_test.IsValid(why) && bank.IsValid(why) && stop_dead_reckoning.IsValid(why);
}

namespace {

/// Both landmark pipelines' options, and with `tracker` those that only landmarks-ukf's
/// continuous tracker reads (a key of the tracker given to landmarks-stopgo is refused as
/// unknown instead of being ignored).
OptionTable<LandmarkEstimatorOptions> MakeLandmarkOptionTable(bool tracker) {
  using O = LandmarkEstimatorOptions;
  OptionTable<O> t;
  t.Real("drift_per_m", &O::drift_per_m, "", OptionBounds::Positive(),
         "PDR drift, 1 sigma per metre walked");
  t.Real("rssi_sigma_db", &O::rssi_sigma_db, "dB", OptionBounds::Positive(),
         "UKF: sigma of one RSSI answer");
  t.Integer("min_stops_heard", &O::min_stops_heard, OptionBounds::AtLeast(1),
            "an unknown landmark is placed (and used) once heard at this many stops");
  t.Integer("regrid_below_stops", &O::regrid_below_stops, OptionBounds::NonNegative(),
            "a landmark heard at up to this many stops is grid-searched at every solve");
  t.Real("regrid_growth", &O::regrid_growth, "", OptionBounds::AtLeast(1),
         "beyond, it is grid-searched again when its stops grew by this factor (1: always)");
  t.Choice("loss", [](O& o) -> Loss& { return o.stop_and_go.loss; },
           std::vector<std::pair<std::string, Loss>>{
               {"squared", Loss::kSquared}, {"huber", Loss::kHuber}, {"cauchy", Loss::kCauchy}},
           "stop-and-go loss (squared: the paper; huber/cauchy: robust to NLOS)");
  t.Flag("foot_ins_errors", &O::foot_ins_own_errors,
         "an agent whose steps come from a foot INS (imu.csv) moves with the INS's own errors "
         "(pdr's foot_ins. sigmas, each step's yaw variance); false: a phone PDR's");
  t.Choice(
      "fix_fusion", [](O& o) -> FixFusion& { return o.fix_fusion; },
      std::vector<std::pair<std::string, FixFusion>>{{"independent", FixFusion::kIndependent},
                                                     {"intersection", FixFusion::kIntersection},
                                                     {"joint", FixFusion::kJoint}},
      "stop-and-go: a stop's fix with the dead reckoning (independent: the paper; "
      "intersection: shared PDR errors and covariance intersection, honest; joint: the "
      "stops solved with the landmarks under the dead reckoning's joint prior)");
  if (!tracker) {
    t.Integer("joint_window_stops", &O::joint_window_stops, OptionBounds::AtLeast(1),
              "fix_fusion=joint: an agent's latest stops solved with its dead reckoning's prior");
    t.Flag("joint_range_calibration", &O::joint_range_calibration,
           "fix_fusion=joint: a solve that fails its chi-square test is solved again with an "
           "intercept and exponent error of the ranges as unknowns");
    t.Real("joint_false_alarm", &O::joint_false_alarm, "", OptionBounds::Between(1e-9, 0.5),
           "fix_fusion=joint: the chi-square test's false-alarm probability");
    t.Real(
        "track_heading_offset_sigma_rad",
        [](O& o) -> double& { return o.stop_dead_reckoning.track_heading_offset_sigma_rad; }, "rad",
        OptionBounds::NonNegative(),
        "the steps' own heading offset, a consider parameter of the stops' dead reckoning "
        "(reported covariance only; 0: none)");
    t.Choice("drift", [](O& o) -> DriftModel& { return o.drift; },
             std::vector<std::pair<std::string, DriftModel>>{
                 {"white", DriftModel::kWhite}, {"dead-reckoning", DriftModel::kDeadReckoning}},
             "fix_fusion=independent: the covariance reported (white: drift_per_m, the paper; "
             "dead-reckoning: the PDR's shared heading, rate and scale errors, at each fix the "
             "intersection's bound; the estimate is the same)");
  }
  if (tracker) {
    t.Choice("filter", [](O& o) -> TrackingFilter& { return o.filter; },
             std::vector<std::pair<std::string, TrackingFilter>>{
                 {"paper", TrackingFilter::kPaper}, {"error-state", TrackingFilter::kErrorState}},
             "landmarks-ukf's tracker (paper: the UKF of sec. 5.4; error-state: heading, drift, "
             "turn and step scale, path-loss and shadowing states, iterated robust 3-D updates, "
             "unknown landmarks placed from the walk)");
    t.Real("shadowing_length_m", [](O& o) -> double& { return o.tracker.shadowing_length_m; }, "m",
           OptionBounds::Positive(), "error-state: shadowing decorrelation distance");
    t.Real("shadowing_variance_share",
           [](O& o) -> double& { return o.tracker.shadowing_variance_share; }, "",
           OptionBounds::Between(0, 0.99), "error-state: share of the RSSI variance that is shadowing");
    t.Real("handheld_height_m", [](O& o) -> double& { return o.tracker.handheld_height_m; }, "m",
           OptionBounds::Any(), "error-state: the handheld above the agent's z");
    t.Integer("tracker_iterations", [](O& o) -> int& { return o.tracker.iterations; },
              OptionBounds::AtLeast(1), "error-state: Gauss-Newton iterations of one packet's update");
    t.Real(
        "turn_scale_sigma", [](O& o) -> double& { return o.tracker.pdr.turn_scale_sigma; }, "",
        OptionBounds::Positive(), "error-state: prior sigma of the PDR's turn-scale error");
    t.Real(
        "track_heading_offset_sigma_rad",
        [](O& o) -> double& { return o.tracker.pdr.track_heading_offset_sigma_rad; }, "rad",
        OptionBounds::NonNegative(),
        "error-state: the steps' own heading offset, a consider parameter (reported covariance "
        "only; 0: none)");
    t.Integer(
        "motion_models", [](O& o) -> int& { return o.bank.models; }, OptionBounds::Between(1, 2),
        "error-state: 2: a typical device's motion model and a poor one's (shared PDR "
        "errors x motion_overbound, the steps' offset estimated), weighed by how well each "
        "predicts the radio; 1: the typical one alone");
    t.Flag(
        "motion_poor_offset_state", [](O& o) -> bool& { return o.bank.poor_offset_state; },
        "error-state: the poor device's heading offset is estimated (false: a consider "
        "parameter, as the typical device's)");
    t.Flag(
        "motion_prefer_typical", [](O& o) -> bool& { return o.bank.prefer_typical; },
        "error-state: the typical device's estimate until the poor one's weight passes 0.5 "
        "(then moving to the poor one's), the mixture's mean squared error about it (false: "
        "the mixture's mean)");
    t.Real(
        "motion_poor_prior", [](O& o) -> double& { return o.bank.poor_prior; }, "",
        OptionBounds::Between(0.001, 0.999),
        "error-state: the poor device's weight before any packet");
    t.Real(
        "motion_overbound", [](O& o) -> double& { return o.bank.overbound; }, "",
        OptionBounds::AtLeast(1),
        "error-state: the poor device's shared PDR error sigmas, x the typical ones");
    t.Flag("adapt_noise", [](O& o) -> bool& { return o.tracker.adapt_noise; },
           "error-state: the RSSI variances scaled up while the packets' mean NIS is above 1");
    t.Flag("dr_first", &O::dr_first,
           "error-state: an agent on a foot INS within its noise model (known start, stated "
           "heading) is written as its dead reckoning while the tracker does not doubt it");
    t.Include("", &O::dr_test, integrity::DeadReckoningFirstOptionTable());
    t.Flag("slam", &O::slam,
           "error-state: unknown landmarks placed from moving packets and tracked jointly");
    t.Flag("track_with_estimated_landmarks", &O::track_with_estimated_landmarks,
           "error-state: also fuse landmarks placed from this dead reckoning's stops");
  }
  t.Include("", &O::integrity, integrity::ConsistencyOptionTable());
  t.Flag("gate_other_floors", &O::gate_other_floors,
         "packets between an agent and a landmark on another level are not used");
  return t;
}

}  // namespace

const OptionTable<LandmarkEstimatorOptions>& LandmarkOptionTable(Tracking tracking) {
  static const OptionTable<LandmarkEstimatorOptions> stop_and_go = MakeLandmarkOptionTable(false);
  static const OptionTable<LandmarkEstimatorOptions> ukf = MakeLandmarkOptionTable(true);
  return tracking == Tracking::kUkf ? ukf : stop_and_go;
}

LandmarkEstimator::LandmarkEstimator(const MissionInfo& info, LandmarkEstimatorOptions options)
    : options_(std::move(options)),
      info_(info),
      mission_levels_(info),
      landmark_integrity_("landmark", options_.integrity) {
  std::string why;
  if (!options_.IsValid(&why)) throw std::invalid_argument("landmarks: " + why);
  calibrated_ = info.radio && info.radio->Complete();
  if (calibrated_) {
    model_ = radio::LogDistanceModel::From(*info.radio);
  } else if (info.radio) {
    // A partial block: its sigma (where given) is the packets' stated noise; the path loss is
    // fitted as without one.
    if (info.radio->sigma_given) {
      model_.sigma_db = info.radio->shadowing_sigma_db;
      stated_sigma_db_ = info.radio->shadowing_sigma_db;
    }
    setup_notes_.push_back(fmt::format(
        "mission.json's radio gives {}{}: not a calibration, the path loss is fitted online from "
        "the stops' RSSI of surveyed landmarks (default log-distance model until then)",
        info.radio->sigma_given
            ? fmt::format("shadowing_sigma_db {:g} dB", info.radio->shadowing_sigma_db)
            : std::string("no shadowing sigma"),
        info.radio->alpha_given      ? " and alpha_dbm without path_loss_exponent"
        : info.radio->exponent_given ? " and path_loss_exponent without alpha_dbm"
                                     : " only"));
  } else {
    setup_notes_.push_back(
        "mission.json has no radio calibration: fitted online from the stops' RSSI of surveyed "
        "landmarks (default log-distance model until then)");
  }
  for (const NodeInfo& n : info.nodes) {
    if (n.kind != NodeKind::kLandmark) continue;
    index_[n.id] = static_cast<int>(ids_.size());
    ids_.push_back(n.id);
    known_.push_back(n.position.has_value());
    estimate_.push_back(n.position ? std::optional<Vec2>(n.position->head<2>()) : std::nullopt);
    landmark_z_.push_back(n.position ? std::optional<double>(n.position->z()) : std::nullopt);
    const double s = n.position_sigma_m.value_or(options_.surveyed_sigma_m);
    estimate_cov_.push_back(Mat2::Identity() * s * s);
    estimate_t_.push_back(0);
    grid_heard_.push_back(0);
  }
  // Unknown landmarks are taken at the surveyed ones' mean height (mounted alike), if any.
  double z_sum = 0;
  int z_count = 0;
  for (const auto& z : landmark_z_) {
    if (z) z_sum += *z, ++z_count;
  }
  if (z_count > 0) unknown_landmark_z_m_ = z_sum / z_count;
  if (ids_.size() < 3) {
    throw std::invalid_argument("the radio-landmark estimators need at least 3 landmarks");
  }
  const int B = static_cast<int>(ids_.size());
  for (const NodeInfo& n : info.nodes) {
    if (n.kind != NodeKind::kAgent) continue;
    Agent a;
    const auto start = info.AgentStart(n);
    a.position = start ? Vec2(start->head<2>()) : Vec2::Zero();
    const double s = start ? n.start_sigma_m.value_or(options_.known_start_sigma_m)
                           : options_.unknown_start_sigma_m;
    a.cov = Mat2::Identity() * s * s;
    a.pdr_position = a.position;
    a.z_m = start ? start->z() : 0.0;
    StartStopDeadReckoning(a, options_.stop_dead_reckoning, n.start_heading_sigma_rad);
    if (!start) {
      setup_notes_.push_back(
          fmt::format("agent '{}' has no start: {:g} m prior", n.id, options_.unknown_start_sigma_m));
    }
    a.sum.assign(B, 0.0);
    a.count.assign(B, 0);
    if (options_.tracking == Tracking::kUkf) {
      LandmarkUkfOptions uo;
      uo.initial_sigma_m = s;
      uo.rssi_sigma_db = options_.rssi_sigma_db;
      if (options_.filter == TrackingFilter::kErrorState) {
        // One packet's sigma: the calibration's shadowing, at least rssi_sigma_db (a packet
        // also carries what a calibration does not: NLOS, a body, the antenna's angle).
        std::optional<radio::LogDistanceModel> given;
        if (calibrated_) {
          given = model_;
          given->sigma_db = std::max(model_.sigma_db, options_.rssi_sigma_db);
        }
        LandmarkTrackerOptions to = options_.tracker;
        if (stated_sigma_db_) to.default_sigma_db = *stated_sigma_db_;  // a partial radio block
        to.default_sigma_db = std::max(to.default_sigma_db, options_.rssi_sigma_db);
        TrackerBankOptions bank = options_.bank;
        bank.evidence_delay_s = options_.integrity.window_s;  // the monitor's window
        a.tracker.emplace(Vec3(a.position.x(), a.position.y(), a.z_m), s, n.start_heading_sigma_rad,
                          given, to, bank);
      } else {
        a.ukf.emplace(a.position, model_, uo);
      }
    }
    agents_[n.id] = std::move(a);
  }
}

void LandmarkEstimator::StepsFromFootIns(const std::string& agent, bool foot_ins) {
  if (foot_ins) foot_ins_.insert(agent);
}

void LandmarkEstimator::StartStopDeadReckoning(Agent& a, const PdrOptions& pdr,
                                               std::optional<double> start_heading_sigma_rad) {
  if (options_.tracking == Tracking::kUkf) return;
  // Before any step: a.position and a.cov are the start's.
  const Vec3 start(a.position.x(), a.position.y(), 0.0);
  const double s = std::sqrt(a.cov(0, 0));
  if (options_.fix_fusion == FixFusion::kIntersection ||
      (options_.fix_fusion == FixFusion::kIndependent &&
       options_.drift == DriftModel::kDeadReckoning)) {
    a.dr.emplace(start, s, pdr, start_heading_sigma_rad);
  }
  if (options_.fix_fusion == FixFusion::kJoint) {
    a.clones.emplace(DeadReckoning(start, s, pdr, start_heading_sigma_rad));
  }
}

void LandmarkEstimator::UseFootInsErrors(const std::string& agent, Agent& a) {
  if (a.tracker) a.tracker->UseTypicalMotionErrors(options_.tracker.pdr.ForFootIns());
  const NodeInfo* node = info_.Find(agent);
  if (options_.dr_first && a.tracker && node && node->start_heading_rad &&
      info_.AgentStart(*node)) {
    // Before the first step: a.position and a.cov are the start's.
    a.own_dr.emplace(Vec3(a.position.x(), a.position.y(), a.z_m), std::sqrt(a.cov(0, 0)),
                     options_.tracker.pdr.ForFootIns(), node->start_heading_sigma_rad);
    a.dr_first.emplace(options_.dr_test);
    setup_notes_.push_back(fmt::format(
        "'{}': steps from a foot INS within its noise model: its dead reckoning is written until "
        "it leaves the tracker's {:g} % region (dr_first)",
        agent, 100 * options_.dr_test.reject_probability));
  }
  StartStopDeadReckoning(a, options_.stop_dead_reckoning.ForFootIns(),
                         node ? node->start_heading_sigma_rad : std::nullopt);
}

Vec2 LandmarkEstimator::PositionOf(const Agent& a) const {
  if (a.dr_first)
    return a.dr_first->Position(a.tracker->position(), a.own_dr->position_n().head<2>());
  if (a.tracker) return a.tracker->position();
  return a.ukf ? a.ukf->position() : a.position;
}

Mat2 LandmarkEstimator::CovarianceOf(const Agent& a) const {
  if (a.dr_first && a.dr_first->doubt() < 1) {
    return a.dr_first->Covariance(a.tracker->position(), a.tracker->reported_position_cov(),
                                  a.own_dr->position_n().head<2>(), a.own_dr->covariance()) +
           Mat2::Identity() * kStepVarianceFloorM2;
  }
  if (a.tracker) return a.tracker->reported_position_cov();
  if (a.ukf) return a.ukf->position_cov();
  // Independent fixes, DriftModel::kDeadReckoning: the estimate is the paper's, its covariance
  // the dead reckoning's since the last fix (set there to the fused one).
  if (a.dr && options_.fix_fusion == FixFusion::kIndependent)
    return a.dr->covariance() + Mat2::Identity() * kStepVarianceFloorM2;
  return a.cov;
}

double LandmarkEstimator::HeightOf(const std::string& id, const Agent& a) const {
  if (levels_) {
    if (const auto b = levels_->NodeLevel(id)) return b->z_m;
  }
  return a.z_m;
}

void LandmarkEstimator::EmitAgent(TimeS t, const std::string& id, Agent& a, EstimateSink& sink) {
  if (a.dr_first) a.dr_first->Count();
  const Vec2 p = PositionOf(a);
  const Mat2 c = CovarianceOf(a);
  sink.Add({t, id, Vec3(p.x(), p.y(), 0), c(0, 0), c(0, 1), c(1, 1)});
}

std::optional<std::pair<Vec2, Mat2>> LandmarkEstimator::LandmarkOf(std::size_t j) const {
  // An unknown landmark placed by the agents' trackers (SLAM): the most certain agent's.
  std::optional<std::pair<Vec2, Mat2>> best;
  if (!known_[j]) {
    for (const auto& [id, a] : agents_) {
      if (!a.tracker) continue;
      const auto e = a.tracker->LandmarkEstimate(static_cast<int>(j));
      if (e && (!best || e->second.trace() < best->second.trace())) best = e;
    }
  }
  if (!best && estimate_[j]) best = std::make_pair(*estimate_[j], estimate_cov_[j]);
  return best;
}

void LandmarkEstimator::EmitLandmark(TimeS t, std::size_t j, EstimateSink& sink) {
  const auto e = LandmarkOf(j);
  if (!e) return;
  estimate_t_[j] = t;
  const Mat2& c = e->second;
  sink.Add({t, ids_[j], Vec3(e->first.x(), e->first.y(), 0), c(0, 0), c(0, 1), c(1, 1)});
}

void LandmarkEstimator::EmitLandmarks(TimeS t, EstimateSink& sink) {
  for (std::size_t j = 0; j < ids_.size(); ++j) EmitLandmark(t, j, sink);
}

void LandmarkEstimator::RangesOf(const Stop& s, std::vector<std::optional<double>>* r,
                                 std::vector<double>* sg) const {
  for (std::size_t j = 0; j < ids_.size(); ++j) {
    if (s.rssi[j]) {
      const auto range = radio::ToRange(model_, *s.rssi[j]);
      r->push_back(range.range_m);
      sg->push_back(std::max(range.sigma_m, options_.min_range_sigma_m));
    } else {
      r->push_back(std::nullopt);
      sg->push_back(1.0);  // unused: no range
    }
  }
}

void LandmarkEstimator::Refit() {
  double dmin = 1e300, dmax = 0;
  for (const auto& c : calibration_) {
    dmin = std::min(dmin, c.distance_m);
    dmax = std::max(dmax, c.distance_m);
  }
  if (calibration_.size() < options_.calibration_min_pairs ||
      !(dmax > options_.calibration_min_spread * dmin))
    return;
  const radio::PathLossCalibration c = radio::CalibratePathLoss(calibration_, options_.calibration);
  if (c.status != radio::CalibrationStatus::kOk) return;
  model_ = c.fit.model;
  model_.sigma_db = std::max(c.fit.residual_sigma_db, options_.min_radio_sigma_db);
  ++refits_;
  for (auto& [id, a] : agents_) {
    if (a.ukf) a.ukf->SetRadioModel(model_);
  }
}

std::vector<int> LandmarkEstimator::HeardAtStops() const {
  std::vector<int> heard(ids_.size(), 0);
  for (const auto& st : stops_) {
    for (std::size_t j = 0; j < ids_.size(); ++j) heard[j] += st.rssi[j].has_value();
  }
  return heard;
}

void LandmarkEstimator::StartLandmarks(const std::vector<int>& heard, StopAndGoProblem* prob) {
  for (std::size_t j = 0; j < ids_.size(); ++j) {
    const bool warm = !known_[j] && estimate_[j] && heard[j] > options_.regrid_below_stops &&
                      heard[j] < options_.regrid_growth * grid_heard_[j];
    if (!known_[j] && !warm) grid_heard_[j] = heard[j];
    prob->landmarks.push_back(known_[j] || warm ? *estimate_[j] : Vec2::Zero());
    prob->landmark_start_given.push_back(warm);
  }
}

void LandmarkEstimator::SolveJoint(TimeS t, const std::string& id, Agent& a, EstimateSink& sink) {
  const int B = static_cast<int>(ids_.size());
  a.clones->Clone(kStopOwnVarianceM2);
  a.clone_stops.push_back(stops_.size() - 1);  // this stop, the last
  const std::vector<int> heard = HeardAtStops();
  // The landmarks: surveyed ones with their survey's prior (not fixed: their error is a shared
  // error of every range to them); unknown ones once heard at min_stops_heard stops; the ranges
  // to the others left out (a landmark heard at one or two stops takes what they say).
  StopAndGoProblem prob;
  StartLandmarks(heard, &prob);
  std::vector<bool> used(B, true);
  for (int j = 0; j < B; ++j) {
    used[j] = known_[j] || heard[j] >= options_.min_stops_heard;
    prob.landmark_known.push_back(!used[j]);
    prob.landmark_prior_sigma_m.push_back(known_[j] ? std::sqrt(0.5 * estimate_cov_[j].trace())
                                                    : 0.0);
  }
  // The stops: this agent's latest (its clones) unknown, with the dead reckoning's joint prior
  // (mean: the dead reckoning's positions there); every other stop at its latest solution.
  std::size_t next_clone = 0;
  for (std::size_t k = 0; k < stops_.size(); ++k) {
    const bool mine = next_clone < a.clone_stops.size() && a.clone_stops[next_clone] == k;
    prob.standing.push_back(mine ? a.clones->clone_position_n(static_cast<int>(next_clone))
                                 : stops_[k].standing);
    prob.standing_known.push_back(!mine);
    next_clone += mine;
    std::vector<std::optional<double>> r;
    std::vector<double> sg;
    RangesOf(stops_[k], &r, &sg);
    for (int j = 0; j < B; ++j) {
      if (!used[j]) r[j].reset();
    }
    prob.range_m.push_back(r);
    prob.sigma_m.push_back(sg);
  }
  const Eigen::MatrixXd& prior = a.clones->clone_covariance();
  prob.standing_prior_information =
      prior.llt().solve(Eigen::MatrixXd::Identity(prior.rows(), prior.cols()));
  StopAndGoResult res = SolveStopAndGo(prob, options_.stop_and_go);
  // The solve's consistency: ranges that disagree with the prior beyond their noise are read
  // through a wrong radio model; solved again with its error as unknowns.
  range_log_scale_ = 0, range_exponent_ratio_ = 1;
  if (res.dof > 0 &&
      2 * res.cost > integrity::ChiSquareQuantile(res.dof, 1 - options_.joint_false_alarm)) {
    ++joint_inconsistent_;
    if (options_.joint_range_calibration) {
      // The unknown landmarks searched again on the corrected ranges (the first solve's were
      // placed by the wrong model; stop_and_go.h).
      prob.range_calibration = StopAndGoProblem::RangeCalibration{};
      res = SolveStopAndGo(prob, options_.stop_and_go);
      range_log_scale_ = res.range_log_scale;
      range_exponent_ratio_ = res.range_exponent_ratio;
    }
  }
  solve_notes_.clear();
  for (const auto& n : res.notes) solve_notes_.insert(n);
  const int clones = a.clones->clones();
  Eigen::VectorXd posterior(2 * clones);
  for (int i = 0; i < clones; ++i) posterior.segment<2>(2 * i) = res.standing[a.clone_stops[i]];
  bool finite = posterior.allFinite() && res.standing_joint_cov.allFinite() &&
                res.standing_joint_cov.rows() == 2 * clones;
  for (int j = 0; j < B; ++j) finite = finite && res.landmarks[j].allFinite();
  if (finite) {
    for (int j = 0; j < B; ++j) {
      if (known_[j] || !used[j]) continue;
      estimate_[j] = res.landmarks[j];
      estimate_cov_[j] = res.landmark_cov[j] + Mat2::Identity() * kCovarianceFloorM2;
    }
    a.clones->Condition(posterior, res.standing_joint_cov);
    for (int i = 0; i < clones; ++i)
      stops_[a.clone_stops[i]].standing = res.standing[a.clone_stops[i]];
    ++fixes_;
  }
  if (clones > options_.joint_window_stops) {
    a.clones->DropOldest();
    a.clone_stops.erase(a.clone_stops.begin());
  }
  a.position = a.clones->position_n();
  a.cov = a.clones->covariance() + Mat2::Identity() * kStepVarianceFloorM2;
  EmitLandmarks(t, sink);
  a.t = t;
  EmitAgent(t, id, a, sink);
}

void LandmarkEstimator::EndOfStop(TimeS t, const std::string& id, Agent& a, EstimateSink& sink) {
  const int B = static_cast<int>(ids_.size());
  a.stopped = false;
  Stop s;
  s.standing = options_.fix_fusion == FixFusion::kIntersection ? a.pdr_position : a.position;
  for (int j = 0; j < B; ++j) {
    s.rssi.push_back(a.count[j] ? std::optional<double>(a.sum[j] / a.count[j]) : std::nullopt);
  }
  stops_.push_back(s);
  // Online calibration (no calibration in mission.json): every stop's averaged RSSI of a
  // surveyed landmark at the PDR distance is a pair; refit once the distances spread.
  if (!calibrated_) {
    for (int j = 0; j < B; ++j) {
      if (known_[j] && s.rssi[j]) {
        calibration_.push_back({std::max((s.standing - *estimate_[j]).norm(),
                                         options_.calibration_min_distance_m),
                                *s.rssi[j]});
      }
    }
    Refit();
  }
  if (a.clones) {
    SolveJoint(t, id, a, sink);
    return;
  }
  // Landmarks from every stop so far (standing positions from the PDR, sec. 6.2).
  const std::vector<int> heard = HeardAtStops();
  StopAndGoProblem prob;
  StartLandmarks(heard, &prob);
  for (int j = 0; j < B; ++j) prob.landmark_known.push_back(known_[j]);
  for (const auto& st : stops_) {
    prob.standing.push_back(st.standing);
    prob.standing_known.push_back(true);
    std::vector<std::optional<double>> r;
    std::vector<double> sg;
    RangesOf(st, &r, &sg);
    prob.range_m.push_back(r);
    prob.sigma_m.push_back(sg);
  }
  const StopAndGoResult res = SolveStopAndGo(prob, options_.stop_and_go);
  solve_notes_.clear();
  for (const auto& n : res.notes) solve_notes_.insert(n);
  for (int j = 0; j < B; ++j) {
    if (known_[j]) continue;
    if (heard[j] >= options_.min_stops_heard) {
      estimate_[j] = res.landmarks[j];
      estimate_cov_[j] = res.landmark_cov[j] + Mat2::Identity() * kCovarianceFloorM2;
    }
  }
  EmitLandmarks(t, sink);
  // Re-localize the handheld at this stop with the landmarks (sec. 6.2).
  StopAndGoProblem fix;
  std::vector<std::optional<double>> r;
  std::vector<double> sg;
  RangesOf(s, &r, &sg);
  int usable = 0;
  for (int j = 0; j < B; ++j) {
    fix.landmarks.push_back(estimate_[j].value_or(Vec2::Zero()));
    fix.landmark_known.push_back(true);
    if (!estimate_[j]) r[j].reset();
    usable += r[j].has_value();
    // The fix takes the landmarks as known; their own uncertainty moves each range by its
    // component along the line of sight: to first order, half the trace of the landmark's
    // covariance (isotropic) is added to the range's variance (issue 21: the fix was as
    // confident as if the estimated landmarks were surveyed).
    if (r[j]) sg[j] = std::sqrt(sg[j] * sg[j] + 0.5 * estimate_cov_[j].trace());
  }
  if (usable >= kRangesForFix && !a.ukf && !a.tracker) {
    fix.standing = {a.position};
    fix.standing_known = {false};
    fix.range_m = {r};
    fix.sigma_m = {sg};
    const StopAndGoResult fr = SolveStopAndGo(fix, options_.stop_and_go);
    const Mat2 c_fix = fr.standing_cov[0] + Mat2::Identity() * kCovarianceFloorM2;
    // Combine the fix with dead reckoning. They are correlated by an unknown amount (the
    // landmarks were placed from this dead reckoning's standing positions, and the fix reuses
    // this stop's RSSI): fix_fusion=intersection does covariance intersection; the paper's
    // independent update makes the ellipse a third of the error (issue 21, docs/landmarks.md).
    if (options_.fix_fusion == FixFusion::kIntersection) {
      a.dr->FusePosition(fr.standing[0], c_fix);
      a.position = a.dr->position_n().head<2>();
      a.cov = a.dr->covariance();
    } else {
      // The paper's: information-weighted, as if independent.
      const Mat2 K = a.cov * (a.cov + c_fix).inverse();
      a.position += K * (fr.standing[0] - a.position);
      a.cov = (Mat2::Identity() - K) * a.cov;
      a.cov = 0.5 * (a.cov + a.cov.transpose());
      if (a.dr) {
        // DriftModel::kDeadReckoning: what the paper's estimate can claim whatever the fix's
        // correlation with the dead reckoning: the covariance intersection of the two
        // (consistent for any correlation) and the paper's offset from the intersection's
        // estimate, whose error is the intersection's plus that offset.
        DeadReckoning intersection = *a.dr;
        intersection.FusePosition(fr.standing[0], c_fix);
        const Vec2 offset = a.position - intersection.position_n().head<2>();
        // A considered heading offset: the paper's estimate keeps (I - K) of its sensitivity.
        a.dr->SetPosition(a.position, intersection.own_covariance() + offset * offset.transpose(),
                          Mat2::Identity() - K);
      }
    }
    ++fixes_;
    a.t = t;
    EmitAgent(t, id, a, sink);
  }
}

bool LandmarkEstimator::TestDeadReckoning(TimeS t, const std::string& agent, Agent& a) {
  if (!a.dr_first || !a.stepped) return false;
  // The tracker's own covariance: its most probable model's, without the steps' heading offset
  // (a consider parameter the dead reckoning shares).
  auto note = a.dr_first->Test(t, agent, "the tracker", a.tracker->position(),
                               a.tracker->best().position_cov(), a.own_dr->position_n().head<2>());
  if (!note) return false;
  dr_notes_.push_back(std::move(*note));
  return true;
}

void LandmarkEstimator::Add(const MissionRow& row, EstimateSink& sink) {
  const TimeS t = RowTime(row);
  const bool used = std::holds_alternative<Step>(row) || std::holds_alternative<RssiPacket>(row) ||
                    std::holds_alternative<MissionEvent>(row);
  if (!used) {
    ++ignored_;
    return;
  }
  if (const auto* step = std::get_if<Step>(&row); step && !agents_.count(step->agent)) {
    throw std::invalid_argument("'" + step->agent + "' has steps but is not an agent");
  }
  if (first_) {
    EmitLandmarks(t, sink);
    first_ = false;
  }
  t_last_ = std::max(t_last_, t);
  if (const auto* step = std::get_if<Step>(&row)) {
    Agent& a = agents_.at(step->agent);
    // A foot INS's agent moves with the INS's own errors where its first step carries them (the
    // INS holds its noise model: ZuptIns::OwnErrorsHold).
    if (!a.stepped && options_.foot_ins_own_errors && foot_ins_.count(step->agent) != 0 &&
        step->heading_var_rad2) {
      UseFootInsErrors(step->agent, a);
    }
    if (a.tracker && !a.stepped) EmitAgent(step->t0, step->agent, a, sink);  // the start, first
    a.stepped = true;
    const Vec2 d = step->delta_n.head<2>();
    const double s = options_.drift_per_m * d.norm();
    a.pdr_position += d;
    if (a.dr) a.dr->AddStep(*step);
    if (a.clones) {
      a.clones->AddStep(*step);
      a.position = a.clones->position_n();
      a.cov = a.clones->covariance() + Mat2::Identity() * kStepVarianceFloorM2;
    } else if (options_.fix_fusion == FixFusion::kIntersection) {
      a.position = a.dr->position_n().head<2>();
      a.cov = a.dr->covariance() + Mat2::Identity() * kStepVarianceFloorM2;
    } else {
      a.position += d;
      a.cov += Mat2::Identity() * (s * s + kStepVarianceFloorM2);
    }
    if (a.ukf) a.ukf->PredictWithDisplacement(d, Mat2::Identity() * (s * s + kStepVarianceFloorM2));
    if (a.tracker) a.tracker->AddStep(*step);
    if (a.own_dr) a.own_dr->AddStep(*step);
    if (a.dr_first && !step->heading_var_rad2) {  // the IMU's mounting not found
      if (auto note = a.dr_first->Abandon(step->t1, step->agent, "the tracker"))
        dr_notes_.push_back(std::move(*note));
    }
    a.z_m += step->delta_n.z();
    a.t = step->t1;
    TestDeadReckoning(step->t1, step->agent, a);
    EmitAgent(step->t1, step->agent, a, sink);
  } else if (const auto* p = std::get_if<RssiPacket>(&row)) {
    const bool rx_agent = agents_.count(p->rx) != 0;
    const std::string& agent = rx_agent ? p->rx : p->tx;
    const std::string& other = rx_agent ? p->tx : p->rx;
    auto ait = agents_.find(agent);
    auto lit = index_.find(other);
    if (ait == agents_.end() || lit == index_.end()) return;
    if (options_.gate_other_floors && mission_levels_.Differ(levels_, agent, other)) {
      ++other_floor_;
      return;
    }
    Agent& a = ait->second;
    const int j = lit->second;
    if (a.stopped) {
      a.sum[j] += p->rssi_dbm;
      ++a.count[j];
    }
    if (a.ukf && estimate_[j]) {
      const auto admit = [&](double nis) { return landmark_integrity_.Record(other, p->t, nis, 1); };
      if (a.ukf->UpdateRssi(*estimate_[j], estimate_cov_[j], p->rssi_dbm, admit)) ++ukf_updates_;
    }
    if (a.tracker) {
      const auto admit = [&](double nis) { return landmark_integrity_.Record(other, p->t, nis, 1); };
      bool used = false;
      if (known_[j] || (estimate_[j] && options_.track_with_estimated_landmarks)) {
        used = a.tracker->UpdateRssi(p->t, j, *estimate_[j], landmark_z_[j], estimate_cov_[j],
                                     HeightOf(agent, a), p->rssi_dbm, admit);
      } else if (options_.slam) {
        const bool placed = a.tracker->LandmarkEstimate(j).has_value();
        const double handheld_z = HeightOf(agent, a) + options_.tracker.handheld_height_m;
        const double dz = unknown_landmark_z_m_.value_or(handheld_z) - handheld_z;
        used = a.tracker->UpdateRssiUnknown(p->t, j, dz, p->rssi_dbm, admit);
        // A landmark just placed, and then every 5 s: its estimate.
        if (!placed || p->t - estimate_t_[j] >= kLandmarkEmitPeriodS - kTimeTolS) {
          if (a.tracker->LandmarkEstimate(j)) EmitLandmark(p->t, j, sink);
        }
      }
      ukf_updates_ += used;
      if (used && TestDeadReckoning(p->t, agent, a)) {
        a.t = p->t;  // the change is shown at once
        EmitAgent(p->t, agent, a, sink);
      }
      // Radio moves a responder who stands still too: an estimate after a used packet, at most
      // every kRadioEmitPeriodS, once the walk has started (a live view between steps).
      // Not while dead reckoning is written: the radio does not move it.
      if (used && a.stepped && !WritesDeadReckoning(a) &&
          p->t - a.t >= kRadioEmitPeriodS - kTimeTolS) {
        a.t = p->t;
        EmitAgent(p->t, agent, a, sink);
      }
    }
  } else if (const auto* e = std::get_if<MissionEvent>(&row)) {
    auto ait = agents_.find(e->agent);
    if (ait == agents_.end()) return;
    Agent& a = ait->second;
    if (e->event == "stop") {
      a.stopped = true;
      std::fill(a.sum.begin(), a.sum.end(), 0.0);
      std::fill(a.count.begin(), a.count.end(), 0);
      if (a.ukf) a.ukf->ZeroMotion();
    } else if (e->event == "go" && a.stopped) {
      EndOfStop(e->t, e->agent, a, sink);
    }
  }
}

void LandmarkEstimator::Finish(EstimateSink& sink) {
  // At the end of the mission (negative mission times too); with no data, at 0.
  EmitLandmarks(first_ ? 0.0 : t_last_, sink);
}

std::optional<Estimate> LandmarkEstimator::Current(const std::string& node) const {
  if (const auto it = agents_.find(node); it != agents_.end()) {
    const Agent& a = it->second;
    const Vec2 p = PositionOf(a);
    const Mat2 c = CovarianceOf(a);
    return Estimate{a.t, node, Vec3(p.x(), p.y(), 0), c(0, 0), c(0, 1), c(1, 1)};
  }
  if (const auto it = index_.find(node); it != index_.end()) {
    const auto e = LandmarkOf(static_cast<std::size_t>(it->second));
    if (!e) return std::nullopt;
    const Mat2& c = e->second;
    return Estimate{estimate_t_[it->second], node, Vec3(e->first.x(), e->first.y(), 0), c(0, 0),
                    c(0, 1), c(1, 1)};
  }
  return std::nullopt;
}

std::optional<Mat2> LandmarkEstimator::StepTransform(const std::string& agent) const {
  const auto it = agents_.find(agent);
  if (it == agents_.end() || !it->second.tracker) return std::nullopt;
  if (it->second.dr_first && it->second.dr_first->doubt() < 0.5)
    return std::nullopt;  // the steps as they come
  const LandmarkTracker& t = it->second.tracker->best();
  return Mat2((1.0 + t.scale_correction()) *
              Eigen::Rotation2Dd(t.heading_correction_rad()).toRotationMatrix());
}

EstimatorSummary LandmarkEstimator::Summary() const {
  EstimatorSummary summary;
  summary.notes = setup_notes_;
  for (const auto& n : solve_notes_) summary.notes.push_back(n);
  int localized = 0;
  for (std::size_t j = 0; j < ids_.size(); ++j) localized += !known_[j] && estimate_[j].has_value();
  summary.numbers["stops"] = static_cast<double>(stops_.size());
  summary.numbers["landmarks_localized"] = localized;
  summary.numbers["landmarks_known"] =
      static_cast<double>(std::count(known_.begin(), known_.end(), true));
  summary.numbers["handheld_fixes"] = static_cast<double>(fixes_);
  summary.numbers["ukf_rssi_updates"] = static_cast<double>(ukf_updates_);
  summary.numbers["radio_other_floor"] = static_cast<double>(other_floor_);
  summary.numbers["radio_refits"] = refits_;
  summary.numbers["radio_path_loss_exponent"] = model_.path_loss_exponent;
  summary.numbers["radio_alpha_dbm"] = model_.alpha_dbm;
  if (options_.fix_fusion == FixFusion::kJoint) {
    // Joint solves that failed their chi-square test, and the latest one's range calibration
    // (ranges read e^a d^b of the distance d; 0 and 1 when not estimated).
    summary.numbers["joint_solves_inconsistent"] = static_cast<double>(joint_inconsistent_);
    summary.numbers["range_log_scale"] = range_log_scale_;
    summary.numbers["range_exponent_ratio"] = range_exponent_ratio_;
  }
  summary.numbers["rows_ignored"] = static_cast<double>(ignored_);
  if (options_.tracking == Tracking::kUkf) landmark_integrity_.Report(summary);
  // The error-state tracker's own estimates of each agent's motion and radio errors.
  std::size_t gated = 0, calibration_only = 0;
  for (const auto& [id, a] : agents_) {
    if (!a.tracker) continue;
    const LandmarkTracker& k = a.tracker->best();
    if (a.tracker->size() > 1) {
      summary.numbers[id + ".poor_device_weight"] = a.tracker->weight(1);
      summary.numbers[id + ".poor_device_ellipse_weight"] = a.tracker->cover_weight(1);
    }
    gated += k.gated();
    calibration_only += k.calibration_only();
    summary.numbers[id + ".heading_correction_deg"] = k.heading_correction_rad() * 180 / M_PI;
    summary.numbers[id + ".heading_rate_deg_per_min"] = k.heading_rate_rad_per_s() * 180 / M_PI * 60;
    summary.numbers[id + ".step_scale_correction"] = k.scale_correction();
    summary.numbers[id + ".turn_scale_correction"] = k.turn_scale_correction();
    summary.numbers[id + ".radio_alpha_dbm"] = k.alpha_dbm();
    summary.numbers[id + ".radio_alpha_sigma_db"] = k.alpha_sigma_db();
    summary.numbers[id + ".radio_path_loss_exponent"] = k.exponent();
    summary.numbers[id + ".radio_exponent_sigma"] = k.exponent_sigma();
    summary.numbers[id + ".radio_mean_nis"] = k.mean_nis();
    summary.numbers[id + ".radio_noise_scale"] = k.noise_scale();
    if (a.dr_first) {
      // dr_first: the share of the agent's estimates that are not its dead reckoning's (moved
      // toward the tracker's, or the tracker's).
      summary.numbers[id + ".dr_first_tracker_share"] = a.dr_first->share_not_dead_reckoning();
    }
  }
  for (const IntegrityNote& n : dr_notes_) summary.integrity.push_back(n);
  if (options_.filter == TrackingFilter::kErrorState) {
    summary.numbers["rssi_gated"] = static_cast<double>(gated);
    summary.numbers["rssi_calibration_only"] = static_cast<double>(calibration_only);
  }
  return summary;
}

}  // namespace trailmark::landmarks

// SPDX-License-Identifier: MIT
#pragma once
/// The height channel every agent has (issue 26): z, its variance and the floor, from the
/// height changes of its steps (a foot INS observes them well on stairs) and its barometer,
/// fused in a two-state Kalman filter per agent. Every pipeline's agent estimates carry them
/// (the StepFrontEnd and the `ins` estimator annotate what leaves the estimator). No I/O.
///
/// State x = [h, b]: h the agent's z in the navigation frame (m), b the barometer's height
/// offset (m): the barometric height H(p) of a reading is h + b + noise. b holds the device's
/// offset and the weather's drift (a random walk); it is referenced at the agent's first
/// reading, where b = H(p) - h.
///  - A step's dz counts only when the height change persists: the steps' dz are summed until
///    |sum| reaches `stairs_min_rise_m` (stairs: committed, and the next steps of the flight
///    directly) or `stairs_window_steps` steps pass (a level floor: the INS's vertical noise,
///    discarded, with `flat_step_sigma_m` of variance per step). A step whose szz exceeds
///    `unknown_step_szz_m2` (a phone's PDR, which does not measure height) moves nothing and adds
///    `unknown_step_sigma_m` of variance: the barometer then carries the height.
///  - A reading is gated by its innovation (chi-square, 1 dof). Rejected readings that agree
///    with each other for `jump_persist_s` after a change faster than a person climbs
///    (`max_vertical_speed_mps`, measured from the last reading that agreed with the state) are
///    a pressure jump (a door, ventilation): b takes it (re-referenced, an integrity note). A
///    slower divergence is the agent's height change when its steps do not measure height (h
///    takes it, b gives back what it absorbed), and the air's when they do (a foot INS sees
///    stairs: the steps win, noted). A lone outlier is skipped. Readings that repeat the same
///    value for `stuck_after_s` are a stuck sensor: skipped until it changes.
///  - The floor: the level of the spec's rule (MissionInfo::floors, else 3 m storeys) with the
///    largest probability under N(h, P_hh).

#include <deque>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "trailmark/core/measurements.h"
#include "trailmark/core/mission.h"
#include "trailmark/core/online_estimator.h"
#include "trailmark/core/options.h"

namespace trailmark {

/// Height of the standard atmosphere (ICAO 1993; hypsometric, 15 degC, 1013.25 hPa at sea
/// level) at pressure p, m: 44330.77 (1 - (p / 1013.25)^0.190263). Only differences are used.
double PressureAltitudeM(double pressure_hpa);

struct HeightOptions {
  /// Steps: a height change counts once it reaches this (two risers of 0.17 m and some), ours.
  double stairs_min_rise_m = 0.45;
  /// ... within this many steps; a smaller change over them is a level floor (ours: a flight
  /// climbs 0.17 m per step, so 0.45 m takes 3 steps; the INS's vertical noise stays below).
  int stairs_window_steps = 6;
  /// Variance added per discarded (level) step, 1 sigma, m (ours).
  double flat_step_sigma_m = 0.01;
  /// A step's szz above this says it does not know its height (m^2): (0.3 m)^2.
  double unknown_step_szz_m2 = 0.09;
  /// Height random walk per step of such a step, 1 sigma, m: a level floor most of the time,
  /// a riser (0.15-0.2 m) on stairs.
  double unknown_step_sigma_m = 0.1;
  /// Barometer: white noise of one reading as height, 1 sigma, m (0.04 hPa rms: phone and boot
  /// sensors of the 0.1 hPa class, e.g. Bosch BMP390 datasheet 0.03 hPa rms at low oversampling).
  double baro_sigma_m = 0.35;
  /// Weather drift of b, random walk, m per sqrt(s): 0.25 m in 10 minutes, 0.6 m in an hour
  /// (0.07 hPa; a front passing drifts 0.5 hPa/h as a trend). Stiff on the seconds of a flight
  /// of stairs, so that a climb is the agent's; chosen on multi-floor seeds 1-5 (docs/floors.md).
  double baro_drift_m_per_sqrt_s = 0.01;
  /// Innovation gate, chi-square with 1 dof (99.9 %).
  double gate_chi2 = 10.83;
  /// A pressure jump: rejected readings agreeing within 3 baro_sigma_m for this long (s).
  double jump_persist_s = 2.0;
  /// Faster than this (m/s) no person climbs: a change that fast is the air, not the agent
  /// (stairs: ~0.3 m/s vertically at 1.7 risers a second; a fan's pressure rises in seconds).
  double max_vertical_speed_mps = 0.6;
  /// The same reading repeated for this long (s) is a stuck sensor.
  double stuck_after_s = 10.0;
  /// Use the barometer (off: steps only).
  bool use_baro = true;
  /// The air every barometer inside shares (ours; HeightChannel): a change of the air seen at
  /// once by at least `shared_air_min_agents` barometers (and half of those reporting),
  /// faster than a person climbs, is taken out of each of their readings from where it began —
  /// a fan started while one of them was on the stairs is no longer that one's climb; a
  /// barometer that changed more than kAirSameTimeS after the others (a door) keeps its own.
  /// On since 2026-12-05: 20 firefighters, fresh seeds 401-410, right floor 97.8 -> 98.6 %
  /// (the worst mission 93.9 -> 98.2 %), vertical in95 89 -> 92 % (docs/floors.md).
  bool shared_air = true;
  int shared_air_min_agents = 3;
  /// The floors as a prior (ours): while the agent's height has stayed within
  /// `floor_prior_level_m` for `floor_prior_window_s` (walking or standing on a level: stairs
  /// climb 3 m in that time) and lies within `floor_prior_gate_m` of a level of the mission's
  /// `floors`, at most every `floor_prior_period_s` h is measured at that level with
  /// `floor_prior_sigma_m`: the barometer's offset then takes the weather's drift instead of the
  /// height (phone steps do not measure height). Only with `floors` in mission.json. On since
  /// 2026-12-05: the 4-hour incident's right floor 17.6 -> 98.9 % (docs/floors.md).
  bool floor_prior = true;
  double floor_prior_window_s = 10.0;
  double floor_prior_level_m = 0.5;
  double floor_prior_gate_m = 1.0;
  double floor_prior_period_s = 5.0;
  double floor_prior_sigma_m = 0.3;
  bool IsValid(std::string* why) const;
};
/// The `height.` keys.
const OptionTable<HeightOptions>& HeightOptionTable();

/// One agent's height filter. Usable without files.
class HeightFilter {
 public:
  HeightFilter(double start_z_m, double start_sigma_m, const HeightOptions& options = {});
  /// A step's height change (its dz and szz; no szz: a known height change of the default
  /// INS-class quality, (0.02 m)^2).
  void AddStep(const Step& step);
  /// One barometer reading. Returns what was done with it.
  enum class BaroUse { kReference, kUsed, kRejected, kJump, kHeightChange, kStuck, kOff };
  BaroUse AddBaro(const BaroSample& sample);
  double height_m() const { return x_[0]; }
  double height_variance_m2() const { return P_(0, 0); }
  /// The barometer's offset b (m) and its variance; nullopt before the first reading.
  std::optional<std::pair<double, double>> baro_offset() const;
  /// The most probable level and its probability under N(h, P_hh).
  std::pair<int, double> Level(const std::vector<FloorLevel>& floors) const;
  /// Counters: steps, stairs steps, baro used / rejected / jumps / height changes / stuck.
  std::map<std::string, double> Counters() const;
  /// Integrity notes since the last call (jumps absorbed, stuck sensor).
  std::vector<IntegrityNote> TakeNotes(const std::string& agent);
  /// The air's barometric height changed by `jump_m` from `since` on, as other barometers saw
  /// it (HeightChannel's shared air): this reading and later ones are taken with it removed,
  /// and so are the readings since `since` the filter still holds (a change being settled,
  /// rejected readings waiting for company).
  /// The change rose linearly over `rise_s` from `since` (0: at once).
  void AirChanged(TimeS since, double rise_s, double jump_m);
  /// The building's levels, for the floor prior (HeightOptions::floor_prior).
  void SetFloors(std::vector<FloorLevel> floors) { floors_ = std::move(floors); }
  /// The sum of those changes (m): what is taken out of every reading.
  double air_m() const { return air_m_; }

 private:
  void Predict(double q_h_m2);
  /// A reading (barometric height y, its air changes removed) gated into the state, or kept
  /// with the rejected ones (a jump, a height change the steps missed).
  BaroUse UseReading(TimeS t, double y);
  void DriftTo(TimeS t);
  HeightOptions options_;
  Eigen::Vector2d x_ = Eigen::Vector2d::Zero();
  Eigen::Matrix2d P_ = Eigen::Matrix2d::Zero();
  bool referenced_ = false;
  std::optional<TimeS> reference_t_;  ///< when the offset was last referenced on one reading
  std::optional<TimeS> last_baro_t_;
  std::vector<FloorLevel> floors_;                ///< for the floor prior (empty: none)
  std::deque<std::pair<TimeS, double>> level_h_;  ///< h after each used reading, the window
  std::optional<TimeS> last_floor_prior_t_;
  std::size_t floor_priors_ = 0;
  void FloorPrior(TimeS t);
  // Persistence of step height changes.
  std::deque<std::pair<double, double>> pending_;  ///< uncommitted steps: dz, szz
  double pending_dz_ = 0;
  int climbing_steps_left_ = 0;
  // Barometer screening.
  struct Agreement {
    TimeS t;
    double h_m, offset_m;
    double innovation_var_m2;  ///< of the predicted barometric height h + b
  };
  void Agree(TimeS t);
  bool LevelShift(TimeS t, double y);
  void SettleShift(TimeS t);
  static constexpr double kShiftWindowS = 1.0;  ///< the medians compared to detect a change
  /// The readings kept before a change (fitted with it) and awaited after it, and how many
  /// sigma from zero a fitted climb rate must be to be a climb. Chosen on development seeds
  /// 1-60 of `reproduce floors` only (docs/floors.md).
  static constexpr double kShiftHistoryS = 4.0;
  static constexpr double kShiftSettleS = 3.0;
  static constexpr double kRateSignificance = 2.0;
  struct Recent {
    TimeS t;
    double y;                ///< the reading's barometric height
    double offset_m, offset_var_m2;  ///< b and its variance before it
    double h_m;                      ///< h before it
  };
  std::deque<Recent> recent_;
  struct Shift {
    TimeS since;
    double before_m;  ///< the barometric height before the change (median)
    double offset_m, offset_var_m2;  ///< b before the window's first reading
    std::vector<std::pair<TimeS, double>> readings;  ///< the window: before and settling
  };
  std::optional<Shift> shift_;  ///< a change of the air being settled
  double committed_since_agreement_ = 0;  ///< step height committed since the agreement
  std::optional<Agreement> agreed_;  ///< when a reading last agreed within 1 sigma, and b then
  bool steps_know_height_ = false;   ///< the latest step's szz says it measures height
  std::vector<std::pair<TimeS, double>> rejected_run_;      ///< consecutive rejected readings
  double repeated_value_ = 0;
  std::optional<TimeS> repeated_since_;
  bool stuck_ = false;
  double air_m_ = 0;
  std::size_t air_changes_ = 0;
  std::size_t steps_ = 0, stairs_steps_ = 0, used_ = 0, rejected_ = 0, jumps_ = 0,
              height_changes_ = 0, stuck_readings_ = 0;
  std::vector<IntegrityNote> notes_;
};

/// A change of the air seen by a barometer while its carrier may be climbing: the readings
/// (t, barometric height) around it fitted as y(t) = a + r (t - t_end) + J ramp(t), a straight
/// climb at rate r plus a jump J that rises linearly from t_j over `rise` (0: a step), t_j and
/// rise chosen among the readings' times and {0, 0.5, 1, 2} s by least squares (readings further
/// than 5 sigma from the median of their five neighbours are spikes and left out). Ours
/// (issue 26: a fan started while a firefighter was on the stairs took the climb with it).
struct PressureJumpFit {
  double rate_mps = 0;           ///< r: the carrier's vertical speed over the window
  double rate_var = 0;           ///< its variance, (m/s)^2
  double jump_m = 0;             ///< J, as barometric height
  double jump_var_m2 = 0;        ///< its variance
  double level_end_m = 0;        ///< a + J: the fitted barometric height at the last reading
  double level_end_var_m2 = 0;   ///< its variance
  TimeS jump_start = 0;          ///< t_j
  double rise_s = 0;
  std::size_t used = 0;          ///< readings fitted (spikes left out)
  double sse_m2 = 0;             ///< the residuals' sum of squares
};
/// with_rate false: r = 0 (a level floor). nullopt: fewer than 8 readings left.
std::optional<PressureJumpFit> FitPressureJump(const std::vector<std::pair<TimeS, double>>& ty,
                                               double sigma_m, bool with_rate = true);

/// Every agent's height filter, created at its first row from its start (mission.json; else
/// z = 0), and the height of every crumb at its drop. Annotates estimates: agents get z, szz
/// and floor from their filter; a dropped node its dropper's at the drop.
class HeightChannel : public LevelSource {
 public:
  HeightChannel(MissionInfo info, HeightOptions options);
  /// Steps, barometer readings and drop events; other rows are ignored.
  void Add(const MissionRow& row);
  /// Sets z, szz and floor of an agent's or a dropped node's estimate (others unchanged; a
  /// floor the estimator set is kept).
  void Annotate(Estimate& estimate) const;
  /// An agent's level (its filter's, or its start's before its first row) or a dropped
  /// node's (its dropper's at the drop, probability 1).
  std::optional<LevelBelief> NodeLevel(const std::string& node) const override;
  /// Per agent: counters, the final level; integrity notes of the barometers.
  void AddToSummary(EstimatorSummary& summary) const;
  const HeightFilter* Filter(const std::string& agent) const;

 private:
  HeightFilter& FilterOf(const std::string& agent);
  /// The shared air (HeightOptions::shared_air): each agent's barometric heights of the last
  /// two seconds, as its filter takes them (its air changes removed); checked at most every
  /// kAirCheckS of mission time.
  void CheckSharedAir(TimeS t);
  static constexpr double kAirWindowS = 1.0;  ///< the two windows compared (as HeightFilter's)
  /// How far a barometer's own time of a shared change of the air may lie from the median of
  /// all of theirs: three readings at 5 Hz (a lag that short costs a few readings).
  static constexpr double kAirSameTimeS = 0.6;
  static constexpr double kAirCheckS = 0.2;
  MissionInfo info_;
  HeightOptions options_;
  std::map<std::string, HeightFilter> filters_;
  std::map<std::string, std::deque<std::pair<TimeS, double>>> air_recent_;
  TimeS air_checked_t_ = -1e300;
  std::size_t air_jumps_ = 0;
  struct Dropped {
    double z_m, szz_m2;
    int level;
  };
  std::map<std::string, Dropped> dropped_;
  std::vector<IntegrityNote> notes_;
};

/// An EstimateSink that annotates every estimate with the channel's height before passing it
/// on.
class HeightAnnotatingSink : public EstimateSink {
 public:
  HeightAnnotatingSink(const HeightChannel& channel, EstimateSink& out)
      : channel_(channel), out_(out) {}
  void Add(const Estimate& estimate) override {
    Estimate e = estimate;
    channel_.Annotate(e);
    out_.Add(e);
  }

 private:
  const HeightChannel& channel_;
  EstimateSink& out_;
};

}  // namespace trailmark

// SPDX-License-Identifier: MIT
#include "trailmark/sim/variation.h"

#include <fmt/format.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <optional>
#include <set>
#include <sstream>
#include <stdexcept>

#include "trailmark/core/random.h"
#include "trailmark/sim/imu_sim.h"

namespace trailmark {

Vec2 FrameMotion::Point(const Vec2& p) const { return Eigen::Rotation2Dd(angle_rad) * p + shift_m; }
Vec3 FrameMotion::Point(const Vec3& p) const {
  const Vec2 q = Point(Vec2(p.head<2>()));
  return Vec3(q.x(), q.y(), p.z());
}
Vec3 FrameMotion::Direction(const Vec3& d) const {
  const Vec2 q = Eigen::Rotation2Dd(angle_rad) * Vec2(d.head<2>());
  return Vec3(q.x(), q.y(), d.z());
}
Vec2 FrameMotion::Back(const Vec2& p) const {
  return Eigen::Rotation2Dd(-angle_rad) * (p - shift_m);
}

SimulatedMission DrawnInFrame(SimulatedMission sim, const FrameMotion& f) {
  MissionData& d = sim.data;
  for (NodeInfo& n : d.info.nodes) {
    if (n.position) n.position = f.Point(*n.position);
    if (n.start) n.start = f.Point(*n.start);
    if (n.start_heading_rad) n.start_heading_rad = WrapAngle(*n.start_heading_rad + f.angle_rad);
  }
  for (Step& s : d.steps) {
    s.delta_n = f.Direction(s.delta_n);
    if (s.variance_m2) {
      const double h = 0.5 * (s.variance_m2->x() + s.variance_m2->y());
      s.variance_m2 = Vec3(h, h, s.variance_m2->z());
    }
  }
  for (BearingMeasurement& b : d.bearings) b.bearing_rad = WrapAngle(b.bearing_rad + f.angle_rad);
  for (TruthSample& t : d.truth) t.position_n = f.Point(t.position_n);
  for (auto& [id, walk] : sim.walks) {
    for (TrueStep& s : walk.steps) s.from = f.Point(s.from), s.to = f.Point(s.to);
    for (Walk::Sample& s : walk.truth) {
      s.position = f.Point(s.position);
      s.heading_rad = WrapAngle(s.heading_rad + f.angle_rad);
    }
  }
  auto drawn = [&f](const FloorPlan& plan) {
    std::vector<Segment2> walls, doors;
    for (const auto& w : plan.walls()) walls.push_back({f.Point(w.a), f.Point(w.b)});
    for (const auto& w : plan.doors()) doors.push_back({f.Point(w.a), f.Point(w.b)});
    std::vector<Room> rooms = plan.rooms();
    for (Room& r : rooms) {
      for (Vec2& p : r.ring) p = f.Point(p);
    }
    return FloorPlan(walls, doors, rooms);
  };
  sim.plan = drawn(sim.plan);
  for (auto& [level, plan] : sim.levels) plan = drawn(plan);
  return sim;
}

namespace {

constexpr VariationFamily kSingleFamilies[] = {VariationFamily::kFrame,  VariationFamily::kRadio,
                                               VariationFamily::kRanges, VariationFamily::kNodes,
                                               VariationFamily::kPdr,    VariationFamily::kPhone,
                                               VariationFamily::kEvents, VariationFamily::kStart,
                                               VariationFamily::kCsv,    VariationFamily::kImu};

/// A seed for (k, family, purpose) that does not collide across families (splitmix64).
std::uint64_t Mix(std::uint64_t k, int family, int purpose) {
  std::uint64_t z = k * 0x9e3779b97f4a7c15ULL + static_cast<std::uint64_t>(family) * 0xbf58476d1ce4e5b9ULL +
                    static_cast<std::uint64_t>(purpose) * 0x94d049bb133111ebULL + 0x2545f4914f6cdd1dULL;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

bool Coin(Random& r, double p = 0.5) { return r.Uniform() < p; }
double Signed(Random& r, double lo, double hi) {
  const double m = r.Uniform(lo, hi);
  return Coin(r) ? m : -m;
}

/// Log-distance ranges per band: alpha at 1 m, exponent, shadowing. The spread of published
/// indoor fits (868 MHz: breadcrumb and radio-landmark papers' hardware class; BLE beacons at
/// 0 dBm; UWB first-path power): wide on purpose, so that no estimator's default is the centre.
struct BandRange {
  double alpha_lo, alpha_hi, n_lo, n_hi, sigma_lo, sigma_hi;
};
BandRange RangeOf(RadioBand b) {
  switch (b) {
    case RadioBand::k868MHz: return {-45, -30, 1.8, 3.3, 3, 7};
    case RadioBand::kBle2G4: return {-65, -55, 1.8, 4.0, 4, 9};
    case RadioBand::kUwb: return {-75, -60, 1.7, 3.0, 2, 6};
  }
  return {-45, -30, 1.8, 3.3, 3, 7};
}
const char* Name(RadioBand b) {
  switch (b) {
    case RadioBand::k868MHz: return "868 MHz";
    case RadioBand::kBle2G4: return "BLE 2.4 GHz";
    case RadioBand::kUwb: return "UWB";
  }
  return "?";
}

void DrawFamily(VariationFamily f, Random& r, Variation& v) {
  switch (f) {
    case VariationFamily::kFrame:
      v.frame.angle_rad = r.Uniform(0, 2 * std::numbers::pi);
      v.frame.shift_m = Vec2(r.Uniform(-2000, 2000), r.Uniform(-2000, 2000));
      v.doors_across_gaps = Coin(r);
      v.write.polyline_walls = Coin(r);
      v.imu_mount_yaw_rad = r.Uniform(0, 2 * std::numbers::pi);
      v.imu_z_down = Coin(r);
      break;
    case VariationFamily::kRadio: {
      v.radio = true;
      const double u = r.Uniform();
      v.band = u < 1.0 / 3 ? RadioBand::k868MHz : u < 2.0 / 3 ? RadioBand::kBle2G4 : RadioBand::kUwb;
      const BandRange b = RangeOf(v.band);
      v.alpha_dbm = r.Uniform(b.alpha_lo, b.alpha_hi);
      v.path_loss_exponent = r.Uniform(b.n_lo, b.n_hi);
      v.shadowing_sigma_db = r.Uniform(b.sigma_lo, b.sigma_hi);
      v.node_offset_max_db = 6.0;
      v.correlated_shadowing_db = r.Uniform(2.0, 6.0);
      v.shadowing_length_m = r.Uniform(2.0, 10.0);
      if (Coin(r)) v.censor_below_dbm = r.Uniform(-92.0, -80.0);
      const double s = r.Uniform();
      v.stated_radio = s < 1.0 / 3 ? StatedRadio::kTrue
                       : s < 2.0 / 3 ? StatedRadio::kNominal
                                     : StatedRadio::kAbsent;
      break;
    }
    case VariationFamily::kRanges:
      v.nlos_fraction = r.Uniform(0.05, 0.3);
      v.nlos_mean_m = r.Uniform(0.3, 2.0);
      v.neighbour_only_links = Coin(r);
      // c = 331.3 sqrt(1 + T / 273.15) m/s: 331 m/s at 0 deg C, 367 m/s at 60 deg C against the
      // 343 m/s of 20 deg C — measured ranges x 343 / c, 0.93-1.04.
      v.ultrasound_range_scale = r.Uniform(0.93, 1.04);
      break;
    case VariationFamily::kNodes: v.survey_error = true; break;
    case VariationFamily::kPdr:
      v.heading_offset_rad = Signed(r, 2.0, 10.0) * std::numbers::pi / 180;
      v.heading_drift_rad_per_s = Signed(r, 0.5, 3.0) * std::numbers::pi / 180 / 60;
      v.zero_length_steps = Coin(r);
      v.gyro_bias_z_rad_per_s = Signed(r, 0.5, 3.0) * std::numbers::pi / 180 / 60;
      break;
    case VariationFamily::kPhone:
      v.phone = true;
      v.phone_scale = r.Uniform(0.85, 1.15);
      v.phone_first_offset_rad = r.Uniform(-20.0, 20.0) * std::numbers::pi / 180;
      v.phone_mode_period_s = r.Uniform(30.0, 120.0);
      break;
    case VariationFamily::kEvents: v.events = Coin(r) ? EventsKept::kDropsOnly : EventsKept::kNone; break;
    case VariationFamily::kStart:
      v.drop_start_heading = true;
      // A third start where the scenario does (at the entry, inside), the others 2-10 m outside.
      if (r.Uniform() >= 1.0 / 3) v.start_outside_m = r.Uniform(2.0, 10.0);
      break;
    case VariationFamily::kCsv: {
      v.write.seed = Mix(v.k, static_cast<int>(f), 7);
      // At least one quirk: draw until one is on.
      do {
        v.write.csv_comments = Coin(r);
        v.write.csv_shuffled_columns = Coin(r);
        v.write.csv_extra_column = Coin(r);
      } while (!v.write.csv_comments && !v.write.csv_shuffled_columns && !v.write.csv_extra_column);
      break;
    }
    case VariationFamily::kImu: {
      // A quarter tactical, half industrial (the simulator's default), a quarter consumer
      // (uncalibrated: +-5 deg/s of gyro bias at turn-on); 100 or 200 Hz; turned on the foot
      // by up to 30 degrees either way (toe-out and a strap: the INS's mounting search).
      v.foot_imu = true;
      const double u = r.Uniform();
      v.imu_grade = u < 0.25 ? "tactical" : u < 0.75 ? "industrial" : "consumer";
      v.imu_rate_hz = Coin(r) ? 100.0 : 200.0;
      v.imu_turn_rad = r.Uniform(-30.0, 30.0) * std::numbers::pi / 180;
      // The gait: the foot lands along its stride (a pivot) or already turned up to half way
      // toward the next one (ImuSimOptions::landing_anticipation). Drawn last: the draws above
      // are those of the family before the gait was drawn.
      v.imu_landing_anticipation = r.Uniform(0.0, 0.5);
      break;
    }
    case VariationFamily::kAll: break;
  }
}

/// Unit-variance Gaussian random field with squared-exponential correlation of length L
/// (random Fourier features, Rahimi & Recht 2007): g(p) = sqrt(2/M) sum cos(w_m . p + phi_m).
class RandomField {
 public:
  RandomField(double length_m, Random& r) {
    for (int m = 0; m < kFeatures; ++m) {
      w_[m] = Vec2(r.Normal(), r.Normal()) / length_m;
      phi_[m] = r.Uniform(0, 2 * std::numbers::pi);
    }
  }
  double operator()(const Vec2& p) const {
    double s = 0;
    for (int m = 0; m < kFeatures; ++m) s += std::cos(w_[m].dot(p) + phi_[m]);
    return std::sqrt(2.0 / kFeatures) * s;
  }

 private:
  static constexpr int kFeatures = 64;
  Vec2 w_[kFeatures];
  double phi_[kFeatures];
};

/// Where a node was at time t: truth interpolated (agents), in force (crumbs), else mission.json.
class Positions {
 public:
  explicit Positions(const MissionData& d) : info_(d.info) {
    for (const TruthSample& s : d.truth) by_id_[s.id].push_back(&s);
    for (const NodeInfo& n : d.info.nodes) kind_[n.id] = n.kind;
  }
  std::optional<Vec2> At(const std::string& id, TimeS t) const {
    auto it = by_id_.find(id);
    if (it == by_id_.end() || it->second.empty()) {
      const NodeInfo* n = info_.Find(id);
      if (n != nullptr && n->position) return Vec2(n->position->head<2>());
      return std::nullopt;
    }
    const auto& v = it->second;
    auto after = std::upper_bound(v.begin(), v.end(), t,
                                  [](TimeS x, const TruthSample* s) { return x < s->t; });
    if (after == v.begin()) return Vec2((*after)->position_n.head<2>());
    if (after == v.end()) return Vec2(v.back()->position_n.head<2>());
    const TruthSample* a = *(after - 1);
    const TruthSample* b = *after;
    const auto k = kind_.find(id);
    const bool moving = k != kind_.end() && k->second == NodeKind::kAgent;
    if (!moving || b->t <= a->t) return Vec2(a->position_n.head<2>());  // static: in force
    const double w = (t - a->t) / (b->t - a->t);
    return Vec2(((1 - w) * a->position_n + w * b->position_n).head<2>());
  }

 private:
  const MissionInfo& info_;
  std::map<std::string, std::vector<const TruthSample*>> by_id_;
  std::map<std::string, NodeKind> kind_;
};

std::string Num(double x) {
  std::ostringstream o;
  o.precision(6);
  o << x;
  return o.str();
}

void ApplyRadio(const Variation& v, SimulatedMission& sim, Random& r, std::vector<std::string>& notes) {
  MissionData& d = sim.data;
  if (d.rssi.empty()) {
    notes.push_back("no rssi.csv: the radio variation changed nothing");
    return;
  }
  const RadioCalibration reference = d.info.radio.value_or(RadioCalibration{});
  std::map<std::string, double> offset_db;
  auto offset = [&](const std::string& id) {
    auto [it, fresh] = offset_db.emplace(id, 0.0);
    if (fresh) it->second = r.Uniform(-v.node_offset_max_db, v.node_offset_max_db);
    return it->second;
  };
  const RandomField field(v.shadowing_length_m, r);
  const Positions where(d);
  // The drawn total shadowing: what the reference channel lacks of it, per packet.
  const double extra_iid_db = std::sqrt(std::max(
      0.0, v.shadowing_sigma_db * v.shadowing_sigma_db -
               reference.shadowing_sigma_db * reference.shadowing_sigma_db));
  std::vector<RssiPacket> kept;
  kept.reserve(d.rssi.size());
  std::size_t moved = 0, censored = 0;
  for (RssiPacket p : d.rssi) {
    const auto a = where.At(p.rx, p.t), b = where.At(p.tx, p.t);
    if (a && b) {
      const double dist_m = std::max(0.1, (*a - *b).norm());
      // Same packet, another channel: the reference model's mean replaced by the drawn one
      // (the packet's own shadowing, walls and fading kept), then the spatially consistent
      // extra shadowing of both ends (the same places give the same loss).
      p.rssi_dbm += (v.alpha_dbm - reference.alpha_dbm) -
                    10.0 * (v.path_loss_exponent - reference.path_loss_exponent) * std::log10(dist_m) +
                    v.correlated_shadowing_db * (field(*a) + field(*b)) / std::sqrt(2.0) +
                    r.Normal(0, extra_iid_db);
      ++moved;
    }
    p.rssi_dbm += offset(p.rx) + offset(p.tx);
    if (v.censor_below_dbm && p.rssi_dbm < *v.censor_below_dbm) {
      ++censored;
      continue;
    }
    kept.push_back(std::move(p));
  }
  if (moved < d.rssi.size())
    notes.push_back(std::to_string(d.rssi.size() - moved) +
                    " packets between nodes without a known position: offsets only");
  if (censored > 0) notes.push_back(std::to_string(censored) + " weak packets censored");
  d.rssi = std::move(kept);
  switch (v.stated_radio) {
    case StatedRadio::kTrue: {
      RadioCalibration c;
      c.alpha_dbm = v.alpha_dbm;
      c.path_loss_exponent = v.path_loss_exponent;
      c.shadowing_sigma_db = std::hypot(std::max(reference.shadowing_sigma_db, v.shadowing_sigma_db),
                                        v.correlated_shadowing_db);
      d.info.radio = c;
      break;
    }
    case StatedRadio::kNominal: d.info.radio = reference; break;  // stale: another channel's
    case StatedRadio::kAbsent: d.info.radio.reset(); break;
  }
}

/// Crumbs in the order they were dropped.
std::map<std::string, int> DropOrder(const MissionData& d) {
  std::map<std::string, int> order;
  for (const MissionEvent& e : d.events) {
    if (e.event == "drop" && !e.node.empty()) order.emplace(e.node, static_cast<int>(order.size()));
  }
  return order;
}

void ApplyRanges(const Variation& v, SimulatedMission& sim, Random& r, std::vector<std::string>& notes) {
  MissionData& d = sim.data;
  if (d.ranges.empty()) {
    notes.push_back("no ranges.csv: the ranges variation changed nothing");
    return;
  }
  const std::map<std::string, int> order = DropOrder(d);
  std::vector<RangeMeasurement> kept;
  std::size_t nlos = 0, cut = 0;
  for (RangeMeasurement m : d.ranges) {
    const auto a = order.find(m.a), b = order.find(m.b);
    if (v.neighbour_only_links && a != order.end() && b != order.end() &&
        std::abs(a->second - b->second) > 1) {
      ++cut;
      continue;
    }
    if (m.kind != "rssi" && r.Uniform() < v.nlos_fraction) {
      // Non-line-of-sight: the first arrival took a longer path; exponential excess.
      m.range_m += -v.nlos_mean_m * std::log(1.0 - r.Uniform());
      ++nlos;
    }
    if (m.kind == "ultrasound") m.range_m *= v.ultrasound_range_scale;  // the path, timed
    kept.push_back(std::move(m));
  }
  d.ranges = std::move(kept);
  notes.push_back(std::to_string(nlos) + " ranges with an NLOS excess" +
                  (cut ? ", " + std::to_string(cut) + " crumb-crumb ranges between non-neighbours removed"
                       : std::string()));
}

void ApplySurvey(SimulatedMission& sim, Random& r, std::vector<std::string>& notes) {
  MissionData& d = sim.data;
  std::set<std::string> with_truth;
  TimeS t0 = d.truth.empty() ? 0.0 : d.truth.front().t;
  for (const TruthSample& s : d.truth) with_truth.insert(s.id), t0 = std::min(t0, s.t);
  int moved = 0;
  for (NodeInfo& n : d.info.nodes) {
    if (!n.position || !n.position_sigma_m || !(*n.position_sigma_m > 0)) continue;
    // The node stays where it is (its measurements were made there); the survey says otherwise
    // by one draw of its stated sigma, shared by every measurement that uses it.
    if (with_truth.insert(n.id).second) d.truth.push_back({t0, n.id, *n.position});
    n.position->x() += r.Normal(0, *n.position_sigma_m);
    n.position->y() += r.Normal(0, *n.position_sigma_m);
    ++moved;
  }
  std::stable_sort(d.truth.begin(), d.truth.end(),
                   [](const TruthSample& a, const TruthSample& b) { return a.t < b.t; });
  notes.push_back(std::to_string(moved) + " surveyed positions drawn with their stated sigma");
}

void ApplyPdr(const Variation& v, SimulatedMission& sim, std::vector<std::string>& notes) {
  MissionData& d = sim.data;
  for (ImuSample& s : d.imu) s.gyro_b.z() += v.gyro_bias_z_rad_per_s;
  if (d.steps.empty()) return;
  std::map<std::string, TimeS> first;
  for (const Step& s : d.steps) first.emplace(s.agent, s.t0);
  std::vector<Step> out;
  out.reserve(d.steps.size());
  std::map<std::string, const Step*> previous;
  std::size_t zeros = 0;
  for (const Step& s : d.steps) {
    if (v.zero_length_steps) {
      auto it = previous.find(s.agent);
      if (it != previous.end() && s.t0 - it->second->t1 > 1.0) {
        // Standing: a PDR that keeps reporting (zero displacement every 0.5 s).
        for (TimeS t = it->second->t1; t + 0.5 < s.t0; t += 0.5) {
          Step z = *it->second;
          z.t0 = t;
          z.t1 = t + 0.5;
          z.delta_n = Vec3::Zero();
          out.push_back(z);
          ++zeros;
        }
      }
    }
    Step rotated = s;
    const double psi = v.heading_offset_rad + v.heading_drift_rad_per_s * (s.t1 - first[s.agent]);
    const Vec2 h = Eigen::Rotation2Dd(psi) * Vec2(s.delta_n.head<2>());
    rotated.delta_n.head<2>() = h;
    out.push_back(rotated);
    previous[s.agent] = &s;
  }
  std::stable_sort(out.begin(), out.end(), [](const Step& a, const Step& b) { return a.t1 < b.t1; });
  d.steps = std::move(out);
  if (zeros > 0) notes.push_back(std::to_string(zeros) + " zero-length steps while standing");
}

/// What a hand-held phone's PDR reports of the same walk (see Variation; the magnitudes are
/// those reported for smartphone PDR, set a priori): the heading is the phone's, offset from the
/// walking direction by its carrying mode (texting, calling, swinging, pocket), which changes at
/// random times to a new offset of up to +-45 deg; a step-length model with a shared scale
/// error and 8 % per step; 4 % of steps missed (their displacement lost) and, when standing
/// longer than 2 s, phantom steps half of the time (1-3 of 0.6 m, a sway read as walking). The
/// steps keep the variances the foot PDR stated: the phone claims as much.
void ApplyPhone(const Variation& v, SimulatedMission& sim, Random& r, std::vector<std::string>& notes) {
  MissionData& d = sim.data;
  if (d.steps.empty()) return;
  struct Mode {
    double offset_rad = 0;
    TimeS next_change = 0;
  };
  std::map<std::string, Mode> modes;
  std::map<std::string, const Step*> previous;
  std::vector<Step> out;
  out.reserve(d.steps.size());
  std::size_t missed = 0, phantom = 0, changes = 0;
  auto next_gap = [&] { return -v.phone_mode_period_s * std::log(1.0 - r.Uniform()); };
  for (const Step& s : d.steps) {
    auto [it, first] = modes.try_emplace(s.agent);
    Mode& m = it->second;
    if (first) m = {v.phone_first_offset_rad, s.t0 + next_gap()};
    while (s.t0 >= m.next_change) {
      m.offset_rad = r.Uniform(-45.0, 45.0) * std::numbers::pi / 180;
      m.next_change += next_gap();
      ++changes;
    }
    if (auto p = previous.find(s.agent); p != previous.end() && s.t0 - p->second->t1 > 2.0 &&
                                         r.Uniform() < 0.5) {
      const Vec2 last = p->second->delta_n.head<2>();
      const Vec2 dir = last.norm() > 1e-9 ? Vec2(last.normalized()) : Vec2(1, 0);
      const int n = 1 + static_cast<int>(r.Uniform() * 3.0);
      for (int k = 0; k < n; ++k) {
        Step z = *p->second;
        z.t0 = p->second->t1 + 0.6 * k;
        z.t1 = z.t0 + 0.5;
        if (z.t1 >= s.t0) break;
        z.delta_n.head<2>() = Eigen::Rotation2Dd(m.offset_rad) * Vec2(0.6 * dir);
        out.push_back(z);
        ++phantom;
      }
    }
    previous[s.agent] = &s;
    if (r.Uniform() < 0.04) {
      ++missed;
      continue;
    }
    Step phone = s;
    const double stretch = v.phone_scale * (1.0 + r.Normal(0, 0.08));
    phone.delta_n.head<2>() = Eigen::Rotation2Dd(m.offset_rad) * Vec2(s.delta_n.head<2>() * stretch);
    out.push_back(phone);
  }
  std::stable_sort(out.begin(), out.end(), [](const Step& a, const Step& b) { return a.t1 < b.t1; });
  d.steps = std::move(out);
  notes.push_back(fmt::format("phone steps: {} carrying-mode changes, {} steps missed, {} phantom",
                              changes, missed, phantom));
}

/// The responder starts `start_outside_m` outside and walks straight in (see Variation).
void ApplyStartOutside(const Variation& v, SimulatedMission& sim, Random& r,
                       std::vector<std::string>& notes) {
  if (!(v.start_outside_m > 0)) return;
  MissionData& d = sim.data;
  if (!d.imu.empty()) {
    notes.push_back("start outside not applied: the mission has a foot IMU");
    return;
  }
  constexpr double kStepM = 0.7, kStepS = 0.55, kTruthPeriodS = 0.1;
  std::vector<TruthSample> truth;
  std::vector<Step> steps;
  for (NodeInfo& n : d.info.nodes) {
    if (n.kind != NodeKind::kAgent || !n.start) continue;
    std::vector<const TruthSample*> mine;
    for (const TruthSample& t : d.truth) {
      if (t.id == n.id) mine.push_back(&t);
    }
    if (mine.empty()) continue;
    const Vec3 s0 = mine.front()->position_n;
    const TimeS t_first = mine.front()->t;
    // The direction of its first 2 m: it came in walking that way.
    std::optional<Vec2> u;
    for (const TruthSample* t : mine) {
      const Vec2 d2 = (t->position_n - s0).head<2>();
      if (d2.norm() >= 2.0) {
        u = d2.normalized();
        break;
      }
    }
    if (!u) continue;
    const double length = v.start_outside_m;
    const int n_steps = static_cast<int>(std::ceil(length / kStepM));
    const double step_m = length / n_steps;
    const TimeS t_begin = t_first - n_steps * kStepS;
    Vec3 outside = s0;
    outside.head<2>() -= length * *u;
    for (TimeS t = t_begin; t < t_first - 1e-9; t += kTruthPeriodS) {
      Vec3 p = outside;
      p.head<2>() += (t - t_begin) / (t_first - t_begin) * length * *u;
      truth.push_back({t, n.id, p});
    }
    std::optional<Vec3> variance;
    for (const Step& st : d.steps) {
      if (st.agent == n.id) {
        variance = st.variance_m2;
        break;
      }
    }
    for (int k = 0; k < n_steps; ++k) {
      // The PDR's own errors on the way in: 2 degrees of heading, 3 % of length (1 sigma).
      const double turn = r.Normal(0, 2.0 * std::numbers::pi / 180);
      const double stretch = 1.0 + r.Normal(0, 0.03);
      Step st;
      st.t0 = t_begin + k * kStepS;
      st.t1 = st.t0 + kStepS;
      st.agent = n.id;
      st.delta_n.head<2>() = Eigen::Rotation2Dd(turn) * Vec2(*u * step_m * stretch);
      st.variance_m2 = variance;
      steps.push_back(st);
    }
    n.start = outside;
    notes.push_back(fmt::format("{} starts {:.1f} m outside and walks in ({} steps)", n.id, length,
                                n_steps));
  }
  d.truth.insert(d.truth.end(), truth.begin(), truth.end());
  std::stable_sort(d.truth.begin(), d.truth.end(),
                   [](const TruthSample& a, const TruthSample& b) { return a.t < b.t; });
  d.steps.insert(d.steps.end(), steps.begin(), steps.end());
  std::stable_sort(d.steps.begin(), d.steps.end(),
                   [](const Step& a, const Step& b) { return a.t1 < b.t1; });
}

void ApplyEvents(const Variation& v, SimulatedMission& sim) {
  MissionData& d = sim.data;
  if (v.events == EventsKept::kAll) return;
  if (v.events == EventsKept::kNone) {
    // Without drop events a crumb is no longer introduced by the stream: declare it.
    for (const auto& [id, k] : DropOrder(d)) {
      if (d.info.Find(id) == nullptr) {
        NodeInfo n;
        n.id = id;
        n.kind = NodeKind::kCrumb;
        d.info.nodes.push_back(n);
      }
    }
    d.events.clear();
    return;
  }
  std::erase_if(d.events, [](const MissionEvent& e) { return e.event != "drop"; });
}

}  // namespace

std::vector<std::pair<VariationFamily, std::string>> VariationFamilies() {
  return {{VariationFamily::kFrame, "frame"},   {VariationFamily::kRadio, "radio"},
          {VariationFamily::kRanges, "ranges"}, {VariationFamily::kNodes, "nodes"},
          {VariationFamily::kPdr, "pdr"},       {VariationFamily::kPhone, "phone"},
          {VariationFamily::kEvents, "events"}, {VariationFamily::kStart, "start"},
          {VariationFamily::kCsv, "csv"},       {VariationFamily::kImu, "imu"},
          {VariationFamily::kAll, "all"}};
}

VariationFamily ParseVariationFamily(const std::string& name) {
  std::string known;
  for (const auto& [f, n] : VariationFamilies()) {
    if (n == name) return f;
    known += (known.empty() ? "" : ", ") + n;
  }
  throw std::invalid_argument("unknown variation family '" + name + "' (known: " + known + ")");
}

std::string ToString(VariationFamily family) {
  for (const auto& [f, n] : VariationFamilies()) {
    if (f == family) return n;
  }
  return "?";
}

Variation DrawVariation(VariationFamily family, std::uint64_t k) {
  Variation v;
  v.family = family;
  v.k = k;
  for (VariationFamily f : kSingleFamilies) {
    if (family != f && (family != VariationFamily::kAll || f == VariationFamily::kImu)) continue;
    Random r(Mix(k, static_cast<int>(f), 0));
    DrawFamily(f, r, v);
  }
  return v;
}

std::vector<std::string> ApplyVariation(const Variation& v, SimulatedMission& sim) {
  std::vector<std::string> notes;
  auto rng = [&](VariationFamily f) { return Random(Mix(v.k, static_cast<int>(f), 1)); };
  auto on = [&](VariationFamily f) { return v.family == f || v.family == VariationFamily::kAll; };
  // The walk first (a start outside extends it), then the measurements, in the simulator's
  // frame; the frame last. The imu family is its own (not part of `all`).
  if (v.family == VariationFamily::kImu && v.foot_imu) {
    if (sim.walks.empty()) {
      notes.push_back("no walks: imu variation not applied");
    } else {
      ImuSimOptions o;
      o.rate_hz = v.imu_rate_hz;
      o.grade = ImuGrade::ByName(v.imu_grade);
      o.landing_anticipation = v.imu_landing_anticipation;
      sim.data.imu.clear();
      AddFootImu(sim, o, Mix(v.k, static_cast<int>(VariationFamily::kImu), 2));
      sim.data.steps.clear();
      MountImu(sim.data.imu, ImuMounting(v.imu_turn_rad));
      notes.push_back("steps.csv replaced by a " + v.imu_grade + " foot IMU at " +
                      Num(v.imu_rate_hz) + " Hz, turned " +
                      Num(v.imu_turn_rad * 180 / std::numbers::pi) + " deg on the foot, landing " +
                      Num(v.imu_landing_anticipation) + " of the way to its next stride");
    }
  }
  if (on(VariationFamily::kStart)) {
    Random r = rng(VariationFamily::kStart);
    ApplyStartOutside(v, sim, r, notes);
  }
  if (on(VariationFamily::kRadio) && v.radio) {
    Random r = rng(VariationFamily::kRadio);
    ApplyRadio(v, sim, r, notes);
  }
  if (on(VariationFamily::kRanges)) {
    Random r = rng(VariationFamily::kRanges);
    ApplyRanges(v, sim, r, notes);
  }
  if (on(VariationFamily::kNodes) && v.survey_error) {
    Random r = rng(VariationFamily::kNodes);
    ApplySurvey(sim, r, notes);
  }
  if (on(VariationFamily::kPhone) && v.phone) {
    Random r = rng(VariationFamily::kPhone);
    ApplyPhone(v, sim, r, notes);
  }
  if (on(VariationFamily::kPdr)) ApplyPdr(v, sim, notes);
  if (on(VariationFamily::kEvents)) ApplyEvents(v, sim);
  if (on(VariationFamily::kStart) && v.drop_start_heading) {
    for (NodeInfo& n : sim.data.info.nodes) n.start_heading_rad.reset(), n.start_heading_sigma_rad.reset();
  }
  if (on(VariationFamily::kFrame)) {
    if (v.doors_across_gaps && !sim.plan.empty()) {
      // The other door convention (spec 1.1): the walls drawn with the gaps, the doors across
      // (on every level of a multi-floor building).
      auto across = [](const FloorPlan& p) {
        return FloorPlan(p.solid_walls(), p.doors(), p.rooms());
      };
      sim.plan = across(sim.plan);
      for (auto& [level, plan] : sim.levels) plan = across(plan);
    }
    sim = DrawnInFrame(std::move(sim), v.frame);
    if (!sim.data.imu.empty()) {
      // The IMU's axes in the foot's frame: turned about the vertical, then maybe upside down
      // (about its x axis); a foot-frame vector reads R^T v in the IMU's.
      MountImu(sim.data.imu,
               ImuMounting(v.imu_mount_yaw_rad, v.imu_z_down ? std::numbers::pi : 0.0));
      notes.push_back("foot IMU mounted turned " +
                      Num(v.imu_mount_yaw_rad * 180 / std::numbers::pi) + " deg" +
                      (v.imu_z_down ? ", upside down" : ""));
    }
  }
  return notes;
}

std::vector<std::pair<std::string, std::string>> Variation::Describe() const {
  std::vector<std::pair<std::string, std::string>> out{{"family", ToString(family)},
                                                       {"k", std::to_string(k)}};
  auto on = [&](VariationFamily f) { return family == f || family == VariationFamily::kAll; };
  if (on(VariationFamily::kFrame)) {
    out.emplace_back("rotation_deg", Num(frame.angle_rad * 180 / std::numbers::pi));
    out.emplace_back("origin_shift_m", Num(frame.shift_m.x()) + "," + Num(frame.shift_m.y()));
    out.emplace_back("doors", doors_across_gaps ? "across gaps" : "along walls");
    out.emplace_back("walls", write.polyline_walls ? "multi-vertex" : "two-point");
    out.emplace_back("imu_mount_yaw_deg", Num(imu_mount_yaw_rad * 180 / std::numbers::pi));
    out.emplace_back("imu_z", imu_z_down ? "down" : "up");
  }
  if (on(VariationFamily::kRadio)) {
    out.emplace_back("band", Name(band));
    out.emplace_back("alpha_dbm", Num(alpha_dbm));
    out.emplace_back("path_loss_exponent", Num(path_loss_exponent));
    out.emplace_back("shadowing_sigma_db", Num(shadowing_sigma_db));
    out.emplace_back("node_offsets_db", "+-" + Num(node_offset_max_db));
    out.emplace_back("correlated_shadowing_db", Num(correlated_shadowing_db));
    out.emplace_back("shadowing_length_m", Num(shadowing_length_m));
    out.emplace_back("censor_below_dbm", censor_below_dbm ? Num(*censor_below_dbm) : "none");
    out.emplace_back("stated_radio", stated_radio == StatedRadio::kTrue      ? "true"
                                     : stated_radio == StatedRadio::kNominal ? "nominal (stale)"
                                                                             : "absent");
  }
  if (on(VariationFamily::kRanges)) {
    out.emplace_back("nlos_fraction", Num(nlos_fraction));
    out.emplace_back("nlos_mean_m", Num(nlos_mean_m));
    out.emplace_back("links", neighbour_only_links ? "neighbours only" : "all");
    out.emplace_back("ultrasound_range_scale", Num(ultrasound_range_scale));
  }
  if (on(VariationFamily::kNodes)) out.emplace_back("survey_error", "one draw of the stated sigma");
  if (on(VariationFamily::kPdr)) {
    out.emplace_back("heading_offset_deg", Num(heading_offset_rad * 180 / std::numbers::pi));
    out.emplace_back("heading_drift_deg_per_min",
                     Num(heading_drift_rad_per_s * 180 / std::numbers::pi * 60));
    out.emplace_back("zero_length_steps", zero_length_steps ? "yes" : "no");
    out.emplace_back("gyro_bias_z_deg_per_min",
                     Num(gyro_bias_z_rad_per_s * 180 / std::numbers::pi * 60));
  }
  if (on(VariationFamily::kPhone)) {
    out.emplace_back("phone_scale", Num(phone_scale));
    out.emplace_back("phone_first_offset_deg", Num(phone_first_offset_rad * 180 / std::numbers::pi));
    out.emplace_back("phone_mode_period_s", Num(phone_mode_period_s));
  }
  if (on(VariationFamily::kEvents))
    out.emplace_back("events", events == EventsKept::kAll         ? "all"
                               : events == EventsKept::kDropsOnly ? "drops only"
                                                                  : "none");
  if (on(VariationFamily::kStart)) {
    out.emplace_back("start_heading", drop_start_heading ? "not given" : "given");
    out.emplace_back("start_outside_m", Num(start_outside_m));
  }
  if (family == VariationFamily::kImu) {
    out.emplace_back("imu_grade", imu_grade);
    out.emplace_back("imu_rate_hz", Num(imu_rate_hz));
    out.emplace_back("imu_turn_deg", Num(imu_turn_rad * 180 / std::numbers::pi));
    out.emplace_back("imu_landing_anticipation", Num(imu_landing_anticipation));
  }
  if (on(VariationFamily::kCsv)) {
    out.emplace_back("csv_comments", write.csv_comments ? "yes" : "no");
    out.emplace_back("csv_columns", write.csv_shuffled_columns ? "shuffled" : "as specified");
    out.emplace_back("csv_extra_column", write.csv_extra_column ? "yes" : "no");
  }
  return out;
}

}  // namespace trailmark

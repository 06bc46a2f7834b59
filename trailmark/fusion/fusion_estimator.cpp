// SPDX-License-Identifier: MIT
#include "trailmark/fusion/fusion_estimator.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "trailmark/integrity/consistency.h"

namespace trailmark::fusion {

bool FusionOptions::IsValid(std::string* why) const {
  auto fail = [why](const char* text) {
    if (why) *why = text;
    return false;
  };
  if (!(max_wait_s >= 0) || !std::isfinite(max_wait_s))
    return fail("fusion: max_wait_s must be >= 0");
  if (!(stale_s >= 0) || !std::isfinite(stale_s)) return fail("fusion: stale_s must be >= 0");
  if (!(follows_dr_m >= 0) || !std::isfinite(follows_dr_m))
    return fail("fusion: follows_dr_m must be >= 0");
  if (!(disagreement_probability > 0 && disagreement_probability < 1))
    return fail("fusion: need 0 < disagreement_probability < 1");
  if (!(predict_fraction >= 0) || !std::isfinite(predict_fraction))
    return fail("fusion: predict_fraction must be >= 0");
  if (!(predict_period_s > 0) || !std::isfinite(predict_period_s) || !(predict_baseline_s > 0) ||
      !std::isfinite(predict_baseline_s))
    return fail("fusion: predict_period_s and predict_baseline_s must be > 0");
  if (!(predict_speed_sigma_mps >= 0) || !std::isfinite(predict_speed_sigma_mps))
    return fail("fusion: predict_speed_sigma must be >= 0");
  if (!(hat_window_s >= 0) || !std::isfinite(hat_window_s))
    return fail("fusion: hat_window_s must be >= 0");
  return true;
}

const OptionTable<FusionOptions>& FusionOptionTable() {
  static const OptionTable<FusionOptions> table = [] {
    OptionTable<FusionOptions> t;
    t.Real("fusion.max_wait_s", &FusionOptions::max_wait_s, "s", OptionBounds::NonNegative(),
           "a fused row waits at most this long (mission time) for members behind it");
    t.Real("fusion.stale_s", &FusionOptions::stale_s, "s", OptionBounds::NonNegative(),
           "a member's estimate older than this at the step's time is left out");
    t.Real("fusion.follows_dr_m", &FusionOptions::follows_dr_m, "m", OptionBounds::NonNegative(),
           "a member within this rms of dead reckoning over the hat's window uses no evidence "
           "of its own for that agent and is left out there; 0: off");
    t.Real("fusion.disagreement_probability", &FusionOptions::disagreement_probability, "",
           OptionBounds::Inside(0, 1),
           "region (2-dof chi-square probability) a member's estimate must lie in around the "
           "fusion of the others");
    t.Real("fusion.hat_window_s", &FusionOptions::hat_window_s, "s", OptionBounds::NonNegative(),
           "time constant of each member's error variance estimated from pairwise differences "
           "(N-cornered hat; inflates members that claim less than that); 0: off");
    t.Real("fusion.hat_power", &FusionOptions::hat_power, "", OptionBounds::Positive(),
           "the hat's weights are 1/variance to this power (1: the minimum-variance "
           "combination of independent errors; larger: closer to the best member alone)");
    t.Flag("fusion.shared_evidence_to_owner", &FusionOptions::shared_evidence_to_owner,
           "where only two members count and one's evidence is all the other's (of lower "
           "static rank), the other alone");
    t.Choice("fusion.shared_evidence_members", &FusionOptions::shared_evidence_members,
             std::vector<std::pair<std::string, FusionOptions::SharedEvidence>>{
                 {"two", FusionOptions::SharedEvidence::kTwo},
                 {"all", FusionOptions::SharedEvidence::kAll},
                 {"witness", FusionOptions::SharedEvidence::kWitness}},
             "where shared_evidence_to_owner applies: two (only two members count), all (any "
             "count), witness (any count, the member left in the hat's differences)");
    t.Real("fusion.predict_fraction", &FusionOptions::predict_fraction, "",
           OptionBounds::NonNegative(),
           "between fused rows, predict an agent's estimate for at most this part of the "
           "interval behind the last one, at its velocity; 0: hold the last fused row (the step "
           "front end's view_period_s moves it on by default: with both, the view moves on from "
           "a row already ahead)");
    t.Real("fusion.predict_period_s", &FusionOptions::predict_period_s, "s",
           OptionBounds::Positive(), "at most one predicted row per agent this often");
    t.Real("fusion.predict_baseline_s", &FusionOptions::predict_baseline_s, "s",
           OptionBounds::Positive(),
           "the velocity from the fused row at least this long before the last one");
    t.Real("fusion.predict_speed_sigma", &FusionOptions::predict_speed_sigma_mps, "m/s",
           OptionBounds::NonNegative(), "a predicted row's covariance grows by (this x time)^2");
    t.Flag("fusion.hat_weights", &FusionOptions::hat_weights,
           "weigh the members' positions by the hat's variances once known (else by their "
           "covariances)");
    return t;
  }();
  return table;
}

/// Receives one member's estimates.
class FusionEstimator::MemberSink : public EstimateSink {
 public:
  MemberSink(FusionEstimator& fusion, std::size_t member) : fusion_(fusion), member_(member) {}
  void Add(const Estimate& e) override { fusion_.OnMemberEstimate(member_, e); }

 private:
  FusionEstimator& fusion_;
  std::size_t member_;
};

namespace {

PositionGaussian ToGaussian(const Estimate& e) {
  PositionGaussian g;
  g.mean_m = e.position_n.head<2>();
  g.cov_m2 << e.sxx, e.sxy, e.sxy, e.syy;
  return g;
}

bool IsAgent(const MissionInfo& info, const std::string& id) {
  const NodeInfo* n = info.Find(id);
  return n != nullptr && n->kind == NodeKind::kAgent;
}

/// The fused estimate of `inputs` (members' estimates of one node at one time): horizontal by
/// covariance intersection, height and floor from the members that give them, weighted alike.
Estimate Combine(const std::vector<Estimate>& inputs, const Intersection& ci) {
  Estimate out = inputs.front();
  out.position_n.head<2>() = ci.fused.mean_m;
  out.sxx = ci.fused.cov_m2(0, 0);
  out.sxy = ci.fused.cov_m2(0, 1);
  out.syy = ci.fused.cov_m2(1, 1);
  // Height: the same intersection in one dimension, over the members that estimate it.
  double info_z = 0.0, info_zz = 0.0;
  std::size_t best = 0;
  for (std::size_t i = 0; i < inputs.size(); ++i) {
    if (ci.weights[i] > ci.weights[best]) best = i;
    if (inputs[i].szz && *inputs[i].szz > 0) {
      info_zz += ci.weights[i] / *inputs[i].szz;
      info_z += ci.weights[i] * inputs[i].position_n.z() / *inputs[i].szz;
    }
  }
  if (info_zz > 0) {
    out.position_n.z() = info_z / info_zz;
    out.szz = 1.0 / info_zz;
  } else {
    out.position_n.z() = inputs[best].position_n.z();
    out.szz = inputs[best].szz;
  }
  out.floor = inputs[best].floor;
  for (std::size_t i = 0; !out.floor && i < inputs.size(); ++i) out.floor = inputs[i].floor;
  return out;
}

Intersection IntersectEstimates(const std::vector<Estimate>& inputs) {
  std::vector<PositionGaussian> g;
  g.reserve(inputs.size());
  for (const Estimate& e : inputs) g.push_back(ToGaussian(e));
  return Intersect(g);
}

/// Squared Mahalanobis distance of `a` from `b` under the sum of their covariances.
double Disagreement(const PositionGaussian& a, const PositionGaussian& b) {
  Mat2 s = a.cov_m2 + b.cov_m2;
  s.diagonal() = s.diagonal().cwiseMax(1e-6);
  const Vec2 d = a.mean_m - b.mean_m;
  return d.dot(s.inverse() * d);
}

}  // namespace

FusionEstimator::FusionEstimator(MissionInfo info, FusionOptions options,
                                 std::vector<FusionMember> members, std::vector<std::string> notes)
    : info_(std::move(info)),
      options_(options),
      members_(std::move(members)),
      member_notes_(std::move(notes)) {
  std::string why;
  if (!options_.IsValid(&why)) throw std::invalid_argument(why);
  if (members_.empty()) throw std::invalid_argument("fusion: no member estimator");
  gate_d2_ = integrity::ChiSquareQuantile(2, options_.disagreement_probability);
  agent_history_.resize(members_.size());
  for (const FusionMember& m : members_) active_.push_back(m.evidence.empty());
  seen_evidence_.resize(members_.size());
  measured_.resize(members_.size());
  static_latest_.resize(members_.size());
  for (std::size_t i = 0; i < members_.size(); ++i) {
    if (!members_[i].estimator) throw std::invalid_argument("fusion: member without estimator");
    sinks_.push_back(std::make_unique<MemberSink>(*this, i));
    summary_.members.push_back({members_[i].name});
  }
}

FusionEstimator::~FusionEstimator() = default;

void FusionEstimator::UseLevels(const LevelSource* levels) {
  for (FusionMember& m : members_) m.estimator->UseLevels(levels);
}

void FusionEstimator::StepsFromFootIns(const std::string& agent, bool foot_ins) {
  if (foot_ins) foot_ins_agents_.insert(agent);
  for (FusionMember& m : members_) m.estimator->StepsFromFootIns(agent, foot_ins);
}

bool FusionEstimator::FallbackFor(std::size_t m, const std::string& agent) const {
  return members_[m].fallback_only &&
         !(members_[m].full_with_foot_ins && foot_ins_agents_.count(agent) != 0);
}

std::vector<std::string> FusionEstimator::MemberNames() const {
  std::vector<std::string> out;
  for (const FusionMember& m : members_) out.push_back(m.name);
  return out;
}

void FusionEstimator::OnMemberEstimate(std::size_t member, const Estimate& e) {
  if (!active_[member]) return;  // it has seen none of its own evidence yet
  if (!e.position_n.allFinite() || !std::isfinite(e.sxx) || !std::isfinite(e.syy) ||
      !std::isfinite(e.sxy)) {
    return;  // a member's non-finite estimate never reaches the fusion
  }
  if (IsAgent(info_, e.id)) {
    std::deque<Estimate>& h = agent_history_[member][e.id];
    if (!h.empty() && e.t < h.back().t) return;  // out of order: the member's contract broken
    h.push_back(e);
    // A time already fused (a member that caught up late) is not fused again.
    const auto done = current_.find(e.id);
    if (done == current_.end() || e.t > done->second.t) {
      PendingTimes& pending = pending_[e.id];
      pending.times.insert(e.t);
      pending.Touch();
    } else if (const auto p = pending_.find(e.id); p != pending_.end()) {
      p->second.Touch();  // a member's latest changed: Due may change
    }
    // Keep what a pending row can still ask for.
    const TimeS keep_from = now_ - (options_.max_wait_s + options_.stale_s + 1.0);
    while (h.size() > 1 && h[1].t <= keep_from) h.pop_front();
  } else {
    static_latest_[member][e.id] = e;
    if (std::find(static_dirty_.begin(), static_dirty_.end(), e.id) == static_dirty_.end())
      static_dirty_.push_back(e.id);
  }
}

void FusionEstimator::Add(const MissionRow& row, EstimateSink& sink) {
  now_ = std::max(now_, RowTime(row));
  std::optional<std::string> error;
  const Stream stream = RowStream(row);
  for (std::size_t i = 0; i < members_.size(); ++i) {
    if (members_[i].evidence.Has(stream)) {
      active_[i] = true;
      seen_evidence_[i].Add(stream);
      std::unordered_set<std::string>& named = measured_[i];
      std::visit(
          [&named](const auto& r) {
            using R = std::decay_t<decltype(r)>;
            if constexpr (std::is_same_v<R, RssiPacket>) {
              named.insert(r.rx);
              named.insert(r.tx);
            } else if constexpr (std::is_same_v<R, RangeMeasurement> ||
                                 std::is_same_v<R, BearingMeasurement>) {
              named.insert(r.a);
              named.insert(r.b);
            }
          },
          row);
    }
    try {
      members_[i].estimator->Add(row, *sinks_[i]);
    } catch (const std::invalid_argument& e) {
      if (!error) error = e.what();
    }
  }
  if (const Step* step = std::get_if<Step>(&row); step != nullptr && IsAgent(info_, step->agent)) {
    PendingTimes& pending = pending_[step->agent];
    pending.times.insert(step->t1);
    pending.Touch();
    auto& steps = steps_[step->agent];
    steps.emplace_back(step->t0, step->t1);
    const TimeS keep_from = now_ - (options_.max_wait_s + options_.hat_window_s + 10.0);
    while (steps.size() > 1 && steps.front().second < keep_from) steps.pop_front();
  }
  for (const std::string& node : static_dirty_) EmitStatic(node, now_, sink);
  static_dirty_.clear();
  Resolve(sink, false);
  if (options_.predict_fraction > 0) Predict(sink);
  if (error) throw std::invalid_argument(*error);
}

void FusionEstimator::Finish(EstimateSink& sink) {
  for (std::size_t i = 0; i < members_.size(); ++i) members_[i].estimator->Finish(*sinks_[i]);
  for (const std::string& node : static_dirty_) EmitStatic(node, now_, sink);
  static_dirty_.clear();
  Resolve(sink, true);
}

std::vector<SourceShare> FusionEstimator::Sources(const std::string& node) const {
  const auto it = sources_.find(node);
  if (it == sources_.end()) return {};
  return it->second;
}

std::optional<Mat2> FusionEstimator::StepTransform(const std::string& agent) const {
  const auto it = sources_.find(agent);
  if (it == sources_.end()) return std::nullopt;
  const SourceShare* top = nullptr;
  for (const SourceShare& s : it->second) {
    if (top == nullptr || s.weight > top->weight) top = &s;
  }
  if (top == nullptr) return std::nullopt;
  for (const FusionMember& m : members_) {
    if (m.name == top->source) return m.estimator->StepTransform(agent);
  }
  return std::nullopt;
}

std::optional<Estimate> FusionEstimator::Current(const std::string& node) const {
  const auto it = current_.find(node);
  if (it == current_.end()) return std::nullopt;
  return it->second;
}

bool FusionEstimator::Due(const Pending& p, TimeS* blocking_latest) const {
  if (now_ > p.t + options_.max_wait_s) return true;
  bool due = true;
  for (std::size_t m = 0; m < members_.size(); ++m) {
    const auto it = agent_history_[m].find(p.agent);
    if (it == agent_history_[m].end() || it->second.empty()) continue;  // does not estimate it
    const TimeS latest = it->second.back().t;
    // A member that has fallen behind by more than the wait is not waited for.
    if (latest < p.t - 1e-9 && latest >= now_ - options_.max_wait_s) {
      if (blocking_latest == nullptr) return false;
      *blocking_latest = due ? latest : std::min(*blocking_latest, latest);
      due = false;
    }
  }
  return due;
}

void FusionEstimator::Resolve(EstimateSink& sink, bool all) {
  for (auto& [agent, pending] : pending_) {
    std::set<TimeS>& times = pending.times;
    if (times.empty()) continue;
    // Nothing of the agent changed since its first time was found waiting: it stays waiting
    // until a member it waits for falls behind or the wait ends (Due, without its look-ups).
    if (!all && !(now_ - options_.max_wait_s > pending.blocked_until_behind) &&
        !(now_ > *times.begin() + options_.max_wait_s)) {
      continue;
    }
    pending.Touch();
    while (!times.empty()) {
      const Pending p{agent, *times.begin()};
      if (!all && !Due(p, &pending.blocked_until_behind)) break;
      EmitAgent(p, sink);
      times.erase(times.begin());
    }
  }
}

std::optional<Estimate> FusionEstimator::MemberAt(std::size_t member, const std::string& agent,
                                                  TimeS t) const {
  const auto it = agent_history_[member].find(agent);
  if (it == agent_history_[member].end()) return std::nullopt;
  const std::deque<Estimate>& h = it->second;
  // The first estimate at or after t, and the one before it.
  auto next = std::lower_bound(h.begin(), h.end(), t - 1e-9,
                               [](const Estimate& e, TimeS v) { return e.t < v; });
  if (next != h.end() && next->t <= t + 1e-9) return *next;
  if (next == h.begin()) return std::nullopt;  // the member starts later
  const Estimate& prev = *std::prev(next);
  if (next != h.end()) {
    // Between two of its estimates: linear in time (position and covariance).
    const double a = (t - prev.t) / (next->t - prev.t);
    Estimate e = prev;
    e.t = t;
    e.position_n = (1 - a) * prev.position_n + a * next->position_n;
    e.sxx = (1 - a) * prev.sxx + a * next->sxx;
    e.sxy = (1 - a) * prev.sxy + a * next->sxy;
    e.syy = (1 - a) * prev.syy + a * next->syy;
    if (prev.szz && next->szz) e.szz = (1 - a) * *prev.szz + a * *next->szz;
    if (t - prev.t > options_.stale_s && next->t - t > options_.stale_s &&
        MovedBetween(agent, prev.t, next->t))
      return std::nullopt;
    return e;
  }
  if (t - prev.t > options_.stale_s && MovedBetween(agent, prev.t, t)) return std::nullopt;
  return prev;
}

bool FusionEstimator::MovedBetween(const std::string& agent, TimeS from, TimeS to) const {
  const auto it = steps_.find(agent);
  if (it == steps_.end()) return true;  // no steps known: time is all there is
  for (auto s = it->second.rbegin(); s != it->second.rend(); ++s) {
    if (s->second <= from + 1e-9) return false;  // steps end in time order
    if (s->first < to - 1e-9) return true;
  }
  return false;
}

void FusionEstimator::Note(TimeS t, const std::string& agent, std::size_t member, bool excluded,
                           double d2) {
  constexpr std::size_t kMaxNotes = 100;
  if (notes_.size() >= kMaxNotes) {
    ++notes_dropped_;
    return;
  }
  IntegrityNote n;
  n.t = t;
  n.source = members_[member].name;
  n.node = agent;
  n.action = excluded ? "excluded" : "readmitted";
  n.message = excluded ? fmt::format(
                             "fusion: {}'s estimate of {} disagrees with the other "
                             "members most (largest pairwise d2 {:.1f} > {:.1f}); left out",
                             members_[member].name, agent, d2, gate_d2_)
                       : fmt::format(
                             "fusion: {}'s estimate of {} agrees with the other members "
                             "again; used",
                             members_[member].name, agent);
  notes_.push_back(std::move(n));
}

void FusionEstimator::EmitAgent(const Pending& p, EstimateSink& sink) {
  std::vector<std::size_t> used;
  std::vector<Estimate> inputs;
  for (const bool fallback : {false, true}) {
    for (std::size_t m = 0; m < members_.size(); ++m) {
      if (FallbackFor(m, p.agent) != fallback) continue;
      if (std::optional<Estimate> e = MemberAt(m, p.agent, p.t)) {
        used.push_back(m);
        inputs.push_back(*e);
      } else if (agent_history_[m].count(p.agent) != 0) {
        ++summary_.members[m].stale;
      }
    }
    if (!inputs.empty()) break;  // the fallback only where no other member estimates
  }
  if (inputs.empty()) return;
  // Leaves out the members marked in `drop`, counting each in the summary's `count` field.
  auto leave_out = [&](const std::vector<bool>& drop, long long FusionMemberSummary::*count) {
    std::vector<std::size_t> keep_used;
    std::vector<Estimate> keep_inputs;
    for (std::size_t i = 0; i < inputs.size(); ++i) {
      if (drop[i]) {
        ++(summary_.members[used[i]].*count);
        continue;
      }
      keep_used.push_back(used[i]);
      keep_inputs.push_back(inputs[i]);
    }
    used = std::move(keep_used);
    inputs = std::move(keep_inputs);
  };
  if (options_.follows_dr_m > 0 && !FallbackFor(used.front(), p.agent)) {
    // Dead reckoning at t (a fallback member), and each member's time-averaged distance from
    // it: a member that stays with it uses no evidence of its own for this agent.
    std::optional<Estimate> dr;
    for (std::size_t m = 0; m < members_.size() && !dr; ++m)
      if (members_[m].fallback_only) dr = MemberAt(m, p.agent, p.t);
    if (dr) {
      TimeS& last = from_dr_t_[p.agent];
      // The hat's window (its default where the hat is off).
      const double window_s =
          options_.hat_window_s > 0 ? options_.hat_window_s : FusionOptions{}.hat_window_s;
      const double fade = std::exp(-std::max(0.0, p.t - last) / window_s);
      last = p.t;
      std::vector<bool> follows(inputs.size(), false);
      std::size_t own = 0;  // members with evidence of their own here
      for (std::size_t i = 0; i < inputs.size(); ++i) {
        if (members_[used[i]].fallback_only) continue;  // dead reckoning itself, a full member
        auto& avg = from_dr_[{p.agent, used[i]}];
        avg.first = avg.first * fade + 1.0;
        avg.second += ((inputs[i].position_n.head<2>() - dr->position_n.head<2>()).squaredNorm() -
                       avg.second) /
                      avg.first;
        follows[i] =
            avg.first >= 10.0 && avg.second < options_.follows_dr_m * options_.follows_dr_m;
        own += !follows[i];
      }
      // Left out only where two or more others use evidence of their own (they can then be
      // compared with each other); beside a single one, the member that stays with dead
      // reckoning is dead reckoning's voice, which may be the right one.
      if (own >= 2) leave_out(follows, &FusionMemberSummary::follows_dr);
    }
  }
  auto covered = [&](std::size_t a, std::size_t b) {  // a's evidence seen is b's, b ranks first
    const StreamSet seen = seen_evidence_[a];
    if (seen.empty() || members_[b].static_rank >= members_[a].static_rank) return false;
    for (Stream st : seen.List())
      if (!members_[b].evidence.Has(st)) return false;
    return true;
  };
  using SE = FusionOptions::SharedEvidence;
  // Members that give way to another built for their evidence but stay in the hat (kWitness).
  std::vector<bool> witness;
  if (options_.shared_evidence_to_owner && inputs.size() == 2 && !FallbackFor(used[0], p.agent)) {
    // Two members reading the same evidence: the one built for it (lower static rank) alone.
    for (std::size_t k = 0; k < 2; ++k) {
      if (covered(used[k], used[1 - k])) {
        ++summary_.members[used[k]].shared_evidence;
        used = {used[1 - k]};
        inputs = {inputs[1 - k]};
        break;
      }
    }
  } else if (options_.shared_evidence_to_owner && options_.shared_evidence_members != SE::kTwo &&
             inputs.size() > 2 && !FallbackFor(used[0], p.agent)) {
    std::vector<bool> gives_way(inputs.size(), false);
    for (std::size_t a = 0; a < inputs.size(); ++a)
      for (std::size_t b = 0; b < inputs.size() && !gives_way[a]; ++b)
        gives_way[a] = b != a && covered(used[a], used[b]);
    if (options_.shared_evidence_members == SE::kWitness) {
      witness = gives_way;
    } else {
      leave_out(gives_way, &FusionMemberSummary::shared_evidence);
    }
  }
  // Leave out a member while three remain and some pair of members disagrees: of the members of
  // pairs that disagree, the one whose disagreements with all others sum highest (the largest
  // normalized residual of RAIM's fault exclusion; a loose member agrees with everyone and
  // arbitrates between two confident ones that disagree).
  const std::size_t n = inputs.size();
  std::vector<PositionGaussian> g(n);
  for (std::size_t i = 0; i < n; ++i) g[i] = ToGaussian(inputs[i]);
  std::vector<double> pair_d2(n * n, 0.0);
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t j = i + 1; j < n; ++j)
      pair_d2[i * n + j] = pair_d2[j * n + i] = Disagreement(g[i], g[j]);
  std::vector<bool> out(n, false);
  std::vector<double> out_d2(n, 0.0);
  std::size_t remaining = n;
  if (!witness.empty()) {
    for (std::size_t i = 0; i < n; ++i) {
      out[i] = witness[i];
      remaining -= witness[i];
    }
  }
  while (remaining >= 3) {
    double worst_sum = -1.0;
    std::size_t worst_i = n;
    for (std::size_t i = 0; i < n; ++i) {
      if (out[i]) continue;
      double sum = 0.0, max_d2 = 0.0;
      for (std::size_t j = 0; j < n; ++j) {
        if (j == i || out[j]) continue;
        sum += pair_d2[i * n + j];
        max_d2 = std::max(max_d2, pair_d2[i * n + j]);
      }
      if (max_d2 > gate_d2_ && sum > worst_sum) {
        worst_sum = sum;
        worst_i = i;
      }
    }
    if (worst_i == n) break;
    double max_d2 = 0.0;
    for (std::size_t j = 0; j < n; ++j)
      if (j != worst_i && !out[j]) max_d2 = std::max(max_d2, pair_d2[worst_i * n + j]);
    out[worst_i] = true;
    out_d2[worst_i] = max_d2;
    --remaining;
  }
  // Members that claim less than their differences show are inflated before the intersection.
  const HatEstimate hat = UpdateHat(p.agent, p.t, used, inputs);
  const std::vector<double>& inflation = hat.inflation;
  for (std::size_t i = 0; i < n; ++i) {
    inputs[i].sxx *= inflation[i];
    inputs[i].sxy *= inflation[i];
    inputs[i].syy *= inflation[i];
  }
  std::vector<Estimate> kept;
  std::vector<std::size_t> kept_members;
  std::vector<double> kept_inflation;
  for (std::size_t i = 0; i < inputs.size(); ++i) {
    const auto key = std::make_pair(p.agent, used[i]);
    const bool was_out = excluded_[key];
    if (!witness.empty() && witness[i]) {
      ++summary_.members[used[i]].shared_evidence;
      continue;
    }
    if (out[i]) {
      ++summary_.members[used[i]].exclusions;
      if (!was_out) Note(p.t, p.agent, used[i], true, out_d2[i]);
    } else {
      kept.push_back(inputs[i]);
      kept_members.push_back(used[i]);
      kept_inflation.push_back(inflation[i]);
      if (was_out) Note(p.t, p.agent, used[i], false, 0.0);
    }
    excluded_[key] = out[i];
  }
  Intersection ci = IntersectEstimates(kept);
  Estimate fused = Combine(kept, ci);
  fused.t = p.t;
  fused.id = p.agent;
  if (options_.hat_weights && hat.variance_m2 && kept.size() >= 2) {
    // The minimum-variance combination under the hat's variances (floored: a variance the
    // differences cannot resolve is not taken as zero); the intersection's covariance grows
    // by the shift so that it still covers the estimate.
    std::vector<double> w;
    double sum = 0.0;
    for (std::size_t i = 0, k = 0; i < n; ++i) {
      if (out[i]) continue;
      const double stated = 0.5 * (kept[k].sxx + kept[k].syy) / inflation[i];
      const double v = std::max({(*hat.variance_m2)[i], 0.05 * stated, 1e-4});
      w.push_back(std::pow(1.0 / v, options_.hat_power));
      sum += w.back();
      ++k;
    }
    Vec2 mean = Vec2::Zero();
    for (std::size_t k = 0; k < kept.size(); ++k) {
      ci.weights[k] = w[k] / sum;
      mean += ci.weights[k] * kept[k].position_n.head<2>();
    }
    const Vec2 shift = mean - fused.position_n.head<2>();
    fused.position_n.head<2>() = mean;
    fused.sxx += shift.x() * shift.x();
    fused.sxy += shift.x() * shift.y();
    fused.syy += shift.y() * shift.y();
  }
  // The last two disagree: keep both, and grow the covariance to cover each of them.
  if (kept.size() == 2 && Disagreement(ToGaussian(kept[0]), ToGaussian(kept[1])) > gate_d2_) {
    Mat2 cov;
    cov << fused.sxx, fused.sxy, fused.sxy, fused.syy;
    for (const Estimate& e : kept) {
      const Vec2 d = e.position_n.head<2>() - fused.position_n.head<2>();
      cov += d * d.transpose();
    }
    fused.sxx = cov(0, 0);
    fused.sxy = cov(0, 1);
    fused.syy = cov(1, 1);
    ++summary_.grown_rows;
  }
  std::vector<SourceShare>& shares = sources_[p.agent];
  shares.clear();
  for (std::size_t i = 0; i < kept.size(); ++i)
    shares.push_back({members_[kept_members[i]].name, ci.weights[i]});
  for (std::size_t i = 0; i < kept.size(); ++i) {
    FusionMemberSummary& s = summary_.members[kept_members[i]];
    ++s.rows_used;
    s.weight_sum += ci.weights[i];
    s.inflation_sum += kept_inflation[i];
  }
  const auto prev = current_.find(p.agent);
  if (prev != current_.end() && fused.t < prev->second.t) fused.t = prev->second.t;
  current_[p.agent] = fused;
  ++summary_.agent_rows;
  auto& track = fused_track_[p.agent];
  track.emplace_back(fused.t, fused.position_n.head<2>());
  while (track.size() > 2 && track[1].first <= fused.t - 2.0 - options_.predict_baseline_s)
    track.pop_front();
  Written& written = last_written_t_[p.agent];
  written.t = std::max(written.t, fused.t);
  written.no_prediction = false;
  sink.Add(fused);
}

std::optional<Estimate> FusionEstimator::PredictedAt(const std::string& agent, TimeS t) const {
  const auto track = fused_track_.find(agent);
  const auto current = current_.find(agent);
  if (track == fused_track_.end() || track->second.size() < 2 || current == current_.end())
    return std::nullopt;
  const auto& [t1, p1] = track->second.back();
  if (current->second.t != t1) return std::nullopt;
  // The baseline: the latest fused row at least predict_baseline_s before the last.
  const std::pair<TimeS, Vec2>* base = nullptr;
  for (auto it = track->second.rbegin(); it != track->second.rend(); ++it) {
    if (it->first <= t1 - options_.predict_baseline_s) {
      base = &*it;
      break;
    }
  }
  if (base == nullptr) return std::nullopt;
  const double interval_s = t1 - base->first;
  const double ahead_s = t - t1;
  if (interval_s > 2.0 || ahead_s <= 0 || ahead_s > options_.predict_fraction * interval_s)
    return std::nullopt;
  Estimate e = current->second;
  e.t = t;
  e.position_n.head<2>() = p1 + (p1 - base->second) / interval_s * ahead_s;
  const double grow = std::pow(options_.predict_speed_sigma_mps * ahead_s, 2);
  e.sxx += grow;
  e.syy += grow;
  return e;
}

void FusionEstimator::Predict(EstimateSink& sink) {
  for (auto& [agent, written] : last_written_t_) {
    if (written.no_prediction || now_ < written.t + options_.predict_period_s - 1e-9) continue;
    if (const std::optional<Estimate> e = PredictedAt(agent, now_)) {
      written.t = now_;
      ++summary_.predicted_rows;
      sink.Add(*e);
    } else if (const auto track = fused_track_.find(agent); track != fused_track_.end() &&
                                                            !track->second.empty() &&
                                                            now_ > track->second.back().first) {
      // Past the last fused row, PredictedAt's reasons to refuse hold until the next one.
      written.no_prediction = true;
    }
  }
}

FusionEstimator::HatEstimate FusionEstimator::UpdateHat(const std::string& agent, TimeS t,
                                                        const std::vector<std::size_t>& members,
                                                        const std::vector<Estimate>& inputs) {
  const std::size_t n = inputs.size();
  HatEstimate out;
  out.inflation.assign(n, 1.0);
  if (options_.hat_window_s <= 0) return out;
  Hat& hat = hats_[agent];
  // Exponential forgetting in mission time: a row's weight is 1, older rows fade with tau.
  const double fade = std::exp(-std::max(0.0, t - hat.t) / options_.hat_window_s);
  hat.t = t;
  auto update = [fade](std::pair<double, double>& avg, double value) {
    avg.first = avg.first * fade + 1.0;
    avg.second += (value - avg.second) / avg.first;
  };
  for (std::size_t i = 0; i < n; ++i) {
    update(hat.stated[members[i]], 0.5 * (inputs[i].sxx + inputs[i].syy));
    for (std::size_t j = i + 1; j < n; ++j) {
      const double d2 =
          (inputs[i].position_n.head<2>() - inputs[j].position_n.head<2>()).squaredNorm();
      update(hat.pair[{members[i], members[j]}], 0.5 * d2);
    }
  }
  if (n < 3) return out;
  // Least squares of D_ij = s_i^2 + s_j^2 over the pairs present now: with S_i the sum of
  // member i's D_ij and T the sum of all, s_i^2 = (S_i - T / (n - 1)) / (n - 2) (the three-
  // cornered hat's (D_ij + D_ik - D_jk) / 2 for n = 3).
  constexpr double kMinWeight = 10.0;  // rows of history before a pair is trusted
  std::vector<double> s(n, 0.0);
  double total = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t j = i + 1; j < n; ++j) {
      const auto& avg = hat.pair[{members[i], members[j]}];
      if (avg.first < kMinWeight) return out;
      s[i] += avg.second;
      s[j] += avg.second;
      total += avg.second;
    }
  }
  const double nn = static_cast<double>(n);
  out.variance_m2.emplace(n, 0.0);
  for (std::size_t i = 0; i < n; ++i) {
    const double variance = std::max(0.0, (s[i] - total / (nn - 1.0)) / (nn - 2.0));
    (*out.variance_m2)[i] = variance;
    const double stated = hat.stated[members[i]].second;
    if (stated > 0) out.inflation[i] = std::max(1.0, variance / stated);
  }
  return out;
}

void FusionEstimator::EmitStatic(const std::string& node, TimeS t, EstimateSink& sink) {
  std::vector<Estimate> inputs;
  std::vector<std::string> input_names;
  TimeS latest = -1e300;
  // The members that estimate the node; of them, those that measured it when any did.
  std::vector<bool> candidate(members_.size(), false);
  bool any_measured = false;
  for (std::size_t m = 0; m < members_.size(); ++m) {
    if (static_latest_[m].count(node) == 0) continue;
    candidate[m] = true;
    any_measured = any_measured || measured_[m].count(node) != 0;
  }
  int best_rank = std::numeric_limits<int>::max();
  for (std::size_t m = 0; m < members_.size(); ++m) {
    if (candidate[m] && (!any_measured || measured_[m].count(node) != 0))
      best_rank = std::min(best_rank, members_[m].static_rank);
  }
  for (std::size_t m = 0; m < members_.size(); ++m) {
    const auto it = static_latest_[m].find(node);
    if (it == static_latest_[m].end() || members_[m].static_rank != best_rank) continue;
    if (any_measured && measured_[m].count(node) == 0) continue;
    inputs.push_back(it->second);
    input_names.push_back(members_[m].name);
    latest = std::max(latest, it->second.t);
  }
  if (inputs.empty()) return;
  const Intersection ci = IntersectEstimates(inputs);
  Estimate fused = Combine(inputs, ci);
  fused.id = node;
  std::vector<SourceShare>& shares = sources_[node];
  shares.clear();
  for (std::size_t i = 0; i < inputs.size(); ++i) shares.push_back({input_names[i], ci.weights[i]});
  fused.t = std::min(t, latest);
  const auto prev = current_.find(node);
  if (prev != current_.end()) fused.t = std::max(fused.t, prev->second.t);
  current_[node] = fused;
  ++summary_.static_rows;
  sink.Add(fused);
}

EstimatorSummary FusionEstimator::Summary() const {
  EstimatorSummary out;
  for (const FusionMember& m : members_) {
    const EstimatorSummary s = m.estimator->Summary();
    for (const auto& [key, value] : s.numbers) out.numbers[m.name + "." + key] = value;
    for (const std::string& note : s.notes) out.notes.push_back(m.name + ": " + note);
    for (IntegrityNote n : s.integrity) {
      n.source = m.name + ": " + n.source;
      out.integrity.push_back(std::move(n));
    }
  }
  out.numbers["fusion.agent_rows"] = static_cast<double>(summary_.agent_rows);
  out.numbers["fusion.static_rows"] = static_cast<double>(summary_.static_rows);
  out.numbers["fusion.grown_rows"] = static_cast<double>(summary_.grown_rows);
  out.numbers["fusion.predicted_rows"] = static_cast<double>(summary_.predicted_rows);
  out.numbers["fusion.members"] = static_cast<double>(members_.size());
  for (const FusionMemberSummary& s : summary_.members) {
    const double rows = static_cast<double>(std::max<long long>(summary_.agent_rows, 1));
    out.numbers["fusion." + s.name + ".used_share"] = static_cast<double>(s.rows_used) / rows;
    out.numbers["fusion." + s.name + ".mean_weight"] =
        s.rows_used > 0 ? s.weight_sum / static_cast<double>(s.rows_used) : 0.0;
    out.numbers["fusion." + s.name + ".exclusions"] = static_cast<double>(s.exclusions);
    out.numbers["fusion." + s.name + ".follows_dr_rows"] = static_cast<double>(s.follows_dr);
    out.numbers["fusion." + s.name + ".shared_evidence_rows"] =
        static_cast<double>(s.shared_evidence);
    out.numbers["fusion." + s.name + ".mean_inflation"] =
        s.rows_used > 0 ? s.inflation_sum / static_cast<double>(s.rows_used) : 1.0;
  }
  out.notes.push_back(
      fmt::format("fusion of {} member(s): {}", members_.size(), fmt::join(MemberNames(), ", ")));
  for (const std::string& note : member_notes_) out.notes.push_back("fusion: " + note);
  for (const IntegrityNote& n : notes_) out.integrity.push_back(n);
  if (notes_dropped_ > 0) {
    out.notes.push_back(
        fmt::format("fusion: {} further exclusion notes not listed", notes_dropped_));
  }
  return out;
}

}  // namespace trailmark::fusion

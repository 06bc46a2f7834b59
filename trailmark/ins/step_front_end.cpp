// SPDX-License-Identifier: MIT
#include "trailmark/ins/step_front_end.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace trailmark {

bool StepFrontEndOptions::IsValid(std::string* why) const {
  if (!ins.IsValid(why) || !height.IsValid(why)) return false;
  if (!(reorder_s >= 0)) {
    if (why) *why = "reorder_s must be >= 0";
    return false;
  }
  if (!(view_period_s == 0 || (view_period_s >= 0.01 && std::isfinite(view_period_s)))) {
    if (why) *why = "view_period_s must be 0 or at least 0.01 s";
    return false;
  }
  if (!(foot_offset_along_sigma_m >= 0) || !std::isfinite(foot_offset_along_sigma_m) ||
      !(foot_offset_across_sigma_m >= 0) || !std::isfinite(foot_offset_across_sigma_m)) {
    if (why)
      *why = "foot_offset_along_sigma_m and foot_offset_across_sigma_m must be finite and >= 0";
    return false;
  }
  if (!(view_speed_sigma >= 0) || !std::isfinite(view_speed_sigma)) {
    if (why) *why = "view_speed_sigma must be finite and >= 0";
    return false;
  }
  return true;
}

const OptionTable<StepFrontEndOptions>& StepSourceOptionTable() {
  static const OptionTable<StepFrontEndOptions> table = [] {
    OptionTable<StepFrontEndOptions> t;
    t.Include("ins.", &StepFrontEndOptions::ins, ins::InsOptionTable());
    t.Include("height.", &StepFrontEndOptions::height, HeightOptionTable());
    t.Real("foot_offset_along_sigma_m", &StepFrontEndOptions::foot_offset_along_sigma_m, "m",
           OptionBounds::NonNegative(),
           "an agent on foot-INS steps: the foot's distance from the walker along the walking "
           "direction, in the covariance of its estimates");
    t.Real("foot_offset_across_sigma_m", &StepFrontEndOptions::foot_offset_across_sigma_m, "m",
           OptionBounds::NonNegative(), "and across it");
    return t;
  }();
  return table;
}

const OptionTable<StepFrontEndOptions>& OrderedStepSourceOptionTable() {
  static const OptionTable<StepFrontEndOptions> table = [] {
    OptionTable<StepFrontEndOptions> t = StepSourceOptionTable();
    t.Real("reorder_s", &StepFrontEndOptions::reorder_s, "s", OptionBounds::NonNegative(),
           "live: the longest a row waits for older rows of other devices (estimates lag by "
           "the window)");
    t.Flag("ignore_steps_in_stops", &StepFrontEndOptions::ignore_steps_in_stops,
           "a steps.csv step that starts after the agent's declared stop (events.csv) and "
           "before its go is not motion: ignored and counted (a phone reads swaying as steps)");
    t.Flag("reorder_adaptive", &StepFrontEndOptions::reorder_adaptive,
           "live: the window is 2 x the feed's largest lateness of the last 20-30 s + 50 ms, "
           "at least 0.2 s, at most reorder_s, which it is for the first 10 s (false: always "
           "reorder_s; on: lower latency, a row late when a device falls further behind)");
    return t;
  }();
  return table;
}

const OptionTable<StepFrontEndOptions>& StepViewOptionTable() {
  static const OptionTable<StepFrontEndOptions> table = [] {
    OptionTable<StepFrontEndOptions> t;
    t.Real("view_period_s", &StepFrontEndOptions::view_period_s, "s", OptionBounds::NonNegative(),
           "between rows, an agent's estimate is written again this often, moved on at the walk's "
           "velocity (its last 0.5 s of steps, as the estimator turns them; at most a step "
           "ahead; 0: the estimator's own estimates only)");
    t.Real("view_speed_sigma", &StepFrontEndOptions::view_speed_sigma, "",
           OptionBounds::NonNegative(),
           "the view's sigma per axis, x the walk's speed x the time ahead of the last step's "
           "end");
    return t;
  }();
  return table;
}

void ReorderWindow::Observe(TimeS t, TimeS newest) {
  if (!std::isfinite(t)) return;
  if (std::isnan(first_)) first_ = t;
  newest_ = std::max({newest_, t, newest});
  const auto bucket = static_cast<std::int64_t>(std::floor((newest_ - first_) / kBucketS));
  if (bucket > bucket_) {
    const std::int64_t shift = std::min<std::int64_t>(bucket - bucket_, 3);
    for (std::int64_t k = 0; k < shift; ++k) {
      peak_[2] = peak_[1];
      peak_[1] = peak_[0];
      peak_[0] = 0;
    }
    bucket_ = bucket;
  }
  if (newest > t) peak_[0] = std::max(peak_[0], newest - t);
}

double ReorderWindow::peak_lateness_s() const { return std::max({peak_[0], peak_[1], peak_[2]}); }

double ReorderWindow::seconds() const {
  if (std::isnan(first_) || newest_ - first_ < kWarmUpS) return cap_s_;
  return std::min(cap_s_, std::max(kFloorS, kMargin * peak_lateness_s() + kSlackS));
}

StepFrontEnd::StepFrontEnd(MissionInfo info, StepFrontEndOptions options, RowOrder order, Feed feed,
                           std::unique_ptr<OnlineEstimator> inner)
    : info_(info),
      options_(options),
      order_(order),
      feed_(feed),
      inner_(std::move(inner)),
      ins_(info, options.ins),
      height_(std::move(info), options.height),
      window_(options.reorder_s) {
  std::string why;
  if (!options_.IsValid(&why)) throw std::invalid_argument(why);
  inner_->UseLevels(&height_);
  ins_.on_step = [this](const Step& step) {
    ++ins_steps_;
    Deliver(step, *sink_);
  };
}

class StepFrontEnd::ViewRecordingSink : public EstimateSink {
 public:
  ViewRecordingSink(StepFrontEnd& front, EstimateSink& out) : front_(front), out_(out) {}
  void Add(const Estimate& inner) override {
    Estimate estimate = inner;
    front_.AddFootOffset(estimate);
    out_.Add(estimate);
    if (front_.options_.view_period_s <= 0) return;
    const auto it = front_.views_.find(estimate.id);
    if (it == front_.views_.end()) return;  // not an agent
    it->second.inner = estimate;
    it->second.out_t = std::max(it->second.out_t, estimate.t);
    front_.next_view_t_ =
        std::min(front_.next_view_t_, it->second.out_t + front_.options_.view_period_s);
  }

 private:
  StepFrontEnd& front_;
  EstimateSink& out_;
};

void StepFrontEnd::EmitViews(View& v, TimeS t, EstimateSink& sink) {
  constexpr double kTolS = 1e-9;
  // The estimate must know the last step (a steps-based estimate is where its last step ended).
  if (!v.inner || v.recent.empty()) return;
  const TimeS step_t1 = v.recent.back().t1;  // the last step's end
  if (v.inner->t < step_t1 - kTolS) return;
  const double step_s = v.step_s;
  std::optional<Vec2> velocity_n;  // the walk's, as the estimator turns and scales its steps
  for (TimeS tk = v.out_t + options_.view_period_s; tk < t - kTolS;
       tk = v.out_t + options_.view_period_s) {
    Estimate e = *v.inner;
    e.t = tk;
    const double ahead = tk - step_t1;
    if (tk < v.stopped_t && ahead <= StepFrontEndOptions::kViewStoppedSteps * step_s) {
      if (!velocity_n) {
        const std::optional<Mat2> m = inner_->StepTransform(v.agent);
        velocity_n = m ? Vec2(*m * v.velocity_n) : v.velocity_n;
      }
      const double a = std::clamp(ahead, 0.0, step_s);
      e.position_n.head<2>() += *velocity_n * a;
      const double s = options_.view_speed_sigma * velocity_n->norm() * a;
      e.sxx += s * s;
      e.syy += s * s;
    }
    sink.Add(e);
    v.out_t = tk;
    ++view_rows_;
  }
}

bool StepFrontEnd::UseSource(const std::string& agent, bool imu) {
  // Every IMU sample asks: an agent seen before is answered from its source, without a search
  // of the mission's nodes (hundreds with a beacon trail's).
  if (const auto seen = source_is_imu_.find(agent); seen != source_is_imu_.end()) {
    if (seen->second == imu) return true;
    ++ignored_;
    return false;
  }
  const NodeInfo* node = info_.Find(agent);
  if (node == nullptr || node->kind != NodeKind::kAgent) {
    throw std::invalid_argument(fmt::format("'{}' has {} but is not an agent in mission.json",
                                            agent, imu ? "IMU samples" : "steps"));
  }
  source_is_imu_.emplace(agent, imu);
  inner_->StepsFromFootIns(agent, imu);
  return true;
}

namespace {
/// A step at least this long (m) says which way the walker walks.
constexpr double kMovedM = 0.05;
}  // namespace

void StepFrontEnd::Pass(const MissionRow& row, EstimateSink& sink) {
  if (options_.ignore_steps_in_stops && order_ == RowOrder::kGlobal) {
    // Rows come here in time order: a declared stop holds until the agent's go.
    if (const auto* e = std::get_if<MissionEvent>(&row)) {
      if (e->event == "stop") stopped_.try_emplace(e->agent, DeclaredStop{e->t, 0});
      if (e->event == "go") stopped_.erase(e->agent);
    } else if (const auto* step = std::get_if<Step>(&row)) {
      const auto stop = stopped_.find(step->agent);
      const auto source = source_is_imu_.find(step->agent);  // a lookup, never an insertion
      const bool from_foot_ins = source != source_is_imu_.end() && source->second;
      if (stop != stopped_.end() && step->t0 >= stop->second.since && !from_foot_ins) {
        if (stop->second.steps < StepFrontEndOptions::kMaxStepsInStop) {
          ++stop->second.steps;
          ++steps_in_stops_;
          return;
        }
        stopped_.erase(stop);  // more steps than a sway: walking, the go was never sent
        ++stops_without_go_;
      }
    }
  }
  const Step* step = std::get_if<Step>(&row);
  if (options_.view_period_s > 0) {
    // The view between rows, from the rows before this one: in global order every agent's
    // (no earlier row can come); in each agent's order its own, before its next step.
    const TimeS t = RowTime(row);
    if (order_ == RowOrder::kGlobal) {
      // Only once some agent's view can be due (a lower bound of every agent's next tick):
      // an incident's rows are many more than its agents' ticks.
      if (t > next_view_t_) {
        next_view_t_ = std::numeric_limits<double>::infinity();
        for (auto& [agent, v] : views_) {
          EmitViews(v, t, sink);
          next_view_t_ = std::min(next_view_t_, v.out_t + options_.view_period_s);
        }
      }
    } else if (step != nullptr) {
      if (const auto it = views_.find(step->agent); it != views_.end())
        EmitViews(it->second, t, sink);
    }
    if (const auto* event = std::get_if<MissionEvent>(&row);
        event != nullptr && event->event == "stop" && order_ == RowOrder::kGlobal) {
      // A declared stop (in global order, where no later row of the agent came before it):
      // the walker stands where the last step ended.
      if (const auto it = views_.find(event->agent); it != views_.end())
        it->second.stopped_t = event->t;
    }
    if (step != nullptr) {
      View& v = views_[step->agent];
      v.agent = step->agent;
      // A stop declared before this step began is over; one within it or at its end (events
      // come before steps of the same time) holds from then.
      if (v.stopped_t < step->t0) v.stopped_t = std::numeric_limits<double>::infinity();
      if (!v.recent.empty() &&
          step->t0 > v.recent.back().t1 + StepFrontEndOptions::kViewContiguousS)
        v.recent.clear();  // it stood between: the walk starts again
      v.recent.push_back({step->t0, step->t1, step->delta_n.head<2>()});
      while (v.recent.size() > 1 &&
             v.recent.back().t1 - v.recent[1].t0 >= StepFrontEndOptions::kViewBaselineS)
        v.recent.pop_front();
      Vec2 sum = Vec2::Zero();
      v.step_s = 0;
      for (const auto& r : v.recent) {
        sum += r.delta_n;
        v.step_s = std::max(v.step_s, r.t1 - r.t0);
      }
      const double span = v.recent.back().t1 - v.recent.front().t0;
      v.velocity_n = span > 1e-6 ? Vec2(sum / span) : Vec2::Zero();
    }
  }
  if (step != nullptr) {
    const auto source = source_is_imu_.find(step->agent);
    const Vec2 d = step->delta_n.head<2>();
    if (source != source_is_imu_.end() && source->second && d.norm() > kMovedM) {
      walking_direction_[step->agent] = d.normalized();
    }
  }
  height_.Add(row);
  ViewRecordingSink recorded(*this, sink);
  HeightAnnotatingSink annotated(height_, recorded);
  inner_->Add(row, annotated);
}

void StepFrontEnd::Deliver(const MissionRow& row, EstimateSink& sink) {
  if (order_ == RowOrder::kPerAgent) {
    Pass(row, sink);
  } else {
    buffer_.Push(row);
  }
}

void StepFrontEnd::Release(EstimateSink& sink) {
  const bool live = feed_ == Feed::kLive;
  const double wait_s = options_.reorder_adaptive ? window_.seconds() : options_.reorder_s;
  TimeS until = live ? newest_ - wait_s : newest_;
  if (const auto b = ins_.EarliestNextStepEndOfActive(live ? until : -1e300)) {
    until = std::min(until, *b);
  }
  buffer_.ReleaseBefore(until, [&](const MissionRow& r) { Pass(r, sink); });
}

void StepFrontEnd::Add(const MissionRow& row, EstimateSink& sink) {
  sink_ = &sink;
  if (feed_ == Feed::kLive && order_ == RowOrder::kGlobal) window_.Observe(RowTime(row), newest_);
  newest_ = std::max(newest_, RowTime(row));
  if (const auto* imu = std::get_if<ImuSample>(&row)) {
    if (UseSource(imu->agent, true)) ins_.Add(*imu);
  } else if (const auto* step = std::get_if<Step>(&row)) {
    if (UseSource(step->agent, false)) Deliver(row, sink);
  } else {
    Deliver(row, sink);
  }
  if (order_ == RowOrder::kGlobal) Release(sink);
}

void StepFrontEnd::Finish(EstimateSink& sink) {
  sink_ = &sink;
  ins_.Finish();
  buffer_.ReleaseAll([&](const MissionRow& r) { Pass(r, sink); });
  ViewRecordingSink recorded(*this, sink);
  HeightAnnotatingSink annotated(height_, recorded);
  inner_->Finish(annotated);
}

std::optional<Estimate> StepFrontEnd::Current(const std::string& node) const {
  std::optional<Estimate> e = inner_->Current(node);
  if (e) {
    height_.Annotate(*e);
    AddFootOffset(*e);
  }
  return e;
}

void StepFrontEnd::AddFootOffset(Estimate& e) const {
  const auto it = source_is_imu_.find(e.id);
  if (it == source_is_imu_.end() || !it->second) return;
  const double along = options_.foot_offset_along_sigma_m * options_.foot_offset_along_sigma_m;
  const double across = options_.foot_offset_across_sigma_m * options_.foot_offset_across_sigma_m;
  const auto d = walking_direction_.find(e.id);
  if (d == walking_direction_.end()) {  // no step yet: either way
    e.sxx += along;
    e.syy += along;
    return;
  }
  // along u u^T + across (I - u u^T)
  const Vec2& u = d->second;
  e.sxx += across + (along - across) * u.x() * u.x();
  e.sxy += (along - across) * u.x() * u.y();
  e.syy += across + (along - across) * u.y() * u.y();
}

EstimatorSummary StepFrontEnd::Summary() const {
  EstimatorSummary s = inner_->Summary();
  const auto agents = ins_.Agents();
  if (!agents.empty()) {
    const EstimatorSummary ins = ins_.Summary();
    for (const auto& id : agents) {
      for (const char* key : {".steps", ".mount_yaw_turned_deg", ".mount_yaw_landings",
                              ".mount_yaw_by_bounds", ".mount_yaw_by_gait", ".zaru_recoveries"}) {
        const auto it = ins.numbers.find(id + key);
        if (it != ins.numbers.end()) s.numbers["ins." + id + key] = it->second;
      }
    }
    for (const auto& note : ins.notes) {
      if (note.rfind("detector: ", 0) != 0) s.notes.push_back("ins " + note);
    }
    s.notes.push_back(
        fmt::format("steps from imu.csv through the ZUPT INS ({} steps)", ins_steps_));
  }
  height_.AddToSummary(s);
  s.numbers["rows_ignored"] += static_cast<double>(ignored_);
  if (options_.view_period_s > 0) s.numbers["view_rows"] = static_cast<double>(view_rows_);
  if (order_ == RowOrder::kGlobal) {
    if (options_.ignore_steps_in_stops) {
      s.numbers["steps_in_declared_stops"] = static_cast<double>(steps_in_stops_);
      if (steps_in_stops_ > 0) {
        s.notes.push_back(fmt::format(
            "{} steps of steps.csv started during a declared stop (events.csv stop .. go): not "
            "motion, ignored (ignore_steps_in_stops)",
            steps_in_stops_));
      }
      if (stops_without_go_ > 0) {
        s.notes.push_back(fmt::format(
            "{} declared stop(s) without a go: more than {} steps followed, taken as walking",
            stops_without_go_, StepFrontEndOptions::kMaxStepsInStop));
      }
    }
    s.numbers["rows_late"] = static_cast<double>(buffer_.late());
    s.numbers["rows_waiting"] = static_cast<double>(buffer_.size());
    if (feed_ == Feed::kLive) {
      s.numbers["reorder_s"] = options_.reorder_s;
      s.numbers["reorder_window_s"] =
          options_.reorder_adaptive ? window_.seconds() : options_.reorder_s;
      s.numbers["reorder_peak_lateness_s"] = window_.peak_lateness_s();
    }
  }
  return s;
}

}  // namespace trailmark

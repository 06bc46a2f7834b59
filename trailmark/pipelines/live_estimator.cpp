#include "trailmark/pipelines/live_estimator.h"

#include <fmt/format.h>

#include <stdexcept>
#include <tuple>

#include "trailmark/pipelines/breadcrumb_pipeline.h"
#include "trailmark/pipelines/ins_pipeline.h"
#include "trailmark/pipelines/live_ins.h"
#include "trailmark/pipelines/mapmatch_pipeline.h"
#include "trailmark/pipelines/merged_stream.h"
#include "trailmark/pipelines/pdr_pipeline.h"
#include "trailmark/pipelines/pipeline_options.h"
#include "trailmark/pipelines/step_source.h"

namespace trailmark {

const std::string& RowNode(const LiveRow& row) {
  struct {
    const std::string& operator()(const ImuSample& r) const { return r.agent; }
    const std::string& operator()(const Step& r) const { return r.agent; }
    const std::string& operator()(const RssiPacket& r) const { return r.rx; }
    const std::string& operator()(const RangeMeasurement& r) const { return r.a; }
    const std::string& operator()(const BearingMeasurement& r) const { return r.a; }
    const std::string& operator()(const MissionEvent& r) const { return r.agent; }
  } node;
  return std::visit(node, row);
}

TimeS RowTime(const LiveRow& row) { return std::visit(RowTimeOf{}, row); }

namespace {

const NodeInfo& RequireAgent(const MissionInfo& info, const std::string& id, const char* what) {
  const NodeInfo* node = info.Find(id);
  if (node == nullptr || node->kind != NodeKind::kAgent) {
    throw std::invalid_argument(
        fmt::format("'{}' has {} but is not an agent in mission.json", id, what));
  }
  return *node;
}

/// Each agent's steps come from its steps rows or from its IMU samples through the INS:
/// whichever arrives first is its source; rows of the other kind are ignored and counted.
class StepSourceChoice {
 public:
  enum Kind { kSteps, kImu };
  bool Use(const std::string& agent, Kind kind) {
    const auto [it, first] = source_.emplace(agent, kind);
    if (it->second == kind) return true;
    ++ignored_;
    return false;
  }
  std::size_t ignored() const { return ignored_; }

 private:
  std::map<std::string, Kind> source_;
  std::size_t ignored_ = 0;
};

/// `pdr` live: each agent's steps (from steps rows, or from its IMU samples through the INS:
/// whichever arrives first is the agent's source) added to its start.
class LivePdr : public LiveEstimator {
 public:
  LivePdr(const MissionInfo& info, const std::map<std::string, std::string>& options)
      : info_(info), ins_(info, InsOnly(options)) {
    ins_.on_step = [this](const Step& step) { AddStep(step, *sink_); };
  }

  void Add(const LiveRow& row, EstimateSink& sink) override {
    sink_ = &sink;
    if (const auto* step = std::get_if<Step>(&row)) {
      if (source_.Use(step->agent, StepSourceChoice::kSteps)) AddStep(*step, sink);
    } else if (const auto* imu = std::get_if<ImuSample>(&row)) {
      if (source_.Use(imu->agent, StepSourceChoice::kImu)) ins_.Add(*imu, nullptr);
    } else {
      ++ignored_;
    }
  }

  PipelineSummary Summary() const override {
    PipelineSummary s = ins_.Summary();
    s.numbers["steps"] = static_cast<double>(steps_);
    s.numbers["rows_ignored"] = static_cast<double>(ignored_ + source_.ignored());
    s.numbers["agents"] = static_cast<double>(agents_.size());
    return s;
  }

 private:
  static std::map<std::string, std::string> InsOnly(const std::map<std::string, std::string>& o) {
    const auto [ins, rest] = SplitInsOptions(o);
    PipelineOptions(rest, "pdr").RejectUnknown();
    return ins;
  }
  void AddStep(const Step& step, EstimateSink& sink) {
    auto it = agents_.find(step.agent);
    if (it == agents_.end()) {
      const NodeInfo& node = RequireAgent(info_, step.agent, "steps");
      const auto start = info_.AgentStart(node);
      if (!start) {
        throw std::invalid_argument(fmt::format(
            "agent '{}' has no 'start' in mission.json and the mission has no single base: pdr "
            "needs a known start",
            step.agent));
      }
      it = agents_.emplace(step.agent, DeadReckoning(*start, node.start_sigma_m.value_or(0.0)))
               .first;
      const Mat2& c = it->second.covariance();
      sink.Add({step.t0, step.agent, *start, c(0, 0), c(0, 1), c(1, 1)});
    }
    it->second.AddStep(step);
    ++steps_;
    const Mat2& c = it->second.covariance();
    sink.Add({step.t1, step.agent, it->second.position_n(), c(0, 0), c(0, 1), c(1, 1)});
  }

  const MissionInfo& info_;
  LiveIns ins_;
  EstimateSink* sink_ = nullptr;
  StepSourceChoice source_;
  std::map<std::string, DeadReckoning> agents_;
  std::size_t steps_ = 0, ignored_ = 0;
};

/// `ins` live: the INS of each agent's IMU samples.
class LiveInsEstimator : public LiveEstimator {
 public:
  LiveInsEstimator(const MissionInfo& info, const std::map<std::string, std::string>& options)
      : ins_(info, options) {}
  void Add(const LiveRow& row, EstimateSink& sink) override {
    if (const auto* imu = std::get_if<ImuSample>(&row)) {
      ins_.Add(*imu, &sink);
    } else {
      ++ignored_;
    }
  }
  PipelineSummary Summary() const override {
    PipelineSummary s = ins_.Summary();
    s.numbers["rows_ignored"] = static_cast<double>(ignored_);
    return s;
  }

 private:
  LiveIns ins_;
  std::size_t ignored_ = 0;
};

/// `breadcrumb` live: the batch pipeline's session behind a reordering buffer. Devices deliver
/// their own rows in time order but not in step with each other; the localizer needs all rows
/// in time order. Rows wait until they are `reorder_s` older than the newest row seen, then go
/// in by (time, kind as the batch merges them, arrival); a row that comes later than that is
/// processed at once (counted as late). Estimates lag the data by reorder_s.
class LiveBreadcrumb : public LiveEstimator {
 public:
  LiveBreadcrumb(const MissionInfo& info, const std::map<std::string, std::string>& options)
      : info_(info),
        reorder_s_(ReorderOption(options)),
        ins_(info, SplitInsOptions(options).first),
        session_(info, WithoutReorder(SplitInsOptions(options).second), &notes_) {
    ins_.on_step = [this](const Step& step) { Buffer(step); };
  }

  void Add(const LiveRow& row, EstimateSink& sink) override {
    if (const auto* imu = std::get_if<ImuSample>(&row)) {
      if (source_.Use(imu->agent, StepSourceChoice::kImu)) ins_.Add(*imu, nullptr);
    } else if (const auto* step = std::get_if<Step>(&row)) {
      RequireAgent(info_, step->agent, "steps");
      if (source_.Use(step->agent, StepSourceChoice::kSteps)) Buffer(*step);
    } else if (const auto* p = std::get_if<RssiPacket>(&row)) {
      Buffer(*p);
    } else if (const auto* r = std::get_if<RangeMeasurement>(&row)) {
      Buffer(*r);
    } else if (const auto* e = std::get_if<MissionEvent>(&row)) {
      Buffer(*e);
    } else {
      ++ignored_;  // bearings: the breadcrumb localizer has no use for them
    }
    Release(newest_ - reorder_s_, sink);
  }

  PipelineSummary Summary() const override {
    PipelineSummary s = notes_;
    s.numbers["rows_ignored"] = static_cast<double>(ignored_ + source_.ignored());
    s.numbers["rows_late"] = static_cast<double>(late_);
    s.numbers["rows_waiting"] = static_cast<double>(buffer_.size());
    s.numbers["reorder_s"] = reorder_s_;
    return s;
  }

 private:
  using Key = std::tuple<TimeS, std::size_t, std::uint64_t>;  // time, kind, arrival
  static double ReorderOption(const std::map<std::string, std::string>& o) {
    std::map<std::string, std::string> only;
    if (const auto it = o.find("reorder_s"); it != o.end()) only.insert(*it);
    const double v = PipelineOptions(only, "breadcrumb").Double("reorder_s", 1.0);
    if (!(v >= 0)) throw std::invalid_argument("pipeline breadcrumb: reorder_s must be >= 0");
    return v;
  }
  static std::map<std::string, std::string> WithoutReorder(std::map<std::string, std::string> o) {
    o.erase("reorder_s");
    return o;
  }
  void Buffer(const MissionRow& row) {
    const TimeS t = RowTime(row);
    newest_ = std::max(newest_, t);
    if (t < released_) ++late_;
    buffer_.emplace(Key{t, row.index(), arrivals_++}, row);
  }
  void Release(TimeS until, EstimateSink& sink) {
    while (!buffer_.empty() && std::get<0>(buffer_.begin()->first) <= until) {
      const MissionRow row = std::move(buffer_.begin()->second);
      buffer_.erase(buffer_.begin());
      released_ = std::max(released_, RowTime(row));
      session_.Add(row, sink);
    }
  }

  const MissionInfo& info_;
  double reorder_s_;
  LiveIns ins_;
  PipelineSummary notes_;
  BreadcrumbSession session_;
  StepSourceChoice source_;
  std::map<Key, MissionRow> buffer_;
  std::uint64_t arrivals_ = 0;
  TimeS newest_ = -1e300, released_ = -1e300;
  std::size_t ignored_ = 0, late_ = 0;
};

/// `mapmatch` live: the batch pipeline's session, each agent's steps (or its IMU through the
/// INS) as they come; agents are independent, so no reordering is needed.
/// The session's options: `level` chose the floor `plan` already is (TakeMapMatchLevel checks
/// it is a whole number).
std::map<std::string, std::string> WithoutLevel(std::map<std::string, std::string> options) {
  TakeMapMatchLevel(options);
  return options;
}

class LiveMapMatch : public LiveEstimator {
 public:
  LiveMapMatch(const MissionInfo& info, const std::map<std::string, std::string>& options,
               const FloorPlan& plan)
      : ins_(info, SplitInsOptions(options).first),
        session_(info, plan, "the floor plan", WithoutLevel(SplitInsOptions(options).second),
                 notes_) {
    ins_.on_step = [this](const Step& step) { session_.AddStep(step, *sink_, notes_); };
  }
  void Add(const LiveRow& row, EstimateSink& sink) override {
    sink_ = &sink;
    if (const auto* step = std::get_if<Step>(&row)) {
      if (source_.Use(step->agent, StepSourceChoice::kSteps)) session_.AddStep(*step, sink, notes_);
    } else if (const auto* imu = std::get_if<ImuSample>(&row)) {
      if (source_.Use(imu->agent, StepSourceChoice::kImu)) ins_.Add(*imu, nullptr);
    } else {
      ++ignored_;
    }
  }
  PipelineSummary Summary() const override {
    PipelineSummary s = notes_;
    session_.Summarize(s);
    s.numbers["rows_ignored"] = static_cast<double>(ignored_ + source_.ignored());
    return s;
  }

 private:
  PipelineSummary notes_;
  LiveIns ins_;
  mutable MapMatchSession session_;
  EstimateSink* sink_ = nullptr;
  StepSourceChoice source_;
  std::size_t ignored_ = 0;
};

}  // namespace

std::unique_ptr<LiveEstimator> MakeLiveEstimator(const std::string& name, const MissionInfo& info,
                                                 const std::map<std::string, std::string>& options,
                                                 const FloorPlan* plan) {
  if (name == "pdr") return std::make_unique<LivePdr>(info, options);
  if (name == "ins") return std::make_unique<LiveInsEstimator>(info, options);
  if (name == "breadcrumb") return std::make_unique<LiveBreadcrumb>(info, options);
  if (name == "mapmatch") {
    if (plan == nullptr)
      throw std::invalid_argument("the mapmatch pipeline needs the incident's floor plan");
    return std::make_unique<LiveMapMatch>(info, options, *plan);
  }
  return nullptr;
}

}  // namespace trailmark

#include "trailmark/pipelines/live_estimator.h"

#include <fmt/format.h>

#include <stdexcept>

#include "trailmark/pipelines/ins_pipeline.h"
#include "trailmark/pipelines/live_ins.h"
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

TimeS RowTime(const LiveRow& row) {
  return std::visit([](const auto& r) -> TimeS {
    if constexpr (std::is_same_v<std::decay_t<decltype(r)>, Step>) {
      return r.t1;
    } else {
      return r.t;
    }
  }, row);
}

namespace {

const NodeInfo& RequireAgent(const MissionInfo& info, const std::string& id, const char* what) {
  const NodeInfo* node = info.Find(id);
  if (node == nullptr || node->kind != NodeKind::kAgent) {
    throw std::invalid_argument(
        fmt::format("'{}' has {} but is not an agent in mission.json", id, what));
  }
  return *node;
}

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
      if (Source(step->agent, kSteps)) AddStep(*step, sink);
    } else if (const auto* imu = std::get_if<ImuSample>(&row)) {
      if (Source(imu->agent, kImu)) ins_.Add(*imu, nullptr);
    } else {
      ++ignored_;
    }
  }

  PipelineSummary Summary() const override {
    PipelineSummary s = ins_.Summary();
    s.numbers["steps"] = static_cast<double>(steps_);
    s.numbers["rows_ignored"] = static_cast<double>(ignored_);
    s.numbers["agents"] = static_cast<double>(agents_.size());
    return s;
  }

 private:
  enum SourceKind { kSteps, kImu };
  static std::map<std::string, std::string> InsOnly(const std::map<std::string, std::string>& o) {
    const auto [ins, rest] = SplitInsOptions(o);
    PipelineOptions(rest, "pdr").RejectUnknown();
    return ins;
  }
  /// True when `kind` is the agent's source of steps (the first that arrived).
  bool Source(const std::string& agent, SourceKind kind) {
    const auto [it, first] = source_.emplace(agent, kind);
    if (it->second == kind) return true;
    ++ignored_;
    return false;
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
  std::map<std::string, SourceKind> source_;
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

}  // namespace

std::unique_ptr<LiveEstimator> MakeLiveEstimator(const std::string& name, const MissionInfo& info,
                                                 const std::map<std::string, std::string>& options) {
  if (name == "pdr") return std::make_unique<LivePdr>(info, options);
  if (name == "ins") return std::make_unique<LiveInsEstimator>(info, options);
  return nullptr;
}

}  // namespace trailmark

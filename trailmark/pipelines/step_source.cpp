#include "trailmark/pipelines/step_source.h"

#include "trailmark/core/error.h"
#include "trailmark/pipelines/ins_pipeline.h"

namespace trailmark {

std::pair<std::map<std::string, std::string>, std::map<std::string, std::string>> SplitInsOptions(
    const std::map<std::string, std::string>& values) {
  std::map<std::string, std::string> ins, rest;
  for (const auto& [k, v] : values) {
    if (k.rfind("ins.", 0) == 0) {
      ins[k.substr(4)] = v;
    } else {
      rest[k] = v;
    }
  }
  return {ins, rest};
}

bool HasSteps(const MissionDirectory& mission) {
  return mission.Has("steps.csv") || mission.Has("imu.csv");
}

std::optional<std::vector<Step>> InsStepsUnlessStepFile(
    const MissionDirectory& mission, const std::map<std::string, std::string>& ins_options,
    const std::string& who, PipelineSummary* summary) {
  if (mission.Has("steps.csv")) {
    if (!ins_options.empty() && summary) {
      summary->notes.push_back("ins.* options ignored: the mission has steps.csv");
    }
    if (mission.Has("imu.csv") && summary) {
      summary->notes.push_back(
          "steps from steps.csv; imu.csv not used (remove steps.csv to run the INS on it, or "
          "run the ins pipeline)");
    }
    return std::nullopt;
  }
  if (!mission.Has("imu.csv")) mission.Require("steps.csv", who + " (or imu.csv for the INS)");
  std::vector<Step> steps = InsStepsFromImu(mission, ins_options, summary);
  if (summary) {
    summary->notes.push_back("steps from imu.csv through the ZUPT INS (" +
                             std::to_string(steps.size()) + " steps)");
  }
  return steps;
}

StepSource::StepSource(const MissionDirectory& mission,
                       const std::map<std::string, std::string>& ins_options,
                       const std::string& who, PipelineSummary* summary)
    : mission_(mission) {
  if (auto steps = InsStepsUnlessStepFile(mission, ins_options, who, summary)) {
    steps_ = std::move(*steps);
  } else {
    reader_ = std::make_unique<RowReader<Step>>(mission.Path("steps.csv").string(),
                                                  &mission.registry());
  }
}

StepSource::~StepSource() = default;

bool StepSource::Next(Step& step) {
  if (reader_) return reader_->Next(step);
  if (next_ >= steps_.size()) return false;
  step = steps_[next_++];
  return true;
}

void StepSource::Fail(const std::string& problem) const {
  if (reader_) reader_->csv().Fail(problem);
  throw InputError(mission_.Path("imu.csv").string(), 0, problem);
}

double StepSource::Progress() const {
  if (reader_) {
    return reader_->csv().bytes_read() / std::max<double>(1.0, reader_->csv().file_size());
  }
  return steps_.empty() ? 1.0 : static_cast<double>(next_) / steps_.size();
}

}  // namespace trailmark

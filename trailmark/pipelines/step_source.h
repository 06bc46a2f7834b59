#pragma once
/// The steps of a mission for the steps-based pipelines: `steps.csv` when present, else the
/// zero-velocity INS run on `imu.csv` (options with the prefix "ins.", e.g.
/// `--option ins.detector=shoe`). This is how every estimator starts from raw IMU data.

#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "trailmark/pipelines/pipeline.h"

namespace trailmark {

/// Splits `--option` values into the INS's ("ins." prefix removed) and the rest.
std::pair<std::map<std::string, std::string>, std::map<std::string, std::string>> SplitInsOptions(
    const std::map<std::string, std::string>& values);

/// True when the mission has steps.csv or imu.csv.
bool HasSteps(const MissionDirectory& mission);

/// For pipelines that read steps.csv themselves (e.g. through MergedStream): the INS steps when
/// the mission has imu.csv but no steps.csv; nullopt when steps.csv is present. Throws
/// InputError when the mission has neither file (naming `who`).
std::optional<std::vector<Step>> InsStepsUnlessStepFile(
    const MissionDirectory& mission, const std::map<std::string, std::string>& ins_options,
    const std::string& who, PipelineSummary* summary);

class StepSource {
 public:
  /// Throws InputError when the mission has neither file (naming `who`).
  StepSource(const MissionDirectory& mission, const std::map<std::string, std::string>& ins_options,
             const std::string& who, PipelineSummary* summary);
  ~StepSource();
  bool Next(Step& step);
  /// Fails at the current row (file:line for steps.csv; imu.csv otherwise).
  [[noreturn]] void Fail(const std::string& problem) const;
  double Progress() const;

 private:
  const MissionDirectory& mission_;
  std::vector<Step> steps_;
  std::size_t next_ = 0;
  std::unique_ptr<RowReader<Step>> reader_;
};

}  // namespace trailmark

#pragma once
/// Typed access to a pipeline's `--option key=value` pairs. Unknown keys and malformed values
/// are errors (std::invalid_argument naming the pipeline, key and value), never ignored.

#include <map>
#include <set>
#include <string>

namespace trailmark {

class PipelineOptions {
 public:
  PipelineOptions(const std::map<std::string, std::string>& values, std::string pipeline)
      : values_(values), pipeline_(std::move(pipeline)) {}
  double Double(const std::string& key, double fallback);
  bool Bool(const std::string& key, bool fallback);
  std::string String(const std::string& key, const std::string& fallback);
  /// Throws if a given key was never asked for.
  void RejectUnknown() const;

 private:
  const std::map<std::string, std::string>& values_;
  std::string pipeline_;
  std::set<std::string> known_;
};

}  // namespace trailmark

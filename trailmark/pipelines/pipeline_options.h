#pragma once
/// Typed access to a pipeline's `--option key=value` pairs. Unknown keys and malformed values
/// are errors (std::invalid_argument naming the pipeline, key and value), never ignored.

#include <cstdint>
#include <map>
#include <set>
#include <string>
#include <utility>

namespace trailmark {

class PipelineOptions {
 public:
  /// Keeps a copy of `values` (a handful of strings; a temporary map is fine).
  PipelineOptions(std::map<std::string, std::string> values, std::string pipeline)
      : values_(std::move(values)), pipeline_(std::move(pipeline)) {}
  double Double(const std::string& key, double fallback);
  /// A whole number within [min_value, max_value]: a fraction or a value out of the range is
  /// refused with the option's name (never truncated or clamped).
  std::int64_t Whole(const std::string& key, std::int64_t fallback, std::int64_t min_value,
                     std::int64_t max_value);
  bool Bool(const std::string& key, bool fallback);
  std::string String(const std::string& key, const std::string& fallback);
  /// Throws if a given key was never asked for.
  void RejectUnknown() const;

 private:
  std::map<std::string, std::string> values_;
  std::string pipeline_;
  std::set<std::string> known_;
};

}  // namespace trailmark

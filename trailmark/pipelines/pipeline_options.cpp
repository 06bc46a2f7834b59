#include "trailmark/pipelines/pipeline_options.h"

#include <cmath>
#include <stdexcept>

#include "trailmark/io/csv.h"

namespace trailmark {

double PipelineOptions::Double(const std::string& key, double fallback) {
  known_.insert(key);
  auto it = values_.find(key);
  if (it == values_.end()) return fallback;
  const auto v = ParseFiniteDouble(it->second);
  if (!v) {
    throw std::invalid_argument("pipeline " + pipeline_ + ": option " + key + "='" + it->second +
                                "' is not a finite number");
  }
  return *v;
}

std::int64_t PipelineOptions::Whole(const std::string& key, std::int64_t fallback,
                                    std::int64_t min_value, std::int64_t max_value) {
  if (!values_.count(key)) {
    known_.insert(key);
    return fallback;
  }
  const double v = Double(key, static_cast<double>(fallback));
  if (v != std::floor(v) || v < static_cast<double>(min_value) ||
      v > static_cast<double>(max_value)) {
    throw std::invalid_argument("pipeline " + pipeline_ + ": option " + key + "='" +
                                values_.at(key) + "' must be a whole number within " +
                                std::to_string(min_value) + " .. " + std::to_string(max_value));
  }
  return static_cast<std::int64_t>(v);
}

bool PipelineOptions::Bool(const std::string& key, bool fallback) {
  known_.insert(key);
  auto it = values_.find(key);
  if (it == values_.end()) return fallback;
  const std::string& v = it->second;
  if (v == "1" || v == "true" || v == "on" || v == "yes") return true;
  if (v == "0" || v == "false" || v == "off" || v == "no") return false;
  throw std::invalid_argument("pipeline " + pipeline_ + ": option " + key + "='" + v +
                              "' is not a boolean (1/0, true/false, on/off)");
}

std::string PipelineOptions::String(const std::string& key, const std::string& fallback) {
  known_.insert(key);
  auto it = values_.find(key);
  return it == values_.end() ? fallback : it->second;
}

void PipelineOptions::RejectUnknown() const {
  for (const auto& [k, v] : values_) {
    if (!known_.count(k)) {
      std::string list;
      for (const auto& x : known_) list += (list.empty() ? "" : ", ") + x;
      throw std::invalid_argument(
          "pipeline " + pipeline_ + ": unknown option '" + k + "' " +
          (list.empty() ? std::string("(it takes none but the INS's ins.* options)")
                        : "(known: " + list + ")"));
    }
  }
}

}  // namespace trailmark

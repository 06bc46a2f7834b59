// SPDX-License-Identifier: MIT
#include "trailmark/core/online_estimator.h"

#include "trailmark/core/mission.h"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

namespace trailmark {

TimeS RowTime(const MissionRow& row) {
  struct {
    TimeS operator()(const Step& s) const { return s.t1; }
    TimeS operator()(const MissionEvent& r) const { return r.t; }
    TimeS operator()(const RangeMeasurement& r) const { return r.t; }
    TimeS operator()(const BearingMeasurement& r) const { return r.t; }
    TimeS operator()(const RssiPacket& r) const { return r.t; }
    TimeS operator()(const ImuSample& r) const { return r.t; }
    TimeS operator()(const BaroSample& r) const { return r.t; }
  } time;
  return std::visit(time, row);
}

const std::string& RowNode(const MissionRow& row) {
  struct {
    const std::string& operator()(const MissionEvent& r) const { return r.agent; }
    const std::string& operator()(const Step& r) const { return r.agent; }
    const std::string& operator()(const RangeMeasurement& r) const { return r.a; }
    const std::string& operator()(const BearingMeasurement& r) const { return r.a; }
    const std::string& operator()(const RssiPacket& r) const { return r.rx; }
    const std::string& operator()(const ImuSample& r) const { return r.agent; }
    const std::string& operator()(const BaroSample& r) const { return r.agent; }
  } node;
  return std::visit(node, row);
}

std::string_view StreamFileName(Stream stream) {
  switch (stream) {
    case Stream::kImu: return "imu.csv";
    case Stream::kSteps: return "steps.csv";
    case Stream::kRssi: return "rssi.csv";
    case Stream::kRanges: return "ranges.csv";
    case Stream::kBearings: return "bearings.csv";
    case Stream::kEvents: return "events.csv";
    case Stream::kBaro: return "baro.csv";
  }
  return "?";
}

Stream RowStream(const MissionRow& row) {
  struct {
    Stream operator()(const MissionEvent&) const { return Stream::kEvents; }
    Stream operator()(const Step&) const { return Stream::kSteps; }
    Stream operator()(const RangeMeasurement&) const { return Stream::kRanges; }
    Stream operator()(const BearingMeasurement&) const { return Stream::kBearings; }
    Stream operator()(const RssiPacket&) const { return Stream::kRssi; }
    Stream operator()(const ImuSample&) const { return Stream::kImu; }
    Stream operator()(const BaroSample&) const { return Stream::kBaro; }
  } stream;
  return std::visit(stream, row);
}

std::vector<Stream> StreamSet::List() const {
  std::vector<Stream> out;
  for (Stream s : kAllStreams) {
    if (Has(s)) out.push_back(s);
  }
  return out;
}

std::vector<Estimate> VectorSink::TakeSortedByTime() {
  std::vector<Estimate> out = std::move(rows);
  rows.clear();
  std::stable_sort(out.begin(), out.end(),
                   [](const Estimate& a, const Estimate& b) { return a.t < b.t; });
  return out;
}

void EstimatorSummary::Merge(const EstimatorSummary& other) {
  for (const auto& [key, value] : other.numbers) numbers[key] = value;
  notes.insert(notes.end(), other.notes.begin(), other.notes.end());
  integrity.insert(integrity.end(), other.integrity.begin(), other.integrity.end());
}

std::string EstimatorSummary::BriefReport() const {
  std::string out;
  for (const auto& [key, value] : numbers) {
    out += fmt::format("{}{} {:g}", out.empty() ? "" : ", ", key, value);
  }
  return out;
}

namespace {
/// A node's level from mission.json: a person's start by the spec's rule; a static node is
/// mounted somewhere in its storey. None without a position.
std::optional<int> DeclaredLevel(const MissionInfo& info, const NodeInfo& n) {
  if (!n.position) return std::nullopt;
  return n.kind == NodeKind::kAgent ? LevelAt(info.floors, n.position->z())
                                    : MountedLevelAt(info.floors, n.position->z());
}
}  // namespace

std::optional<int> NodeLevelOf(const LevelSource* levels, const MissionInfo& info,
                               const std::string& node) {
  if (levels != nullptr) {
    if (const auto b = levels->NodeLevel(node)) return b->level;
  }
  const NodeInfo* n = info.Find(node);
  return n != nullptr ? DeclaredLevel(info, *n) : std::nullopt;
}

MissionLevels::MissionLevels(const MissionInfo& info) {
  for (const NodeInfo& n : info.nodes) by_id_.emplace(n.id, DeclaredLevel(info, n));
}

std::optional<int> MissionLevels::Of(const LevelSource* levels, const std::string& node) const {
  if (levels != nullptr) {
    if (const auto b = levels->NodeLevel(node)) return b->level;
  }
  const auto it = by_id_.find(node);
  return it != by_id_.end() ? it->second : std::nullopt;
}

bool MissionLevels::Differ(const LevelSource* levels, const std::string& a,
                           const std::string& b) const {
  if (levels == nullptr) return false;
  const auto la = Of(levels, a), lb = Of(levels, b);
  return la && lb && *la != *lb;
}

bool OnDifferentLevels(const LevelSource* levels, const MissionInfo& info, const std::string& a,
                       const std::string& b) {
  if (levels == nullptr) return false;
  const auto la = NodeLevelOf(levels, info, a), lb = NodeLevelOf(levels, info, b);
  return la && lb && *la != *lb;
}

}  // namespace trailmark

// SPDX-License-Identifier: MIT
#include "trailmark/io/merged_stream.h"

#include <optional>
#include <vector>

#include "trailmark/core/error.h"

namespace trailmark {

namespace {

struct SourceBase {
  virtual ~SourceBase() = default;
  virtual bool Advance() = 0;  // loads the next row into `head`
  virtual double bytes_read() const = 0;
  virtual double file_size() const = 0;
  virtual const std::string& path() const = 0;
  virtual std::size_t line() const = 0;
  std::optional<MissionRow> head;
  std::size_t head_line = 0;
};

template <class Row>
struct Source : SourceBase {
  explicit Source(const MissionDirectory& m) : reader(m.OpenStream<Row>()) {}
  bool Advance() override {
    Row r;
    if (reader.Next(r)) {
      head = MissionRow(std::move(r));
      head_line = reader.csv().line();
      return true;
    }
    head.reset();
    return false;
  }
  double bytes_read() const override { return static_cast<double>(reader.csv().bytes_read()); }
  double file_size() const override { return static_cast<double>(reader.csv().file_size()); }
  const std::string& path() const override { return reader.csv().path(); }
  std::size_t line() const override { return head_line; }
  RowReader<Row> reader;
};

}  // namespace

struct MergedStream::Impl {
  std::vector<std::unique_ptr<SourceBase>> sources;  // in tie-break order
  std::string last_path;
  std::size_t last_line = 0;
};

MergedStream::MergedStream(const MissionDirectory& m, StreamSet streams)
    : impl_(std::make_unique<Impl>()) {
  auto add = [&](auto tag, Stream stream) {
    using Row = decltype(tag);
    if (streams.Has(stream) && m.HasStream<Row>()) {
      auto s = std::make_unique<Source<Row>>(m);
      s->Advance();
      impl_->sources.push_back(std::move(s));
      present_.Add(stream);
    }
  };
  // In the MissionRow variant's order: the tie-break at equal times.
  add(MissionEvent{}, Stream::kEvents);
  add(Step{}, Stream::kSteps);
  add(RangeMeasurement{}, Stream::kRanges);
  add(BearingMeasurement{}, Stream::kBearings);
  add(RssiPacket{}, Stream::kRssi);
  add(ImuSample{}, Stream::kImu);
  add(BaroSample{}, Stream::kBaro);
}

MergedStream::~MergedStream() = default;

bool MergedStream::Next(MissionRow& row) {
  SourceBase* best = nullptr;
  TimeS best_t = 0;
  for (auto& s : impl_->sources) {
    if (!s->head) continue;
    const TimeS t = RowTime(*s->head);
    if (!best || t < best_t) {
      best = s.get();
      best_t = t;
    }
  }
  if (!best) return false;
  row = std::move(*best->head);
  impl_->last_path = best->path();
  impl_->last_line = best->line();
  best->Advance();
  return true;
}

double MergedStream::Progress() const {
  double read = 0, size = 0;
  for (const auto& s : impl_->sources) {
    read += s->bytes_read();
    size += s->file_size();
  }
  return size > 0 ? read / size : 1.0;
}

void MergedStream::Fail(const std::string& problem) const {
  throw InputError(impl_->last_path, impl_->last_line, problem);
}

}  // namespace trailmark

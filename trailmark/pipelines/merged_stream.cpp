#include "trailmark/pipelines/merged_stream.h"

#include <array>

namespace trailmark {

TimeS RowTime(const MissionRow& row) { return std::visit(RowTimeOf{}, row); }

namespace {

struct SourceBase {
  virtual ~SourceBase() = default;
  virtual bool Advance() = 0;  // loads the next row into `head`
  virtual double bytes_read() const = 0;
  virtual double file_size() const = 0;
  std::optional<MissionRow> head;
};

template <class Row>
struct Source : SourceBase {
  explicit Source(const MissionDirectory& m) : reader(m.OpenStream<Row>()) {}
  bool Advance() override {
    Row r;
    if (reader.Next(r)) {
      head = MissionRow(std::move(r));
      return true;
    }
    head.reset();
    return false;
  }
  double bytes_read() const override { return static_cast<double>(reader.csv().bytes_read()); }
  double file_size() const override { return static_cast<double>(reader.csv().file_size()); }
  RowReader<Row> reader;
};

struct VectorSource : SourceBase {
  explicit VectorSource(const std::vector<Step>* v) : rows(v) {}
  bool Advance() override {
    if (next < rows->size()) {
      head = MissionRow((*rows)[next++]);
      return true;
    }
    head.reset();
    return false;
  }
  double bytes_read() const override { return static_cast<double>(next); }
  double file_size() const override { return static_cast<double>(rows->size()); }
  const std::vector<Step>* rows;
  std::size_t next = 0;
};

}  // namespace

struct MergedStream::Impl {
  std::vector<std::unique_ptr<SourceBase>> sources;  // in tie-break order
};

MergedStream::MergedStream(const MissionDirectory& m, MergedStreamOptions o)
    : impl_(std::make_unique<Impl>()) {
  auto add = [&](auto tag, bool enabled) {
    using Row = decltype(tag);
    if (enabled && m.HasStream<Row>()) {
      auto s = std::make_unique<Source<Row>>(m);
      s->Advance();
      impl_->sources.push_back(std::move(s));
    }
  };
  add(MissionEvent{}, o.events);
  if (o.steps && o.steps_override) {
    auto s = std::make_unique<VectorSource>(o.steps_override);
    s->Advance();
    impl_->sources.push_back(std::move(s));
  } else {
    add(Step{}, o.steps);
  }
  add(RangeMeasurement{}, o.ranges);
  add(BearingMeasurement{}, o.bearings);
  add(RssiPacket{}, o.rssi);
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

}  // namespace trailmark

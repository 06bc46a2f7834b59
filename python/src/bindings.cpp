// SPDX-License-Identifier: MIT
// The Python module `trailmark._trailmark` (pybind11): the pipeline registry, the batch run, the
// online estimator interface, the mission readers and writers and the evaluation, with columns
// as numpy arrays. Rows cross the boundary as the mission format's own CSV text, so every row
// from Python passes the readers' checks (errors name the stream and its line) and every column
// returned is exactly what the CLI writes (numbers in shortest round-trip form, parsed back).
// The pure-Python package (python/trailmark/__init__.py) wraps this module.

#include <glog/logging.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <charconv>
#include <cmath>
#include <filesystem>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "trailmark/core/error.h"
#include "trailmark/eval/metrics.h"
#include "trailmark/io/metrics_io.h"
#include "trailmark/io/mission_io.h"
#include "trailmark/io/streams.h"
#include "trailmark/pipelines/batch_run.h"
#include "trailmark/pipelines/registry.h"
#include "trailmark_generated/version.h"

namespace py = pybind11;
namespace fs = std::filesystem;

namespace trailmark::python {
namespace {

/// Columns of the mission format that hold node ids or words (the others are numbers).
bool IsTextColumn(std::string_view name) {
  return name == "agent" || name == "rx" || name == "tx" || name == "a" || name == "b" ||
         name == "kind" || name == "event" || name == "node" || name == "id";
}

std::vector<std::string_view> SplitCells(std::string_view line) {
  std::vector<std::string_view> cells;
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = line.find(',', start);
    cells.push_back(line.substr(start, comma == std::string_view::npos ? line.npos : comma - start));
    if (comma == std::string_view::npos) return cells;
    start = comma + 1;
  }
}

/// Canonical CSV lines (header first, as RowWriter writes them) as a dict of columns: numbers
/// as float64 arrays (NaN for an empty cell), words and ids as lists of str (the package makes
/// them numpy object arrays). The writer's shortest round-trip numbers parse back exactly.
py::dict LinesToColumns(const std::vector<std::string>& lines) {
  py::dict columns;
  if (lines.empty()) return columns;
  const std::vector<std::string_view> header = SplitCells(lines.front());
  const std::size_t rows = lines.size() - 1;
  std::vector<std::vector<double>> numbers(header.size());
  std::vector<std::vector<std::string>> words(header.size());
  for (std::size_t c = 0; c < header.size(); ++c) {
    (IsTextColumn(header[c]) ? static_cast<void>(words[c].reserve(rows))
                             : static_cast<void>(numbers[c].reserve(rows)));
  }
  for (std::size_t r = 1; r < lines.size(); ++r) {
    const std::vector<std::string_view> cells = SplitCells(lines[r]);
    if (cells.size() != header.size()) {
      throw std::logic_error("canonical CSV line with a wrong number of cells: " + lines[r]);
    }
    for (std::size_t c = 0; c < cells.size(); ++c) {
      if (IsTextColumn(header[c])) {
        words[c].emplace_back(cells[c]);
        continue;
      }
      double value = std::numeric_limits<double>::quiet_NaN();
      if (!cells[c].empty()) {
        const auto [end, ec] = std::from_chars(cells[c].data(), cells[c].data() + cells[c].size(), value);
        if (ec != std::errc() || end != cells[c].data() + cells[c].size()) {
          throw std::logic_error("canonical CSV cell is not a number: " + std::string(cells[c]));
        }
      }
      numbers[c].push_back(value);
    }
  }
  for (std::size_t c = 0; c < header.size(); ++c) {
    const py::str key(std::string(header[c]));
    if (IsTextColumn(header[c])) {
      columns[key] = py::cast(words[c]);
    } else {
      py::array_t<double> array(static_cast<py::ssize_t>(numbers[c].size()));
      std::copy(numbers[c].begin(), numbers[c].end(), array.mutable_data());
      columns[key] = std::move(array);
    }
  }
  return columns;
}

/// Estimates as the columns `trailmark run` writes for this mission (1.1 columns when it is
/// about floors).
py::dict EstimatesToColumns(const std::vector<Estimate>& rows, bool floor_columns) {
  std::vector<std::string> lines;
  RowWriter<Estimate> writer("(estimates)", &lines, floor_columns);
  for (const Estimate& e : rows) writer.Write(e);
  writer.Close();
  return LinesToColumns(lines);
}

py::dict SummaryToDict(const EstimatorSummary& summary) {
  py::dict out;
  out["numbers"] = py::cast(summary.numbers);
  out["notes"] = py::cast(summary.notes);
  py::list integrity;
  for (const IntegrityNote& n : summary.integrity) {
    py::dict note;
    note["t"] = n.t;
    note["source"] = n.source;
    note["node"] = n.node;
    note["action"] = n.action;
    note["message"] = n.message;
    integrity.append(std::move(note));
  }
  out["integrity"] = std::move(integrity);
  return out;
}

OptionValues ToOptions(const std::map<std::string, std::string>& options) {
  OptionValues values;
  for (const auto& [key, value] : options) values[key] = value;
  return values;
}

/// A pipeline run on a mission directory (what `trailmark run` does, without the files):
/// (estimate columns, summary). The GIL is released while the pipeline runs.
py::tuple PyRunPipeline(const std::string& name, const fs::path& mission_dir,
                      const std::map<std::string, std::string>& options) {
  const PipelineSpec& pipeline = RequirePipeline(name);
  const MissionDirectory mission(mission_dir);
  VectorSink rows;
  EstimatorSummary summary;
  {
    py::gil_scoped_release release;
    RestampingSink sink(rows);
    summary = RunBatch(pipeline, PipelineContext{mission, ToOptions(options)}, sink);
  }
  return py::make_tuple(EstimatesToColumns(rows.rows, EstimatesHaveFloorColumns(mission)),
                        SummaryToDict(summary));
}

/// One stream file of a mission directory, checked by its reader (ids against mission.json's
/// nodes and the dropped crumbs), as columns.
py::dict ReadStream(const fs::path& mission_dir, const std::string& file) {
  const MissionDirectory mission(mission_dir);
  mission.Require(file, "read_stream");
  return WithStreamRowType</*kOutputs=*/true>(
      file,
      [&]<class Row>(std::type_identity<Row>) {
        std::vector<std::string> lines;
        {
          py::gil_scoped_release release;
          const std::vector<Row> rows = ReadAll<Row>(mission.Path(file).string(), &mission.registry());
          lines = FormatAll(rows);
          if (lines.empty()) lines = FormatAll(std::vector<Row>{});
        }
        return LinesToColumns(lines);
      });
}

/// A CSV document of one stream (named `name` in errors) checked by its reader and written
/// canonically to `path`: how the package writes a mission from numpy columns. Returns the
/// number of rows.
std::size_t WriteStream(const std::string& file, const std::string& name, const std::string& text,
                        const fs::path& path) {
  return WithStreamRowType</*kOutputs=*/true>(
      file,
      [&]<class Row>(std::type_identity<Row>) {
        const std::vector<Row> rows = ParseAll<Row>(name, text);
        WriteAll(path.string(), rows);
        return rows.size();
      });
}

/// Scores estimates (a CSV document of estimates.csv, named `name` in errors) against the
/// mission's truth: metrics.json's text.
std::string PyEvaluate(const fs::path& mission_dir, const std::string& name, const std::string& text,
                     std::size_t max_series) {
  const MissionDirectory mission(mission_dir);
  mission.Require("truth.csv", "evaluation");
  const auto truth = ReadAll<TruthSample>(mission.Path("truth.csv").string(), &mission.registry());
  const auto estimates = ParseAll<Estimate>(name, text, &mission.registry());
  return MetricsToJson(trailmark::Evaluate(mission.info(), truth, estimates), max_series);
}

/// An online estimator of the registry for a mission's incident (nodes, floor plan), fed rows
/// from Python as CSV documents of one stream, in any number of calls.
class PyOnlineEstimator {
 public:
  PyOnlineEstimator(const std::string& name, const fs::path& mission_dir,
                    const std::map<std::string, std::string>& options, bool live)
      : pipeline_(RequirePipeline(name)), mission_(mission_dir) {
    const OptionValues values = ToOptions(options);
    plan_ = LoadPipelinePlan(pipeline_, mission_, values);
    estimator_ = pipeline_.make(plan_.InputsFor(mission_.info()), values,
                                live ? Feed::kLive : Feed::kTimeOrdered);
    floor_columns_ = EstimatesHaveFloorColumns(mission_);
    for (Stream s : BatchFeedStreams(pipeline_, mission_, values).List()) {
      streams_.emplace_back(StreamFileName(s));
    }
  }

  /// The mission's stream files a batch run would feed this pipeline.
  const std::vector<std::string>& streams() const { return streams_; }

  /// Rows of one stream; returns how many were added.
  std::size_t Add(const std::string& file, const std::string& name, const std::string& text) {
    std::vector<MissionRow> rows;
    std::vector<std::size_t> lines;
    WithStreamRowType(file, [&]<class Row>(std::type_identity<Row>) {
      for (Row& r : ParseAll<Row>(name, text, nullptr, &lines)) rows.emplace_back(std::move(r));
    });
    py::gil_scoped_release release;
    for (std::size_t k = 0; k < rows.size(); ++k) {
      try {
        estimator_->Add(rows[k], sink_);
      } catch (const std::invalid_argument& e) {
        throw InputError(name, lines[k], e.what());
      }
    }
    return rows.size();
  }

  void Finish() {
    py::gil_scoped_release release;
    estimator_->Finish(sink_);
  }

  /// The estimates emitted since the last call, as columns.
  py::dict TakeEstimates() {
    std::vector<Estimate> rows = std::move(vector_.rows);
    vector_.rows.clear();
    return EstimatesToColumns(rows, floor_columns_);
  }

  std::optional<py::dict> Current(const std::string& node) const {
    const std::optional<Estimate> e = estimator_->Current(node);
    if (!e) return std::nullopt;
    py::dict out;
    out["t"] = e->t;
    out["id"] = e->id;
    out["x"] = e->position_n.x();
    out["y"] = e->position_n.y();
    out["z"] = e->position_n.z();
    out["sxx"] = e->sxx;
    out["sxy"] = e->sxy;
    out["syy"] = e->syy;
    if (e->szz) out["szz"] = *e->szz;
    if (e->floor) out["floor"] = *e->floor;
    return out;
  }

  py::dict Summary() const { return SummaryToDict(estimator_->Summary()); }
  const std::string& pipeline() const { return pipeline_.name; }

 private:
  const PipelineSpec& pipeline_;
  MissionDirectory mission_;
  PipelinePlan plan_;
  std::unique_ptr<OnlineEstimator> estimator_;
  VectorSink vector_;
  RestampingSink sink_{vector_};
  bool floor_columns_ = false;
  std::vector<std::string> streams_;
};

}  // namespace
}  // namespace trailmark::python

PYBIND11_MODULE(_trailmark, m) {
  using namespace trailmark;
  using namespace trailmark::python;
  m.doc() = "trailmark's C++ library (use the `trailmark` package, which wraps this module)";
  m.attr("__version__") = TRAILMARK_VERSION;
  // As the CLI: Ceres' glog warnings (a damped Levenberg-Marquardt step) stay off stderr, errors
  // still print, no log files; unless the host process set glog up itself.
  if (!google::IsGoogleLoggingInitialized()) {
    FLAGS_logtostderr = true;
    FLAGS_minloglevel = google::GLOG_ERROR;
    google::InitGoogleLogging("trailmark");
  }

  // InputError (bad input: file, line, problem) as trailmark.InputError, a ValueError.
  static py::exception<InputError> input_error(m, "InputError", PyExc_ValueError);
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const InputError& e) {
      py::object error = py::reinterpret_borrow<py::object>(input_error.ptr())(e.what());
      error.attr("file") = e.file();
      error.attr("line") = e.line();
      error.attr("problem") = e.problem();
      PyErr_SetObject(input_error.ptr(), error.ptr());
    }
  });

  m.def("pipelines", [] {
    std::vector<std::string> names;
    for (const PipelineSpec& p : Pipelines()) names.push_back(p.name);
    return names;
  }, "The registry's pipeline names, in its order.");
  m.def("registry_json", &RegistryJson, "The registry as `trailmark pipelines --json` prints it.");
  m.def("runnable_pipelines",
        [](const fs::path& dir) { return RunnablePipelines(MissionDirectory(dir)); },
        py::arg("mission_dir"), "Names of the pipelines the mission can feed.");
  m.def("run_pipeline", &PyRunPipeline, py::arg("name"), py::arg("mission_dir"),
        py::arg("options"), "(estimate columns, summary) of a batch run.");
  m.def("read_stream", &ReadStream, py::arg("mission_dir"), py::arg("file"));
  m.def("write_stream", &WriteStream, py::arg("file"), py::arg("name"), py::arg("text"),
        py::arg("path"));
  m.def("evaluate", &PyEvaluate, py::arg("mission_dir"), py::arg("name"), py::arg("text"),
        py::arg("max_series"));
  m.def("validate_mission",
        [](const fs::path& dir) {
          const MissionDirectory mission(dir);
          return mission.dropped_crumbs();
        },
        py::arg("mission_dir"),
        "Opens the mission (mission.json checked); returns the crumbs dropped in events.csv.");

  py::class_<PyOnlineEstimator>(m, "OnlineEstimator")
      .def(py::init<const std::string&, const fs::path&, const std::map<std::string, std::string>&,
                    bool>(),
           py::arg("name"), py::arg("mission_dir"), py::arg("options"), py::arg("live"))
      .def("add", &PyOnlineEstimator::Add, py::arg("file"), py::arg("name"), py::arg("text"))
      .def("finish", &PyOnlineEstimator::Finish)
      .def("take_estimates", &PyOnlineEstimator::TakeEstimates)
      .def("current", &PyOnlineEstimator::Current, py::arg("node"))
      .def("summary", &PyOnlineEstimator::Summary)
      .def_property_readonly("pipeline", &PyOnlineEstimator::pipeline)
      .def_property_readonly("streams", &PyOnlineEstimator::streams);
}

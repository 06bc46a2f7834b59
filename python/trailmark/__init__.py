# SPDX-License-Identifier: MIT
"""trailmark from Python: missions as numpy columns, every pipeline of the registry, the online
estimators row by row, and the evaluation.

    import trailmark
    trailmark.pipelines()                       # ['pdr', 'breadcrumb', ...]
    est = trailmark.run_pipeline("pdr", "out/mission")
    est["t"], est["id"], est["x"], est["y"]     # numpy arrays, as `trailmark run` writes them
    est.summary["numbers"]                      # what diagnostics.json reports
    trailmark.evaluate("out/mission", est)["agents"]["stats"]["p75_m"]

Rows cross into the C++ library as the mission format's CSV text, so every row from Python is
checked by the same readers as a file (a bad row raises InputError naming the stream and line),
and every column returned is what the CLI writes, number for number. See docs/python.md.
"""

from __future__ import annotations

import json
import math
import os
from typing import Any, Dict, Iterable, Mapping, Optional, Union

import numpy as np

from ._trailmark import InputError, __version__
from . import _trailmark as _core

__all__ = [
    "InputError",
    "Estimates",
    "Mission",
    "OnlineEstimator",
    "__version__",
    "evaluate",
    "pipeline_info",
    "pipelines",
    "read_mission",
    "run_pipeline",
    "runnable_pipelines",
    "to_csv",
    "write_mission",
]

PathLike = Union[str, "os.PathLike[str]"]
Columns = Mapping[str, Any]

#: The stream files of a mission directory (spec: "Streams"), in the order they are read.
STREAM_FILES = ("imu.csv", "steps.csv", "rssi.csv", "ranges.csv", "bearings.csv", "events.csv",
                "baro.csv", "truth.csv")

_INTEGER_COLUMNS = ("floor",)
# The tie order of a batch run's merge (core/online_estimator.h: MissionRow).
_MERGE_ORDER = ("events.csv", "steps.csv", "ranges.csv", "bearings.csv", "rssi.csv", "imu.csv",
                "baro.csv")


def _columns(raw: Dict[str, Any]) -> Dict[str, np.ndarray]:
    """The module's columns with word/id columns as numpy object arrays."""
    return {k: (v if isinstance(v, np.ndarray) else np.array(v, dtype=object)) for k, v in raw.items()}


class Estimates(dict):
    """Estimate columns by name (`t`, `id`, `x`, `y`, `z`, `sxx`, `sxy`, `syy`, and `szz`,
    `floor` where the mission is about floors; NaN for an empty cell), with the estimator's
    `summary` (numbers, notes, integrity notes)."""

    def __init__(self, columns: Dict[str, np.ndarray], summary: Optional[dict] = None):
        super().__init__(columns)
        self.summary = summary if summary is not None else {"numbers": {}, "notes": [], "integrity": []}

    def __len__(self) -> int:  # the number of rows, not of columns
        return len(self["t"]) if "t" in self else 0

    def node(self, node_id: str) -> Dict[str, np.ndarray]:
        """The rows of one node, as columns."""
        mask = self["id"] == node_id
        return {k: v[mask] for k, v in self.items()}


def pipelines() -> list:
    """The registry's pipeline names, in its order (`trailmark pipelines`)."""
    return list(_core.pipelines())


def pipeline_info(name: Optional[str] = None) -> Any:
    """The registry as `trailmark pipelines --json` gives it: a list of pipelines with needs,
    uses, capabilities and options; or the entry of one pipeline by name."""
    registry = json.loads(_core.registry_json())
    entries = registry["pipelines"] if isinstance(registry, dict) else registry
    if name is None:
        return entries
    for entry in entries:
        if entry["name"] == name:
            return entry
    raise ValueError(f"no pipeline '{name}' (known: {', '.join(pipelines())})")


def runnable_pipelines(mission_dir: PathLike) -> list:
    """The pipelines the mission has the streams, floor plan and landmarks for."""
    return list(_core.runnable_pipelines(os.fspath(mission_dir)))


def _option_text(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


def _options(options: Optional[Mapping[str, Any]]) -> Dict[str, str]:
    return {str(k): _option_text(v) for k, v in (options or {}).items()}


def run_pipeline(name: str, mission_dir: PathLike, options: Optional[Mapping[str, Any]] = None) -> Estimates:
    """Runs a pipeline on a mission directory, as `trailmark run --pipeline NAME MISSION
    [--option key=value ...]` does, and returns its estimates as columns (equal to the
    estimates.csv the CLI writes) with the summary. Releases the GIL while it runs. Raises
    InputError for bad input, ValueError for unknown pipelines or bad options."""
    columns, summary = _core.run_pipeline(name, os.fspath(mission_dir), _options(options))
    return Estimates(_columns(columns), summary)


class Mission:
    """A mission directory read into memory: `info` (mission.json as a dict), `streams`
    (file name -> columns, e.g. `streams["steps.csv"]["dx"]`), `floorplan` (the GeoJSON as a
    dict, or None) and `dir`."""

    def __init__(self, info: dict, streams: Dict[str, Dict[str, np.ndarray]],
                 floorplan: Optional[dict] = None, directory: Optional[str] = None):
        self.info = info
        self.streams = streams
        self.floorplan = floorplan
        self.dir = directory

    def rows(self, streams: Optional[Iterable[str]] = None):
        """Yields (stream, columns of a run of consecutive rows of that stream) over the
        measurement streams (or those named) merged in time order as a batch run merges them:
        steps by t1, ties in the order events, steps, ranges, bearings, RSSI, IMU, barometer,
        then file order. Feed each to OnlineEstimator.add_columns."""
        names = [s for s in (streams or _MERGE_ORDER) if s in self.streams and s in _MERGE_ORDER]
        times, ranks, index = [], [], []
        for name in names:
            cols = self.streams[name]
            t = np.asarray(cols["t1" if name == "steps.csv" else "t"], dtype=float)
            times.append(t)
            ranks.append(np.full(len(t), _MERGE_ORDER.index(name)))
            index.append(np.arange(len(t)))
        if not times:
            return
        t, rank, idx = np.concatenate(times), np.concatenate(ranks), np.concatenate(index)
        order = np.lexsort((idx, rank, t))
        rank, idx = rank[order], idx[order]
        cuts = np.flatnonzero(np.diff(rank)) + 1
        for start, stop in zip(np.r_[0, cuts], np.r_[cuts, len(rank)]):
            name = _MERGE_ORDER[rank[start]]
            yield name, {k: v[idx[start:stop]] for k, v in self.streams[name].items()}

    def __repr__(self) -> str:
        sizes = ", ".join(f"{k}: {len(next(iter(v.values()), []))} rows" for k, v in self.streams.items())
        return f"Mission({self.dir!r}; {sizes})"


def read_mission(mission_dir: PathLike, streams: Optional[Iterable[str]] = None) -> Mission:
    """Reads mission.json, every stream present (or those named) and the floor plan, each
    checked by trailmark's readers (InputError names the file and line of a bad row)."""
    directory = os.fspath(mission_dir)
    _core.validate_mission(directory)
    with open(os.path.join(directory, "mission.json"), encoding="utf-8") as f:
        info = json.load(f)
    names = list(streams) if streams is not None else [
        s for s in STREAM_FILES if os.path.exists(os.path.join(directory, s))]
    data = {name: _columns(_core.read_stream(directory, name)) for name in names}
    floorplan = None
    if info.get("floorplan") and os.path.exists(os.path.join(directory, info["floorplan"])):
        with open(os.path.join(directory, info["floorplan"]), encoding="utf-8") as f:
            floorplan = json.load(f)
    return Mission(info, data, floorplan, directory)


def _cell(value: Any, integer: bool) -> str:
    if isinstance(value, (str, np.str_)):
        return str(value)
    if value is None:
        return ""
    number = float(value)
    if math.isnan(number):
        return ""
    if integer:
        if not number.is_integer():
            raise ValueError(f"'{value}' is not a whole number")
        return str(int(number))
    return repr(number)  # shortest text that reads back as the same double


def to_csv(columns: Columns) -> str:
    """Columns (equal lengths) as CSV text with the columns' names as header; NaN and None
    become empty cells, numbers their shortest round-trip text."""
    names = list(columns.keys())
    if not names:
        raise ValueError("no columns")
    values = [np.asarray(columns[n]).tolist() if not isinstance(columns[n], list) else columns[n]
              for n in names]
    lengths = {len(v) for v in values}
    if len(lengths) != 1:
        raise ValueError("columns of different lengths: " +
                         ", ".join(f"{n} {len(v)}" for n, v in zip(names, values)))
    integer = [n in _INTEGER_COLUMNS for n in names]
    lines = [",".join(names)]
    for row in zip(*values):
        lines.append(",".join(_cell(v, i) for v, i in zip(row, integer)))
    return "\n".join(lines) + "\n"


def write_mission(mission_dir: PathLike, info: Mapping[str, Any],
                  streams: Mapping[str, Columns], floorplan: Optional[Mapping[str, Any]] = None) -> None:
    """Writes a mission directory: mission.json from `info`, each stream from its columns
    (written canonically after the readers' checks: a bad row raises InputError naming the
    stream and its line), and the floor plan GeoJSON (under info["floorplan"], default
    "floorplan.geojson"). The directory is then opened as the CLI would open it."""
    directory = os.fspath(mission_dir)
    os.makedirs(directory, exist_ok=True)
    info = dict(info)
    if floorplan is not None:
        info.setdefault("floorplan", "floorplan.geojson")
        with open(os.path.join(directory, info["floorplan"]), "w", encoding="utf-8") as f:
            json.dump(floorplan, f)
    with open(os.path.join(directory, "mission.json"), "w", encoding="utf-8") as f:
        json.dump(info, f, indent=2)
    for name, columns in streams.items():
        _core.write_stream(name, f"{name} (from Python)", to_csv(columns), os.path.join(directory, name))
    _core.validate_mission(directory)


def evaluate(mission_dir: PathLike, estimates: Union[Columns, PathLike], max_series: int = 5000) -> dict:
    """Scores estimates (columns, e.g. from run_pipeline, or the path of an estimates.csv)
    against the mission's truth, as `trailmark eval` does: metrics.json as a dict."""
    if isinstance(estimates, (str, os.PathLike)):
        path = os.fspath(estimates)
        with open(path, encoding="utf-8") as f:
            text, name = f.read(), path
    else:
        text, name = to_csv(estimates), "estimates (from Python)"
    return json.loads(_core.evaluate(os.fspath(mission_dir), name, text, max_series))


class OnlineEstimator:
    """A pipeline's online estimator for a mission's incident (its nodes and floor plan from
    mission.json), driven row by row as the live server drives it:

        est = trailmark.OnlineEstimator("pdr", "out/mission")
        est.add("steps.csv", {"t0": 0.0, "t1": 0.6, "agent": "ff1", "dx": 0.7, "dy": 0.0})
        est.current("ff1")            # {'t': 0.6, 'x': ..., 'sxx': ..., ...} or None
        est.finish(); est.estimates() # every estimate so far, as columns

    `live=True` (default) accepts rows interleaved by device, each device's rows of a stream in
    time order; `live=False` expects rows in global time order, as a batch run merges them.
    """

    def __init__(self, pipeline: str, mission_dir: PathLike,
                 options: Optional[Mapping[str, Any]] = None, live: bool = True):
        self._core = _core.OnlineEstimator(pipeline, os.fspath(mission_dir), _options(options), live)
        self._taken: list = []
        self._rows = 0

    @property
    def pipeline(self) -> str:
        return self._core.pipeline

    @property
    def streams(self) -> list:
        """The mission's stream files a batch run feeds this pipeline (steps.csv shadows
        imu.csv for a steps-based one): `Mission.rows(estimator.streams)` replays the batch run."""
        return list(self._core.streams)

    def add(self, stream: str, row: Mapping[str, Any]) -> None:
        """One row of a stream ("steps.csv", "imu.csv", ...), as a mapping of column to value."""
        self.add_columns(stream, {k: [v] for k, v in row.items()})

    def add_columns(self, stream: str, columns: Columns) -> int:
        """Many rows of one stream as columns (numpy arrays or lists); returns the count.
        The GIL is released while the estimator works."""
        name = f"{stream} (rows {self._rows + 1}.. from Python)"
        added = self._core.add(stream, name, to_csv(columns))
        self._rows += added
        return added

    def finish(self) -> None:
        """End of data: whatever the estimator holds is processed, final estimates emitted."""
        self._core.finish()

    def current(self, node: str) -> Optional[dict]:
        """The node's current estimate (t, x, y, z, sxx, sxy, syy[, szz, floor]) or None."""
        return self._core.current(node)

    def take_estimates(self) -> Estimates:
        """The estimates emitted since the last call, as columns."""
        cols = _columns(self._core.take_estimates())
        self._taken.append(cols)
        return Estimates(cols, self.summary())

    def estimates(self) -> Estimates:
        """Every estimate emitted so far, as columns (in emission order, restamped to
        non-decreasing time as estimates.csv is)."""
        self.take_estimates()
        merged = {k: np.concatenate([c[k] for c in self._taken]) for k in self._taken[0]}
        return Estimates(merged, self.summary())

    def summary(self) -> dict:
        """Numbers, notes and integrity notes so far."""
        return self._core.summary()

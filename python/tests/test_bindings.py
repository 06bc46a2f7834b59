# SPDX-License-Identifier: MIT
"""The Python bindings against the CLI: the same estimates, metrics and files; row-by-row
online estimation equal to the batch run; bad input raising InputError with file and line."""

import json
import os
import shutil
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

import trailmark
from conftest import assert_same_columns, cli_path, read_csv_columns, run_cli


def test_registry_matches_cli():
    cli = json.loads(run_cli("pipelines", "--json"))
    assert trailmark.pipelines() == [p["name"] for p in cli]
    assert trailmark.pipeline_info("pdr")["description"] == cli[0]["description"]
    with pytest.raises(ValueError, match="no pipeline 'nope'"):
        trailmark.pipeline_info("nope")


def test_version_is_the_projects():
    assert trailmark.__version__ == run_cli("--version").split()[-1]


# Every pipeline on a mission that can feed it, with and without options.
CASES = [
    ("office", "pdr", {}),
    ("office", "breadcrumb", {}),
    ("floors", "pdr", {}),
    ("floors", "mapmatch", {"particles": 300}),
    ("corridor", "landmarks-stopgo", {}),
    ("corridor", "landmarks-ukf", {}),
    ("lab", "beacons-mds", {}),
    ("lab", "beacons-ekf", {}),
]


@pytest.mark.parametrize("mission,pipeline,options", CASES)
def test_run_pipeline_equals_cli(missions, tmp_path, mission, pipeline, options):
    directory = missions[mission]
    args = ["run", "--pipeline", pipeline, directory, "--out", tmp_path / "run"]
    for key, value in options.items():
        args += ["--option", f"{key}={value}"]
    run_cli(*args)
    ours = trailmark.run_pipeline(pipeline, directory, options)
    cli = read_csv_columns(tmp_path / "run" / "estimates.csv")
    assert len(ours) == len(cli["t"]) > 0
    assert_same_columns(ours, cli)
    with open(tmp_path / "run" / "diagnostics.json") as f:
        diagnostics = json.load(f)
    def measured(numbers):  # everything but the timings measured during the run
        return {k: v for k, v in numbers.items() if "latency" not in k}

    assert measured(ours.summary["numbers"]) == pytest.approx(measured(diagnostics["numbers"]))
    assert ours.summary["notes"] == diagnostics["notes"]


def test_evaluate_equals_cli(missions, tmp_path):
    directory = missions["office"]
    run_cli("run", "--pipeline", "breadcrumb", directory, "--out", tmp_path / "run")
    run_cli("eval", directory, tmp_path / "run" / "estimates.csv", "--out", tmp_path / "m.json")
    with open(tmp_path / "m.json") as f:
        cli = json.load(f)
    from_columns = trailmark.evaluate(directory, trailmark.run_pipeline("breadcrumb", directory))
    from_file = trailmark.evaluate(directory, tmp_path / "run" / "estimates.csv")
    assert from_columns == cli
    assert from_file == cli
    assert cli["overall"]["agents"]["p75_m"] > 0


def test_floor_columns_where_the_mission_has_floors(missions):
    floors = trailmark.run_pipeline("pdr", missions["floors"])
    assert {"szz", "floor"} <= set(floors)
    assert np.all(np.isfinite(floors["szz"])) and np.all(floors["floor"] == np.round(floors["floor"]))
    assert "floor" not in trailmark.run_pipeline("pdr", missions["office"])


def test_read_write_round_trip(missions, tmp_path):
    source = missions["office"]
    mission = trailmark.read_mission(source)
    assert mission.info["nodes"] and set(mission.streams) >= {"steps.csv", "rssi.csv", "truth.csv"}
    steps = mission.streams["steps.csv"]
    assert steps["agent"].dtype == object and steps["dx"].dtype == np.float64
    copy = tmp_path / "copy"
    trailmark.write_mission(copy, mission.info, mission.streams, mission.floorplan)
    for name in mission.streams:  # canonical text both ways: byte for byte
        with open(source / name) as a, open(copy / name) as b:
            assert a.read() == b.read(), name
    assert_same_columns(trailmark.run_pipeline("breadcrumb", copy),
                        trailmark.run_pipeline("breadcrumb", source))


def test_metamorphic_shift_of_the_frame(missions, tmp_path):
    """The same walk in a frame shifted by (1000, -250) m: pdr's estimates shift by exactly that."""
    mission = trailmark.read_mission(missions["office"], streams=["steps.csv", "events.csv", "truth.csv"])
    info = json.loads(json.dumps(mission.info))
    shift = np.array([1000.0, -250.0])
    for node in info["nodes"]:
        for key in ("start", "position"):
            if key in node and node[key] is not None:
                node[key] = [node[key][0] + shift[0], node[key][1] + shift[1], *node[key][2:]]
    truth = dict(mission.streams["truth.csv"])
    truth["x"] = truth["x"] + shift[0]
    truth["y"] = truth["y"] + shift[1]
    info.pop("floorplan", None)
    trailmark.write_mission(tmp_path / "a", {k: v for k, v in mission.info.items() if k != "floorplan"},
                            mission.streams)
    trailmark.write_mission(tmp_path / "b", info, dict(mission.streams, **{"truth.csv": truth}))
    a = trailmark.run_pipeline("pdr", tmp_path / "a")
    b = trailmark.run_pipeline("pdr", tmp_path / "b")
    assert np.allclose(b["x"] - a["x"], shift[0], atol=1e-6)
    assert np.allclose(b["y"] - a["y"], shift[1], atol=1e-6)
    assert np.array_equal(a["sxx"], b["sxx"])
    ma = trailmark.evaluate(tmp_path / "a", a)["overall"]["agents"]
    mb = trailmark.evaluate(tmp_path / "b", b)["overall"]["agents"]
    assert mb["p75_m"] == pytest.approx(ma["p75_m"], abs=1e-6)


@pytest.mark.parametrize("mission,pipeline,live", [("floors", "pdr", False), ("office", "breadcrumb", False),
                                                   ("office", "breadcrumb", True), ("corridor", "landmarks-ukf", True)])
def test_online_row_by_row_equals_batch(missions, mission, pipeline, live):
    directory = missions[mission]
    data = trailmark.read_mission(directory)
    estimator = trailmark.OnlineEstimator(pipeline, directory, live=live)
    for stream, columns in data.rows(estimator.streams):
        n = len(next(iter(columns.values())))
        if n <= 3:  # some one row at a time, as a live feed would
            for k in range(n):
                estimator.add(stream, {c: v[k] for c, v in columns.items()})
        else:
            assert estimator.add_columns(stream, columns) == n
    agent = next(n["id"] for n in data.info["nodes"] if n["kind"] == "agent")
    assert estimator.current(agent) is not None
    estimator.finish()
    online = estimator.estimates()
    assert_same_columns(online, trailmark.run_pipeline(pipeline, directory))
    assert estimator.summary()["numbers"]


def test_bad_rows_name_the_stream_and_line(missions, tmp_path):
    mission = trailmark.read_mission(missions["office"], streams=["steps.csv"])
    steps = {k: v.copy() for k, v in mission.streams["steps.csv"].items()}
    steps["dx"][4] = np.inf
    with pytest.raises(trailmark.InputError) as error:
        trailmark.write_mission(tmp_path / "bad", mission.info, {"steps.csv": steps})
    assert error.value.line == 6 and "steps.csv" in error.value.file and "dx" in str(error.value)
    with pytest.raises(ValueError, match="columns of different lengths"):
        trailmark.to_csv({"t": [1.0, 2.0], "agent": ["ff1"]})

    estimator = trailmark.OnlineEstimator("pdr", missions["office"])
    with pytest.raises(trailmark.InputError, match="not an agent|no agent|unknown"):
        estimator.add("steps.csv", {"t0": 0.0, "t1": 0.5, "agent": "ghost", "dx": 0.5, "dy": 0.0})
    with pytest.raises(ValueError, match="unknown stream 'wifi.csv'"):
        estimator.add("wifi.csv", {"t": 0.0})
    # The estimator stays usable after a refused row.
    agent = next(n["id"] for n in mission.info["nodes"] if n["kind"] == "agent")
    estimator.add("steps.csv", {"t0": 0.0, "t1": 0.5, "agent": agent, "dx": 0.5, "dy": 0.0})
    assert estimator.current(agent)["t"] == 0.5


def test_bad_files_and_options(missions, tmp_path):
    broken = tmp_path / "broken"
    shutil.copytree(missions["office"], broken)
    with open(broken / "steps.csv") as f:
        lines = f.readlines()
    lines[3] = lines[3].replace(",", ",x", 1)
    with open(broken / "steps.csv", "w") as f:
        f.writelines(lines)
    with pytest.raises(trailmark.InputError) as error:
        trailmark.read_mission(broken)
    assert error.value.line == 4 and error.value.file.endswith("steps.csv")
    with pytest.raises(trailmark.InputError) as error:
        trailmark.run_pipeline("pdr", broken)
    assert error.value.line == 4
    with pytest.raises(ValueError, match="nope"):
        trailmark.run_pipeline("nope", missions["office"])
    with pytest.raises(ValueError, match="no_such_key"):
        trailmark.run_pipeline("pdr", missions["office"], {"no_such_key": 1})
    with pytest.raises(trailmark.InputError, match="mission.json"):
        trailmark.run_pipeline("pdr", tmp_path)
    plain = trailmark.read_mission(missions["office"], streams=["steps.csv"])
    del plain.info["floorplan"]
    trailmark.write_mission(tmp_path / "plain", plain.info, plain.streams)
    with pytest.raises(trailmark.InputError, match="needs a floor plan"):
        trailmark.OnlineEstimator("mapmatch", tmp_path / "plain")


def test_long_runs_release_the_gil(missions):
    """The main thread keeps running while a pipeline runs in another thread: it wakes from
    1 ms sleeps hundreds of times during the run. With the GIL held by the run it could wake
    only before the run starts and after it ends (a handful of times)."""
    worker = threading.Thread(target=lambda: trailmark.run_pipeline("mapmatch", missions["floors"]))
    wakes = 0
    worker.start()
    while worker.is_alive():
        time.sleep(0.001)
        wakes += 1
    worker.join()
    assert wakes >= 50, f"the main thread woke only {wakes} times during the run"


def test_recorded_ins_equals_cli(tmp_path):
    """A recorded foot-IMU walk (OpenShoe's 820 Hz figure 8): the Python run gives the CLI's
    estimates."""
    source = os.path.join(os.environ.get("TRAILMARK_SHARED_DIR", ""), "data", "openshoe-figure8",
                          "imu_820hz.txt")
    if not os.path.exists(source):
        pytest.skip("../shared/data/openshoe-figure8 not present")
    run_cli("convert", "openshoe-figure8", source, "--out", tmp_path / "m")
    run_cli("run", "--pipeline", "ins", tmp_path / "m", "--out", tmp_path / "run")
    ours = trailmark.run_pipeline("ins", tmp_path / "m")
    cli = read_csv_columns(tmp_path / "run" / "estimates.csv")
    assert len(ours) > 1000
    assert_same_columns(ours, cli)


def test_docs_example_runs(tmp_path):
    script = os.path.join(os.environ.get("TRAILMARK_SOURCE_DIR", ""), "docs", "examples", "python_quickstart.py")
    if not os.path.exists(script):
        pytest.skip("TRAILMARK_SOURCE_DIR not set")
    result = subprocess.run([sys.executable, script, "--cli", cli_path(), "--work", str(tmp_path)],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert "p75" in result.stdout and "breadcrumb" in result.stdout


def test_no_library_logging_on_stderr(tmp_path, capfd):
    # A beacon-trail variant whose map solve meets a failed linear solve inside Levenberg-Marquardt:
    # Ceres' glog warnings (12 lines before 2026-12-06) stay off the process's stderr.
    run_cli("simulate", "beacon-trail", "--seed", 119, "--vary", 19, "--family", "all",
            "--out", tmp_path / "bt19")
    capfd.readouterr()
    estimates = trailmark.run_pipeline("beacons-ekf", tmp_path / "bt19")
    assert len(estimates["t"]) > 0
    assert capfd.readouterr().err == ""

# SPDX-License-Identifier: MIT
"""Fixtures: the CLI built with the bindings (TRAILMARK_CLI) and missions it simulates."""

import csv
import os
import subprocess

import numpy as np
import pytest


def cli_path():
    path = os.environ.get("TRAILMARK_CLI")
    if not path or not os.path.exists(path):
        pytest.skip("TRAILMARK_CLI not set (run through ctest)")
    return path


def run_cli(*args):
    result = subprocess.run([cli_path(), *map(str, args)], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    return result.stdout


def read_csv_columns(path):
    """A CSV file as columns: numbers as float arrays (empty cells NaN), other cells as str."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    header = list(rows[0].keys()) if rows else []
    out = {}
    for name in header:
        cells = [r[name] for r in rows]
        try:
            out[name] = np.array([float(c) if c != "" else np.nan for c in cells])
        except ValueError:
            out[name] = np.array(cells, dtype=object)
    return out


def assert_same_columns(ours, cli):
    """Every column of the CLI's file is in `ours` with exactly the same values."""
    assert list(ours.keys()) == list(cli.keys())
    for name, expected in cli.items():
        got = ours[name]
        if expected.dtype == object:
            assert list(got) == list(expected), name
        else:
            assert got.dtype == np.float64, name
            assert np.array_equal(got, expected, equal_nan=True), name


@pytest.fixture(scope="session")
def missions(tmp_path_factory):
    """Simulated missions (seeds not used for any setting): name -> directory."""
    root = tmp_path_factory.mktemp("missions")
    made = {}
    for name, scenario, seed in [("office", "office-loop-1lap", 41), ("floors", "multi-floor", 43),
                                 ("corridor", "landmark-corridor", 47), ("lab", "beacon-lab", 53)]:
        run_cli("simulate", scenario, "--seed", seed, "--out", root / name)
        made[name] = root / name
    return made

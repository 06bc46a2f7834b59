#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""trailmark from Python, notebook style (docs/python.md). The tests run this script.

    PYTHONPATH=build/release/python python3 docs/examples/python_quickstart.py \
        --cli build/release/apps/trailmark/trailmark --work /tmp/quickstart
"""

import argparse
import os
import subprocess

import numpy as np

import trailmark

parser = argparse.ArgumentParser()
parser.add_argument("--cli", default="trailmark", help="the trailmark executable (to simulate)")
parser.add_argument("--work", default="quickstart", help="a directory to write the mission in")
args = parser.parse_args()

# %% A simulated mission: one lap of the breadcrumb paper's office loop.
mission_dir = os.path.join(args.work, "office")
subprocess.run([args.cli, "simulate", "office-loop-1lap", "--seed", "7", "--out", mission_dir],
               check=True, capture_output=True)
mission = trailmark.read_mission(mission_dir)
print(mission)
steps = mission.streams["steps.csv"]
print(f"walked {np.hypot(steps['dx'], steps['dy']).sum():.0f} m in {len(steps['t1'])} steps")

# %% Every pipeline the mission can feed, scored against the truth.
print(f"{'pipeline':<12} {'p75 (m)':>8} {'in95':>6}")
for name in trailmark.runnable_pipelines(mission_dir):
    estimates = trailmark.run_pipeline(name, mission_dir)
    agents = trailmark.evaluate(mission_dir, estimates)["overall"]["agents"]
    print(f"{name:<12} {agents['p75_m']:8.2f} {agents['in95']:6.2f}")

# %% The breadcrumb estimator online, fed as a live system would feed it.
estimator = trailmark.OnlineEstimator("breadcrumb", mission_dir)
for stream, rows in mission.rows(estimator.streams):
    estimator.add_columns(stream, rows)
now = estimator.current("ff1")
print(f"ff1 at t={now['t']:.1f} s: ({now['x']:.1f}, {now['y']:.1f}) m, "
      f"sigma {np.sqrt(now['sxx']):.1f} x {np.sqrt(now['syy']):.1f} m")
estimator.finish()
summary = estimator.summary()
print("breadcrumb:", ", ".join(f"{k} {v:g}" for k, v in list(summary["numbers"].items())[:4]),
      f"({len(summary['integrity'])} integrity notes)")

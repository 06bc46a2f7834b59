#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# The main job: install, build Release, simulate the default mission, run every pipeline on it,
# print the summary table and write out/demo/report.html.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
bash scripts/install-deps.sh
bash scripts/build.sh release
./build/release/apps/trailmark/trailmark demo --out out/demo "$@"
echo "open out/demo/report.html in a browser"

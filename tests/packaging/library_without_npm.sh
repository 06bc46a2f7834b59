#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# The library alone configures without npm's Chart.js; with the report on it is refused.
set -euo pipefail
cmake="$1"; src="$2"; out="$3"
rm -rf "$out" "$out-control"
lib_only=(-DTRAILMARK_BUILD_APPS=OFF -DTRAILMARK_BUILD_TESTS=OFF -DTRAILMARK_BUILD_BENCH=OFF
          -DTRAILMARK_BUILD_PYTHON=OFF -DTRAILMARK_BUILD_DOCS=OFF -DCHARTJS_FILE=/nonexistent/chart.umd.js)
"$cmake" -S "$src" -B "$out" -G Ninja -DTRAILMARK_BUILD_REPORT=OFF "${lib_only[@]}" > "$out.log" 2>&1 \
  || { cat "$out.log"; echo "the library without the report does not configure"; exit 1; }
if grep -q "trailmark_report" "$out/build.ninja"; then echo "the report is still built"; exit 1; fi
grep -q "trailmark_pipelines" "$out/build.ninja" || { echo "the library is not built"; exit 1; }
if "$cmake" -S "$src" -B "$out-control" -G Ninja -DTRAILMARK_BUILD_REPORT=ON "${lib_only[@]}" > "$out-control.log" 2>&1; then
  echo "control: a report build without Chart.js configured"; exit 1
fi
grep -q "Chart.js bundle missing" "$out-control.log" || { cat "$out-control.log"; exit 1; }
rm -rf "$out" "$out-control" "$out.log" "$out-control.log"
echo "library without npm: configures; the report build refuses a missing Chart.js"

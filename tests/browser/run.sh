#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Browser test of the dashboard: a replayed two-firefighter mission (371 s at 10x, so the replay
# outlasts a slow Chromium start on a loaded machine), Debian's Chromium headless; then the
# floor selector on the multi-floor building.
set -euo pipefail
TM="$1"
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
dir=$(mktemp -d)
trap 'kill $pid 2>/dev/null || true; rm -rf "$dir"' EXIT
[ -d "$here/node_modules/playwright-core" ] && [ -d "$here/node_modules/axe-core" ] || { echo "FAIL: run scripts/install-deps.sh (npm ci in tests/browser)"; exit 1; }
# The dashboard's pure helpers, compiled with the dashboard's own TypeScript.
web="$here/../../web/dashboard"
"$web/node_modules/.bin/tsc" --target es2022 --module es2022 --moduleResolution bundler \
  --outDir "$dir/geometry" "$web/src/geometry.ts" || { echo "FAIL: tsc geometry.ts"; exit 1; }
echo '{"type":"module"}' > "$dir/geometry/package.json"
node "$here/geometry.mjs" "$dir/geometry"
"$TM" simulate training-building --seed 2 --out "$dir/m" > /dev/null
"$TM" serve --replay "$dir/m" --pipeline pdr --speed 10 --port 0 --token br0wser > "$dir/serve.log" 2>&1 &
pid=$!
for _ in $(seq 100); do grep -q "listening on" "$dir/serve.log" && break; sleep 0.1; done
port=$(sed -n 's|.*listening on http://127.0.0.1:\([0-9]*\)/.*|\1|p' "$dir/serve.log")
[ -n "$port" ] || { cat "$dir/serve.log"; echo "FAIL: serve did not start"; exit 1; }
node "$here/dashboard.mjs" "http://127.0.0.1:$port" br0wser 2 "${SCREENSHOT:-$dir/dashboard.png}"
kill $pid; wait $pid 2>/dev/null || true
# The HTML report's map at true scale, zoomable (issue 28, item 5).
"$TM" run --pipeline pdr "$dir/m" --out "$dir/run-pdr" > /dev/null
"$TM" run --pipeline breadcrumb "$dir/m" --out "$dir/run-breadcrumb" > /dev/null
"$TM" report "$dir/run-pdr" "$dir/run-breadcrumb" --out "$dir/report.html" > /dev/null
report_shot="${SCREENSHOT:+${SCREENSHOT%.png}-report.png}"
node "$here/report.mjs" "$dir/report.html" $report_shot
# ... with map matching's search patterns as layers to tick on (issue 23).
"$TM" simulate house1-search --seed 1 --out "$dir/h" > /dev/null
"$TM" run --pipeline mapmatch "$dir/h" --out "$dir/run-mapmatch" > /dev/null
"$TM" report "$dir/run-mapmatch" --out "$dir/report-house.html" > /dev/null
node "$here/report.mjs" "$dir/report-house.html" | tee "$dir/report-house.log"
grep -q "ticked on: search sequences" "$dir/report-house.log" || { echo "FAIL: the house report has no search-pattern layer"; exit 1; }
# The floor selector: the multi-floor building drawn in another frame (rotated 224 degrees, the
# origin 1.2 km away: the view must fit the building, not the origin), replayed at 20x.
"$TM" simulate multi-floor --seed 3 --vary 1 --family frame --out "$dir/f" > /dev/null
"$TM" serve --replay "$dir/f" --pipeline pdr --speed 20 --port 0 --token br0wser > "$dir/serve2.log" 2>&1 &
pid=$!
for _ in $(seq 100); do grep -q "listening on" "$dir/serve2.log" && break; sleep 0.1; done
port=$(sed -n 's|.*listening on http://127.0.0.1:\([0-9]*\)/.*|\1|p' "$dir/serve2.log")
[ -n "$port" ] || { cat "$dir/serve2.log"; echo "FAIL: serve did not start"; exit 1; }
shot="${SCREENSHOT:-$dir/dashboard.png}"
node "$here/floors.mjs" "http://127.0.0.1:$port" br0wser "${shot%.png}-floors.png"
echo "browser: 4 passed, 0 failed"

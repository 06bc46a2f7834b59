#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# The dashboard's soak test (issue 28, item 2): the 4-hour, 20-firefighter synthetic incident
# replayed at 120x (about two minutes) into headless Chromium; soak.mjs measures and asserts.
set -euo pipefail
TM="$1"; out="${2:-}"
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
dir=$(mktemp -d)
trap 'kill $pid 2>/dev/null || true; rm -rf "$dir"' EXIT
[ -d "$here/node_modules/playwright-core" ] || { echo "FAIL: run scripts/install-deps.sh (npm ci in tests/browser)"; exit 1; }
"$TM" simulate incident-4h --seed 11 --out "$dir/m" > /dev/null
"$TM" serve --replay "$dir/m" --pipeline pdr --speed 120 --port 0 --token s0ak > "$dir/serve.log" 2>&1 &
pid=$!
for _ in $(seq 300); do grep -qs "listening on" "$dir/serve.log" && break; sleep 0.1; done
port=$(sed -n 's|.*listening on http://127.0.0.1:\([0-9]*\)/.*|\1|p' "$dir/serve.log")
[ -n "$port" ] || { cat "$dir/serve.log"; echo "FAIL: serve did not start"; exit 1; }
node "$here/soak.mjs" "http://127.0.0.1:$port" s0ak $out
echo "soak: 1 passed, 0 failed"

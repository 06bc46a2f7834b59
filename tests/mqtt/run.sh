#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# MQTT end to end: a Mosquitto broker started here on a free loopback port, `trailmark serve
# --live --mqtt`, devices publishing rows (QoS 1), a malformed message, a last-will "lost"; the
# state over HTTP, the retained estimate over MQTT, and the journal equal to what was published.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh" "$1"
start_broker "allow_anonymous true"
"$TM" simulate office-loop-1lap --seed 4 --out "$dir/m" > /dev/null
mkdir -p "$dir/live" && cp "$dir/m/mission.json" "$dir/live/"
"$TM" serve --live "$dir/live" --journal "$dir/j.db" --mqtt "tcp://127.0.0.1:$port" --incident inc7 \
  --port 0 --token mq > "$dir/serve.log" 2>&1 &
serve_pid=$!
for _ in $(seq 50); do grep -q "listening on" "$dir/serve.log" && break; sleep 0.1; done
hport=$(sed -n 's|.*listening on http://127.0.0.1:\([0-9]*\)/.*|\1|p' "$dir/serve.log")
[ -n "$hport" ] || fail "serve did not start"
header=$(head -1 "$dir/m/steps.csv")
sed -n 2,101p "$dir/m/steps.csv" | split -l 25 - "$dir/chunk."  # (sed, not tail | head: SIGPIPE under pipefail)
for c in "$dir"/chunk.*; do
  { echo "$header"; cat "$c"; } > "$dir/body.csv"
  mosquitto_pub -p "$port" -q 1 -t trailmark/inc7/ff1/steps.csv -f "$dir/body.csv"
done
mosquitto_pub -p "$port" -q 1 -t trailmark/inc7/ff1/steps.csv -m 'not,a,mission,row'
sleep 2.5
curl -s -H "Authorization: Bearer mq" "http://127.0.0.1:$hport/api/state" > "$dir/state.json"
grep -q '"id":"ff1"' "$dir/state.json" || fail "state after MQTT ingest: $(cat "$dir/state.json")"
timeout 5 mosquitto_sub -p "$port" -C 1 -t trailmark/inc7/ff1/estimate > "$dir/estimate.json" || fail "no retained estimate"
grep -q '"kind":"agent"' "$dir/estimate.json" || fail "estimate payload: $(cat "$dir/estimate.json")"
mosquitto_pub -p "$port" -q 1 -r -t trailmark/inc7/ff1/status -m lost   # a device's last will
sleep 0.5
curl -s -H "Authorization: Bearer mq" "http://127.0.0.1:$hport/api/state" | matches '"kind":"device-lost"' \
  || fail "no device-lost alert"
kill $serve_pid; wait $serve_pid || true; serve_pid=""
grep -q "1 rejected" "$dir/serve.log" || fail "the malformed message was not counted"
"$TM" journal export "$dir/j.db" --mission "$dir/live" --out "$dir/exported" > /dev/null
cmp <(sed -n 2,101p "$dir/m/steps.csv") <(tail -n +2 "$dir/exported/steps.csv") \
  || fail "journal differs from what was published"
echo "mqtt: 1 passed, 0 failed"

# SPDX-License-Identifier: MIT
# Shared by the MQTT tests (sourced): a scratch directory cleaned up on exit, `fail`, and
# `start_broker "CONFIG LINES"`, which starts Mosquitto on a free loopback port (sets $port and
# $broker_pid) with the given configuration after its listener line.
TM="$1"
dir=$(mktemp -d)
serve_pid=""; broker_pid=""
cleanup() { kill $serve_pid $broker_pid 2>/dev/null || true; rm -rf "$dir"; }
trap cleanup EXIT
fail() { echo "FAIL: $*"; cat "$dir"/*.log 2>/dev/null | tail -20; exit 1; }
# `cmd | matches PATTERN`: like grep -q, but reads to the end — grep -q stops at the first
# match and the writer then dies of SIGPIPE, which pipefail turns into a failure.
matches() { grep "$@" > /dev/null; }
command -v mosquitto > /dev/null || fail "mosquitto not installed (scripts/install-deps.sh)"
start_broker() {
  for _ in $(seq 20); do  # a free port
    port=$(( 20000 + RANDOM % 20000 ))
    printf 'listener %s 127.0.0.1\n%s\npersistence false\n' "$port" "$1" > "$dir/mosquitto.conf"
    mosquitto -c "$dir/mosquitto.conf" > "$dir/broker.log" 2>&1 &
    broker_pid=$!
    sleep 0.3
    kill -0 $broker_pid 2>/dev/null && return 0
  done
  fail "no free port for the broker"
}

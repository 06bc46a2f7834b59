#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# TLS and authentication end to end: a self-signed certificate made here (openssl), a Mosquitto
# with a TLS listener that requires a user name and password, `trailmark serve --live` over
# HTTPS connecting to it with ssl://, --mqtt-ca and credentials. Checks: HTTPS answers only
# with the certificate trusted, the broker refuses an anonymous device and accepts the server,
# rows published over TLS are journaled and estimated, plain HTTP is not served, a connection
# that never starts its TLS handshake is closed after the header deadline (2 s here).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh" "$1"
command -v openssl > /dev/null || fail "openssl needed (scripts/install-deps.sh)"
openssl req -x509 -newkey rsa:2048 -nodes -days 2 -subj /CN=localhost \
  -addext "subjectAltName=DNS:localhost,IP:127.0.0.1" \
  -keyout "$dir/key.pem" -out "$dir/cert.pem" > "$dir/openssl.log" 2>&1 || fail "openssl"
mosquitto_passwd -b -c "$dir/passwd" trailmark s3cret > /dev/null 2>&1 || fail "mosquitto_passwd"
# Mosquitto started as root drops to the mosquitto user: it must be able to read these.
chmod 755 "$dir" && chmod 644 "$dir/passwd" "$dir/key.pem" "$dir/cert.pem"
start_broker "cafile $dir/cert.pem
certfile $dir/cert.pem
keyfile $dir/key.pem
allow_anonymous false
password_file $dir/passwd"
"$TM" simulate office-loop-1lap --seed 4 --out "$dir/m" > /dev/null
mkdir -p "$dir/live" && cp "$dir/m/mission.json" "$dir/live/"
TRAILMARK_MQTT_PASSWORD=s3cret "$TM" serve --live "$dir/live" --journal "$dir/j.db" \
  --mqtt "ssl://127.0.0.1:$port" --mqtt-ca "$dir/cert.pem" --mqtt-user trailmark --incident tls \
  --tls-cert "$dir/cert.pem" --tls-key "$dir/key.pem" --port 0 --token tt --header-deadline 2 \
  > "$dir/serve.log" 2>&1 &
serve_pid=$!
for _ in $(seq 50); do grep -q "listening on" "$dir/serve.log" && break; sleep 0.1; done
hport=$(sed -n 's|.*listening on https://127.0.0.1:\([0-9]*\)/.*|\1|p' "$dir/serve.log")
[ -n "$hport" ] || fail "serve over HTTPS did not start"
# HTTPS: verified with our CA; refused without it; plain HTTP gets no answer.
curl -s --cacert "$dir/cert.pem" "https://localhost:$hport/api/health" | matches '"ok": *true' || fail "HTTPS health"
curl -s "https://localhost:$hport/api/health" > /dev/null 2>&1 && fail "an untrusted certificate was accepted"
curl -s --max-time 2 "http://127.0.0.1:$hport/api/health" > /dev/null 2>&1 && fail "plain HTTP answered"
# A stranger that connects and never starts the handshake is closed after 2 s (the library's
# own handshake waited for its 5 s read timeout, and as long as bytes trickled in).
exec 3<>"/dev/tcp/127.0.0.1/$hport"
t0=$(date +%s%N)
timeout 8 cat <&3 > /dev/null || fail "a connection without a TLS handshake was kept open"
exec 3<&-
waited_ms=$(( ($(date +%s%N) - t0) / 1000000 ))
[ "$waited_ms" -ge 1500 ] && [ "$waited_ms" -le 4000 ] || fail "closed after $waited_ms ms, not ~2 s"
curl -s --cacert "$dir/cert.pem" -H "Authorization: Bearer tt" "https://localhost:$hport/api/stats" \
  | matches '"tls_handshakes_failed": *[1-9]' || fail "the failed handshake is not counted"
# An anonymous device is refused by the broker; one with the credentials is accepted.
mosquitto_pub -p "$port" --cafile "$dir/cert.pem" -h localhost -q 1 -t tls/x -m x > "$dir/anon.log" 2>&1 \
  && fail "the broker accepted an anonymous client"
header=$(head -1 "$dir/m/steps.csv")
{ echo "$header"; sed -n 2,41p "$dir/m/steps.csv"; } > "$dir/body.csv"  # (not tail | head: SIGPIPE under pipefail)
mosquitto_pub -p "$port" --cafile "$dir/cert.pem" -h localhost -u trailmark -P s3cret -q 1 \
  -t trailmark/tls/ff1/steps.csv -f "$dir/body.csv" || fail "publish over TLS"
for _ in $(seq 30); do
  curl -s --cacert "$dir/cert.pem" -H "Authorization: Bearer tt" "https://localhost:$hport/api/state" \
    | matches '"id":"ff1"' && break
  sleep 0.1
done
curl -s --cacert "$dir/cert.pem" -H "Authorization: Bearer tt" "https://localhost:$hport/api/state" \
  | matches '"id":"ff1"' || fail "no estimate after publishing over TLS"
kill $serve_pid; wait $serve_pid || true; serve_pid=""
"$TM" journal export "$dir/j.db" --mission "$dir/live" --out "$dir/exported" > /dev/null
cmp <(tail -n +2 "$dir/body.csv") <(tail -n +2 "$dir/exported/steps.csv") || fail "journal differs"
echo "tls: 1 passed, 0 failed"

#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# End-to-end: the command-line contract on a fresh simulated mission, and bad input gives a
# clear error with a non-zero exit code (never a crash).
set -euo pipefail
TM="$1"
dir=$(mktemp -d)
trap 'status=$?; pids=$(jobs -p); [ -z "$pids" ] || kill $pids 2>/dev/null; rm -rf "$dir"; exit $status' EXIT  # no server left behind
fail() { echo "FAIL: $*"; exit 1; }
# A command that stops the script through `set -e` names itself (CI once saw this test fail
# with no FAIL line); commands run by run_failing (errexit off) are meant to fail and do not.
set -E
trap 'err=$?; [[ $- == *e* ]] && echo "FAIL: line $LINENO: exit $err from: $BASH_COMMAND" >&2' ERR
# Runs a command that must fail; leaves its exit code in $rc and its stderr in $dir/err.
# `cmd | matches PATTERN`: like grep -q, but reads to the end — grep -q stops at the first
# match and the writer then dies of SIGPIPE, which pipefail turns into a failure.
matches() { grep "$@" > /dev/null; }
run_failing() { set +e; "$@" 2> "$dir/err"; rc=$?; set -e; }

"$TM" --help | matches simulate || fail "--help"
# One version: project(trailmark VERSION ...) is what the CLI says.
version=$(sed -n 's/^project(trailmark VERSION \([0-9.]*\).*/\1/p' "$(dirname "$0")/../../CMakeLists.txt")
"$TM" --version | matches "^trailmark $version\$" || fail "--version is not $version"
for c in simulate run eval report pipelines demo bench scenarios validate reproduce convert export energy wayout serve journal; do
  "$TM" "$c" --help > /dev/null || fail "$c --help"
done
"$TM" simulate office-loop-1lap --seed 5 --out "$dir/m" | matches "crumbs dropped" || fail simulate
"$TM" simulate office-loop-1lap --seed 5 --out "$dir/m2" > /dev/null
cmp "$dir/m/steps.csv" "$dir/m2/steps.csv" || fail "not deterministic per seed"
cmp "$dir/m/rssi.csv" "$dir/m2/rssi.csv" || fail "not deterministic per seed"
"$TM" pipelines | matches "^pdr" || fail pipelines
# A WRLD indoor map (two levels, lon/lat) -> a multi-floor floor plan in metres.
mkdir -p "$dir/wrld"
cat > "$dir/wrld/main.json" <<'JSON'
{"id":"tiny","location":{"type":"Point","coordinates":[-2.978,56.46]},
 "levels":[{"id":"g","name":"G","z_order":0,"filename":"g.geojson"},
           {"id":"one","name":"1","z_order":1,"filename":"one.geojson"}]}
JSON
square='[[[-2.978,56.46],[-2.9779,56.46],[-2.9779,56.4601],[-2.978,56.4601],[-2.978,56.46]]]'
echo "{\"type\":\"FeatureCollection\",\"features\":[{\"type\":\"Feature\",\"properties\":{\"type\":\"wall\"},\"geometry\":{\"type\":\"Polygon\",\"coordinates\":$square}}]}" > "$dir/wrld/g.geojson"
cp "$dir/wrld/g.geojson" "$dir/wrld/one.geojson"
"$TM" convert wrld-indoor "$dir/wrld" --out "$dir/wm" | matches "2 levels" || fail "convert wrld-indoor"
"$TM" validate "$dir/wm" | matches "level 1: 4 walls" || fail "validate a multi-floor plan"
# An IMDF venue (level, unit and opening files): a room and a corridor with a door between.
mkdir -p "$dir/imdf"
echo '{"type":"FeatureCollection","features":[{"id":"L0","type":"Feature","feature_type":"level","geometry":null,"properties":{"ordinal":0,"name":{"en":"Ground"}}}]}' > "$dir/imdf/level.geojson"
echo '{"type":"FeatureCollection","features":[{"id":"u1","type":"Feature","properties":{"category":"room","level_id":"L0","name":{"en":"Kitchen"}},"geometry":{"type":"Polygon","coordinates":[[[2.35,48.85],[2.3501,48.85],[2.3501,48.8501],[2.35,48.8501],[2.35,48.85]]]}},{"id":"u2","type":"Feature","properties":{"category":"walkway","level_id":"L0"},"geometry":{"type":"Polygon","coordinates":[[[2.3501,48.85],[2.3503,48.85],[2.3503,48.8501],[2.3501,48.8501],[2.3501,48.85]]]}}]}' > "$dir/imdf/unit.geojson"
echo '{"type":"FeatureCollection","features":[{"id":"o1","type":"Feature","properties":{"category":"pedestrian","level_id":"L0"},"geometry":{"type":"LineString","coordinates":[[2.3501,48.85004],[2.3501,48.85006]]}}]}' > "$dir/imdf/opening.geojson"
"$TM" convert imdf "$dir/imdf" --out "$dir/venue" | matches "level   0 (Ground): 7 walls, 1 doors, 1 rooms" || fail "convert imdf"
"$TM" validate "$dir/venue" | matches "7 walls, 1 doors, 1 rooms" || fail "validate an IMDF plan"
"$TM" export geojson-wgs84 "$dir/venue" --out "$dir/venue.geojson" > /dev/null || fail "export an IMDF plan"
grep -q '\[2.35[0-9]*,48.85' "$dir/venue.geojson" || fail "IMDF round trip to WGS 84"
# Back to WGS 84 for GIS tools: longitude/latitude of the corners, not metres.
"$TM" export geojson-wgs84 "$dir/wm" --out "$dir/wm.geojson" > /dev/null || fail "export geojson-wgs84"
grep -q '\[-2.978[0-9]*,56.46' "$dir/wm.geojson" || { head -c 300 "$dir/wm.geojson"; fail "geojson-wgs84 coordinates"; }
rm "$dir/wrld/one.geojson"
run_failing "$TM" convert wrld-indoor "$dir/wrld" --out "$dir/wm2"
[ $rc -ne 0 ] && grep -q "one.geojson: file does not exist" "$dir/err" || fail "wrld missing level file"
"$TM" validate "$dir/m" | matches "runnable pipelines: pdr" || fail validate
"$TM" run --pipeline pdr "$dir/m" --out "$dir/run" | matches estimates || fail run
head -1 "$dir/run/estimates.csv" | matches "^t,id,x,y,z,sxx,sxy,syy$" || fail "estimates header"
"$TM" eval "$dir/m" "$dir/run/estimates.csv" | matches "^ff1" || fail eval
test -s "$dir/run/metrics.json" || fail "metrics.json"
grep -q '"mean_pct_of_distance"' "$dir/run/metrics.json" || fail "metrics keys"
grep -q '"in95"' "$dir/run/metrics.json" || fail "metrics in95"
grep -q '"in95_at_estimates"' "$dir/run/metrics.json" || fail "metrics in95 at the estimates"
# A run that produces no estimate says so (issue 30: it exited 0 without a word).
mkdir -p "$dir/nosteps" && cp "$dir/m/mission.json" "$dir/nosteps/"
head -1 "$dir/m/steps.csv" > "$dir/nosteps/steps.csv"
"$TM" run --pipeline pdr "$dir/nosteps" --out "$dir/nostepsrun" 2> "$dir/nosteps.err" > /dev/null
grep -q "wrote no estimates" "$dir/nosteps.err" || fail "no warning for a run without estimates"
# The beacon map's least squares on a variant where Levenberg-Marquardt meets a failed linear
# solve (and damps and retries): Ceres' glog warnings stay off the user's stderr, and no log file
# is written (they printed 12 "Linear solver failure" lines before 2026-12-06).
"$TM" simulate beacon-trail --seed 119 --vary 19 --family all --out "$dir/bt19" > /dev/null
TMPDIR="$dir/glogtmp" GLOG_log_dir="$dir/glogtmp" "$TM" run --pipeline beacons-ekf "$dir/bt19" --out "$dir/bt19run" > /dev/null 2> "$dir/bt19.err" || fail "beacons-ekf on a variant"
[ ! -s "$dir/bt19.err" ] || { cat "$dir/bt19.err" | head -3; fail "glog warnings on stderr"; }
[ -z "$(ls -A "$dir/glogtmp" 2>/dev/null)" ] || fail "glog wrote log files"
# A variant: written with what was drawn, valid; bad --vary / --family named.
"$TM" simulate office-loop-1lap --seed 2 --vary 4 --out "$dir/var" | matches "rotation_deg" || fail "simulate --vary"
grep -q '"family": "all"' "$dir/var/variation.json" || fail "variation.json"
"$TM" validate "$dir/var" | matches "^valid" || fail "variant valid"
# The multi-floor building's variants keep every level.
"$TM" simulate multi-floor --seed 2 --vary 3 --out "$dir/mfvar" > /dev/null || fail "simulate multi-floor --vary"
"$TM" validate "$dir/mfvar" | matches "level -1: " || fail "multi-floor variant levels"
"$TM" validate "$dir/mfvar" | matches "^valid" || fail "multi-floor variant valid"
# A barometer's range is its 1st-99th percentile: one spike shows among the extremes only.
"$TM" simulate multi-floor --seed 2 --out "$dir/mf" > /dev/null || fail "simulate multi-floor"
awk -F, 'BEGIN{OFS=","} NR==101{$3="1020.00"} {print}' "$dir/mf/baro.csv" > "$dir/baro.tmp" && mv "$dir/baro.tmp" "$dir/mf/baro.csv"
"$TM" validate "$dir/mf" > "$dir/v.txt" || fail "validate a spiked barometer"
grep "barometer" "$dir/v.txt" | grep -q "extremes .* 1020.00 hPa" || { cat "$dir/v.txt"; fail "the spike among the extremes"; }
! grep "barometer" "$dir/v.txt" | grep -q "\.\. 1020.00 hPa (1st-99th" || fail "the spike stretched the range"
run_failing "$TM" simulate office-loop --vary -3 --out "$dir/x"
[ $rc -ne 0 ] && grep -q "whole number >= 0, not '-3'" "$dir/err" || fail "negative --vary"
run_failing "$TM" simulate office-loop --vary 1 --family weather --out "$dir/x"
[ $rc -ne 0 ] && grep -q "unknown variation family 'weather' (known: frame" "$dir/err" || fail "bad --family"
"$TM" report "$dir/run" --out "$dir/r.html" > /dev/null || fail report
# TUM trajectories (evo's format) of the estimates and of the truth: one pose per row of ff1.
"$TM" export tum "$dir/run/estimates.csv" --id ff1 --out "$dir/est.tum" | matches "poses of ff1" || fail "export tum"
[ "$(grep -vc '^#' "$dir/est.tum")" -eq "$(grep -c ',ff1,' "$dir/run/estimates.csv")" ] || fail "tum pose count"
awk '!/^#/ && (NF != 8 || $5 != 0 || $8 != 1) { exit 1 }' "$dir/est.tum" || fail "tum line format"
"$TM" export tum "$dir/m/truth.csv" --id ff1 --out "$dir/truth.tum" > /dev/null || fail "export tum truth"
run_failing "$TM" export geojson-wgs84 "$dir/m" --out "$dir/x.geojson"
[ $rc -eq 2 ] && grep -q 'no "geo_origin"' "$dir/err" || { cat "$dir/err"; fail "geojson-wgs84 without an origin"; }
run_failing "$TM" export tum "$dir/run/estimates.csv" --id ghost --out "$dir/x.tum"
[ $rc -eq 2 ] && grep -q "no rows of 'ghost' (ids: .*ff1" "$dir/err" || { cat "$dir/err"; fail "export tum of an unknown id"; }
# A EuRoC ground-truth file (ASL format) -> truth.csv, and back to TUM.
mkdir -p "$dir/euroc/mav0/state_groundtruth_estimate0"
printf '#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z []\n1403636579763555584,4.5,-1.5,0.75,1,0,0,0\n1403636579768555584,4.625,-1.5,0.75,1,0,0,0\n' > "$dir/euroc/mav0/state_groundtruth_estimate0/data.csv"
"$TM" convert euroc "$dir/euroc" --out "$dir/em" > /dev/null || fail "convert euroc"
"$TM" validate "$dir/em" > /dev/null || fail "validate a EuRoC mission"
"$TM" export tum "$dir/em/truth.csv" --id body --out "$dir/em.tum" > /dev/null
grep -q '^0.005 4.625 -1.5 0.75 0 0 0 1$' "$dir/em.tum" || { cat "$dir/em.tum"; fail "EuRoC -> TUM"; }
# An IPIN logfile (GetSensorData format, written here): 20 s of a phone at rest at 50 Hz, a
# barometer, two labelled positions, BLE and WiFi; converted, validated and run.
awk 'BEGIN {
  print "% LogFile data created by the GetSensorData App for Android."
  for (k = 0; k < 1000; k++) {
    t = k * 0.02
    printf "GYRO;%.3f;%.3f;0.001;-0.002;0.0005;3\n", t, t + 100
    printf "ACCE;%.3f;%.3f;0.05;0.02;9.81;3\n", t + 0.01, t + 100.01
    if (k % 10 == 0) printf "PRES;%.3f;%.3f;1013.2;0\n", t + 0.011, t + 100.011
    if (k % 25 == 0) printf "BLE4;%.3f;iBeacon;F4:B8:5E:DE:4D:F1;-7%d;-59;1;2;e2c56db5\n", t + 0.012, k % 10
    if (k % 50 == 0) printf "WIFI;%.3f;%.3f;lab;00:0b:86:27:36:c1;2412;-60\n", t + 0.013, t + 100.013
  }
  print "POSI;0.500;1;56.4620000;-2.9707000;0;0"
  print "POSI;19.500;2;56.4620000;-2.9707000;0;0"
  print "AHRS;19.600;119.6;1;2;3;0.1;0.2;0.3;3"
}' > "$dir/ipin.txt"
"$TM" convert ipin-logfile "$dir/ipin.txt" --out "$dir/im" > "$dir/ipin.out" || { cat "$dir/ipin.out"; fail "convert ipin-logfile"; }
grep -q "record types not converted: AHRS: 1" "$dir/ipin.out" || { cat "$dir/ipin.out"; fail "ipin: unknown records reported"; }
grep -q '"geo_origin"' "$dir/im/mission.json" || fail "ipin: geo_origin"
"$TM" validate "$dir/im" | matches "baro.csv" || fail "validate an IPIN mission"
"$TM" run --pipeline pdr "$dir/im" --out "$dir/im/run" > /dev/null || fail "pdr on an IPIN mission"
"$TM" eval "$dir/im" "$dir/im/run/estimates.csv" > /dev/null || fail "eval on an IPIN mission"
printf 'ACCE;0.1;0.1;9.8\n' > "$dir/bad-ipin.txt"
run_failing "$TM" convert ipin-logfile "$dir/bad-ipin.txt" --out "$dir/bi"
[ $rc -eq 2 ] && grep -q "bad-ipin.txt:1: ACCE record: expected at least 6 fields" "$dir/err" || { cat "$dir/err"; fail "bad IPIN record"; }
run_failing "$TM" convert ipin-logfile "$dir/ipin.txt" --out "$dir/bi" --origin 56.4,east
[ $rc -ne 0 ] && grep -q "expected LAT,LON" "$dir/err" || { cat "$dir/err"; fail "bad --origin"; }
grep -q "new Chart" "$dir/r.html" || fail "report content"
"$TM" validate "$dir/m" | matches "breadcrumb" || fail "breadcrumb runnable"
"$TM" run --pipeline breadcrumb "$dir/m" --out "$dir/bc" --option state_period_s=0.5 > /dev/null \
  || fail "run breadcrumb"
grep -q '"encounters"' "$dir/bc/diagnostics.json" || fail "breadcrumb diagnostics"
grep -q '"integrity": \[' "$dir/bc/diagnostics.json" || fail "integrity notes in diagnostics"
"$TM" eval "$dir/m" "$dir/bc/estimates.csv" | matches "^c1 " || fail "breadcrumb crumbs estimated"
run_failing "$TM" run --pipeline breadcrumb "$dir/m" --out "$dir/x" --option nope=1
[ $rc -eq 1 ] && grep -q "unknown option 'nope'" "$dir/err" || fail "unknown pipeline option"
run_failing "$TM" run --pipeline breadcrumb "$dir/m" --out "$dir/x" --option gate_sigma=abc
[ $rc -eq 1 ] && grep -q "gate_sigma='abc' is not a finite number" "$dir/err" || fail "bad option value"
"$TM" reproduce breadcrumb --seeds 1 --out "$dir/rep" | matches "| mean error | 5.6 m" || fail reproduce
test -s "$dir/rep/breadcrumb/results.md" || fail "reproduce results.md"
"$TM" simulate training-building --seed 2 --out "$dir/tb" > /dev/null || fail "simulate training"
"$TM" run --pipeline breadcrumb "$dir/tb" --out "$dir/tbr" > /dev/null || fail "run training"
"$TM" eval "$dir/tb" "$dir/tbr/estimates.csv" | matches "^ff2 " || fail "two firefighters"

# The INS from raw IMU samples: 2 s at rest (100 Hz), then every steps-based pipeline from imu.csv.
mkdir -p "$dir/imu"
echo '{"format": "trailmark-mission/1", "nodes": [{"id": "foot", "kind": "agent", "start": [0, 0, 0]}]}' \
  > "$dir/imu/mission.json"
awk 'BEGIN { print "t,agent,ax,ay,az,gx,gy,gz"; for (k = 0; k < 200; k++) printf "%.2f,foot,0.01,0,9.80,0,0.001,0\n", k / 100 }' \
  > "$dir/imu/imu.csv"
"$TM" validate "$dir/imu" | matches "runnable pipelines: pdr breadcrumb ins" || fail "ins runnable"
"$TM" run --pipeline ins "$dir/imu" --out "$dir/insr" --option detector=shoe > /dev/null || fail "run ins"
# 2 s at the default 50 Hz, the last sample besides: 100 or 101 estimates; every sample at 0 Hz
rows=$(($(wc -l < "$dir/insr/estimates.csv") - 1))
[ "$rows" -ge 100 ] && [ "$rows" -le 101 ] || fail "ins: 50 Hz by default ($rows estimates)"
"$TM" run --pipeline ins "$dir/imu" --out "$dir/insr0" --option detector=shoe --option output_hz=0 > /dev/null || fail "run ins 0 Hz"
[ "$(($(wc -l < "$dir/insr0/estimates.csv") - 1))" -eq 200 ] || fail "ins: output_hz=0 is one estimate per sample"
"$TM" run --pipeline pdr "$dir/imu" --out "$dir/pdri" > /dev/null || fail "pdr from imu.csv"
grep -q "steps from imu.csv" "$dir/pdri/diagnostics.json" || fail "pdr from imu note"
awk 'BEGIN { print "t,agent,ax,ay,az,gx,gy,gz"; for (k = 0; k < 200; k++) printf "%.2f,foot,0,0,1.0,0,0,0\n", k / 100 }' \
  > "$dir/imu/imu.csv"
run_failing "$TM" run --pipeline ins "$dir/imu" --out "$dir/x"
[ $rc -eq 2 ] && grep -q "imu.csv.*in g, not m/s^2" "$dir/err" || { cat "$dir/err"; fail "g units"; }

# A simulated foot IMU, no steps.csv: the steps-based pipelines run the INS.
"$TM" simulate office-loop-1lap --seed 3 --imu-rate 100 --imu-grade tactical --imu-only \
  --out "$dir/si" | matches "0 steps, [0-9]* IMU samples" || fail "simulate --imu-rate"
"$TM" run --pipeline breadcrumb "$dir/si" --out "$dir/sir" > /dev/null || fail "breadcrumb from simulated IMU"
"$TM" eval "$dir/si" "$dir/sir/estimates.csv" | matches "^ff1 " || fail "eval breadcrumb from IMU"
run_failing "$TM" run --pipeline landmarks-stopgo "$dir/si" --out "$dir/x"  # imu.csv, no landmarks
[ $rc -eq 2 ] && grep -q "needs steps.csv or imu.csv, rssi.csv, 3+ landmarks" "$dir/err" \
  && ! grep -q "steps.csv: missing" "$dir/err" || { cat "$dir/err"; fail "imu.csv stands for steps.csv"; }
run_failing "$TM" simulate office-loop-1lap --imu-rate 100 --imu-grade navigation --out "$dir/x"
[ $rc -eq 1 ] && grep -q "unknown IMU grade 'navigation'" "$dir/err" || fail "bad IMU grade"
# The same foot IMU mounted turned 90 deg (y forward): the INS finds the mounting from its strides.
"$TM" simulate office-loop-1lap --seed 3 --imu-rate 100 --imu-grade tactical --imu-only --imu-mount 90 \
  --out "$dir/sim90" > /dev/null || fail "simulate --imu-mount"
"$TM" run --pipeline ins "$dir/sim90" --out "$dir/sim90r" > /dev/null || fail "ins on a mounted IMU"
grep -q '"ff1.mount_yaw_turned_deg": 9[0-9]\|"ff1.mount_yaw_turned_deg": 8[0-9]' "$dir/sim90r/diagnostics.json" \
  || { grep mount "$dir/sim90r/diagnostics.json"; fail "the mounting found"; }
run_failing "$TM" simulate office-loop-1lap --imu-rate 100 --imu-mount 9a --out "$dir/x"
[ $rc -eq 1 ] && grep -q "imu-mount: '9a' is not a number" "$dir/err" || { cat "$dir/err"; fail "bad --imu-mount"; }
run_failing "$TM" simulate office-loop-1lap --imu-rate 100 --imu-mount "" --out "$dir/x"
[ $rc -eq 1 ] && grep -q "imu-mount takes YAW\[,ROLL\[,PITCH\]\] in degrees, not ''" "$dir/err" \
  || { cat "$dir/err"; fail "an empty --imu-mount"; }

"$TM" energy | matches "sleep-only lifetime: 8.62 years" || fail "energy"
"$TM" simulate landmark-corridor --seed 1 --out "$dir/lc" > /dev/null || fail "simulate landmark-corridor"
"$TM" run --pipeline landmarks-stopgo "$dir/lc" --out "$dir/lcr" > /dev/null || fail "landmarks-stopgo"
"$TM" eval "$dir/lc" "$dir/lcr/estimates.csv" | matches "^lm3 " || fail "landmarks estimated"
run_failing "$TM" run --pipeline landmarks-ukf "$dir/lc" --out "$dir/x" --option loss=l1
[ $rc -eq 1 ] && grep -q "option loss=.l1. must be one of squared, huber, cauchy" "$dir/err" || fail "bad loss option"
"$TM" reproduce landmarks --out "$dir/rep" | matches "| landmark localization, median error | 0.78 m" \
  || fail "reproduce landmarks"
"$TM" reproduce beacons --seeds 1 --out "$dir/rep" > "$dir/repb.txt" || fail "reproduce beacons"
grep -q "1,000 beacons" "$dir/repb.txt" && grep -q "| \*\*overall\*\* | 1.93 / 3.70 |" "$dir/repb.txt" \
  || fail "reproduce beacons tables"
# reproduce robustness for one pipeline with its options (an ablation over the families); a
# pipeline not in its table, options without --pipeline or refused by the pipeline are errors.
"$TM" reproduce robustness --pipeline beacons-mds --option map_lag_s=1 --seeds 1 --out "$dir/rob" \
  > "$dir/rob.txt" || fail "reproduce robustness --pipeline"
grep -q "Options (the pipelines', not dead reckoning's): \`map_lag_s=1\`" "$dir/rob.txt" \
  && grep -q "^| beacons-mds | beacon-trail | frame |" "$dir/rob.txt" \
  && ! grep -q "^| beacons-ekf " "$dir/rob.txt" || fail "reproduce robustness, one pipeline"
# Each variant keeps what was drawn, as `simulate --vary` writes it: the same draw.
"$TM" simulate beacon-trail --seed 101 --vary 1 --family radio --out "$dir/rob-bt1" > /dev/null
cmp "$dir/rob-bt1/variation.json" "$dir/rob/robustness/missions/beacon-trail-radio-1/mission/variation.json" \
  || fail "reproduce robustness variation.json"
run_failing "$TM" reproduce robustness --option map_lag_s=1 --seeds 1 --out "$dir/x"
[ $rc -eq 1 ] && grep -q "option needs --pipeline" "$dir/err" || fail "robustness option alone"
run_failing "$TM" reproduce robustness --pipeline pdr --seeds 1 --out "$dir/x"
[ $rc -eq 1 ] && grep -q "'pdr' is not one of its pipelines" "$dir/err" || fail "robustness pdr"
run_failing "$TM" reproduce robustness --pipeline landmarks-stopgo --option map_lag_s=1 --seeds 1 --out "$dir/x"
[ $rc -eq 1 ] && grep -q "unknown option 'map_lag_s'" "$dir/err" || fail "robustness refused option"
run_failing "$TM" reproduce beacons --pipeline beacons-ekf --out "$dir/x"
[ $rc -eq 1 ] && grep -q "takes no --pipeline" "$dir/err" || fail "reproduce beacons --pipeline"
# The ultrasound beacon trail: MDS, the SCAAT EKF, the way back out.
"$TM" simulate beacon-trail --seed 3 --out "$dir/bt" | matches "crumbs dropped" || fail "simulate beacon-trail"
"$TM" validate "$dir/bt" | matches "beacons-mds beacons-ekf" || fail "beacon pipelines runnable"
"$TM" run --pipeline beacons-mds "$dir/bt" --out "$dir/btm" > /dev/null || fail "beacons-mds"
"$TM" eval "$dir/bt" "$dir/btm/estimates.csv" | matches "^b12 " || fail "beacons localized"
"$TM" run --pipeline beacons-ekf "$dir/bt" --out "$dir/bte" > /dev/null || fail "beacons-ekf"
grep -q '"ff1: way out b01"' "$dir/bte/diagnostics.json" || fail "way out in diagnostics"
"$TM" wayout "$dir/bt" --at 100 | matches "then out through the entry" || fail "wayout command"
run_failing "$TM" wayout "$dir/bt" --agent nobody
[ $rc -eq 2 ] && grep -q "no agent 'nobody'" "$dir/err" || fail "wayout unknown agent"
# Map-aided search: the house search, pattern observations, no initial position.
"$TM" simulate house1-search --seed 2 --out "$dir/hs" > /dev/null || fail "simulate house1-search"
"$TM" validate "$dir/hs" | matches "mapmatch" || fail "mapmatch runnable"
"$TM" run --pipeline mapmatch "$dir/hs" --out "$dir/hsr" --option init=uniform > /dev/null || fail "mapmatch"
grep -q '"ff1.pattern_comparisons"' "$dir/hsr/diagnostics.json" || fail "mapmatch diagnostics"
"$TM" eval "$dir/hs" "$dir/hsr/estimates.csv" | matches "^ff1 " || fail "mapmatch eval"
# The search grid and sequences as GeoJSON (issue 23): the plan stays readable as a plan, the
# sequences and inside nodes are added; the same house rotated (the frame family) has the
# same number of sequences and nodes.
"$TM" patterns "$dir/hs" --out "$dir/hsp.geojson" > "$dir/hsp.txt" || { cat "$dir/hsp.txt"; fail "patterns"; }
grep -q "search sequences" "$dir/hsp.txt" && grep -q "inner doors no sequence passes: none" "$dir/hsp.txt" || { cat "$dir/hsp.txt"; fail "patterns summary"; }
grep -q '"search_sequence"' "$dir/hsp.geojson" && grep -q '"inside_nodes"' "$dir/hsp.geojson" || fail "patterns file"
"$TM" simulate house1-search --seed 2 --vary 3 --family frame --out "$dir/hsv" > /dev/null || fail "simulate frame variant"
"$TM" patterns "$dir/hsv" --out "$dir/hsvp.geojson" > "$dir/hsvp.txt" || { cat "$dir/hsvp.txt"; fail "patterns of the rotated house"; }
[ "$(head -1 "$dir/hsp.txt" | cut -d' ' -f1-5)" = "$(head -1 "$dir/hsvp.txt" | cut -d' ' -f1-5)" ] || { cat "$dir/hsp.txt" "$dir/hsvp.txt"; fail "rotated house: other sequences"; }
mkdir -p "$dir/noplan" && sed '/"floorplan"/d' "$dir/hs/mission.json" > "$dir/noplan/mission.json"
run_failing "$TM" patterns "$dir/noplan" --out "$dir/x.geojson"
[ $rc -ne 0 ] && grep -q 'no "floorplan" to search' "$dir/err" || { cat "$dir/err"; fail "patterns without a plan"; }
run_failing "$TM" run --pipeline mapmatch "$dir/hs" --out "$dir/x" --option init=somewhere
[ $rc -eq 1 ] && grep -q "option init=.somewhere. must be one of auto, known, uniform" "$dir/err" || fail "bad mapmatch option"
# The report draws the floor a mapmatch run was matched on (its level option).
"$TM" run --pipeline mapmatch "$dir/hs" --out "$dir/hsl" --option level=0 > /dev/null || fail "mapmatch level=0"
"$TM" report "$dir/hsl" --out "$dir/hsl.html" > /dev/null || fail "report of a mapmatch run with a level"
# ... with map matching's search patterns as layers (issue 23): the sequences and the grid.
grep -q 'search sequences (mapmatch, 1 m grid at ' "$dir/hsl.html" && grep -q 'search grid: inside nodes' "$dir/hsl.html" || fail "report: search patterns"
sed -i 's/"level": *"0"/"level":"5"/' "$dir/hsl/diagnostics.json"
run_failing "$TM" report "$dir/hsl" --out "$dir/x.html"
[ $rc -ne 0 ] && grep -q "no level 5" "$dir/err" || { cat "$dir/err"; fail "report reads the run's level"; }
# A directional search simulated on a given floor plan (here house 1's map), then matched.
"$TM" simulate search --floorplan "$dir/hs/floorplan.geojson" --entry 1.5,0.5 --minutes 2 --seed 4 --out "$dir/ss" | matches "simulated 'search'" || fail "simulate search"
grep -q '"start_heading": 1.57' "$dir/ss/mission.json" || { cat "$dir/ss/mission.json"; fail "search: heading from the entry door"; }
"$TM" run --pipeline mapmatch "$dir/ss" --out "$dir/ssr" > /dev/null || fail "mapmatch on the simulated search"
run_failing "$TM" simulate search --floorplan "$dir/hs/floorplan.geojson" --out "$dir/x"
[ $rc -ne 0 ] && grep -q "needs --floorplan FILE and --entry X,Y" "$dir/err" || { cat "$dir/err"; fail "search without an entry"; }
run_failing "$TM" simulate office-loop --entry 1,1 --out "$dir/x"
[ $rc -ne 0 ] && grep -q "are for the 'search' scenario" "$dir/err" || { cat "$dir/err"; fail "search options elsewhere"; }
# The live server reads mapmatch's floor (level) as the pipeline does: a missing one is named.
run_failing "$TM" serve --live "$dir/hs" --journal "$dir/hsj.db" --pipeline mapmatch --option level=7 --port 0 --token x
[ $rc -ne 0 ] && grep -q "no level 7 (its levels: 0)" "$dir/err" || { cat "$dir/err"; fail "serve mapmatch level"; }
run_failing "$TM" run --pipeline beacons-ekf "$dir/bt" --out "$dir/x" --option update=polar
[ $rc -eq 1 ] && grep -q "must be one of range-bearing, position" "$dir/err" || fail "bad update option"
# The incident server: replay, token, state contract (curl on loopback).
"$TM" serve --replay "$dir/bt" --speed 100 --port 0 --token t0k3n > "$dir/serve.log" 2>&1 &
serve_pid=$!
for _ in $(seq 300); do grep -q "listening on" "$dir/serve.log" && break; sleep 0.1; done
port=$(sed -n 's|.*listening on http://127.0.0.1:\([0-9]*\)/.*|\1|p' "$dir/serve.log")
[ -n "$port" ] || { cat "$dir/serve.log"; fail "serve did not start"; }
# Without --pipeline the replay runs the fusion (issue 27).
grep -q "serve: fusion on" "$dir/serve.log" || { cat "$dir/serve.log"; fail "serve: default pipeline is not the fusion"; }
for _ in $(seq 300); do  # the replay releases its first estimates (up to 30 s on a loaded machine)
  curl -s -H "Authorization: Bearer t0k3n" "http://127.0.0.1:$port/api/state" | grep -q '"nodes":\[{' && break
  sleep 0.1
done
code=$(curl -s -o /dev/null -w "%{http_code}" "http://127.0.0.1:$port/api/state")
[ "$code" = 401 ] || fail "serve: /api/state without the token gave $code"
curl -s -H "Authorization: Bearer t0k3n" "http://127.0.0.1:$port/api/state" > "$dir/state.json"
grep -q '"nodes":\[{' "$dir/state.json" && grep -q '"kind":"agent"' "$dir/state.json" && grep -q '"alerts":' "$dir/state.json" \
  || { cat "$dir/state.json"; fail "serve: state"; }
code=$(curl -s -o /dev/null -w "%{http_code}" "http://127.0.0.1:$port/?token=t0k3n")
[ "$code" = 200 ] || fail "serve: dashboard gave $code"
# The history since a time, and a bad time named.
curl -s -H "Authorization: Bearer t0k3n" "http://127.0.0.1:$port/api/history?since=1" | grep -q '"since":1' \
  || fail "serve: history since"
code=$(curl -s -o "$dir/h.json" -w "%{http_code}" -H "Authorization: Bearer t0k3n" "http://127.0.0.1:$port/api/history?since=soon")
[ "$code" = 400 ] && grep -q "not 'soon'" "$dir/h.json" || fail "serve: a bad since gave $code"
code=$(curl -s -o "$dir/h.json" -w "%{http_code}" -H "Authorization: Bearer t0k3n" "http://127.0.0.1:$port/api/history?max_rows=1")
[ "$code" = 400 ] && grep -q "max_rows: expected a whole number" "$dir/h.json" || fail "serve: a bad max_rows gave $code"
decimated=no
for _ in $(seq 300); do  # once an agent has more than 2 history rows (0.5 s of mission time each)
  curl -s -H "Authorization: Bearer t0k3n" "http://127.0.0.1:$port/api/history?max_rows=2" | grep -q '"decimated"' \
    && { decimated=yes; break; }
  sleep 0.1
done
[ $decimated = yes ] || fail "serve: history within 2 rows is not decimated"
code=$(curl -s -o /dev/null -w "%{http_code}" "http://127.0.0.1:$port/?token=wrong")
[ "$code" = 401 ] || fail "serve: dashboard with a wrong token gave $code"
kill $serve_pid; wait $serve_pid || true
# Live without --pipeline: the fusion too.
mkdir -p "$dir/live-default"
cp "$dir/m2/mission.json" "$dir/live-default/"
"$TM" serve --live "$dir/live-default" --journal "$dir/jd.db" --port 0 --token T > "$dir/live-default.log" 2>&1 &
ld_pid=$!
for _ in $(seq 300); do grep -q "listening on" "$dir/live-default.log" && break; sleep 0.1; done
kill $ld_pid; wait $ld_pid || true
grep -q "pipeline fusion (incremental)" "$dir/live-default.log" || { cat "$dir/live-default.log"; fail "serve --live: default pipeline is not the fusion"; }
grep -q "2 refused without the token" "$dir/serve.log" || { cat "$dir/serve.log"; fail "serve: refusals counted"; }
run_failing "$TM" serve --replay "$dir/bt" --port 0 --token x --tls-cert "$dir/none.pem" --tls-key "$dir/none.key"
[ $rc -ne 0 ] && grep -q "none.pem: no such file" "$dir/err" || { cat "$dir/err"; fail "serve with a missing certificate"; }
printf 'not a certificate\n' > "$dir/bad.pem"
run_failing "$TM" serve --replay "$dir/bt" --port 0 --token x --tls-cert "$dir/bad.pem" --tls-key "$dir/bad.pem"
[ $rc -ne 0 ] && grep -q "not a PEM certificate chain" "$dir/err" || { cat "$dir/err"; fail "serve with a bad certificate"; }
# Live ingest into the durable journal, with the server killed (-9) mid-stream and restarted:
# nothing acknowledged may be lost, redelivered rows are dropped as duplicates.
mkdir -p "$dir/live"
cp "$dir/m2/mission.json" "$dir/live/"
start_live() {
  # The restart writes the same log: removed first, so that the wait below cannot read the
  # killed server's "listening on" before the new one has truncated the file (the background
  # job's redirection runs after this shell goes on: CI failed on that race once).
  rm -f "$dir/live.log"
  "$TM" serve --live "$dir/live" --journal "$dir/j.db" --pipeline pdr --port 0 --token T > "$dir/live.log" 2>&1 &
  live_pid=$!
  lport=""
  for _ in $(seq 300); do
    lport=$(sed -n 's|.*listening on http://127.0.0.1:\([0-9]*\)/.*|\1|p' "$dir/live.log" 2>/dev/null)
    [ -n "$lport" ] && break
    sleep 0.1
  done
  [ -n "$lport" ] || { cat "$dir/live.log"; kill $live_pid 2>/dev/null; fail "live serve did not start"; }
}
header=$(head -1 "$dir/m2/steps.csv")
tail -n +2 "$dir/m2/steps.csv" | split -l 20 - "$dir/chunk."
chunks=("$dir"/chunk.*)
: > "$dir/acked.txt"
post() {  # post CHUNK: 0 when acknowledged
  { echo "$header"; cat "$1"; } > "$dir/body.csv"
  code=$(curl -s -o "$dir/ack.json" -w "%{http_code}" -H "Content-Type: text/csv" -H "Authorization: Bearer T" --data-binary @"$dir/body.csv" \
         "http://127.0.0.1:$lport/api/ingest/steps.csv" || true)
  [ "$code" = 200 ]
}
start_live
half=$(( ${#chunks[@]} / 2 ))
for ((k = 0; k < half; k++)); do post "${chunks[$k]}" && cat "${chunks[$k]}" >> "$dir/acked.txt"; done
kill -9 $live_pid; wait $live_pid 2>/dev/null || true
post "${chunks[$half]}" && fail "a dead server acknowledged"
start_live
for ((k = half - 1; k < ${#chunks[@]}; k++)); do  # one chunk sent again: a redelivery
  post "${chunks[$k]}" || fail "live ingest refused chunk $k"; cat "${chunks[$k]}" >> "$dir/acked.txt"
done
grep -q '"duplicates":20' <(post "${chunks[0]}" && cat "$dir/ack.json") || fail "redelivered rows not detected"
printf 't0,t1,agent,dx,dy\n1,2,ff1,abc,0\n' > "$dir/body.csv"
code=$(curl -s -o "$dir/bad.json" -w "%{http_code}" -H "Content-Type: text/csv" -H "Authorization: Bearer T" --data-binary @"$dir/body.csv" \
       "http://127.0.0.1:$lport/api/ingest/steps.csv")
[ "$code" = 400 ] && grep -q "request body:2" "$dir/bad.json" || { cat "$dir/bad.json"; fail "bad live row"; }
# Steps of a node that is not an agent of the incident: refused at the door.
printf 't0,t1,agent,dx,dy\n100,101,ghost,0.3,0\n' > "$dir/body.csv"
code=$(curl -s -o "$dir/ghost.json" -w "%{http_code}" -H "Content-Type: text/csv" -H "Authorization: Bearer T" --data-binary @"$dir/body.csv" \
       "http://127.0.0.1:$lport/api/ingest/steps.csv")
[ "$code" = 400 ] && grep -q "request body:2: 'ghost' is not an agent" "$dir/ghost.json" || { cat "$dir/ghost.json"; fail "steps of a non-agent"; }
# A row older than the last accepted one of its device (not a repeat): refused, reason logged.
printf 't0,t1,agent,dx,dy\n0.05,0.1,ff1,0.3,0\n' > "$dir/body.csv"
code=$(curl -s -o "$dir/old.json" -w "%{http_code}" -H "Content-Type: text/csv" -H "Authorization: Bearer T" --data-binary @"$dir/body.csv" \
       "http://127.0.0.1:$lport/api/ingest/steps.csv")
[ "$code" = 400 ] && grep -q "time order" "$dir/old.json" || { cat "$dir/old.json"; fail "row out of time order across requests"; }
# A device's streams in one request (POST /api/ingest, a JSON object of CSV texts): a chunk sent
# again comes back as duplicates; a bad section refuses the whole bundle, naming the section.
bundle() {  # bundle OUT STREAM FILE [STREAM FILE ...]: the JSON body
  out="$1"; shift
  /usr/bin/python3 -c 'import json, sys; a = sys.argv[1:]; print(json.dumps({a[i]: open(a[i + 1]).read() for i in range(0, len(a), 2)}))' "$@" > "$out"
}
{ echo "$header"; cat "${chunks[0]}"; } > "$dir/body.csv"
bundle "$dir/bundle.json" steps.csv "$dir/body.csv"
code=$(curl -s -o "$dir/bundle_ack.json" -w "%{http_code}" -H "Content-Type: application/json" -H "Authorization: Bearer T" \
       --data-binary @"$dir/bundle.json" "http://127.0.0.1:$lport/api/ingest")
[ "$code" = 200 ] && grep -q '"duplicates":20' "$dir/bundle_ack.json" && grep -q '"streams":{"steps.csv"' "$dir/bundle_ack.json" \
  || { cat "$dir/bundle_ack.json"; fail "bundle redelivery"; }
printf 't,rx,tx,rssi_dbm\n5,ff1,b1,loud\n' > "$dir/bad_rssi.csv"
bundle "$dir/bundle.json" steps.csv "$dir/body.csv" rssi.csv "$dir/bad_rssi.csv"
code=$(curl -s -o "$dir/bundle_bad.json" -w "%{http_code}" -H "Authorization: Bearer T" \
       --data-binary @"$dir/bundle.json" "http://127.0.0.1:$lport/api/ingest")
[ "$code" = 400 ] && grep -q "request body rssi.csv:2" "$dir/bundle_bad.json" || { cat "$dir/bundle_bad.json"; fail "bad bundle"; }
code=$(curl -s -o /dev/null -w "%{http_code}" --data-binary @"$dir/bundle.json" "http://127.0.0.1:$lport/api/ingest")
[ "$code" = 401 ] || fail "a bundle without the token: HTTP $code"
curl -s -H "Authorization: Bearer T" "http://127.0.0.1:$lport/api/stats" > "$dir/stats.json"
grep -q '"recent_rejections":\[{' "$dir/stats.json" && grep -q "time order" "$dir/stats.json" \
  || { cat "$dir/stats.json"; fail "rejection reasons in /api/stats"; }
grep -q "rejected: steps.csv: request body:2: t=0.1" "$dir/live.log" || { cat "$dir/live.log"; fail "rejection not logged"; }
# The incremental live pdr (re-fed from the journal after the restart) ends exactly where the
# batch pipeline ends on the whole mission. The live estimator runs behind the acknowledgement
# (rows are estimated after they are committed): poll until it has caught up, up to 30 s.
"$TM" run --pipeline pdr "$dir/m2" --out "$dir/m2run" > /dev/null
want=$(awk -F, 'NR > 1 && $2 == "ff1" { x = $3; y = $4 } END { printf "%.6f %.6f", x, y }' "$dir/m2run/estimates.csv")
for _ in $(seq 300); do
  curl -s -H "Authorization: Bearer T" "http://127.0.0.1:$lport/api/state" > "$dir/lstate.json"
  got=$(sed 's/.*"id":"ff1"[^}]*"x":\([-0-9.e]*\),"y":\([-0-9.e]*\).*/\1 \2/' "$dir/lstate.json" | awk '{ printf "%.6f %.6f", $1, $2 }')
  [ "$want" = "$got" ] && break
  sleep 0.1
done
grep -q '"id":"ff1"' "$dir/lstate.json" || fail "live state"
echo "live pdr end: $got (batch: $want)" >&2; [ "$want" = "$got" ] && [ "$want" != "0.000000 0.000000" ] || fail "live pdr ended at ($got), the batch pdr at ($want)"
curl -s -H "Authorization: Bearer T" "http://127.0.0.1:$lport/api/history" | matches '"trails":{"ff1":\[\[' || fail "history"
# Server-sent events: the state as a stream (the dashboard's live updates).
curl -s -N --max-time 1 "http://127.0.0.1:$lport/api/events?token=T" > "$dir/events.txt" || true
grep -q '^data: {"alerts":' "$dir/events.txt" || { head -c 300 "$dir/events.txt"; fail "event stream"; }
code=$(curl -s -o /dev/null -w "%{http_code}" --max-time 1 "http://127.0.0.1:$lport/api/events?token=wrong")
[ "$code" = 401 ] || fail "event stream without the token gave $code"
kill $live_pid; wait $live_pid || true
# The map-aided pipeline live: the floor plan next to mission.json, steps posted, incremental.
"$TM" simulate house1-search --seed 2 --out "$dir/h1" > /dev/null
mkdir -p "$dir/hlive" && cp "$dir/h1/mission.json" "$dir/h1/floorplan.geojson" "$dir/hlive/"
"$TM" serve --live "$dir/hlive" --journal "$dir/h.db" --pipeline mapmatch --port 0 --token H > "$dir/hlive.log" 2>&1 &
hpid=$!
for _ in $(seq 300); do grep -q "listening on" "$dir/hlive.log" && break; sleep 0.1; done
hport=$(sed -n 's|.*listening on http://127.0.0.1:\([0-9]*\)/.*|\1|p' "$dir/hlive.log")
grep -q "pipeline mapmatch (incremental)" "$dir/hlive.log" || { cat "$dir/hlive.log"; fail "live mapmatch not incremental"; }
code=$(curl -s -o "$dir/hack.json" -w "%{http_code}" -H "Content-Type: text/csv" -H "Authorization: Bearer H" \
       --data-binary @"$dir/h1/steps.csv" "http://127.0.0.1:$hport/api/ingest/steps.csv")
[ "$code" = 200 ] || { cat "$dir/hack.json"; fail "live mapmatch ingest"; }
# The filter runs behind the acknowledgement: poll until it has estimated (up to 30 s).
for _ in $(seq 300); do
  curl -s -H "Authorization: Bearer H" "http://127.0.0.1:$hport/api/state" | grep -q '"id":"ff1"' && break
  sleep 0.1
done
curl -s -H "Authorization: Bearer H" "http://127.0.0.1:$hport/api/state" | matches '"id":"ff1"' || fail "live mapmatch state"
curl -s -H "Authorization: Bearer H" "http://127.0.0.1:$hport/api/floorplan" | matches '"walls":\[\[' || fail "live floor plan"
kill $hpid; wait $hpid || true
# The landmark incident benchmark, short (2 firefighters, 3 minutes), and bad lengths named.
"$TM" bench landmarks --agents 2 --hours 0.05 > "$dir/bl.log" 2>&1 \
  && grep -q "dead reckoning (pdr) at the same step ends" "$dir/bl.log" || { cat "$dir/bl.log"; fail "bench landmarks"; }
for h in abc 0 nan -1; do
  run_failing "$TM" bench landmarks --hours "$h"
  [ $rc -ne 0 ] && matches "hours" "$dir/err" || { cat "$dir/err"; fail "bench landmarks --hours $h"; }
done
run_failing "$TM" bench load --firefighters 1 --minutes 0.1 --pipeline nope --dir "$dir/load"
[ $rc -ne 0 ] && matches "unknown pipeline 'nope'" "$dir/err" || { cat "$dir/err"; fail "bench load with an unknown pipeline"; }
# A bounded load test (3 firefighters, 30 s each, as fast as possible): fails unless every row
# sent is acknowledged and journaled.
"$TM" bench load --firefighters 3 --minutes 0.5 --dir "$dir/load" > "$dir/load.log" 2>&1 \
  && grep -q "rows sent and journaled" "$dir/load.log" || { cat "$dir/load.log"; fail "bench load"; }
# Staggered starts on the beacon trail (firefighter k starts (k-1) x 2 s later, paced against
# the others from its own start): completes with every row journaled; a negative stagger is refused.
"$TM" bench load --firefighters 3 --minutes 0.5 --stagger 2 --pipeline beacons-ekf --dir "$dir/load" \
  --json "$dir/load.json" > "$dir/load.log" 2>&1 \
  && grep -q "starts 2 s apart" "$dir/load.log" && grep -q '"stagger_s": 2' "$dir/load.json" \
  || { cat "$dir/load.log"; fail "bench load --stagger"; }
# A given mission replayed (--mission: its agents as the devices, steps as their clock; the two
# firefighters of the training building stand still at times, and the packets they hear then
# still go): every row of every stream journaled, no more and no fewer.
"$TM" bench load --mission "$dir/tb" --pipeline breadcrumb --dir "$dir/load" --json "$dir/load.json" \
  > "$dir/load.log" 2>&1 || { cat "$dir/load.log"; fail "bench load --mission"; }
tb_rows=0
for f in "$dir"/tb/*.csv; do
  case "$f" in */truth.csv) ;; *) tb_rows=$((tb_rows + $(tail -n +2 "$f" | wc -l)));; esac
done
# The devices are paced on every window, steps or not: no row reaches the estimator late.
grep -q "\"rows\": $tb_rows," "$dir/load.json" && grep -q '"firefighters": 2,' "$dir/load.json" \
  && grep -q '"rows_late": 0.0,' "$dir/load.json" \
  && grep -q "replayed" "$dir/load.log" || { cat "$dir/load.log" "$dir/load.json"; fail "bench load --mission rows ($tb_rows)"; }
# --speed: the devices keep to the wall clock's schedule (371 s of mission at 100x: not under
# 3.5 s), and a negative speed is refused.
"$TM" bench load --mission "$dir/tb" --pipeline pdr --speed 100 --dir "$dir/load" --json "$dir/load.json" \
  > "$dir/load.log" 2>&1 || { cat "$dir/load.log"; fail "bench load --speed"; }
python3 -c "import json,sys; d=json.load(open(sys.argv[1])); sys.exit(0 if d['speed'] == 100 and d['ingest_wall_s'] >= 3.5 else 1)" \
  "$dir/load.json" || { cat "$dir/load.json"; fail "bench load --speed 100 kept no schedule"; }
for bad_speed in -1 nan inf; do
  run_failing "$TM" bench load --mission "$dir/tb" --speed "$bad_speed" --dir "$dir/load"
  [ $rc -ne 0 ] && matches "speed" "$dir/err" || { cat "$dir/err"; fail "bench load --speed $bad_speed"; }
done
mkdir -p "$dir/nomotion" && cp "$dir/tb/mission.json" "$dir/nomotion/"
run_failing "$TM" bench load --mission "$dir/nomotion" --pipeline breadcrumb --dir "$dir/load"
[ $rc -ne 0 ] && matches "no imu.csv or steps.csv rows" "$dir/err" || { cat "$dir/err"; fail "bench load --mission without motion"; }
# bench breadcrumb takes the pipeline's options; a wrong one is refused before the incident is made
run_failing "$TM" bench breadcrumb --option heading_rate=maybe
[ $rc -ne 0 ] && matches "heading_rate" "$dir/err" || { cat "$dir/err"; fail "bench breadcrumb --option heading_rate=maybe"; }
run_failing "$TM" bench load --stagger -1 --dir "$dir/load"
[ $rc -ne 0 ] && matches "stagger" "$dir/err" || { cat "$dir/err"; fail "bench load --stagger -1"; }
"$TM" journal export "$dir/j.db" --mission "$dir/live" --out "$dir/exported" > /dev/null || fail "journal export"
sort -u "$dir/acked.txt" > "$dir/acked.sorted"
tail -n +2 "$dir/exported/steps.csv" | sort > "$dir/journal.sorted"
cmp -s "$dir/acked.sorted" "$dir/journal.sorted" || fail "journal differs from what was acknowledged"
[ "$(wc -l < "$dir/journal.sorted")" -eq "$(tail -n +2 "$dir/m2/steps.csv" | wc -l)" ] || fail "journal row count"
# A damaged journal (its second page zeroed) is refused — by export and by the server — naming
# the salvage; the salvage writes what is readable and exits 3.
cp "$dir/j.db" "$dir/jd.db" && cp "$dir/j.db.acked" "$dir/jd.db.acked"
dd if=/dev/zero of="$dir/jd.db" bs=4096 seek=1 count=1 conv=notrunc 2> /dev/null
run_failing "$TM" journal export "$dir/jd.db" --mission "$dir/live" --out "$dir/jdx"
[ $rc -ne 0 ] && grep -q "salvage" "$dir/err" || { cat "$dir/err"; fail "damaged journal exported"; }
run_failing "$TM" serve --live "$dir/live" --journal "$dir/jd.db" --port 0 --token T
[ $rc -ne 0 ] && grep -q "salvage" "$dir/err" || { cat "$dir/err"; fail "server started on a damaged journal"; }
run_failing "$TM" journal export "$dir/jd.db" --mission "$dir/live" --out "$dir/jds" --salvage
[ $rc -eq 3 ] || { cat "$dir/err"; fail "salvage exit code $rc"; }
run_failing "$TM" energy --sleep-ua 0
[ $rc -ne 0 ] || fail "energy with zero sleep current"

# Bad input: clear message naming file and line, exit code 2.
run_failing "$TM" run --pipeline nope "$dir/m" --out "$dir/x"
[ $rc -ne 0 ] && grep -q "unknown pipeline 'nope'" "$dir/err" || fail "unknown pipeline"
printf 't0,t1,agent,dx,dy\n0,1,ff1,1,0\n0.5,2,ff1,abc,0\n' > "$dir/m/steps.csv"
run_failing "$TM" run --pipeline pdr "$dir/m" --out "$dir/x"
[ $rc -eq 2 ] || fail "bad steps exit code $rc"
grep -q "steps.csv:3: column 'dx': 'abc' is not a finite number" "$dir/err" || { cat "$dir/err"; fail "bad steps message"; }
run_failing "$TM" validate "$dir/m"
[ $rc -eq 2 ] && grep -q "steps.csv:3:" "$dir/err" || fail "validate bad steps"
rm "$dir/m/steps.csv"
run_failing "$TM" run --pipeline pdr "$dir/m" --out "$dir/x"
[ $rc -eq 2 ] && grep -q "steps.csv: missing" "$dir/err" || fail "missing steps"
echo '{"nodes": [' > "$dir/m/mission.json"
run_failing "$TM" eval "$dir/m" "$dir/run/estimates.csv"
[ $rc -eq 2 ] && grep -q "mission.json:.*invalid JSON" "$dir/err" || fail "bad mission.json"
echo "cli: 1 passed, 0 failed"

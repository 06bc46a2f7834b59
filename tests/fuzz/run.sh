#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Builds the libFuzzer target with clang (ASan + UBSan) and runs it for a bounded time on a
# seed corpus of valid and broken files.
set -euo pipefail
CXX="$1"; SRC="$2"; OUT="$3"; SECONDS_LIMIT="${4:-20}"
mkdir -p "$OUT/corpus"
gen="$OUT/generated"
mkdir -p "$gen/trailmark_generated"
printf '#pragma once\n#include <string_view>\nnamespace trailmark::generated {\ninline constexpr std::string_view kChartJsParts[] = {""};\n}\n' \
  > "$gen/trailmark_generated/chartjs_bundle.h"
sources=(core/types.cpp core/mission.cpp io/csv.cpp io/streams.cpp io/mission_io.cpp io/json_input.cpp
         geometry/segment.cpp geometry/segment_index.cpp geometry/floor_plan.cpp)
srcs=()
for s in "${sources[@]}"; do srcs+=("$SRC/trailmark/$s"); done
if [ ! -x "$OUT/csv_fuzz" ] || [ -n "$(find "$SRC/trailmark/io" "$SRC/tests/fuzz" -newer "$OUT/csv_fuzz" -name '*.*' | head -1)" ]; then
  "$CXX" -std=c++20 -O1 -g -fsanitize=fuzzer,address,undefined -DFMT_HEADER_ONLY \
    -I"$SRC" -I"$gen" -isystem /usr/include/eigen3 \
    "$SRC/tests/fuzz/csv_fuzz.cpp" "${srcs[@]}" -o "$OUT/csv_fuzz"
fi
printf 't,agent,ax,ay,az,gx,gy,gz\n0,ff1,0,0,9.8,0,0,0\n' > "$OUT/corpus/imu.csv"
printf 't0,t1,agent,dx,dy,sxx,syy\n0,1,ff1,0.5,0,0.01,0.01\n1,2,ff1,nan,0,,\n' > "$OUT/corpus/steps.csv"
printf 't,rx,tx,rssi_dbm\n0,a,b,-50\n"q,x",a,b,1\n' > "$OUT/corpus/rssi.csv"
printf '{"nodes":[{"id":"b","kind":"base","position":[0,0,0]}],"radio":{"alpha_dbm":-40}}' > "$OUT/corpus/m.json"
printf '{"type":"FeatureCollection","features":[{"type":"Feature","properties":{"kind":"wall"},"geometry":{"type":"LineString","coordinates":[[0,0],[1,0]]}}]}' > "$OUT/corpus/p.json"
# Regressions the fuzzer found: a geometry whose "type" is an array (2026-12-02).
printf '{"type":"FeatureCollection","features":[{"type":"Feature","properties":{"kind":"wall"},"geometry":{"type":[[0,0],[1,0]]}}]}' > "$OUT/corpus/p-type-array.json"
cd "$OUT"
./csv_fuzz -max_total_time="$SECONDS_LIMIT" -max_len=4096 -timeout=10 -print_final_stats=1 corpus 2>&1 | tail -5
echo "fuzz: 1 passed, 0 failed"

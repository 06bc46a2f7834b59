#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Builds the libFuzzer targets with clang (ASan + UBSan) and runs each for a bounded time on a
# seed corpus of valid and broken files: the readers (csv_fuzz) and the converters of recorded
# sets (convert_fuzz).
set -euo pipefail
CXX="$1"; SRC="$2"; OUT="$3"; SECONDS_LIMIT="${4:-20}"
mkdir -p "$OUT/corpus"
gen="$OUT/generated"
mkdir -p "$gen/trailmark_generated"
printf '#pragma once\n#include <string_view>\nnamespace trailmark::generated {\ninline constexpr std::string_view kChartJsParts[] = {""};\n}\n' \
  > "$gen/trailmark_generated/chartjs_bundle.h"
sources=(core/types.cpp core/mission.cpp io/csv.cpp io/streams.cpp io/mission_io.cpp io/json_input.cpp io/geo.cpp
         geometry/segment.cpp geometry/segment_index.cpp geometry/floor_plan.cpp)
srcs=()
for s in "${sources[@]}"; do srcs+=("$SRC/trailmark/$s"); done
for target in csv_fuzz convert_fuzz; do
  if [ ! -x "$OUT/$target" ] || [ -n "$(find "$SRC/trailmark/io" "$SRC/tests/fuzz" -newer "$OUT/$target" -name '*.*' | head -1)" ]; then
    extra=()
    if [ "$target" = convert_fuzz ]; then
      extra=("$SRC/trailmark/io/convert_foot_imu.cpp" "$SRC/trailmark/io/convert_pyshoe.cpp"
             "$SRC/trailmark/io/convert_wrld.cpp" "$SRC/trailmark/io/trajectory_formats.cpp"
             "$SRC/trailmark/io/convert_ipin.cpp" "$SRC/trailmark/io/convert_imdf.cpp" -lzip)
    fi
    "$CXX" -std=c++20 -O1 -g -fsanitize=fuzzer,address,undefined -DFMT_HEADER_ONLY \
      -I"$SRC" -I"$gen" -isystem /usr/include/eigen3 \
      "$SRC/tests/fuzz/$target.cpp" "${srcs[@]}" "${extra[@]}" -lGeographicLib -o "$OUT/$target"
  fi
done
printf 't,agent,ax,ay,az,gx,gy,gz\n0,ff1,0,0,9.8,0,0,0\n' > "$OUT/corpus/imu.csv"
printf 't0,t1,agent,dx,dy,sxx,syy\n0,1,ff1,0.5,0,0.01,0.01\n1,2,ff1,nan,0,,\n' > "$OUT/corpus/steps.csv"
printf 't,rx,tx,rssi_dbm\n0,a,b,-50\n"q,x",a,b,1\n' > "$OUT/corpus/rssi.csv"
printf '{"nodes":[{"id":"b","kind":"base","position":[0,0,0]}],"radio":{"alpha_dbm":-40}}' > "$OUT/corpus/m.json"
printf '{"type":"FeatureCollection","features":[{"type":"Feature","properties":{"kind":"wall"},"geometry":{"type":"LineString","coordinates":[[0,0],[1,0]]}}]}' > "$OUT/corpus/p.json"
# Regressions the fuzzer found: a geometry whose "type" is an array (2026-12-02).
printf '{"type":"FeatureCollection","features":[{"type":"Feature","properties":{"kind":"wall"},"geometry":{"type":[[0,0],[1,0]]}}]}' > "$OUT/corpus/p-type-array.json"
# The converters' corpus: valid files of each set, split into files at "\n==\n".
conv="$OUT/convert-corpus"
mkdir -p "$conv"
printf '0.1,0.2,9.8,0.01,0.02,0.03\n0.1,0.2,9.8,0.01,0.02,0.03\n' > "$conv/openshoe.txt"
printf 't_s,ax_mps2,ay_mps2,az_mps2,gx_radps,gy_radps,gz_radps,gt_x_m,gt_y_m,gt_z_m,zv_best\n0,0,0,9.8,0,0,0,0,0,0,1\n' > "$conv/pyshoe.csv"
printf 't_s,ax_mps2,ay_mps2,az_mps2,gx_radps,gy_radps,gz_radps\n0,0,0,9.8,0,0,0\n\n==\nt_s,x_m,y_m\n0,0,0\n' > "$conv/llio.csv"
printf 'time_index,acc_x,acc_y,acc_z,gyro_x,gyro_y,gyro_z\n0,0,0,9.8,0,0,0\n\n==\ntime_index,acc_x,acc_y,acc_z,gyro_x,gyro_y,gyro_z\n0,0,0,9.8,0,0,0\n\n==\ntime_index,pos_left_x,pos_left_y,pos_left_z,pos_right_x,pos_right_y,pos_right_z\n0,0,0,0,0.2,0,0\n' > "$conv/dualfoot.csv"
printf '{"id":"b","location":{"type":"Point","coordinates":[-6.3,53.3]},"levels":[{"id":"l0","filename":"level.json","z_order":0}]}\n==\n{"type":"FeatureCollection","features":[{"type":"Feature","properties":{"type":"wall"},"geometry":{"type":"Polygon","coordinates":[[[-6.3,53.3],[-6.2999,53.3],[-6.2999,53.3001],[-6.3,53.3]]]}},{"type":"Feature","properties":{"type":"room","name":"A"},"geometry":{"type":"Polygon","coordinates":[[[-6.3,53.3],[-6.2999,53.3],[-6.2999,53.3001],[-6.3,53.3]]]}}]}' > "$conv/wrld.json"
printf '#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z []\n1403636579763555584,4.5,-1.5,0.75,1,0,0,0\n==\n#timestamp [ns],w_RS_S_x,w_RS_S_y,w_RS_S_z,a_RS_S_x,a_RS_S_y,a_RS_S_z\n1403636579758555392,0,0,0,9.8,0,0\n' > "$conv/euroc.csv"
printf '%% GetSensorData\nGYRO;0.01;1.01;0.1;0.2;0.3;3\nACCE;0.015;1.015;9.1;0.1;0.6;3\nGYRO;0.02;1.02;0.3;0.4;0.5;3\nPRES;0.03;1.03;1013.25;0\nPOSI;0.04;1;40.3132;-3.4831;0;0\nWIFI;0.06;1.06;eduroam;00:0b:86:27:36:c1;2412;-55\nBLE4;0.07;iBeacon;F4:B8:5E:DE:4D:F1;-79;-59;1;2;e2c5\nBLE4;0.09;2;15;-90\nPOSI;0.1;3;40.3132;-3.482;1;0\n' > "$conv/ipin.txt"
# Regression (2026-12-05): a pressure of 1,130 hPa converted, then refused by baro.csv's reader.
printf 'GYRO;0.01;1.01;0.1;0.2;0.3;3\nACCE;0.015;1.015;9.1;0.1;0.6;3\nPRES;0.03;1.00000000006;1130.25;0\n' > "$conv/ipin-pressure-beyond-reader.txt"
# Regression (2026-12-04): an ACCE sample after the last GYRO sample read past the gyro samples.
printf 'GYRO;0.01;1.01;0.1;0.2;0.3;3\nACCE;010.5;1.015;9.1;0.1;0.6;3\nGYRO;0.02;1.02;0.3;0.4;0.5;3\n' > "$conv/ipin-accel-after-gyro.txt"
printf '{"type":"FeatureCollection","features":[{"id":"L0","type":"Feature","properties":{"ordinal":0,"name":{"en":"G"}},"geometry":null}]}\n==\n{"type":"FeatureCollection","features":[{"id":"u1","type":"Feature","properties":{"category":"room","level_id":"L0","name":{"en":"A"}},"geometry":{"type":"Polygon","coordinates":[[[2.35,48.85],[2.3501,48.85],[2.3501,48.8501],[2.35,48.8501],[2.35,48.85]]]}}]}\n==\n{"type":"FeatureCollection","features":[{"id":"o1","type":"Feature","properties":{"level_id":"L0"},"geometry":{"type":"LineString","coordinates":[[2.3501,48.85004],[2.3501,48.85006]]}}]}\n' > "$conv/imdf.json"
cd "$OUT"
./csv_fuzz -max_total_time="$SECONDS_LIMIT" -max_len=4096 -timeout=10 -print_final_stats=1 corpus 2>&1 | tail -5
./convert_fuzz -max_total_time="$SECONDS_LIMIT" -max_len=4096 -timeout=10 -print_final_stats=1 convert-corpus 2>&1 | tail -5
echo "fuzz: 2 passed, 0 failed"

#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Installs this build into a temporary prefix and builds a separate consumer against it.
set -euo pipefail
build="$1"; src="$2"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cmake --install "$build" --prefix "$tmp/prefix" > "$tmp/install.log"
cmake -S "$src" -B "$tmp/build" -G Ninja -DCMAKE_PREFIX_PATH="$tmp/prefix" > "$tmp/cfg.log" \
  || { cat "$tmp/cfg.log"; exit 1; }
cmake --build "$tmp/build" > "$tmp/build.log" || { cat "$tmp/build.log"; exit 1; }
"$tmp/build/consumer"
# The Python package, where the build has it: importable from the install alone.
for site in "$tmp"/prefix/lib/python3*/dist-packages; do
  [ -f "$site/trailmark/__init__.py" ] || continue
  (cd "$tmp" && PYTHONPATH="$site" /usr/bin/python3 -c \
    'import trailmark, sys; n = trailmark.pipelines(); assert "pdr" in n, n; print("python:", trailmark.__file__, len(n), "pipelines")')
done
# pkg-config: the same consumer compiled and linked by hand from trailmark.pc.
pc=$(dirname "$(find "$tmp/prefix" -name trailmark.pc | head -1)")
[ -n "$pc" ] || { echo "no trailmark.pc installed"; exit 1; }
# shellcheck disable=SC2046
c++ -std=c++20 -O1 "$src/main.cpp" -o "$tmp/consumer-pc" \
  $(PKG_CONFIG_PATH="$pc" pkg-config --cflags --libs trailmark) \
  || { echo "pkg-config build failed"; exit 1; }
"$tmp/consumer-pc" > /dev/null || { echo "the pkg-config build does not run"; exit 1; }
echo "pkg-config: built and ran the consumer with $(PKG_CONFIG_PATH="$pc" pkg-config --modversion trailmark)"

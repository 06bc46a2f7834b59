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
for site in "$tmp"/prefix/lib*/python3/dist-packages "$tmp"/prefix/lib/*/python3/dist-packages; do
  [ -f "$site/trailmark/__init__.py" ] || continue
  (cd "$tmp" && PYTHONPATH="$site" /usr/bin/python3 -c \
    'import trailmark, sys; n = trailmark.pipelines(); assert "pdr" in n, n; print("python:", trailmark.__file__, len(n), "pipelines")')
done

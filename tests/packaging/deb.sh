#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# The Debian package (cpack -G DEB): built from this build tree, its contents listed, and the
# command-line tool and the Python package it carries run from the unpacked files.
set -euo pipefail
build="$1"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
(cd "$tmp" && cpack -G DEB --config "$build/CPackConfig.cmake" > cpack.log 2>&1) \
  || { cat "$tmp/cpack.log"; exit 1; }
deb=$(ls "$tmp"/trailmark_*.deb)
dpkg-deb --info "$deb" | grep "Package: trailmark" > /dev/null || { echo "no package name"; exit 1; }
dpkg-deb --info "$deb" | grep "Depends:.*libgeographiclib" > /dev/null || { dpkg-deb --info "$deb"; echo "no shared-library dependencies"; exit 1; }
contents=$(dpkg-deb -c "$deb")
for f in ./usr/bin/trailmark ./usr/include/trailmark/core/online_estimator.h \
         /pkgconfig/trailmark.pc /cmake/trailmark/trailmarkConfig.cmake \
         ./usr/share/doc/trailmark/LICENSE; do
  grep -q -- "$f" <<< "$contents" || { echo "missing from the package: $f"; exit 1; }
done
# The Python package where Debian's python3 finds it: /usr/lib/python3.X/dist-packages.
py=$(/usr/bin/python3 -c 'import sys; print(f"{sys.version_info[0]}.{sys.version_info[1]}")')
grep -q -- "./usr/lib/python$py/dist-packages/trailmark/__init__.py" <<< "$contents" \
  || { echo "missing from the package: the Python package in /usr/lib/python$py/dist-packages"; exit 1; }
dpkg-deb -x "$deb" "$tmp/root"
"$tmp/root/usr/bin/trailmark" --version | grep "^trailmark " > /dev/null || { echo "the packaged CLI does not run"; exit 1; }
site="$tmp/root/usr/lib/python$py/dist-packages"
PYTHONPATH="$site" /usr/bin/python3 -c 'import trailmark; assert "pdr" in trailmark.pipelines()' \
  || { echo "the packaged Python module does not import"; exit 1; }
echo "deb: $(basename "$deb"), $(grep -c . <<< "$contents") entries; CLI and Python package run"

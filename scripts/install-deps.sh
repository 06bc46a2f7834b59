#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Installs everything trailmark needs to build, test and report, from Debian 12 packages
# (and npm for the report's charting bundle). Idempotent: re-running installs nothing new.
set -euo pipefail

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi

PACKAGES=(
  build-essential cmake ninja-build ccache pkg-config git
  libeigen3-dev libcli11-dev nlohmann-json3-dev libfmt-dev libspdlog-dev
  libgtest-dev libgmock-dev libbenchmark-dev libnanoflann-dev libboost-dev libspectra-dev libceres-dev libsqlite3-dev
  libcpp-httplib-dev libbrotli-dev zlib1g-dev curl chromium
  libpaho-mqtt-dev libpaho-mqttpp-dev mosquitto mosquitto-clients openssl libssl-dev
  clang libclang-rt-14-dev
  pybind11-dev python3-dev python3-numpy python3-pytest libgeographiclib-dev libzip-dev doxygen
)

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ "${#missing[@]}" -gt 0 ]; then
  echo "[install] installing: ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
else
  echo "[install] all Debian packages present"
fi

# npm packages of the web front end (the report embeds Chart.js; the dashboard is built with
# TypeScript and Vite). Node.js from Debian only where no node is installed (a newer Node.js
# conflicts with Debian's nodejs/npm packages).
if ! command -v npm >/dev/null 2>&1; then
  echo "[install] installing nodejs and npm from Debian"
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends nodejs npm
fi
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [ ! -d "$here/tests/browser/node_modules/playwright-core" ] || [ ! -d "$here/tests/browser/node_modules/axe-core" ]; then
  echo "[install] npm ci in tests/browser (playwright-core, axe-core; the browser is Debian's chromium)"
  (cd "$here/tests/browser" && npm ci --no-audit --no-fund --loglevel=error)
fi
if [ ! -f "$here/web/report/node_modules/chart.js/dist/chart.umd.js" ]; then
  echo "[install] npm ci in web/report"
  (cd "$here/web/report" && npm ci --no-audit --no-fund --loglevel=error)
fi
if [ ! -x "$here/web/dashboard/node_modules/.bin/vite" ]; then
  echo "[install] npm ci in web/dashboard (TypeScript and Vite, to build the dashboard)"
  (cd "$here/web/dashboard" && npm ci --no-audit --no-fund --loglevel=error)
fi

#!/usr/bin/env bash
# Installs everything trailmark needs to build, test and report, from Debian 12 packages
# (and npm for the report's charting bundle). Idempotent: re-running installs nothing new.
set -euo pipefail

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi

PACKAGES=(
  build-essential cmake ninja-build ccache pkg-config git
  libeigen3-dev libcli11-dev nlohmann-json3-dev libfmt-dev libspdlog-dev
  libgtest-dev libgmock-dev libbenchmark-dev libnanoflann-dev libsqlite3-dev
  clang libclang-rt-14-dev
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

# Node.js is only needed to rebuild the report's bundled chart script; the bundle is
# committed, so a missing node is not an error.
if ! command -v node >/dev/null 2>&1; then
  echo "[install] node not found; the committed report bundle will be used"
fi

#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Install, build (Release with tests) and run every test: unit tests, the CLI end to end, the
# installed-package consumer and a bounded libFuzzer run of the readers.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
bash scripts/install-deps.sh
bash scripts/build.sh release
ctest --preset release -j "$(nproc)"

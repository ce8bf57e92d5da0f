#!/usr/bin/env bash
# The README's test command: configure, build (Release) and run every test.
# LAPFLOW_WERROR=ON (as CI sets it) turns compiler warnings into errors.
set -euo pipefail
cd "$(dirname "$0")/.."
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release -DLAPFLOW_WERROR="${LAPFLOW_WERROR:-OFF}"
cmake --build build -j "$(nproc)"
ctest --test-dir build --output-on-failure -j "$(nproc)"

#!/usr/bin/env bash
# The README's test command: configure, build (Release) and run every test.
# LAPFLOW_WERROR=ON (as CI sets it) turns compiler warnings into errors.
# With ../shared/data beside the project, a test whose shared scene is
# missing fails (LAPFLOW_REQUIRE_SHARED_DATA, which CI sets); without it
# those tests skip. The last line counts the skipped tests.
set -euo pipefail
cd "$(dirname "$0")/.."
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release -DLAPFLOW_WERROR="${LAPFLOW_WERROR:-OFF}"
cmake --build build -j "$(nproc)"
if [ -d ../shared/data ]; then
  export LAPFLOW_REQUIRE_SHARED_DATA=${LAPFLOW_REQUIRE_SHARED_DATA:-1}
else
  echo "test: ../shared/data is absent: the tests on the shared scenes skip" >&2
fi
log=$(mktemp)
trap 'rm -f "$log"' EXIT
status=0
ctest --test-dir build --output-on-failure -j "$(nproc)" 2>&1 | tee "$log" || status=$?
echo "test: $(grep -c '(Skipped)' "$log" || true) tests skipped (ctest lists them above)"
exit "$status"

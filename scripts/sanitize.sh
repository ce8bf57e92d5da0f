#!/usr/bin/env bash
# Builds lapflow and its tests with AddressSanitizer and
# UndefinedBehaviorSanitizer (RelWithDebInfo, in build-asan/) and runs the
# unit tests once under them: every test but the long bakes of the shared
# scenes (label shared_data_bake) and the longest multi-frame bakes whose
# code shorter tests run too (label long_bake). Fails on any sanitizer report: UBSan
# stops at its first finding, ASan always does, and LeakSanitizer reports
# leaks when each test process exits. CI runs it after scripts/test.sh
# (docs/robustness.md, "Sanitizers").
#
#   bash scripts/sanitize.sh
#
# SANITIZE_BUILD_JOBS (default 2) and SANITIZE_TEST_JOBS (default 2) set the
# parallelism; extra arguments go to ctest (e.g. -R Budget).
set -euo pipefail
cd "$(dirname "$0")/.."
build_jobs="${SANITIZE_BUILD_JOBS:-2}"
test_jobs="${SANITIZE_TEST_JOBS:-2}"

# RelWithDebInfo with line tables only (-g1): a report's stack still names
# file and line, and the build takes a third less than with -g (the
# instrumented build costs 5-7x a Release one; docs/robustness.md). A unity
# build of the library and the command line (8 sources a unit; the tests
# stay one unit a file): the templates every source instantiates are
# instrumented and optimised once a unit, not once a source.
cmake -S . -B build-asan -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DLAPFLOW_SANITIZE=address,undefined \
  -DCMAKE_UNITY_BUILD=ON -DCMAKE_UNITY_BUILD_BATCH_SIZE=8 \
  -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O2 -g1 -DNDEBUG" -DCMAKE_C_FLAGS_RELWITHDEBINFO="-O2 -g1 -DNDEBUG" \
  -DLAPFLOW_WERROR="${LAPFLOW_WERROR:-OFF}" >/dev/null
# The tests run lapflow_tests and the lapflow CLI only: the bench and the
# exemplar generator are left to the Release build.
cmake --build build-asan -j "$build_jobs" --target lapflow_tests lapflow

# Only lapflow's own code is instrumented; TBB, OpenVDB, Embree, OIIO and the
# rest are Debian's uninstrumented libraries, so ASan sees their allocations
# only through malloc/new and can report nothing inside them but leaks (see
# scripts/lsan.supp). halt_on_error makes UBSan fail the test, as ASan does.
export ASAN_OPTIONS="${ASAN_OPTIONS:-detect_leaks=1:check_initialization_order=1:strict_init_order=1}"
export UBSAN_OPTIONS="${UBSAN_OPTIONS:-halt_on_error=1:print_stacktrace=1}"
export LSAN_OPTIONS="${LSAN_OPTIONS:-suppressions=$PWD/scripts/lsan.supp:print_suppressions=0}"
start=$(date +%s)
status=0
ctest --test-dir build-asan --output-on-failure -j "$test_jobs" -LE "shared_data_bake|long_bake|blender" "$@" || status=$?
echo "sanitize.sh: the sanitized tests took $(( $(date +%s) - start )) s"
exit "$status"

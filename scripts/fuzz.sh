#!/usr/bin/env bash
# Builds lapflow's libFuzzer targets (tests/fuzz: PLY, OBJ, TOML scene file,
# bake manifest, bake state; clang with AddressSanitizer and UndefinedBehaviorSanitizer)
# in build-fuzz/, replays each target's seed corpus (tests/fuzz/corpus/<target>),
# then fuzzes each target for SECONDS (default 60). Fails on any crash,
# sanitizer report, timeout, leak or allocation over the limit; the input
# that found it is left in build-fuzz/findings/.
#
#   bash scripts/fuzz.sh [SECONDS]
#
# New inputs the fuzzer finds go to build-fuzz/corpus/<target>, never into the
# tree: copy a regression input into tests/fuzz/corpus/<target>/ by hand.
#
# FUZZ_SEED=S makes a run reproducible: the inputs come from that random seed
# and the seed corpus only (build-fuzz/corpus is emptied first), so an input
# that fails is found again at the same place on any machine. FUZZ_RUNS=N
# stops each target after N inputs (or SECONDS, whichever comes first). CI
# runs `FUZZ_SEED=1 FUZZ_RUNS=N fuzz.sh 60`: at most 60 s a target, never
# past the N inputs that were checked from that seed before the commit
# (`FUZZ_SEED=1 FUZZ_RUNS=N fuzz.sh 100000` runs all N), so CI's verdict on
# a commit does not depend on luck. Open-ended fuzzing for new findings is
# the plain SECONDS form.
set -euo pipefail
cd "$(dirname "$0")/.."
seconds="${1:-60}"
runs="${FUZZ_RUNS:-}"
seed="${FUZZ_SEED:-}"
targets=(ply obj scene manifest state)
jobs="${FUZZ_BUILD_JOBS:-2}"

if ! command -v clang++ >/dev/null; then
  echo "fuzz.sh: clang++ not found: run scripts/install-deps.sh (it installs clang and libclang-rt-14-dev)" >&2
  exit 1
fi

cmake -S . -B build-fuzz -G Ninja -DLAPFLOW_FUZZ=ON -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_CXX_COMPILER=clang++ -DCMAKE_C_COMPILER=clang -DLAPFLOW_WERROR="${LAPFLOW_WERROR:-OFF}" >/dev/null
cmake --build build-fuzz -j "$jobs"

export ASAN_OPTIONS="${ASAN_OPTIONS:-detect_leaks=1:allocator_may_return_null=0}"
export UBSAN_OPTIONS="${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}"
# Per input: 10 s, and 2 GiB of memory (a reader that trusts a header's
# count would ask for more).
common=(-timeout=10 -rss_limit_mb=2048 -malloc_limit_mb=2048 -print_final_stats=1)
mkdir -p build-fuzz/findings
status=0
for t in "${targets[@]}"; do
  bin="build-fuzz/tests/fuzz/fuzz_$t"
  seeds="tests/fuzz/corpus/$t"
  work="build-fuzz/corpus/$t"
  mkdir -p "$work"
  echo "== fuzz_$t: replaying $(ls "$seeds" | wc -l) seed inputs"
  if ! "$bin" "${common[@]}" -runs=0 -artifact_prefix="build-fuzz/findings/$t-" "$seeds" \
      >"build-fuzz/fuzz_$t.replay.log" 2>&1; then
    echo "fuzz_$t: a seed input fails; see build-fuzz/fuzz_$t.replay.log" >&2
    tail -n 30 "build-fuzz/fuzz_$t.replay.log" >&2
    status=1
    continue
  fi
  budget=(-max_total_time="$seconds")
  what="fuzzing for at most $seconds s"
  if [ -n "$runs" ]; then
    budget+=(-runs="$runs")
    what+=", $runs inputs"
  fi
  if [ -n "$seed" ]; then
    # A fresh, empty work folder: the run depends on the seed corpus only.
    rm -rf "$work" && mkdir -p "$work"
    budget+=(-seed="$seed")
    what+=" from seed $seed"
  fi
  echo "== fuzz_$t: $what"
  if ! "$bin" "${common[@]}" "${budget[@]}" -artifact_prefix="build-fuzz/findings/$t-" \
      "$work" "$seeds" >"build-fuzz/fuzz_$t.log" 2>&1; then
    echo "fuzz_$t: FOUND A FAILURE; see build-fuzz/fuzz_$t.log and build-fuzz/findings/" >&2
    tail -n 40 "build-fuzz/fuzz_$t.log" >&2
    status=1
    continue
  fi
  grep -E "stat::number_of_executed_units|stat::average_exec_per_sec|stat::peak_rss_mb" "build-fuzz/fuzz_$t.log" |
    sed "s/^/   /"
done
if [ "$status" -ne 0 ]; then
  echo "fuzz.sh: failures found" >&2
fi
exit "$status"

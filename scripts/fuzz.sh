#!/usr/bin/env bash
# Runs omnirig's libFuzzer targets (fuzz/) and prints a table: target, executions, corpus size,
# failures. Exits non-zero when any target crashed, leaked, or took longer than 1 s on an input.
#
#   scripts/fuzz.sh SECONDS [--merge] [TARGET...]   fuzz each target for SECONDS
#   scripts/fuzz.sh --runs N [TARGET...]            regression: every input of the corpus, then N
#                                                   mutations with a fixed seed (the test command)
#
# Builds build-fuzz/ with clang (ASan + UBSan + libFuzzer) when needed. Each target starts from
# its seed corpus fuzz/corpus/TARGET/ and writes what it finds to a scratch copy, so the
# repository's corpus grows only with --merge (then the new inputs that add coverage are merged
# back with -merge=1). Inputs that fail are kept in fuzz-out/TARGET/ (crash-*, leak-*,
# timeout-*); reproduce one with build-fuzz/fuzz/fuzz_TARGET FILE. TARGET defaults to all.
# fuzz/dict/TARGET.dict, when present, is the target's libFuzzer dictionary. --no-build runs
# the executables in $OMNIRIG_FUZZ_BUILD_DIR/fuzz/ (default build-fuzz) as they are.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
export CCACHE_BASEDIR="$ROOT"

usage() {
  echo "usage: $0 SECONDS [--merge] [--no-build] [TARGET...] | $0 --runs N [--no-build] [TARGET...]" >&2
  exit 2
}

seconds="" runs="" merge=0 build=1 targets=()
case "${1:-}" in
  --runs)
    [[ ${2:-} =~ ^[0-9]+$ ]] || usage
    runs=$2
    shift 2
    ;;
  *)
    [[ ${1:-} =~ ^[0-9]+$ ]] || usage
    seconds=$1
    shift
    ;;
esac
for arg in "$@"; do
  case $arg in
    --merge) merge=1 ;;
    --no-build) build=0 ;;
    -*) usage ;;
    *) targets+=("$arg") ;;
  esac
done
if [[ ${#targets[@]} -eq 0 ]]; then
  for dir in fuzz/corpus/*/; do targets+=("$(basename "$dir")"); done
fi

BUILD=${OMNIRIG_FUZZ_BUILD_DIR:-build-fuzz}
if [[ $build -eq 1 && ! -f $BUILD/build.ninja ]]; then
  # -O1: enough for the sanitizers, and a much faster build than -O3. Warnings are errors in
  # the GCC builds that ship; here they stay warnings, so that clang's other set of warnings
  # cannot keep the fuzzers from running.
  CC=clang CXX=clang++ cmake -S . -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=Release \
    -DOMNIRIG_FUZZ=ON -DCMAKE_CXX_FLAGS_RELEASE="-O1 -DNDEBUG" >/dev/null
fi
build_targets=()
for target in "${targets[@]}"; do build_targets+=("fuzz_$target"); done
[[ $build -eq 0 ]] || cmake --build "$BUILD" -j "${OMNIRIG_JOBS:-$(nproc)}" --target "${build_targets[@]}"

OUT=$ROOT/fuzz-out
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
# Leaks are failures; a UBSan report aborts (the build has -fno-sanitize-recover=undefined).
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}

failed=0
# Each row as its target ends, so that a long run stopped half-way keeps what it measured.
printf '%-32s %12s %8s %10s %9s\n' target executions inputs bytes failures
for target in "${targets[@]}"; do
  binary=$BUILD/fuzz/fuzz_$target
  seeds=fuzz/corpus/$target
  [[ -d $seeds ]] || { echo "no seed corpus $seeds" >&2; exit 2; }
  work=$scratch/$target
  mkdir -p "$work" "$OUT/$target"
  rm -f "$OUT/$target"/{crash,leak,timeout,oom}-*
  # New inputs go to the first folder ($work); the seeds are read, not written.
  args=(-timeout=1 -detect_leaks=1 -rss_limit_mb=2048 -print_final_stats=1
    -artifact_prefix="$OUT/$target/")
  # JSON targets: the tokens and field names mutations would hardly spell out byte by byte.
  [[ -f fuzz/dict/$target.dict ]] && args+=(-dict="fuzz/dict/$target.dict")
  if [[ -n $runs ]]; then
    args+=(-runs="$runs" -seed=1)
  else
    args+=(-max_total_time="$seconds")
  fi
  log=$OUT/$target/fuzz.log
  status=0
  "$binary" "${args[@]}" "$work" "$seeds" >"$log" 2>&1 || status=$?
  executions=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  [[ -n $executions ]] || executions=$(grep -o '^#[0-9]*' "$log" | tail -1 | tr -d '#')
  found=$(find "$OUT/$target" -maxdepth 1 \( -name 'crash-*' -o -name 'leak-*' -o -name 'timeout-*' \
    -o -name 'oom-*' \) | wc -l)
  if [[ $status -ne 0 && $found -eq 0 ]]; then found=1; fi  # e.g. an abort before any input
  [[ $found -eq 0 ]] || failed=1
  corpus_files=$(find "$work" "$seeds" -type f | wc -l)
  corpus_bytes=$(cat "$work"/* "$seeds"/* 2>/dev/null | wc -c)
  if [[ $merge -eq 1 && $found -eq 0 ]]; then
    "$binary" -merge=1 "$seeds" "$work" >>"$log" 2>&1
  fi
  printf '%-32s %12s %8s %10s %9s\n' "$target" "${executions:-0}" "$corpus_files" \
    "$corpus_bytes" "$found"
  [[ $found -eq 0 ]] || echo "$target: failed, see $log and $OUT/$target/" >&2
done
exit "$failed"

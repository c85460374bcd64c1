#!/usr/bin/env bash
# The project's multi-threaded code under ThreadSanitizer: configures build-tsan (once), builds
# only the tests that start threads, and runs them. Not part of CI (`./omnirig.sh test`): a TSan
# build of these targets took ~20 min on 2 shared cores from a cold ccache, the 15 tests 8.5 min
# (2026-11-28; the live job's pipeline and server_live 4 of them).
#
#   scripts/tsan.sh                 configure, build, run every threaded test below
#   scripts/tsan.sh -R server/http  only the tests whose ctest name matches (ctest -R)
#
# Any data race, lock-order inversion or misuse TSan reports makes the test fail (TSan exits 66).
# Reports from inside uninstrumented libraries only are suppressed in tests/tsan.supp, each with
# its reason; nothing in omnirig's own code is suppressed.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
BUILD=${OMNIRIG_TSAN_BUILD:-build-tsan}
JOBS=${OMNIRIG_JOBS:-2}
export CCACHE_BASEDIR="$ROOT"

# ctest name -> build target. Each test here runs code on more than one thread.
declare -A TESTS=(
  [engine/util/parallel]=engine_util_parallel_test  # RunTasks
  [engine/rig/relpose_model_select]=engine_rig_relpose_model_select_test  # candidates, folds
  [api/calibration_job]=api_calibration_job_test  # parallel detection, 2 threads
  [api/slam_job]=api_slam_job_test  # pipelined front/back end
  [engine/synth_render]=engine_synth_render_test  # RunTasks rows, renderer cache
  [storage/sqlite_job_store]=storage_sqlite_job_store_test  # concurrent claims, readers
  [server/http]=server_http_test  # thread per connection, refuser
  [server/events]=server_events_test  # SSE streams
  [server/worker_pool]=server_worker_pool_test  # workers, heartbeat, drain
  [tests/server_api]=tests_server_api_test  # workers, queue, cancel, drain
  [tests/server_crash]=tests_server_crash_test  # SIGKILLed server, restarts
  [engine/util/background_task]=engine_util_background_task_test  # the dense job's writer
  [api/stereo_job_unit]=api_stereo_job_unit_test  # dense pairs matched two at a time
  [engine/slam/session]=engine_slam_session_test  # live front end beside back end
  [api/live_publisher]=api_live_publisher_test  # live snapshots written behind
  [tests/server_live]=tests_server_live_test  # live frames, finish, cancel
  [api/live_slam]=api_live_slam_test  # frames stored beside their front end, answers before mapping
)

log() { printf '\033[1m[tsan]\033[0m %s\n' "$*" >&2; }

if [[ ! -f $BUILD/build.ninja ]]; then
  log "configuring $BUILD"
  cmake -S . -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DOMNIRIG_WERROR=ON \
    -DOMNIRIG_BUILD_BENCH=OFF \
    -DCMAKE_CXX_FLAGS="-fsanitize=thread -fno-omit-frame-pointer" \
    -DCMAKE_EXE_LINKER_FLAGS=-fsanitize=thread -DCMAKE_SHARED_LINKER_FLAGS=-fsanitize=thread
fi
log "building ${#TESTS[@]} test targets with -j$JOBS"
cmake --build "$BUILD" -j "$JOBS" --target "${TESTS[@]}"

# Reports go to files rather than to each test's output: the servers that tests/server_crash
# starts as child processes (and SIGKILLs) write theirs nowhere a test would look otherwise.
REPORTS="$ROOT/$BUILD/tsan-reports"
rm -rf "$REPORTS"
mkdir -p "$REPORTS"
TSAN_OPTIONS="suppressions=$ROOT/tests/tsan.supp second_deadlock_stack=1 history_size=4 \
log_path=$REPORTS/report ${TSAN_OPTIONS:-}"
export TSAN_OPTIONS

# TSan needs its fixed address layout: with high mmap randomisation (vm.mmap_rnd_bits > 28 on
# some kernels) it dies at start with "unexpected memory mapping". Running without address
# randomisation (inherited by the tests ctest starts) avoids it without touching sysctl.
RUN=()
probe_binary="$BUILD/engine/util/engine_util_parallel_test"
if ! probe=$(TSAN_OPTIONS= "$probe_binary" --gtest_list_tests 2>&1); then
  if grep -q "unexpected memory mapping" <<<"$probe"; then
    log "TSan cannot map its shadow memory here: running the tests under setarch -R"
    RUN=(setarch "$(uname -m)" -R)
  else
    printf '%s\n' "$probe" >&2
    exit 1
  fi
fi

# One CPU for the tests. Debian's OpenCV runs cv::parallel_for_ (detection, features, imgproc)
# on TBB's worker threads, and TBB passes work to and from them with its own uninstrumented
# atomics: TSan then reports OpenCV's own buffers (filled by a worker, freed by the caller) as
# races (~130 reports from api/slam_job and engine/calib/real_data). On one CPU, TBB starts no
# workers (its default concurrency follows the affinity mask) and OpenCV runs inline, so every
# thread left is one omnirig or the tests started, and needs no suppression. TSan finds races by
# happens-before, not by timing, so threads sharing one CPU still have every access checked.
CPU=$(awk '/^Cpus_allowed_list/ {split($2, first, /[-,]/); print first[1]}' /proc/self/status)
RUN+=(taskset -c "$CPU")

if [[ $# -eq 0 ]]; then
  set -- -R "^($(IFS='|'; echo "${!TESTS[*]}"))\$"
fi
log "running under ThreadSanitizer on CPU $CPU: ctest $*"
cd "$BUILD"
status=0
"${RUN[@]}" ctest --output-on-failure --no-tests=error "$@" || status=$?
if compgen -G "$REPORTS/report*" >/dev/null; then
  cat "$REPORTS"/report*
  log "ThreadSanitizer reports above (also in $REPORTS; the file suffix is the process id)"
  exit 1
fi
[[ $status -eq 0 ]] || exit "$status"
log "all passed, no ThreadSanitizer reports"

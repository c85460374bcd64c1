#!/usr/bin/env bash
# Load benchmark of the omnirig service (against its targets), on this machine:
#   1. 200 clients following jobs while the workers run real calibration jobs on real images
#      (CPU busy): wrk's 200 connections poll GET /jobs/{id} at ~1,000 requests/s for 20 s
#      (target: p99 under 10 ms on 2 cores), independently and then in lockstep (see
#      bench/load_poll.lua); meanwhile bench/sse_latency.py follows GET /api/v1/events and times
#      the events of jobs it creates and cancels (target: an event within 100 ms);
#   2. upload throughput: a 200 MB dataset (50 PNG files of 4 MB) PUT over loopback;
#   3. SIGKILL-and-restart cycles during a batch of jobs (tests/server_crash with 20 cycles).
# Usage: bench/load_bench.sh [BUILD_DIR]   (default: build). Needs wrk, curl, python3.
# LOAD_BENCH_PARTS (default "poll upload crash") picks the parts to run.
# LOAD_BENCH_CONNECTIONS (default 200) and LOAD_BENCH_DELAY_MS (default 199, the mean pause of
# each connection between polls) set the polling load; LOAD_BENCH_SERVE_ARGS adds `omnirig serve`
# flags (e.g. "--worker-sched idle").
set -euo pipefail
PARTS=${LOAD_BENCH_PARTS:-poll upload crash}
ROOT=$(cd "$(dirname "$0")/.." && pwd)
BUILD=$(cd "${1:-$ROOT/build}" && pwd)
OMNIRIG=$BUILD/server/omnirig
CRASH_TEST=$BUILD/tests/tests_server_crash_test
REAL=${LOAD_BENCH_REAL:-$ROOT/../shared/data/real/ocamcalib-vmr}  # real images (calibration jobs)
WORK=$(mktemp -d /tmp/omnirig-load-XXXXXX)
SERVER_PID=
cleanup() {
  [[ -n $SERVER_PID ]] && kill "$SERVER_PID" 2>/dev/null && wait "$SERVER_PID" 2>/dev/null
  rm -rf "$WORK"
}
trap cleanup EXIT
for tool in wrk curl python3; do
  command -v $tool >/dev/null || { echo "load_bench: $tool is required" >&2; exit 2; }
done

start_server() {  # args...
  "$OMNIRIG" serve --port 0 --data "$WORK/data" --web "" "$@" > "$WORK/serve.out" 2> "$WORK/serve.err" &
  SERVER_PID=$!
  for _ in $(seq 100); do
    PORT=$(sed -n 's/^omnirig listening on http:\/\/[^:]*:\([0-9]*\)$/\1/p' "$WORK/serve.out" 2>/dev/null || true)
    [[ -n $PORT ]] && break
    sleep 0.1
  done
  [[ -n $PORT ]] || { cat "$WORK/serve.err" >&2; exit 1; }
  URL=http://127.0.0.1:$PORT
}
# CPU seconds (user + system) the server process has used so far.
server_cpu_s() { awk -v hz="$(getconf CLK_TCK)" '{printf "%.2f", ($14 + $15) / hz}' "/proc/$SERVER_PID/stat"; }
json_field() { python3 -c "import json,sys; print(json.load(sys.stdin)[sys.argv[1]])" "$1"; }

echo "== omnirig load benchmark ($(nproc) cores, $(date -u +%FT%TZ))"
echo "load_average_start $(cut -d' ' -f1-3 /proc/loadavg)"
start_server ${LOAD_BENCH_SERVE_ARGS:-}  # e.g. "--worker-sched idle"
echo "server on $URL"

# 1. Polling while the worker computes.
if [[ $PARTS == *poll* ]]; then
DATASET=$(curl -sf -X POST "$URL/api/v1/datasets" -d '{"name": "load"}' | json_field id)
BUSY=no
if [[ -d $REAL ]] && curl -sf "$URL/api/v1/health" | grep -q '"calibration"'; then
  for image in "$REAL"/*.jpg; do
    curl -sf -X PUT --data-binary @"$image" "$URL/api/v1/datasets/$DATASET/images/$(basename "$image")" > /dev/null
  done
  PARAMS='{"board": {"type": "checkerboard", "cols": 6, "rows": 7, "square_size_mm": 30}}'
  # Enough jobs that the worker is still busy when polling ends (one takes ~1.5-3 s).
  for _ in $(seq 60); do
    JOB=$(curl -sf -X POST "$URL/api/v1/jobs" \
      -d "{\"type\": \"calibration\", \"dataset\": \"$DATASET\", \"params\": $PARAMS}" | json_field id)
  done
  sleep 1
  BUSY=$(curl -sf "$URL/api/v1/health" | json_field busy_workers)
fi
POLL_JOB=${JOB:-missing}
echo "polling job $POLL_JOB with workers busy: $BUSY"
CONNECTIONS=${LOAD_BENCH_CONNECTIONS:-200}
DELAY=${LOAD_BENCH_DELAY_MS:-199}
echo "poll_connections $CONNECTIONS"
echo "poll_delay_ms $DELAY"
# Two readings of "200 clients at 1,000 requests/s" (bench/load_poll.lua): clients that poll
# independently (Poisson arrivals, the target's reading), then the same clients in lockstep
# (all of them at once every DELAY_MS, the worst case for the same average rate). Keys of the
# second reading start with poll_lockstep_.
poll_run() {  # ARRIVALS PREFIX
  local cpu_start requests
  cpu_start=$(server_cpu_s)
  echo "${2}arrivals $1"
  # The /metrics gauge of open connections halfway through the run: wrk's connections plus
  # the one reading it.
  (sleep 10; curl -sf "$URL/metrics" | sed -n 's/^omnirig_http_open_connections //p') \
      > "$WORK/open_connections.txt" &
  local sampler=$!
  # The client's own CPU (user + system) too: wrk shares the 2 cores with the server.
  local TIMEFORMAT='%U %S'
  { time ARRIVALS=$1 DELAY_MS=$DELAY wrk -t2 -c"$CONNECTIONS" -d20s \
      -s "$ROOT/bench/load_poll.lua" "$URL/api/v1/jobs/$POLL_JOB" > "$WORK/wrk.txt" ; } \
      2> "$WORK/wrk_cpu.txt"
  wait "$sampler" || true
  grep -E '^poll_' "$WORK/wrk.txt" | sed "s/^poll_/$2/"
  echo "${2}open_connections_midway $(cat "$WORK/open_connections.txt")"
  grep -E 'Socket errors|Non-2xx' "$WORK/wrk.txt" || true
  # Server CPU over the run includes the busy workers.
  echo "${2}server_cpu_s $(python3 -c "print(f'{$(server_cpu_s) - $cpu_start:.2f}')")"
  requests=$(sed -n 's/^poll_requests //p' "$WORK/wrk.txt")
  local client_user client_system
  read -r client_user client_system < <(tail -n1 "$WORK/wrk_cpu.txt")
  python3 -c "print(f'${2}client_cpu_us_per_request {($client_user + $client_system) * 1e6 / max(1, $requests):.0f}')"
  echo "${2}load_average $(cut -d' ' -f1-3 /proc/loadavg)"
}
# SSE event latency, measured during the independent polling run.
( sleep 2; python3 "$ROOT/bench/sse_latency.py" "$URL" "$DATASET" calibration \
    "${PARAMS:-{\}}" 250 > "$WORK/sse.txt" 2>&1 ) &
SSE_PID=$!
poll_run independent poll_
wait "$SSE_PID" || true
cat "$WORK/sse.txt"
poll_run lockstep poll_lockstep_
echo "busy workers after polling: $(curl -sf "$URL/api/v1/health" | json_field busy_workers)"
# The upload is measured with the workers idle: cancel what is left of the batch.
for job in $(curl -sf "$URL/api/v1/jobs?limit=10000" |
    python3 -c "import json,sys; print(' '.join(j['id'] for j in json.load(sys.stdin) if j['state'] in ('queued', 'running')))"); do
  curl -sf -o /dev/null -X POST "$URL/api/v1/jobs/$job/cancel" || true
done
fi

# 2. Upload throughput: 50 x 4 MB PNG (random pixels, stored uncompressed-ish by zlib level 0).
if [[ $PARTS == *upload* ]]; then
python3 - "$WORK/upload" <<'PY'
import os, struct, sys, zlib
out = sys.argv[1]; os.makedirs(out)
w, h = 2048, 2048
def chunk(kind, data):
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xffffffff)
for i in range(50):
    rows = b"".join(b"\x00" + os.urandom(w) for _ in range(h))
    png = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0))
           + chunk(b"IDAT", zlib.compress(rows, 0)) + chunk(b"IEND", b""))
    open(os.path.join(out, "img%03d.png" % i), "wb").write(png)
PY
UPLOAD_DATASET=$(curl -sf -X POST "$URL/api/v1/datasets" -d '{"name": "upload"}' | json_field id)
BYTES=$(du -cb "$WORK"/upload/*.png | tail -1 | cut -f1)
START=$(date +%s.%N)
CPU_START=$(server_cpu_s)
# 4 parallel clients, each one curl with a keep-alive connection PUTting its share of the
# files in turn (as `omnirig submit` does), so the client's process start-up is not measured.
LANE_PIDS=()
for lane in 0 1 2 3; do
  ARGS=()
  i=0
  for image in "$WORK"/upload/*.png; do
    (( i++ % 4 == lane )) && ARGS+=(-T "$image" "$URL/api/v1/datasets/$UPLOAD_DATASET/images/$(basename "$image")")
  done
  curl -sf -H "Expect:" "${ARGS[@]}" > /dev/null &
  LANE_PIDS+=($!)
done
for pid in "${LANE_PIDS[@]}"; do wait "$pid"; done
END=$(date +%s.%N)
python3 -c "import sys; b, t = int(sys.argv[1]), float(sys.argv[3]) - float(sys.argv[2]); print(f'upload_mb {b/1e6:.0f}\nupload_s {t:.2f}\nupload_mb_per_s {b/1e6/t:.0f}')" "$BYTES" "$START" "$END"
echo "upload_server_cpu_s $(python3 -c "print(f'{$(server_cpu_s) - $CPU_START:.2f}')")"
curl -sf "$URL/api/v1/datasets/$UPLOAD_DATASET" | python3 -c "import json,sys; d=json.load(sys.stdin); print('uploaded_images', d['image_count'])"
echo "upload_load_average $(cut -d' ' -f1-3 /proc/loadavg)"
fi
kill -TERM "$SERVER_PID"; wait "$SERVER_PID" || true; SERVER_PID=

# 3. Kill-restart cycles (the crash integration test, scaled up).
if [[ $PARTS == *crash* ]]; then
START=$(date +%s.%N)
if OMNIRIG_CRASH_CYCLES=20 OMNIRIG_CRASH_JOBS=10 "$CRASH_TEST" --gtest_filter='*Repeated*' > "$WORK/crash.txt" 2>&1; then
  RESULT=passed
else
  RESULT=FAILED; tail -30 "$WORK/crash.txt"
fi
END=$(date +%s.%N)
python3 -c "import sys; print(f'kill_restart_cycles 20\nkill_restart_result {sys.argv[1]}\nkill_restart_s {float(sys.argv[3]) - float(sys.argv[2]):.1f}')" "$RESULT" "$START" "$END"
fi

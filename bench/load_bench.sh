#!/usr/bin/env bash
# Load benchmark of the omnirig service (issue 6 targets), on this machine:
#   1. job status polling with wrk: 200 connections offering ~2,000 requests/s for 20 s while
#      the worker runs real calibration jobs on real images (CPU busy); p50/p99 latency;
#   2. upload throughput: a 200 MB dataset (50 PNG files of 4 MB) PUT over loopback;
#   3. SIGKILL-and-restart cycles during a batch of jobs (tests/server_crash with 20 cycles).
# Usage: bench/load_bench.sh [BUILD_DIR]   (default: build). Needs wrk, curl, python3.
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
BUILD=$(cd "${1:-$ROOT/build}" && pwd)
OMNIRIG=$BUILD/server/omnirig
CRASH_TEST=$BUILD/tests/tests_server_crash_test
REAL=$ROOT/../shared/data/real/ocamcalib-vmr
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
json_field() { python3 -c "import json,sys; print(json.load(sys.stdin)[sys.argv[1]])" "$1"; }

echo "== omnirig load benchmark ($(nproc) cores, $(date -u +%FT%TZ))"
start_server --http-threads 256
echo "server on $URL"

# 1. Polling while the worker computes.
DATASET=$(curl -sf -X POST "$URL/api/v1/datasets" -d '{"name": "load"}' | json_field id)
BUSY=no
if [[ -d $REAL ]] && curl -sf "$URL/api/v1/health" | grep -q '"calibration"'; then
  for image in "$REAL"/*.jpg; do
    curl -sf -X PUT --data-binary @"$image" "$URL/api/v1/datasets/$DATASET/images/$(basename "$image")" > /dev/null
  done
  PARAMS='{"board": {"type": "checkerboard", "cols": 6, "rows": 7, "square_size_mm": 30}}'
  for _ in $(seq 14); do
    JOB=$(curl -sf -X POST "$URL/api/v1/jobs" \
      -d "{\"type\": \"calibration\", \"dataset\": \"$DATASET\", \"params\": $PARAMS}" | json_field id)
  done
  sleep 1
  BUSY=$(curl -sf "$URL/api/v1/health" | json_field busy_workers)
fi
POLL_JOB=${JOB:-missing}
echo "polling job $POLL_JOB with workers busy: $BUSY"
DELAY_MS=100 wrk -t2 -c200 -d20s -s "$ROOT/bench/load_poll.lua" "$URL/api/v1/jobs/$POLL_JOB" \
  | tee "$WORK/wrk.txt" | grep -E '^poll_|Requests/sec|Socket errors|Non-2xx'
echo "busy workers after polling: $(curl -sf "$URL/api/v1/health" | json_field busy_workers)"

# 2. Upload throughput: 50 x 4 MB PNG (random pixels, stored uncompressed-ish by zlib level 0).
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
ls "$WORK"/upload/*.png | xargs -P 4 -I{} sh -c \
  'curl -sf -o /dev/null -H "Expect:" -X PUT --data-binary @"$1" "$2/$(basename "$1")"' _ {} \
  "$URL/api/v1/datasets/$UPLOAD_DATASET/images"
END=$(date +%s.%N)
python3 -c "import sys; b, t = int(sys.argv[1]), float(sys.argv[3]) - float(sys.argv[2]); print(f'upload_mb {b/1e6:.0f}\nupload_s {t:.2f}\nupload_mb_per_s {b/1e6/t:.0f}')" "$BYTES" "$START" "$END"
curl -sf "$URL/api/v1/datasets/$UPLOAD_DATASET" | python3 -c "import json,sys; d=json.load(sys.stdin); print('uploaded_images', d['image_count'])"
kill -TERM "$SERVER_PID"; wait "$SERVER_PID" || true; SERVER_PID=

# 3. Kill-restart cycles (the crash integration test, scaled up).
START=$(date +%s.%N)
if OMNIRIG_CRASH_CYCLES=20 OMNIRIG_CRASH_JOBS=10 "$CRASH_TEST" --gtest_filter='*Repeated*' > "$WORK/crash.txt" 2>&1; then
  RESULT=passed
else
  RESULT=FAILED; tail -30 "$WORK/crash.txt"
fi
END=$(date +%s.%N)
python3 -c "import sys; print(f'kill_restart_cycles 20\nkill_restart_result {sys.argv[1]}\nkill_restart_s {float(sys.argv[3]) - float(sys.argv[2]):.1f}')" "$RESULT" "$START" "$END"

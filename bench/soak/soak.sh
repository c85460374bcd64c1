#!/usr/bin/env bash
# Soak benchmark: a day of use, compressed, against one `omnirig serve` (SQLite, its default
# worker count) on this machine:
#   - 200 clients following jobs: wrk connections polling GET /api/v1/jobs/{id} of the newest
#     jobs at about 1,000 requests/s in all (bench/soak/poll.lua);
#   - job churn and uploads: bench/soak/churn.py keeps the worker busy with real calibrations
#     (bench's real image set), cancels, retries and deletes jobs, and uploads, reads back and
#     deletes a dataset every 10 s;
#   - SOAK_LIVE_SESSIONS (default 2) robots driving live slam jobs: each plays a rendered
#     40-frame 640x480 stereo sequence through `omnirig live` at 10 Hz, finishes the job, deletes
#     it and its dataset, and starts again, until the soak ends (the churn cancels some of them,
#     as it cancels any running job);
#   - every SOAK_SAMPLE_S seconds the server's resident memory, open file descriptors and threads
#     are sampled from /proc.
# After SOAK_MINUTES the churn stops and accounts for every job; then the figures: memory and
# descriptors after the warm-up (SOAK_WARMUP_MINUTES) against their highest later reading
# (target: within 10 %), the polls' p99 (target: under 10 ms), answers of 500 or more (target:
# none), jobs lost (target: none).
# Usage: bench/soak/soak.sh [BUILD_DIR]   (default: build). Needs wrk, curl, python3.
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
BUILD=$(cd "${1:-$ROOT/build}" && pwd)
OMNIRIG=$BUILD/server/omnirig
MINUTES=${SOAK_MINUTES:-30}
WARMUP_MINUTES=${SOAK_WARMUP_MINUTES:-5}
CLIENTS=${SOAK_CLIENTS:-200}
DELAY_MS=${SOAK_DELAY_MS:-199}
SAMPLE_S=${SOAK_SAMPLE_S:-30}
LIVE_SESSIONS=${SOAK_LIVE_SESSIONS:-2}
IMAGES=${SOAK_IMAGES:-$ROOT/../shared/data/real/ocamcalib-vmr}
WORK=$(mktemp -d /tmp/omnirig-soak-XXXXXX)
SERVER_PID=
CHURN_PID=
LIVE_PIDS=()
cleanup() {
  # SOAK_KEEP=DIR keeps the raw readings (samples, wrk's and the churn's output, server log).
  [[ -n ${SOAK_KEEP:-} ]] && mkdir -p "$SOAK_KEEP" && cp -r "$WORK"/*.txt "$WORK"/*.err "$SOAK_KEEP"/ 2>/dev/null || true
  [[ -n $CHURN_PID ]] && kill "$CHURN_PID" 2>/dev/null || true
  for pid in "${LIVE_PIDS[@]}"; do kill "$pid" 2>/dev/null || true; done
  [[ -n $SERVER_PID ]] && kill "$SERVER_PID" 2>/dev/null && wait "$SERVER_PID" 2>/dev/null || true
  rm -rf "$WORK"
}
trap cleanup EXIT
for tool in wrk curl python3; do
  command -v $tool >/dev/null || { echo "soak: $tool is required" >&2; exit 2; }
done
[[ -d $IMAGES ]] || { echo "soak: no images in $IMAGES (SOAK_IMAGES)" >&2; exit 2; }

"$OMNIRIG" serve --port 0 --data "$WORK/data" --web "" > "$WORK/serve.out" 2> "$WORK/serve.err" &
SERVER_PID=$!
for _ in $(seq 100); do
  PORT=$(sed -n 's/^omnirig listening on http:\/\/[^:]*:\([0-9]*\)$/\1/p' "$WORK/serve.out" || true)
  [[ -n $PORT ]] && break
  sleep 0.1
done
[[ -n $PORT ]] || { cat "$WORK/serve.err" >&2; exit 1; }
URL=http://127.0.0.1:$PORT

echo "== omnirig soak ($(nproc) cores, $(date -u +%FT%TZ)): $MINUTES min, warm-up $WARMUP_MINUTES min," \
     "$CLIENTS clients at a mean pause of $DELAY_MS ms"
echo "load_average_start $(cut -d' ' -f1-3 /proc/loadavg)"
# The live robots' rig: a relative_pose job on a rendered board set, before the clock starts.
if (( LIVE_SESSIONS > 0 )); then
  "$OMNIRIG" synth --preset stereo-board --out "$WORK/board" --width 640 --height 480 --views 8 \
    --supersampling 2 > /dev/null 2>&1
  "$OMNIRIG" synth --preset stereo-sequence --out "$WORK/sequence" --width 640 --height 480 \
    --frames 40 --supersampling 2 > /dev/null 2>&1
  RIG=$("$OMNIRIG" submit --server "$URL" --type relative_pose --out "$WORK/rig" \
    --params '{"board": {"type": "checkerboard", "cols": 8, "rows": 6, "square_size_mm": 40}}' \
    "$WORK/board" 2> "$WORK/rig.err" | head -1)
  [[ -f $WORK/rig/result.json ]] || { echo "soak: the live sessions' rig failed" >&2; cat "$WORK/rig.err" >&2; exit 1; }
fi

# One robot: live slam runs one after the other until the soak stops; each run's figures (the
# `omnirig live --json` summary) on one line of live_N.txt. A run whose job the churn canceled
# (its frames then answered 409 job_finished, or the job canceled while it finished) is
# "canceled"; any other failure is "failed".
# Either way its job and dataset are deleted, so that the runs do not fill the disk.
live_session() {  # N
  local run=0 summary err job dataset
  while [[ ! -e $WORK/stop ]]; do
    run=$((run + 1))
    summary=$WORK/live_$1_$run.json
    err=$WORK/live_$1_run.err
    if "$OMNIRIG" live --server "$URL" --rig "$RIG" --rate 10 --json "$summary" "$WORK/sequence" \
         > "$err.out" 2> "$err"; then
      python3 -c 'import json, sys; s = json.load(open(sys.argv[1])); print(s["frames_tracked"], s["frames_skipped"], s["latency_ms"]["p50"], s["latency_ms"]["p95"])' \
        "$summary" >> "$WORK/live_$1.txt"
    elif grep -q 'job_finished\|has ended (' "$err" || grep -q '^job [0-9a-f]* canceled:' "$err.out"; then
      echo canceled >> "$WORK/live_$1.txt"
    else
      echo failed >> "$WORK/live_$1.txt"
      cat "$err" >> "$WORK/live_$1.err"
    fi
    job=$(sed -n 's/^live job \([0-9a-f]*\) (dataset \([0-9a-f]*\)).*/\1/p' "$err")
    dataset=$(sed -n 's/^live job \([0-9a-f]*\) (dataset \([0-9a-f]*\)).*/\2/p' "$err")
    if [[ -n $job ]]; then
      # A canceled live job the churn retried runs again as a batch job: cancel it first.
      curl -s -o /dev/null -X POST "$URL/api/v1/jobs/$job/cancel"
      for _ in $(seq 240); do
        curl -s "$URL/api/v1/jobs/$job" | grep -q '"state": *"\(queued\|running\)"' || break
        sleep 0.5
      done
      curl -s -o /dev/null -X DELETE "$URL/api/v1/jobs/$job"
      curl -s -o /dev/null -X DELETE "$URL/api/v1/datasets/$dataset"
    fi
    rm -f "$summary"
  done
}

python3 "$ROOT/bench/soak/churn.py" "$URL" "$IMAGES" "$WORK/ids.txt" "$WORK/stop" \
  > "$WORK/churn.txt" 2> "$WORK/churn.err" &
CHURN_PID=$!
while [[ ! -s $WORK/ids.txt ]]; do sleep 0.2; done
for n in $(seq "$LIVE_SESSIONS"); do
  live_session "$n" &
  LIVE_PIDS+=($!)
done

sample() {  # elapsed_s
  local rss fds threads
  rss=$(awk '/^VmRSS/ {print $2}' "/proc/$SERVER_PID/status")
  threads=$(awk '/^Threads/ {print $2}' "/proc/$SERVER_PID/status")
  fds=$(find "/proc/$SERVER_PID/fd" -mindepth 1 | wc -l)
  echo "$1 $rss $fds $threads $(cut -d' ' -f1 /proc/loadavg)"
}
echo "elapsed_s rss_kb fds threads load1" > "$WORK/samples.txt"
START=$(date +%s)
( while kill -0 "$SERVER_PID" 2>/dev/null && [[ ! -e $WORK/stop ]]; do
    sample $(( $(date +%s) - START )) >> "$WORK/samples.txt"
    sleep "$SAMPLE_S"
  done ) &
SAMPLER_PID=$!

IDS_FILE=$WORK/ids.txt DELAY_MS=$DELAY_MS wrk -t2 -c"$CLIENTS" -d"$((MINUTES * 60))s" --timeout 10s \
  -s "$ROOT/bench/soak/poll.lua" "$URL/" > "$WORK/wrk.txt" 2>&1
sample $(( $(date +%s) - START )) >> "$WORK/samples.txt"
touch "$WORK/stop"
wait "$SAMPLER_PID" || true
wait "$CHURN_PID"
CHURN_PID=
for pid in "${LIVE_PIDS[@]}"; do wait "$pid" || true; done
LIVE_PIDS=()
kill -0 "$SERVER_PID" || { echo "soak: the server exited" >&2; exit 1; }

cat "$WORK/samples.txt"
grep -E '^poll_' "$WORK/wrk.txt"
cat "$WORK/churn.txt"
for n in $(seq "$LIVE_SESSIONS"); do
  # Per robot: runs, failed runs, frames tracked and skipped, the worst run's latency p95.
  awk -v n="$n" '$1 == "failed" {failed++; next} $1 == "canceled" {canceled++; next}
    {runs++; tracked += $1; skipped += $2; if ($4 > p95) p95 = $4}
    END {printf "live_session_%d runs_finished %d canceled_by_churn %d failed %d frames_tracked %d frames_skipped %d worst_latency_p95_ms %.1f\n",
         n, runs, canceled, failed, tracked, skipped, p95}' "$WORK/live_$n.txt"
done
echo "load_average_end $(cut -d' ' -f1-3 /proc/loadavg)"
echo "server_5xx_logged $(grep -c ': 5[0-9][0-9]: ' "$WORK/serve.err" || true)"
python3 - "$WORK/samples.txt" "$WARMUP_MINUTES" <<'PY'
import sys
rows = [line.split() for line in open(sys.argv[1]).read().splitlines()[1:]]
rows = [(int(t), int(rss), int(fds), int(threads)) for t, rss, fds, threads, _ in rows]
warm = [r for r in rows if r[0] >= float(sys.argv[2]) * 60]
if not warm:
    sys.exit("soak: no sample after the warm-up")
base, later = warm[0], warm[1:] or warm
for name, i in (("rss_kb", 1), ("fds", 2), ("threads", 3)):
    top = max(r[i] for r in later)
    print(f"{name}_after_warmup {base[i]} max_later {top} final {rows[-1][i]} "
          f"growth_pct {100.0 * (top - base[i]) / max(1, base[i]):.1f}")
PY

"""SSE event latency for bench/load_bench.sh: follows GET /api/v1/events and, N times, creates a
job (then cancels it while still queued) and takes the time from sending the request to the
arrival of the job's "queued" (then "canceled") event on the stream. The change happens between
the request's start and its reply, so two readings bound the push delay: from the request's
start (sse_*, the request's own round trip included: an upper bound) and from its reply
(sse_after_reply_*, 0 when the event came first: the delay once the change was acknowledged,
without the store's write). The requests' round trips are printed too (sse_request_*). Prints
key/value lines.
Usage: sse_latency.py URL DATASET TYPE PARAMS_JSON N"""
import http.client, json, sys, threading, time, urllib.parse

url, dataset, job_type, params, count = sys.argv[1], sys.argv[2], sys.argv[3], json.loads(sys.argv[4]), int(sys.argv[5])
host = urllib.parse.urlparse(url)
seen = {}  # (job id, state) -> arrival time
cond = threading.Condition()

def follow():
    stream = http.client.HTTPConnection(host.hostname, host.port)
    stream.request("GET", "/api/v1/events")
    response = stream.getresponse()
    event, data = None, None
    for raw in response:
        line = raw.decode().rstrip("\n")
        if line.startswith("event: "):
            event = line[7:]
        elif line.startswith("data: "):
            data = line[6:]
        elif line == "" and event == "job" and data:
            job = json.loads(data)
            with cond:
                seen[(job["id"], job["state"])] = time.monotonic()
                cond.notify_all()
            event, data = None, None

threading.Thread(target=follow, daemon=True).start()
time.sleep(0.5)  # let the stream open before the first job
client = http.client.HTTPConnection(host.hostname, host.port)

latencies, after_reply, requests = [], [], []

def timed(method, path, body, state, job_id=None):
    start = time.monotonic()
    client.request(method, path, body=body, headers={"Content-Type": "application/json"})
    reply = json.loads(client.getresponse().read() or b"{}")
    replied = time.monotonic()
    job_id = job_id or reply["id"]
    with cond:
        cond.wait_for(lambda: (job_id, state) in seen, timeout=10)
        arrived = seen.get((job_id, state), float("inf"))
    latencies.append((arrived - start) * 1e3)
    after_reply.append(max(0.0, arrived - replied) * 1e3)
    requests.append((replied - start) * 1e3)
    return job_id

for _ in range(count):
    body = json.dumps({"type": job_type, "dataset": dataset, "params": params})
    job_id = timed("POST", "/api/v1/jobs", body, "queued")
    timed("POST", f"/api/v1/jobs/{job_id}/cancel", "", "canceled", job_id)
    time.sleep(0.05)

def summary(prefix, values):
    values = sorted(values)
    pick = lambda q: values[min(len(values) - 1, int(q * len(values)))]
    print(f"{prefix}p50_ms {pick(0.5):.2f}\n{prefix}p99_ms {pick(0.99):.2f}\n{prefix}max_ms {values[-1]:.2f}")

print(f"sse_events {len(latencies)}")
summary("sse_", latencies)
summary("sse_after_reply_", after_reply)
summary("sse_request_", requests)

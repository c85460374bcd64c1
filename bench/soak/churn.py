#!/usr/bin/env python3
"""The churn client of bench/soak/soak.sh: jobs and uploads, as a day of use brings them.

Usage: churn.py URL IMAGES_DIR IDS_FILE STOP_FILE

Until STOP_FILE exists it keeps the worker busy with calibration jobs on the real images
(at most 3 queued), cancels about one job in six (queued or running), retries about half of
the canceled ones, deletes finished jobs once more than 60 are kept, and every 10 s uploads a
new dataset (PUT each image, then the same as one multipart POST), reads it back and deletes it.
IDS_FILE always lists the newest 50 jobs (the pollers follow those; older ones may be deleted).
Then it stops creating, waits for the queue to empty, and checks that every job it created and
did not delete exists in an end state, and every job it deleted is gone: "lost" counts the jobs
that are neither. Prints `churn_*` lines. Every answer of 500 or more is counted in churn_5xx.
"""
import http.client
import json
import os
import random
import sys
import time
import uuid

URL, IMAGES, IDS_FILE, STOP_FILE = sys.argv[1:5]
HOST, PORT = URL.replace("http://", "").split(":")
PARAMS = {"board": {"type": "checkerboard", "cols": 6, "rows": 7, "square_size_mm": 30}}
random.seed(27)
counts = {"5xx": 0, "requests": 0, "created": 0, "canceled": 0, "retried": 0, "deleted": 0,
          "uploads": 0, "upload_bytes": 0}
connection = http.client.HTTPConnection(HOST, int(PORT), timeout=60)


def call(method, path, body=None, headers=None):
    global connection
    for _ in range(3):
        try:
            connection.request(method, path, body=body, headers=headers or {})
            answer = connection.getresponse()
            data = answer.read()
            break
        except (http.client.HTTPException, OSError):
            connection.close()
            connection = http.client.HTTPConnection(HOST, int(PORT), timeout=60)
    else:
        raise RuntimeError(f"{method} {path}: no answer")
    counts["requests"] += 1
    if answer.status >= 500:
        counts["5xx"] += 1
        print(f"churn 5xx: {method} {path}: {answer.status} {data[:200]!r}", file=sys.stderr)
    return answer.status, (json.loads(data) if data and data[:1] in b"{[" else data)


def post_json(path, value):
    return call("POST", path, json.dumps(value), {"Content-Type": "application/json"})


images = sorted(f for f in os.listdir(IMAGES) if f.lower().endswith((".jpg", ".png")))
image_bytes = {name: open(os.path.join(IMAGES, name), "rb").read() for name in images}
status, calib = post_json("/api/v1/datasets", {"name": "soak calibration"})
for name in images:
    call("PUT", f"/api/v1/datasets/{calib['id']}/images/{name}", image_bytes[name])

created, deleted = [], set()


def write_ids():
    live = [job for job in created if job not in deleted][-50:]
    with open(IDS_FILE + ".tmp", "w") as out:
        out.write("\n".join(live) + "\n")
    os.replace(IDS_FILE + ".tmp", IDS_FILE)


def upload_round():
    status, dataset = post_json("/api/v1/datasets", {"name": "soak upload"})
    if status != 201:
        return
    for name in images[:5]:
        call("PUT", f"/api/v1/datasets/{dataset['id']}/images/{name}", image_bytes[name])
        counts["upload_bytes"] += len(image_bytes[name])
    boundary = uuid.uuid4().hex
    parts = []
    for name in images[5:10]:
        parts.append(f"--{boundary}\r\nContent-Disposition: form-data; name=\"files\"; "
                     f"filename=\"{name}\"\r\nContent-Type: image/jpeg\r\n\r\n".encode()
                     + image_bytes[name] + b"\r\n")
        counts["upload_bytes"] += len(image_bytes[name])
    body = b"".join(parts) + f"--{boundary}--\r\n".encode()
    call("POST", f"/api/v1/datasets/{dataset['id']}/images", body,
         {"Content-Type": f"multipart/form-data; boundary={boundary}"})
    call("GET", f"/api/v1/datasets/{dataset['id']}")
    call("DELETE", f"/api/v1/datasets/{dataset['id']}")
    counts["uploads"] += 1


def churn_step():
    status, jobs = call("GET", "/api/v1/jobs?limit=1000")
    if status != 200:
        return
    by_state = {}
    for job in jobs:
        by_state.setdefault(job["state"], []).append(job["id"])
    if len(by_state.get("queued", [])) < 3:
        status, job = post_json("/api/v1/jobs", {"type": "calibration", "dataset": calib["id"],
                                                 "params": PARAMS})
        if status == 202:
            created.append(job["id"])
            counts["created"] += 1
    active = by_state.get("queued", []) + by_state.get("running", [])
    if active and random.random() < 1 / 6:
        if call("POST", f"/api/v1/jobs/{random.choice(active)}/cancel")[0] in (200, 202):
            counts["canceled"] += 1
    canceled = by_state.get("canceled", [])
    if canceled and random.random() < 0.1:
        if call("POST", f"/api/v1/jobs/{random.choice(canceled)}/retry")[0] == 202:
            counts["retried"] += 1
    live = set([job for job in created if job not in deleted][-50:])
    finished = [j for s in ("succeeded", "failed", "canceled") for j in by_state.get(s, [])]
    old = [job for job in finished if job not in live and job in created]
    for job in old[: max(0, len(finished) - 60)]:
        if call("DELETE", f"/api/v1/jobs/{job}")[0] in (200, 204):
            deleted.add(job)
            counts["deleted"] += 1
    write_ids()


next_upload = time.monotonic()
while not os.path.exists(STOP_FILE):
    churn_step()
    if time.monotonic() >= next_upload:
        upload_round()
        next_upload = time.monotonic() + 10
    time.sleep(0.2)

# The end: the queue drains, then every job is accounted for.
while True:
    status, jobs = call("GET", "/api/v1/jobs?limit=10000")
    if status == 200 and not any(j["state"] in ("queued", "running") for j in jobs):
        break
    time.sleep(1)
states, lost = {}, 0
for job in created:
    status, record = call("GET", f"/api/v1/jobs/{job}")
    if job in deleted:
        lost += status != 404
    elif status != 200 or record["state"] not in ("succeeded", "failed", "canceled"):
        lost += 1
    else:
        states[record["state"]] = states.get(record["state"], 0) + 1
for key, value in counts.items():
    print(f"churn_{key} {value}")
for key in ("succeeded", "failed", "canceled"):
    print(f"churn_end_{key} {states.get(key, 0)}")
print(f"churn_lost {lost}")

#!/usr/bin/python3
"""Writes large recordings for bench/recording_index_bench.cc, with the same independent
writers as the tests: python3-rosbag (ROS 1, uncompressed and lz4) and rosbag2's SQLite schema
(.db3); the MCAP files come from write_mcap.mjs --bench.

usage: write_bench_recordings.py OUT_DIR SIZE_MB

Each recording holds two camera topics of 1280x1024 mono8 images at 20 Hz: a gradient with
3 bits of noise (lz4 keeps about half of it), about SIZE_MB of messages.
"""
import os
import sqlite3
import sys

import genpy
import rosbag
from sensor_msgs.msg import Image

WIDTH, HEIGHT = 1280, 1024
T0_S = 1700000000
PERIOD_NS = 50_000_000


def frames(count):
    size = WIDTH * HEIGHT
    base = int.from_bytes(bytes(range(256)) * (size // 256), "little")
    high = int.from_bytes(b"\xf8" * size, "little")
    low = int.from_bytes(b"\x07" * size, "little")
    out = []
    for _ in range(count):
        noise = int.from_bytes(os.urandom(size), "little")
        out.append(((base & high) | (noise & low)).to_bytes(size, "little"))
    return out


def image(data, i):
    msg = Image()
    msg.header.stamp = genpy.Time(T0_S, 0) + genpy.Duration(0, i * PERIOD_NS)
    msg.height, msg.width, msg.encoding, msg.step = HEIGHT, WIDTH, "mono8", WIDTH
    msg.data = data
    return msg


def main():
    out, size_mb = sys.argv[1], int(sys.argv[2])
    os.makedirs(out, exist_ok=True)
    count = max(2, size_mb * 2**20 // (WIDTH * HEIGHT) // 2)
    pool = frames(8)
    for compression in ("none", "lz4"):
        with rosbag.Bag(os.path.join(out, "bench_%s.bag" % compression), "w",
                        compression=compression) as bag:
            for i in range(count):
                t = genpy.Time(T0_S, 0) + genpy.Duration(0, i * PERIOD_NS)
                bag.write("/cam0/image_raw", image(pool[i % 8], i), t)
                bag.write("/cam1/image_raw", image(pool[(i + 3) % 8], i), t)
    db = sqlite3.connect(os.path.join(out, "bench.db3"))
    db.executescript("""
      CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL,
        serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL);
      CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL,
        timestamp INTEGER NOT NULL, data BLOB NOT NULL);
      CREATE INDEX timestamp_idx ON messages (timestamp ASC);""")
    db.execute("INSERT INTO topics VALUES (1, '/cam0/image_raw', 'sensor_msgs/msg/Image', 'cdr', '')")
    db.execute("INSERT INTO topics VALUES (2, '/cam1/image_raw', 'sensor_msgs/msg/Image', 'cdr', '')")
    for i in range(count):
        t = T0_S * 10**9 + i * PERIOD_NS
        db.execute("INSERT INTO messages(topic_id, timestamp, data) VALUES (1, ?, ?)", (t, pool[i % 8]))
        db.execute("INSERT INTO messages(topic_id, timestamp, data) VALUES (2, ?, ?)", (t, pool[(i + 3) % 8]))
    db.commit()
    db.close()


if __name__ == "__main__":
    main()

#!/usr/bin/python3
"""Writes ROS 2 bags as rosbag2 lays them out, with SQLite (rosbag2's sqlite3 storage schema),
for tests. No ROS is needed: the CDR messages come from write_mcap.mjs (@foxglove/cdr).

usage: write_ros2_bag.py OUT_DIR   (after write_mcap.mjs OUT_DIR)

OUT_DIR/ros2_db3/ (metadata.yaml, ros2_db3_0.db3, ros2_db3_1.db3: the recording split in two
files), OUT_DIR/ros2_mcap/ (metadata.yaml, images_lz4.mcap), OUT_DIR/ros2_db3.tar (the first
folder archived).
"""
import os
import shutil
import sqlite3
import sys
import tarfile

T0_NS = 1700000000 * 10**9
FRAMES, PERIOD_NS = 10, 50_000_000

# rosbag2's sqlite3 storage plugin, schema version 3 (Humble and later).
SCHEMA = """
CREATE TABLE schema(schema_version INTEGER PRIMARY KEY, ros_distro TEXT NOT NULL);
CREATE TABLE metadata(id INTEGER PRIMARY KEY, metadata_version INTEGER NOT NULL, metadata TEXT NOT NULL);
CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL,
  serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL);
CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, timestamp INTEGER NOT NULL,
  data BLOB NOT NULL);
CREATE INDEX timestamp_idx ON messages (timestamp ASC);
"""

METADATA = """rosbag2_bagfile_information:
  version: 5
  storage_identifier: {storage}
  duration:
    nanoseconds: {duration}
  starting_time:
    nanoseconds_since_epoch: {start}
  message_count: {count}
  topics_with_message_count:
    - topic_metadata:
        name: /cam0/image_raw
        type: sensor_msgs/msg/Image
        serialization_format: cdr
        offered_qos_profiles: ""
      message_count: {frames}
  compression_format: ""
  compression_mode: ""
  relative_file_paths:
{paths}
  files: []
"""


def write_db3(path, first, last, messages):
    db = sqlite3.connect(path)
    db.executescript(SCHEMA)
    db.execute("INSERT INTO schema VALUES (3, 'humble')")
    db.execute("INSERT INTO topics VALUES (1, '/cam0/image_raw', 'sensor_msgs/msg/Image', 'cdr', '')")
    db.execute("INSERT INTO topics VALUES (2, '/cam1/image_raw', 'sensor_msgs/msg/Image', 'cdr', '')")
    for i in range(first, last):
        t = T0_NS + i * PERIOD_NS + 5_000_000
        db.execute("INSERT INTO messages(topic_id, timestamp, data) VALUES (1, ?, ?)", (t, messages["mono8"]))
        db.execute("INSERT INTO messages(topic_id, timestamp, data) VALUES (2, ?, ?)", (t, messages["rgb8"]))
    db.commit()
    db.close()


def metadata(storage, files, count):
    paths = "".join("    - %s\n" % f for f in files)
    return METADATA.format(storage=storage, duration=(FRAMES - 1) * PERIOD_NS, start=T0_NS + 5_000_000,
                           count=count, frames=FRAMES, paths=paths.rstrip("\n"))


def main():
    out = sys.argv[1]
    messages = {}
    for name in ("mono8", "rgb8"):
        with open(os.path.join(out, "messages", name + ".cdr"), "rb") as f:
            messages[name] = f.read()
    folder = os.path.join(out, "ros2_db3")
    shutil.rmtree(folder, ignore_errors=True)
    os.makedirs(folder)
    write_db3(os.path.join(folder, "ros2_db3_0.db3"), 0, 6, messages)
    write_db3(os.path.join(folder, "ros2_db3_1.db3"), 6, FRAMES, messages)
    with open(os.path.join(folder, "metadata.yaml"), "w") as f:
        f.write(metadata("sqlite3", ["ros2_db3_0.db3", "ros2_db3_1.db3"], 2 * FRAMES))
    with tarfile.open(os.path.join(out, "ros2_db3.tar"), "w", format=tarfile.GNU_FORMAT) as tar:
        tar.add(folder, arcname="ros2_db3")
    folder = os.path.join(out, "ros2_mcap")
    shutil.rmtree(folder, ignore_errors=True)
    os.makedirs(folder)
    shutil.copy(os.path.join(out, "images_lz4.mcap"), folder)
    with open(os.path.join(folder, "metadata.yaml"), "w") as f:
        f.write(metadata("mcap", ["images_lz4.mcap"], 4 * FRAMES))


if __name__ == "__main__":
    main()

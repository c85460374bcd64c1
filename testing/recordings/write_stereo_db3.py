#!/usr/bin/python3
"""Writes a stereo sequence as a ROS 2 bag folder with rosbag2's sqlite3 storage, for tests.

usage: write_stereo_db3.py CDR_DIR OUT_DIR

CDR_DIR is what write_stereo_ros2.mjs writes (index.txt: "TOPIC LOG_TIME_NS FILE" per message,
the messages CDR-serialised by @foxglove/cdr). OUT_DIR gets metadata.yaml and OUT_DIR_0.db3
(rosbag2's schema version 3, as write_ros2_bag.py documents it).
"""
import os
import sqlite3
import sys

from write_ros2_bag import SCHEMA

TYPES = {"/cam0/image_raw": "sensor_msgs/msg/Image",
         "/cam1/image_raw/compressed": "sensor_msgs/msg/CompressedImage"}

METADATA = """rosbag2_bagfile_information:
  version: 5
  storage_identifier: sqlite3
  duration:
    nanoseconds: {duration}
  starting_time:
    nanoseconds_since_epoch: {start}
  message_count: {count}
  topics_with_message_count:
{topics}
  compression_format: ""
  compression_mode: ""
  relative_file_paths:
    - {file}
  files: []
"""

TOPIC = """    - topic_metadata:
        name: {name}
        type: {type}
        serialization_format: cdr
        offered_qos_profiles: ""
      message_count: {count}
"""


def main():
    cdr_dir, out = sys.argv[1], sys.argv[2]
    with open(os.path.join(cdr_dir, "index.txt")) as f:
        messages = [line.split() for line in f if line.strip()]
    os.makedirs(out, exist_ok=True)
    name = os.path.basename(os.path.normpath(out)) + "_0.db3"
    db = sqlite3.connect(os.path.join(out, name))
    db.executescript(SCHEMA)
    db.execute("INSERT INTO schema VALUES (3, 'humble')")
    topic_ids = {}
    for topic, type_name in TYPES.items():
        topic_ids[topic] = len(topic_ids) + 1
        db.execute("INSERT INTO topics VALUES (?, ?, ?, 'cdr', '')", (topic_ids[topic], topic, type_name))
    for topic, log_time_ns, file in messages:
        with open(os.path.join(cdr_dir, file), "rb") as f:
            db.execute("INSERT INTO messages(topic_id, timestamp, data) VALUES (?, ?, ?)",
                       (topic_ids[topic], int(log_time_ns), f.read()))
    db.commit()
    db.close()
    times = [int(m[1]) for m in messages]
    topics = "".join(TOPIC.format(name=t, type=TYPES[t], count=sum(m[0] == t for m in messages))
                     for t in TYPES)
    with open(os.path.join(out, "metadata.yaml"), "w") as f:
        f.write(METADATA.format(duration=max(times) - min(times), start=min(times),
                                count=len(messages), topics=topics.rstrip("\n"), file=name))


if __name__ == "__main__":
    main()

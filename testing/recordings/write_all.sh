#!/usr/bin/env bash
# Writes every test recording into OUT_DIR with independent writers (see each script):
# ROS 1 bags with Debian's python3-rosbag, MCAP with npm's @mcap/core, ROS 2 bags (.db3) with
# rosbag2's SQLite schema. Needs python3-rosbag, python3-sensor-msgs, python3-roslz4 (Debian)
# and web/node_modules (omnirig.sh installs both).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
out=${1:?usage: write_all.sh OUT_DIR}
mkdir -p "$out"
/usr/bin/python3 "$here/write_ros1_bags.py" "$out"
node "$here/write_mcap.mjs" "$out"
/usr/bin/python3 "$here/write_ros2_bag.py" "$out"

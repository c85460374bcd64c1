#!/usr/bin/python3
"""Writes a stereo sequence as a ROS 1 bag with Debian's python3-rosbag, as a robot records one.

usage: write_stereo_bag.py FRAMES_DIR OUT.bag

FRAMES_DIR/manifest.txt holds one line per stereo frame: "SEC NSEC WIDTH HEIGHT ENCODING CAM0
CAM1", with CAM0 a file of raw pixels (row by row) in ENCODING (mono8 or bgr8) and CAM1 a PNG
file. They are written as /cam0/image_raw (sensor_msgs/Image, stamped SEC.NSEC) and /cam1/image_raw/compressed
(sensor_msgs/CompressedImage, png, stamped 1 ms later: cameras triggered by software), each
received 5 ms after its stamp, in lz4 chunks; and /note (std_msgs/String) once at the start.
"""
import os
import sys

import genpy
import rosbag
from sensor_msgs.msg import CompressedImage, Image
from std_msgs.msg import String


def read(path):
    with open(path, "rb") as f:
        return f.read()


def main():
    frames_dir, out = sys.argv[1], sys.argv[2]
    with open(os.path.join(frames_dir, "manifest.txt")) as f:
        lines = [line.split() for line in f if line.strip()]
    with rosbag.Bag(out, "w", compression="lz4") as bag:
        for i, (sec, nsec, width, height, encoding, cam0, cam1) in enumerate(lines):
            stamp_ns = int(sec) * 1_000_000_000 + int(nsec)
            if i == 0:
                bag.write("/note", String(data="stereo sequence"), genpy.Time(0, stamp_ns))
            image = Image()
            image.header.stamp = genpy.Time(0, stamp_ns)
            image.header.frame_id = "cam0"
            image.height, image.width, image.encoding = int(height), int(width), encoding
            image.step = (3 if encoding == "bgr8" else 1) * int(width)
            image.data = read(os.path.join(frames_dir, cam0))
            bag.write("/cam0/image_raw", image, genpy.Time(0, stamp_ns + 5_000_000))
            compressed = CompressedImage()
            compressed.header.stamp = genpy.Time(0, stamp_ns + 1_000_000)
            compressed.header.frame_id = "cam1"
            compressed.format = "png"
            compressed.data = read(os.path.join(frames_dir, cam1))
            bag.write("/cam1/image_raw/compressed", compressed,
                      genpy.Time(0, stamp_ns + 6_000_000))


if __name__ == "__main__":
    main()

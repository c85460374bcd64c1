#!/usr/bin/python3
"""Writes ROS 1 bags with Debian's python3-rosbag (the ROS project's own writer), for tests.

usage: write_ros1_bags.py OUT_DIR

OUT_DIR/images_none.bag, images_bz2.bag, images_lz4.bag: the same messages, uncompressed and
with bz2 and lz4 chunks; OUT_DIR/cut_short.bag: a recorder killed (SIGKILL) before it closed
the bag; OUT_DIR/messages/*.ros1: single serialized messages for the decoder's tests. The
content follows testing/recordings/README.md's formulas, which the C++ tests recompute.
"""
import io
import os
import signal
import sys

import genpy
import rosbag
from sensor_msgs.msg import CompressedImage, Image
from std_msgs.msg import String

WIDTH, HEIGHT = 32, 24
T0_S = 1700000000
FRAMES = 10
PERIOD_NS = 50_000_000  # 20 Hz


def channel_value(x, y, c):
    return (x * 7 + y * 13 + c * 50) % 256


def rgb_pixel(x, y):  # a linear gradient: bilinear debayering reproduces it inside the image
    return (4 * x + 40, 4 * y + 20, 128)


def image(encoding, stamp):
    msg = Image()
    msg.header.stamp = stamp
    msg.header.frame_id = "cam0"
    msg.height, msg.width, msg.encoding = HEIGHT, WIDTH, encoding
    rows = []
    for y in range(HEIGHT):
        row = bytearray()
        for x in range(WIDTH):
            if encoding == "mono8":
                row.append(channel_value(x, y, 0))
            elif encoding == "mono16":
                row += ((channel_value(x, y, 0) * 257 + 3) & 0xFFFF).to_bytes(2, "little")
            elif encoding in ("rgb8", "bgr8", "rgba8", "bgra8"):
                r, g, b = (channel_value(x, y, c) for c in range(3))
                px = {"rgb8": (r, g, b), "bgr8": (b, g, r), "rgba8": (r, g, b, 255),
                      "bgra8": (b, g, r, 255)}[encoding]
                row += bytes(px)
            elif encoding.startswith("bayer_"):
                pattern = encoding[6:10]  # e.g. "rggb": colours of (0,0) (1,0) (0,1) (1,1)
                colour = pattern[(y % 2) * 2 + (x % 2)]
                row.append(rgb_pixel(x, y)["rgb".index(colour)])
        rows.append(bytes(row))
    msg.step = len(rows[0])
    msg.data = b"".join(rows)
    return msg


def compressed(fmt, stamp):
    msg = CompressedImage()
    msg.header.stamp = stamp
    msg.format = fmt
    here = os.path.dirname(os.path.abspath(__file__))
    with open(os.path.join(here, "gradient." + fmt), "rb") as f:
        msg.data = f.read()
    return msg


def stamp(i):
    return genpy.Time(T0_S, i * PERIOD_NS)


def receive_time(i):  # received 5 ms after the camera's stamp
    return genpy.Time(T0_S, i * PERIOD_NS + 5_000_000)


def write_bag(path, compression):
    with rosbag.Bag(path, "w", compression=compression, chunk_threshold=4096) as bag:
        for i in range(FRAMES):
            bag.write("/cam0/image_raw", image("mono8", stamp(i)), receive_time(i))
            bag.write("/cam1/image_raw", image("rgb8", stamp(i)), receive_time(i))
            bag.write("/bayer/image_raw", image("bayer_rggb8", stamp(i)), receive_time(i))
            bag.write("/cam0/image_raw/compressed", compressed("png", stamp(i)), receive_time(i))
            if i % 5 == 0:
                bag.write("/note", String(data="frame %d" % i), receive_time(i))


def write_cut_short(path):
    """A recorder killed mid-recording: whole chunks, one unfinished, no index."""
    pid = os.fork()
    if pid == 0:
        bag = rosbag.Bag(path, "w", compression="lz4", chunk_threshold=4096)
        for i in range(FRAMES):
            bag.write("/cam0/image_raw", image("mono8", stamp(i)), receive_time(i))
        bag._file.flush()  # what a recorder had written when killed
        os.kill(os.getpid(), signal.SIGKILL)
    _, status = os.waitpid(pid, 0)
    assert os.WIFSIGNALED(status), "the writer was to be killed"


def write_messages(folder):
    os.makedirs(folder, exist_ok=True)
    encodings = ["mono8", "mono16", "rgb8", "bgr8", "rgba8", "bgra8", "bayer_rggb8", "bayer_bggr8",
                 "bayer_gbrg8", "bayer_grbg8"]
    for encoding in encodings:
        buffer = io.BytesIO()
        image(encoding, stamp(3)).serialize(buffer)
        with open(os.path.join(folder, encoding + ".ros1"), "wb") as f:
            f.write(buffer.getvalue())
    for fmt in ("png", "jpeg"):
        buffer = io.BytesIO()
        compressed(fmt, stamp(3)).serialize(buffer)
        with open(os.path.join(folder, "compressed_" + fmt + ".ros1"), "wb") as f:
            f.write(buffer.getvalue())


def main():
    out = sys.argv[1]
    os.makedirs(out, exist_ok=True)
    for compression in ("none", "bz2", "lz4"):
        write_bag(os.path.join(out, "images_%s.bag" % compression), compression)
    write_cut_short(os.path.join(out, "cut_short.bag"))
    write_messages(os.path.join(out, "messages"))


if __name__ == "__main__":
    main()

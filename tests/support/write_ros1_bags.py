#!/usr/bin/python3
"""Writes small ROS 1 bags with Debian's rosbag writer (python3-rosbag,
python3-sensor-msgs) for the bag reader's tests (tests/unit/io/test_bags.cpp):

  encodings_<none|bz2|lz4>.bag  one 24x20 sensor_msgs/Image topic per encoding vmap reads
                                (mono8, 8UC1, mono16 and 16UC1 little- and big-endian, rgb8,
                                bgr8, 8UC3, rgba8, bgra8), 3 messages each, and one in
                                bayer_rggb8 (refused); pixel (x, y) of channel c of message k
                                is (x + 2 y + 40 c + 7 k) % 256 (16-bit: that times 257)
  camera.bag                    /cam/image_raw (3 mono8 frames, header stamps 10 s apart,
                                record times 1 ms after them), /cam/camera_info (plumb_bob),
                                /fish/image_raw/compressed (2 PNG frames) with
                                /fish/camera_info (equidistant), /imu/data
                                (sensor_msgs/Imu), /cam/camera_info_zero (K all zero)
  no_images.bag                 only /imu/data
  empty.bag                     no message
  flat_<bz2|lz4>.bag            /cam/image_raw: 2 mono8 320x240 frames of one value each (k + 1),
                                in one chunk that compresses hundreds of times: the readers grow
                                their buffer while it decompresses

Usage: write_ros1_bags.py OUT_DIR
"""
import struct
import sys
import zlib

import rosbag
import rospy
from sensor_msgs.msg import CameraInfo, CompressedImage, Image, Imu

out = sys.argv[1]


def pixels(w, h, channels, k, wide, big):
    data = bytearray()
    for y in range(h):
        for x in range(w):
            for c in range(channels):
                v = (x + 2 * y + 40 * c + 7 * k) % 256
                if wide:
                    data += struct.pack(">H" if big else "<H", v * 257)
                else:
                    data.append(v)
    return bytes(data)


def image(stamp, w, h, encoding, channels, wide=False, big=False, k=0):
    m = Image()
    m.header.stamp = stamp
    m.header.frame_id = "cam"
    m.height, m.width, m.encoding = h, w, encoding
    m.is_bigendian = 1 if big else 0
    m.step = w * channels * (2 if wide else 1)
    m.data = pixels(w, h, channels, k, wide, big)
    return m


def png(w, h, k):
    """A grey 8-bit PNG of the pixels above (zlib, no filter)."""
    raw = b"".join(b"\x00" + bytes((x + 2 * y + 7 * k) % 256 for x in range(w)) for y in range(h))

    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)

    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0)) +
            chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


encodings = [("mono8", 1, False, False), ("8UC1", 1, False, False), ("mono16", 1, True, False),
             ("mono16", 1, True, True), ("16UC1", 1, True, False), ("16UC1", 1, True, True),
             ("rgb8", 3, False, False), ("bgr8", 3, False, False), ("8UC3", 3, False, False),
             ("rgba8", 4, False, False), ("bgra8", 4, False, False), ("bayer_rggb8", 1, False, False)]
for compression in ("none", "bz2", "lz4"):
    with rosbag.Bag(f"{out}/encodings_{compression}.bag", "w", compression=compression, chunk_threshold=4096) as bag:
        for k in range(3):
            for enc, ch, wide, big in encodings:
                topic = f"/{enc}{'_be' if big else ''}/image_raw"
                t = rospy.Time(100 + k, 1000 * len(topic))
                bag.write(topic, image(t, 24, 20, enc, ch, wide, big, k), t)

with rosbag.Bag(f"{out}/camera.bag", "w") as bag:
    info = CameraInfo()
    info.height, info.width = 20, 24
    info.distortion_model = "plumb_bob"
    info.D = [0.1, -0.2, 0.001, 0.002, 0.05]
    info.K = [30.0, 0.0, 12.0, 0.0, 31.0, 10.0, 0.0, 0.0, 1.0]
    fish = CameraInfo()
    fish.height, fish.width = 20, 24
    fish.distortion_model = "equidistant"
    fish.D = [0.01, -0.02, 0.003, -0.004]
    fish.K = [20.0, 0.0, 12.5, 0.0, 20.5, 9.5, 0.0, 0.0, 1.0]
    zero = CameraInfo()
    for k in range(3):
        stamp = rospy.Time(1000 + 10 * k, 5)
        record = stamp + rospy.Duration(0, 1000000)
        info.header.stamp = stamp
        bag.write("/cam/camera_info", info, record)
        bag.write("/cam/camera_info_zero", zero, record)
        bag.write("/cam/image_raw", image(stamp, 24, 20, "mono8", 1, k=k), record)
        imu = Imu()
        imu.header.stamp = stamp
        bag.write("/imu/data", imu, record)
        if k < 2:
            c = CompressedImage()
            c.header.stamp = stamp
            c.format = "mono8; png compressed"
            c.data = png(24, 20, k)
            fish.header.stamp = stamp
            bag.write("/fish/camera_info", fish, record)
            bag.write("/fish/image_raw/compressed", c, record)

with rosbag.Bag(f"{out}/no_images.bag", "w") as bag:
    bag.write("/imu/data", Imu(), rospy.Time(5, 0))

with rosbag.Bag(f"{out}/empty.bag", "w") as bag:
    pass

for compression in ("bz2", "lz4"):
    with rosbag.Bag(f"{out}/flat_{compression}.bag", "w", compression=compression, chunk_threshold=1 << 20) as bag:
        for k in range(2):
            t = rospy.Time(200 + k, 0)
            m = Image()
            m.header.stamp = t
            m.height, m.width, m.encoding, m.step = 240, 320, "mono8", 320
            m.data = bytes([k + 1]) * (320 * 240)
            bag.write("/cam/image_raw", m, t)

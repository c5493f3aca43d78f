"""Decodes a rendered camera's topics of a twin MCAP recording with the independent `mcap` +
`mcap-ros2-support` readers and prints what a ROS 2 consumer would see, as JSON: per topic the
messages' headers and sizes, and the first message's pixels (rgb8: [r, g, b] per pixel; 32FC1:
metres, null for NaN; 16UC1: labels) or text (std_msgs/String).

usage: camera_check.py RUN.mcap TOPIC...
Exits 3 when a package is missing (the calling test fails on it).
"""
import json
import math
import struct
import sys

try:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
except ImportError as e:  # the test fails with this message
    print(f"missing Python package: {e.name} (pip install -r .ci/requirements.txt)", file=sys.stderr)
    sys.exit(3)


def pixels(ros):
    n = ros.width * ros.height
    data = bytes(ros.data)
    if ros.encoding == "rgb8":
        return [list(data[3 * i:3 * i + 3]) for i in range(n)]
    if ros.encoding == "32FC1":
        return [None if not math.isfinite(v) else v for v in struct.unpack("<%df" % n, data)]
    if ros.encoding == "16UC1":
        return list(struct.unpack("<%dH" % n, data))
    raise SystemExit("unexpected encoding " + ros.encoding)


def main():
    path, topics = sys.argv[1], sys.argv[2:]
    out = {t: [] for t in topics}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, ros in reader.iter_decoded_messages(topics=topics):
            entry = {"schema": schema.name, "log_time": message.log_time}
            if schema.name == "std_msgs/msg/String":
                entry["text"] = ros.data if not out[channel.topic] else None
            else:
                entry.update({
                    "stamp": ros.header.stamp.sec * 1_000_000_000 + ros.header.stamp.nanosec,
                    "frame_id": ros.header.frame_id,
                    "width": ros.width,
                    "height": ros.height,
                })
                if schema.name == "sensor_msgs/msg/Image":
                    entry.update({"encoding": ros.encoding, "step": ros.step, "bytes": len(ros.data)})
                    if not out[channel.topic]:
                        entry["pixels"] = pixels(ros)
                else:
                    entry.update({"k": list(ros.k), "d": list(ros.d), "distortion_model": ros.distortion_model})
            out[channel.topic].append(entry)
    json.dump(out, sys.stdout)


main()

"""Decodes the depth camera topics of a twin MCAP recording with the independent `mcap` +
`mcap-ros2-support` readers and prints what a ROS 2 consumer would see, as JSON.

usage: sense_check.py RUN.mcap IMAGE_TOPIC INFO_TOPIC POINTS_TOPIC
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


def main():
    path, image_topic, info_topic, points_topic = sys.argv[1:5]
    out = {"images": [], "infos": [], "clouds": []}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, ros in reader.iter_decoded_messages(
            topics=[image_topic, info_topic, points_topic]
        ):
            stamp = ros.header.stamp.sec * 1_000_000_000 + ros.header.stamp.nanosec
            if channel.topic == image_topic:
                n = ros.width * ros.height
                depth = struct.unpack("<%df" % n, bytes(ros.data))
                finite = [d for d in depth if math.isfinite(d)]
                out["images"].append({
                    "schema": schema.name,
                    "log_time": message.log_time,
                    "stamp": stamp,
                    "frame_id": ros.header.frame_id,
                    "encoding": ros.encoding,
                    "width": ros.width,
                    "height": ros.height,
                    "step": ros.step,
                    "is_bigendian": ros.is_bigendian,
                    "bytes": len(ros.data),
                    "finite": len(finite),
                    "min": min(finite) if finite else None,
                    "max": max(finite) if finite else None,
                })
            elif channel.topic == info_topic:
                out["infos"].append({
                    "schema": schema.name,
                    "width": ros.width,
                    "height": ros.height,
                    "k": list(ros.k),
                    "p": list(ros.p),
                    "d": list(ros.d),
                    "distortion_model": ros.distortion_model,
                })
            else:
                out["clouds"].append({
                    "schema": schema.name,
                    "width": ros.width,
                    "height": ros.height,
                    "fields": [[fl.name, fl.offset, fl.datatype, fl.count] for fl in ros.fields],
                    "point_step": ros.point_step,
                    "row_step": ros.row_step,
                    "is_dense": ros.is_dense,
                    "bytes": len(ros.data),
                })
    json.dump(out, sys.stdout)


main()

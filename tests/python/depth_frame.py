"""Decodes the first depth image of a twin recording with the independent `mcap` +
`mcap-ros2-support` readers, with its camera_info and the pose of its optical frame in the
world composed from /tf and /tf_static (the transform tree as ROS tools would walk it).

Usage: python depth_frame.py MCAP IMAGE_TOPIC INFO_TOPIC
Prints JSON: width, height, k (row-major 3×3), frame_id, stamp, depth (row-major metres,
null for NaN), world_from_optical (row-major 4×4; the tree's root is taken as the world).
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


def matrix(t):
    """4×4 row-major matrix of a geometry_msgs/Transform."""
    x, y, z, w = t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w
    return [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w), t.translation.x],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w), t.translation.y],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y), t.translation.z],
        [0.0, 0.0, 0.0, 1.0],
    ]


def mul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(4)) for j in range(4)] for i in range(4)]


def main():
    path, image_topic, info_topic = sys.argv[1:4]
    image = info = None
    static = {}   # child -> (parent, matrix)
    history = {}  # child -> [(stamp, parent, matrix)]
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, channel, _, ros in reader.iter_decoded_messages(
            topics=[image_topic, info_topic, "/tf", "/tf_static"], log_time_order=True
        ):
            if channel.topic == "/tf_static":
                for t in ros.transforms:
                    static[t.child_frame_id] = (t.header.frame_id, matrix(t.transform))
            elif channel.topic == "/tf":
                for t in ros.transforms:
                    stamp = t.header.stamp.sec * 10**9 + t.header.stamp.nanosec
                    history.setdefault(t.child_frame_id, []).append((stamp, t.header.frame_id, matrix(t.transform)))
            elif channel.topic == image_topic and image is None:
                n = ros.width * ros.height
                depth = struct.unpack("<%df" % n, bytes(ros.data))
                image = {
                    "width": ros.width,
                    "height": ros.height,
                    "encoding": ros.encoding,
                    "frame_id": ros.header.frame_id,
                    "stamp": ros.header.stamp.sec * 10**9 + ros.header.stamp.nanosec,
                    "depth": [d if math.isfinite(d) else None for d in depth],
                }
            elif channel.topic == info_topic and info is None:
                info = list(ros.k)
    if image is None or info is None:
        print(f"no {image_topic} or {info_topic} in {path}", file=sys.stderr)
        sys.exit(1)
    # Each moving frame at the image's instant: its latest transform at or before the stamp.
    dynamic = {}
    for child, items in history.items():
        before = [i for i in items if i[0] <= image["stamp"]] or items[:1]
        _, parent, m = max(before, key=lambda i: i[0])
        dynamic[child] = (parent, m)
    frame, pose, chain = image["frame_id"], [[float(i == j) for j in range(4)] for i in range(4)], []
    while frame in dynamic or frame in static:
        parent, m = dynamic.get(frame) or static[frame]
        pose = mul(m, pose)
        chain.append(frame)
        frame = parent
    chain.append(frame)
    image["k"] = info
    image["world_from_optical"] = pose
    image["tf_chain"] = chain
    json.dump(image, sys.stdout)


main()

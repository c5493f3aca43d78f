"""Independent readers and writers for twin's MCAP interop tests.

    decode FILE   print {"mcap_ros2": [...], "rosbags": [...]}: every message of FILE decoded by
                  the `mcap` + `mcap-ros2-support` packages and by `rosbags`, as plain JSON.
    write DIR     write a ROS 2 bag (rosbags' writer, folder layout, MCAP storage) with the
                  messages `expected_messages()` describes, and print them as JSON.

Exit code 3 with a message on stderr when a package is missing (the Rust test then skips).
"""

import json
import math
import sys
from pathlib import Path

try:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore
except ImportError as e:  # pragma: no cover
    print(f"missing Python package: {e}", file=sys.stderr)
    sys.exit(3)


def plain(v):
    """ROS message objects (mcap_ros2 dynamic classes, rosbags dataclasses) -> JSON values."""
    if isinstance(v, (bool, int, str)) or v is None:
        return v
    if isinstance(v, float):
        return None if math.isnan(v) else v
    if isinstance(v, (bytes, bytearray)):
        return list(v)
    if hasattr(v, "tolist"):  # numpy arrays (rosbags)
        return [plain(x) for x in v.tolist()]
    if isinstance(v, (list, tuple)):
        return [plain(x) for x in v]
    slots = getattr(v, "__slots__", None) or list(getattr(v, "__dataclass_fields__", {}))
    return {k: plain(getattr(v, k)) for k in slots if not k.startswith("_") and k != "__msgtype__"}


def decode(path):
    out = {"mcap_ros2": [], "rosbags": []}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        header = reader.get_header()
        out["profile"] = header.profile
        out["library"] = header.library
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            out["mcap_ros2"].append(
                {"topic": channel.topic, "type": schema.name, "log_time": message.log_time,
                 "msg": plain(decoded)})
    store = get_typestore(Stores.ROS2_HUMBLE)
    with AnyReader([Path(path)], default_typestore=store) as reader:
        for conn, t, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            out["rosbags"].append(
                {"topic": conn.topic, "type": conn.msgtype, "log_time": t, "msg": plain(msg)})
    json.dump(out, sys.stdout)


NAMES = ["waist_yaw_joint", "left_knee_joint", "right_elbow_joint"]


def write(path):
    import numpy as np

    store = get_typestore(Stores.ROS2_HUMBLE)
    JointState = store.types["sensor_msgs/msg/JointState"]
    Header = store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]
    Imu = store.types["sensor_msgs/msg/Imu"]
    Quaternion = store.types["geometry_msgs/msg/Quaternion"]
    Vector3 = store.types["geometry_msgs/msg/Vector3"]
    WrenchStamped = store.types["geometry_msgs/msg/WrenchStamped"]
    Wrench = store.types["geometry_msgs/msg/Wrench"]
    F64Array = store.types["std_msgs/msg/Float64MultiArray"]
    Layout = store.types["std_msgs/msg/MultiArrayLayout"]
    Dim = store.types["std_msgs/msg/MultiArrayDimension"]
    expected = []
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        cjs = w.add_connection("/joint_states", JointState.__msgtype__, typestore=store)
        cimu = w.add_connection("/imu", Imu.__msgtype__, typestore=store)
        cwr = w.add_connection("/ft", WrenchStamped.__msgtype__, typestore=store)
        ccmd = w.add_connection("/cmd", F64Array.__msgtype__, typestore=store)
        for i in range(50):
            t = 2_000_000_000 + i * 10_000_000
            stamp = Time(sec=t // 1_000_000_000, nanosec=t % 1_000_000_000)
            pos = [math.sin(0.1 * i + k) for k in range(3)]
            vel = [math.cos(0.1 * i + k) for k in range(3)] if i % 2 == 0 else []
            eff = [0.5 * k - 0.01 * i for k in range(3)]
            msg = JointState(header=Header(stamp=stamp, frame_id=""), name=NAMES,
                             position=np.array(pos), velocity=np.array(vel, dtype=np.float64),
                             effort=np.array(eff))
            w.write(cjs, t, store.serialize_cdr(msg, JointState.__msgtype__))
            expected.append({"topic": "/joint_states", "t": t, "position": pos,
                             "velocity": vel, "effort": eff})
            acc = [0.01 * i, -0.02 * i, 9.81]
            imu = Imu(header=Header(stamp=stamp, frame_id="imu_link"),
                      orientation=Quaternion(x=0.0, y=0.0, z=math.sin(0.01 * i), w=math.cos(0.01 * i)),
                      orientation_covariance=np.zeros(9),
                      angular_velocity=Vector3(x=0.1, y=0.2, z=0.3 * i),
                      angular_velocity_covariance=np.full(9, 0.5),
                      linear_acceleration=Vector3(x=acc[0], y=acc[1], z=acc[2]),
                      linear_acceleration_covariance=np.zeros(9))
            w.write(cimu, t, store.serialize_cdr(imu, Imu.__msgtype__))
            expected.append({"topic": "/imu", "t": t, "z": math.sin(0.01 * i), "acc": acc,
                             "wz": 0.3 * i})
            wr = WrenchStamped(header=Header(stamp=stamp, frame_id="foot"),
                               wrench=Wrench(force=Vector3(x=1.0, y=2.0, z=100.0 + i),
                                             torque=Vector3(x=-1.0, y=0.0, z=0.5)))
            w.write(cwr, t, store.serialize_cdr(wr, WrenchStamped.__msgtype__))
            expected.append({"topic": "/ft", "t": t, "fz": 100.0 + i})
            cmd = F64Array(layout=Layout(dim=[Dim(label="joints", size=3, stride=3)], data_offset=0),
                           data=np.array([i * 0.5, -i * 0.25, 1.0]))
            w.write(ccmd, t, store.serialize_cdr(cmd, F64Array.__msgtype__))
            expected.append({"topic": "/cmd", "t": t, "data": [i * 0.5, -i * 0.25, 1.0]})
    json.dump({"names": NAMES, "messages": expected}, sys.stdout)


if __name__ == "__main__":
    {"decode": decode, "write": write}[sys.argv[1]](sys.argv[2])

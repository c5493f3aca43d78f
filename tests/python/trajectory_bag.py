"""Writes, with mcap-ros2-support (an independent writer), a ROS 2 bag where a trajectory
controller's commands are known exactly: /joint_states at 100 Hz for 3 s (shoulder, elbow, neck;
stamps from 1 s) and /arm/joint_trajectory (trajectory_msgs/JointTrajectory, joints named elbow,
shoulder) every 0.1 s with points at 0, 0.1 and 0.2 s from the start on the ramps
shoulder = 0.2 t, elbow = 0.3 t (rad). Actual: shoulder = 0.2 t + 0.02 sin(2 pi t) (RMS error
0.02 / sqrt 2 over whole periods), elbow = 0.3 t - 0.1 (RMS and largest error 0.1), neck = 0 and
never commanded. Every other trajectory has a zero stamp (start on receipt), the others their
start in the stamp and a receipt 50 ms late.

    python trajectory_bag.py OUT.mcap
"""

import math
import sys

try:
    from mcap_ros2.writer import Writer
except ImportError as e:  # the test fails with this message
    print(f"missing Python package: {e.name} (pip install -r .ci/requirements.txt)", file=sys.stderr)
    sys.exit(3)

TIME = "int32 sec\nuint32 nanosec\n"
HEADER = "builtin_interfaces/Time stamp\nstring frame_id\n"
SEP = "=" * 80 + "\n"
JOINT_STATE = (
    "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n"
    + SEP + "MSG: std_msgs/Header\n" + HEADER
    + SEP + "MSG: builtin_interfaces/Time\n" + TIME
)
TRAJECTORY = (
    "std_msgs/Header header\nstring[] joint_names\nJointTrajectoryPoint[] points\n"
    + SEP + "MSG: std_msgs/Header\n" + HEADER
    + SEP + "MSG: builtin_interfaces/Time\n" + TIME
    + SEP + "MSG: trajectory_msgs/JointTrajectoryPoint\n"
    + "float64[] positions\nfloat64[] velocities\nfloat64[] accelerations\nfloat64[] effort\n"
    + "builtin_interfaces/Duration time_from_start\n"
    + SEP + "MSG: builtin_interfaces/Duration\n" + TIME
)
T0 = 1_000_000_000


def stamp(ns):
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def main(out):
    with open(out, "wb") as f:
        w = Writer(f)
        js = w.register_msgdef("sensor_msgs/msg/JointState", JOINT_STATE)
        jt = w.register_msgdef("trajectory_msgs/msg/JointTrajectory", TRAJECTORY)
        messages = []
        for i in range(300):
            t = i * 0.01
            ns = T0 + i * 10_000_000
            msg = {
                "header": {"stamp": stamp(ns), "frame_id": ""},
                "name": ["shoulder", "elbow", "neck"],
                "position": [0.2 * t + 0.02 * math.sin(2 * math.pi * t), 0.3 * t - 0.1, 0.0],
                "velocity": [],
                "effort": [],
            }
            messages.append((ns, "/joint_states", js, msg))
        for k in range(30):
            t = k * 0.1
            ns = T0 + k * 100_000_000
            points = [
                {
                    "positions": [0.3 * (t + d), 0.2 * (t + d)],
                    "velocities": [],
                    "accelerations": [],
                    "effort": [],
                    "time_from_start": {"sec": 0, "nanosec": int(round(d * 1e9))},
                }
                for d in (0.0, 0.1, 0.2)
            ]
            if k % 2 == 0:
                header, received = {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""}, ns
            else:
                header, received = {"stamp": stamp(ns), "frame_id": ""}, ns + 50_000_000
            msg = {"header": header, "joint_names": ["elbow", "shoulder"], "points": points}
            messages.append((received, "/arm/joint_trajectory", jt, msg))
        messages.sort(key=lambda m: m[0])
        for ns, topic, schema, msg in messages:
            w.write_message(topic=topic, schema=schema, message=msg, log_time=ns, publish_time=ns)
        w.finish()


if __name__ == "__main__":
    main(sys.argv[1])

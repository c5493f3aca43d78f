"""Rewrites a one-topic JointState bag as two drivers would publish it: the first N joints on
/arm_a/joint_states at the source's own stamps, the others on /arm_b/joint_states at their own
instants (every STEP_NS from the first stamp plus OFFSET_NS), their values linearly interpolated
from the source there. Written with mcap-ros2-support (not twin's writer).

Usage: python split_joint_states.py IN.mcap OUT.mcap N STEP_NS OFFSET_NS
Prints JSON: {"a": messages on /arm_a, "b": messages on /arm_b}.
"""

import json
import sys

import numpy as np
from mcap_ros2.reader import read_ros2_messages
from mcap_ros2.writer import Writer

JOINT_STATE = (
    "std_msgs/Header header\n\nstring[] name\nfloat64[] position\nfloat64[] velocity\n"
    "float64[] effort\n"
    + "=" * 80 + "\nMSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
    + "=" * 80 + "\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
)


def main():
    src, dst, n, step, offset = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
    names, t, q, qd, tau = None, [], [], [], []
    for m in read_ros2_messages(src):
        msg = m.ros_msg
        names = list(msg.name)
        t.append(msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec)
        q.append(list(msg.position))
        qd.append(list(msg.velocity))
        tau.append(list(msg.effort))
    t, q, qd, tau = np.array(t), np.array(q), np.array(qd), np.array(tau)
    events = []
    for k in range(len(t)):
        events.append((int(t[k]), "/arm_a/joint_states", names[:n], q[k, :n], qd[k, :n], tau[k, :n]))
    tb = np.arange(t[0] + offset, t[-1], step)
    js = range(n, len(names))
    qb, qdb, taub = (np.stack([np.interp(tb, t, a[:, j]) for j in js], axis=1) for a in (q, qd, tau))
    for k, tk in enumerate(tb):
        events.append((int(tk), "/arm_b/joint_states", names[n:], qb[k], qdb[k], taub[k]))
    events.sort(key=lambda e: e[0])
    with open(dst, "wb") as f:
        w = Writer(f)
        schema = w.register_msgdef("sensor_msgs/msg/JointState", JOINT_STATE)
        for ns, topic, nm, p, v, e in events:
            msg = {"header": {"stamp": {"sec": ns // 10**9, "nanosec": ns % 10**9}, "frame_id": ""}, "name": nm,
                   "position": [float(x) for x in p], "velocity": [float(x) for x in v],
                   "effort": [float(x) for x in e]}
            w.write_message(topic, schema, msg, log_time=ns, publish_time=ns)
        w.finish()
    print(json.dumps({"a": len(t), "b": len(tb)}))


if __name__ == "__main__":
    main()

"""Regenerates the small log fixtures in this folder (run from the repository root):

    python3 -m venv /tmp/fixvenv && /tmp/fixvenv/bin/pip install mcap mcap-ros2-support
    /tmp/fixvenv/bin/python data/make_fixtures.py

humanoid_joint_states.mcap: /joint_states of the shipped humanoid (23 revolute joints, names and
order from models/humanoid.urdf), 2 s at 100 Hz, written by an independent writer
(`mcap-ros2-support`, zstd chunks, profile ros2) the way a ros2_control joint_state_broadcaster
publishes it: a small standing sway. 16 KiB chunks. Values follow `expected()` so tests can recompute them:
    position[k] = q0[k] + 0.05 sin(2π 0.5 t + 0.3 k)
    velocity[k] = 0.05 · 2π 0.5 cos(2π 0.5 t + 0.3 k)
    effort[k]   = 2 + 0.5 k + sin(2π 0.5 t + 0.3 k)      (every 10th message: empty effort)
with q0 = 0.3 for knees, -0.15 for hip and ankle pitch, 0 otherwise; t = i / 100 s; header
stamp = log time = 1 700 000 000 s + t.
"""

import math
import re
from pathlib import Path

from mcap_ros2.writer import Writer

ROOT = Path(__file__).resolve().parent.parent
JOINT_STATE = (
    "std_msgs/Header header\n\nstring[] name\nfloat64[] position\nfloat64[] velocity\n"
    "float64[] effort\n"
    + "=" * 80 + "\nMSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
    + "=" * 80 + "\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
)


def joint_names():
    urdf = (ROOT / "models" / "humanoid.urdf").read_text()
    return re.findall(r'<joint\s+name="([^"]+)"\s+type="revolute"', urdf)


def q0(name):
    if "knee" in name:
        return 0.3
    if "hip_pitch" in name or "ankle_pitch" in name:
        return -0.15
    return 0.0


def main():
    names = joint_names()
    assert len(names) == 23, names
    out = ROOT / "data" / "humanoid_joint_states.mcap"
    with open(out, "wb") as f:
        # Small chunks, as a recorder flushing often would: a cut file keeps most of them.
        w = Writer(f, chunk_size=16 * 1024)
        schema = w.register_msgdef("sensor_msgs/msg/JointState", JOINT_STATE)
        for i in range(200):
            t = i / 100.0
            stamp_ns = 1_700_000_000 * 10**9 + i * 10_000_000
            ph = [2 * math.pi * 0.5 * t + 0.3 * k for k in range(23)]
            msg = {
                "header": {"stamp": {"sec": stamp_ns // 10**9, "nanosec": stamp_ns % 10**9},
                           "frame_id": ""},
                "name": names,
                "position": [q0(n) + 0.05 * math.sin(p) for n, p in zip(names, ph)],
                "velocity": [0.05 * 2 * math.pi * 0.5 * math.cos(p) for p in ph],
                "effort": [] if i % 10 == 0 else [2 + 0.5 * k + math.sin(p) for k, p in enumerate(ph)],
            }
            w.write_message("/joint_states", schema, msg, log_time=stamp_ns, publish_time=stamp_ns)
        w.finish()
    print(f"wrote {out} ({out.stat().st_size} bytes)")


if __name__ == "__main__":
    main()

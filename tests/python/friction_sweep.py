"""Writes a constant-velocity friction sweep as a ROS 2 bag (rosbags, MCAP storage), made
without any of twin's code: three gravity-loaded joints (pendulums), each driven in turn by a
PD + feed-forward tracking controller along trapezoidal velocity profiles at SPEEDS log-spaced
speeds from 0.03 to 1.2 rad/s in each direction, with a 1 s settle before each sweep; the
other joints hold still. Friction is Stribeck (Coulomb, breakaway, Stribeck velocity,
exponent, viscous) with stick–slip (Karnopp) at rest. /joint_states at 250 Hz carries
17-bit quantized positions, the drive's noisy velocity and the motor torque (noisy) as effort.

Usage: python friction_sweep.py OUT_BAG SPEEDS [--no-stribeck]
Prints the true friction of each joint as JSON.
"""
import json
import math
import random
import sys

import numpy as np
import sweep_plan
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

NAMES = ["shoulder", "elbow", "wrist"]
# inertia kg m², gravity load m g l N m, Fc, Fs, vs, delta, Fv
JOINTS = [
    (0.08, 6.0, 2.0, 3.0, 0.10, 1.0, 0.8),
    (0.04, 3.0, 1.0, 1.5, 0.08, 2.0, 0.4),
    (0.02, 1.0, 0.4, 0.6, 0.15, 1.0, 0.15),
]
DT = 0.0005          # integration step, s
LOG_EVERY = 8        # log at 250 Hz
ACCEL = 4.0          # rad/s² of the trapezoid ramps
STROKE = 1.2         # rad, at most
MAX_CRUISE = 3.0     # s, at most, at one speed
SETTLE = 1.0         # s before each sweep
HOME = 0.3           # rad, where each sweep starts (gravity loads every joint)


def friction(j, w, stribeck):
    _, _, fc, fs, vs, delta, fv = JOINTS[j]
    if not stribeck:
        fs = fc
    return math.copysign(fc + (fs - fc) * math.exp(-abs(w / vs) ** delta), w) + fv * w


def main():
    out, nspeeds = sys.argv[1], int(sys.argv[2])
    stribeck = "--no-stribeck" not in sys.argv
    speeds = [0.03 * (40.0 ** (k / (nspeeds - 1))) for k in range(nspeeds)] if nspeeds > 1 else [0.3]
    rng = random.Random(5)
    res = 2 * math.pi / 2 ** 17
    n = len(JOINTS)
    q = [HOME] * n
    w = [0.0] * n
    ref = [(HOME, 0.0, 0.0)] * n  # (position, velocity, acceleration)
    t = 0.0
    step = 0
    store = get_typestore(Stores.ROS2_HUMBLE)
    Header = store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]
    JointState = store.types["sensor_msgs/msg/JointState"]
    with Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as bag:
        conn = bag.add_connection("/joint_states", JointState.__msgtype__, typestore=store)

        def advance(moving, profile, secs):
            nonlocal t, step
            for k in range(int(round(secs / DT))):
                s = k * DT
                for j in range(n):
                    if j == moving and profile is not None:
                        ref[j] = profile(s)
                torques = []
                for j in range(n):
                    inertia, load, _, fs, *_ = JOINTS[j]
                    qr, wr, ar = ref[j]
                    kp, kd = inertia * 100.0**2, inertia * 2 * 100.0
                    tau = inertia * ar + load * math.sin(qr) + kp * (qr - q[j]) + kd * (wr - w[j])
                    torques.append(tau)
                    other = tau - load * math.sin(q[j])
                    fs_now = fs if stribeck else JOINTS[j][2]
                    if abs(w[j]) < 1e-4 and abs(other) <= fs_now:
                        acc = 0.0
                        w[j] = 0.0
                    elif abs(w[j]) < 1e-4:
                        acc = (other - math.copysign(fs_now, other)) / inertia
                    else:
                        acc = (other - friction(j, w[j], stribeck)) / inertia
                    w_new = w[j] + acc * DT
                    if w[j] != 0.0 and w_new * w[j] < 0.0:
                        w_new = 0.0  # friction stops the joint; it does not reverse it
                    w[j] = w_new
                    q[j] += w[j] * DT
                if step % LOG_EVERY == 0:
                    stamp = int(round(t * 1e9))
                    msg = JointState(
                        header=Header(stamp=Time(sec=stamp // 10**9, nanosec=stamp % 10**9), frame_id=""),
                        name=NAMES,
                        position=np.array([round(x / res) * res for x in q]),
                        velocity=np.array([x + rng.gauss(0.0, 0.002) for x in w]),
                        effort=np.array([x + rng.gauss(0.0, 0.02) for x in torques]),
                    )
                    bag.write(conn, stamp, store.serialize_cdr(msg, JointState.__msgtype__))
                t += DT
                step += 1

        sweep_plan.sweep(n, speeds, ref, advance, ACCEL, STROKE, MAX_CRUISE, SETTLE)
    truth = {}
    for name, (_, _, fc, fs, vs, delta, fv) in zip(NAMES, JOINTS):
        truth[name] = {"coulomb": fc, "breakaway": fs if stribeck else fc, "stribeck_velocity": vs,
                       "exponent": delta, "viscous": fv}
    json.dump({"speeds": speeds, "joints": truth}, sys.stdout)


if __name__ == "__main__":
    main()

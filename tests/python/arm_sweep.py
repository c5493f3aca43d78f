"""Writes a constant-velocity friction sweep of a 4-joint arm as a ROS 2 bag (rosbags, MCAP
storage), simulated by MuJoCo's own Python package, without any of twin's code: a heavy
turret on a vertical-axis base joint (yaw), then shoulder, elbow and wrist pitch joints with
the arm stretched out, so the whole arm's inertia (≈ 4.9 kg m²) swings about the yaw axis.
Each joint in turn follows trapezoidal velocity profiles at SPEEDS log-spaced speeds from 0.03
to 1.2 rad/s in each direction (1 s settle before each), under a PD + feed-forward torque
controller (10 Hz bandwidth on the joint's inertia; the yaw drive's set for a third of it, as
a drive tuned by hand with the arm folded), with the other joints held at home. Friction is
MuJoCo's: `frictionloss` (Coulomb), `damping` (viscous, integrated implicitly), plus a
Stribeck hump applied as a joint force that fades in over the first 0.02 rad/s. /joint_states at 250 Hz carries 17-bit quantized
positions, the drive's noisy velocity and the motor torque (noisy) as effort.

Usage: python arm_sweep.py OUT_BAG SPEEDS
Prints the true friction of each joint as JSON.
"""
import json
import math
import sys

import mujoco
import numpy as np
import sweep_plan
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

NAMES = ["base_yaw", "shoulder", "elbow", "wrist"]
# Coulomb Fc, breakaway Fs, Stribeck velocity vs, exponent delta, viscous Fv (N m, rad/s)
FRICTION = [
    (0.8, 1.2, 0.08, 1.0, 0.35),
    (1.5, 2.2, 0.10, 1.0, 0.60),
    (0.8, 1.2, 0.08, 2.0, 0.30),
    (0.3, 0.45, 0.12, 1.0, 0.10),
]
HOME = [0.0, 0.4, -0.6, 0.3]
ONSET = 0.02  # rad/s over which the Stribeck hump fades in (keeps the explicit force stable)
DT = 0.0005
LOG_EVERY = 8  # 250 Hz
ACCEL = 4.0
STROKE = 1.2
MAX_CRUISE = 3.0
SETTLE = 1.0

XML = """
<mujoco model="arm4">
  <option timestep="{dt}" integrator="implicitfast" gravity="0 0 -9.81"/>
  <worldbody>
    <body name="turret" pos="0 0 0.3">
      <joint name="base_yaw" type="hinge" axis="0 0 1" frictionloss="{f0}" damping="{d0}" armature="0.05"/>
      <geom type="cylinder" size="0.15 0.1" mass="12"/>
      <geom type="box" pos="0.25 0 0" size="0.2 0.05 0.05" mass="4"/>
      <body name="upper" pos="0.45 0 0.1">
        <joint name="shoulder" type="hinge" axis="0 1 0" frictionloss="{f1}" damping="{d1}" armature="0.02"/>
        <geom type="capsule" fromto="0 0 0 0.4 0 0" size="0.04" mass="3"/>
        <body name="fore" pos="0.4 0 0">
          <joint name="elbow" type="hinge" axis="0 1 0" frictionloss="{f2}" damping="{d2}" armature="0.05"/>
          <geom type="capsule" fromto="0 0 0 0.35 0 0" size="0.03" mass="2"/>
          <body name="hand" pos="0.35 0 0">
            <joint name="wrist" type="hinge" axis="0 1 0" frictionloss="{f3}" damping="{d3}" armature="0.05"/>
            <geom type="box" pos="0.06 0 0" size="0.06 0.03 0.03" mass="0.8"/>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def hump(j, w):
    """The Stribeck part beyond Coulomb, faded in over ONSET (the joint force MuJoCo lacks)."""
    fc, fs, vs, delta, _ = FRICTION[j]
    s = abs(w)
    return math.copysign((fs - fc) * math.exp(-((s / vs) ** delta)) * min(1.0, s / ONSET), w)


def main():
    out, nspeeds = sys.argv[1], int(sys.argv[2])
    speeds = [0.03 * (40.0 ** (k / (nspeeds - 1))) for k in range(nspeeds)] if nspeeds > 1 else [0.3]
    fill = {"dt": DT}
    for j, (fc, _, _, _, fv) in enumerate(FRICTION):
        fill[f"f{j}"], fill[f"d{j}"] = fc, fv
    model = mujoco.MjModel.from_xml_string(XML.format(**fill))
    data = mujoco.MjData(model)
    n = model.nv
    data.qpos[:] = HOME
    mujoco.mj_forward(model, data)
    # Each drive's feed-forward inertia and gains (10 Hz, critically damped) come from its
    # joint's inertia at home, but the base yaw drive's: tuned by hand with the arm folded, it
    # assumes a third of the inertia it moves with the arm stretched out, so its speed changes
    # ring on (≈ 5.8 Hz, damping ratio 0.58) into the cruise at every speed.
    full = np.zeros((n, n))
    mujoco.mj_fullM(model, data, full)
    inertia = np.diag(full).copy()
    inertia[0] /= 3.0
    kp, kd = inertia * (2 * math.pi * 10.0) ** 2, inertia * 2 * (2 * math.pi * 10.0)
    rng = np.random.default_rng(5)
    res = 2 * math.pi / 2**17
    ref = [(HOME[j], 0.0, 0.0) for j in range(n)]
    store = get_typestore(Stores.ROS2_HUMBLE)
    Header = store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]
    JointState = store.types["sensor_msgs/msg/JointState"]
    step = 0
    with Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as bag:
        conn = bag.add_connection("/joint_states", JointState.__msgtype__, typestore=store)

        def advance(moving, profile, secs):
            nonlocal step
            for k in range(int(round(secs / DT))):
                if profile is not None:
                    ref[moving] = profile(k * DT)
                q, w = data.qpos, data.qvel
                qr = np.array([r[0] for r in ref])
                wr = np.array([r[1] for r in ref])
                ar = np.array([r[2] for r in ref])
                # Feed-forward: the joint's own inertia times the reference acceleration, and
                # gravity and Coriolis (MuJoCo's bias force); friction is what the PD must give.
                tau = inertia * ar + data.qfrc_bias + kp * (qr - q) + kd * (wr - w)
                data.ctrl[:] = 0.0
                data.qfrc_applied[:] = tau - np.array([hump(j, w[j]) for j in range(n)])
                if step % LOG_EVERY == 0:
                    stamp = int(round(data.time * 1e9))
                    msg = JointState(
                        header=Header(stamp=Time(sec=stamp // 10**9, nanosec=stamp % 10**9), frame_id=""),
                        name=NAMES,
                        position=np.round(q / res) * res,
                        velocity=w + rng.normal(0.0, 0.002, n),
                        effort=tau + rng.normal(0.0, 0.02, n),
                    )
                    bag.write(conn, stamp, store.serialize_cdr(msg, JointState.__msgtype__))
                mujoco.mj_step(model, data)
                step += 1

        sweep_plan.sweep(n, speeds, ref, advance, ACCEL, STROKE, MAX_CRUISE, SETTLE)
    truth = {}
    for name, (fc, fs, vs, delta, fv) in zip(NAMES, FRICTION):
        truth[name] = {"coulomb": fc, "breakaway": fs, "stribeck_velocity": vs, "exponent": delta, "viscous": fv}
    json.dump({"speeds": speeds, "inertia": list(np.diag(full)), "drive_inertia": list(inertia), "joints": truth},
              sys.stdout)


if __name__ == "__main__":
    main()

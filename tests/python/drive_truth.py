"""Writes a ROS 2 bag of a robot whose drives are known, simulated by MuJoCo's own Python package
without any of twin's code: the URDF loaded by MuJoCo's URDF importer (root link fixed: the robot
held in the air), each listed joint driven by a MuJoCo `position` actuator with the given gains
and MuJoCo's own command `delay` (history buffer), and the given joint armature. Physics at
0.5 ms (explicit Euler, no implicit damping, so the joint damping is the URDF's as written), the
position commands published at 500 Hz as std_msgs/msg/Float64MultiArray on
/position_controller/commands (joints in the order given), /joint_states at 1 kHz with noisy
positions and velocities and the drive's torque as effort. The commands: per joint, steps held
0.3-0.8 s plus a sum of three sines (0.2-2.5 Hz), around the middle of the joint's range.

Usage: python drive_truth.py URDF OUT_BAG TRUTH_JSON DURATION_SECS SEED
TRUTH_JSON: [{"name": joint, "delay": s, "kp": N m/rad, "kd": N m s/rad, "armature": kg m2}, ...]
in command order. Prints what the simulation used, read back from the compiled model, as JSON.
"""
import json
import math
import sys

import mujoco
import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

DT = 0.0005
STATE_EVERY = 2  # 1 kHz
COMMAND_EVERY = 4  # 500 Hz
POS_NOISE = 2e-5
VEL_NOISE = 2e-3


def main():
    urdf, out, truth_json, duration, seed = sys.argv[1:6]
    truth = {t["name"]: t for t in json.loads(truth_json)}
    duration = float(duration)
    rng = np.random.default_rng(int(seed))
    spec = mujoco.MjSpec.from_file(urdf)
    spec.option.timestep = DT
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_EULER
    spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_EULERDAMP
    names = list(truth)
    for name in names:
        t = truth[name]
        spec.joint(name).armature = t["armature"]
        a = spec.add_actuator()
        a.name = name
        a.target = name
        a.trntype = mujoco.mjtTrn.mjTRN_JOINT
        a.set_to_position(kp=t["kp"], kv=t["kd"])
        a.delay = t["delay"]
        a.nsample = int(math.ceil(t["delay"] / DT)) + 2
    m = spec.compile()
    d = mujoco.MjData(m)
    jid = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n) for n in names]
    qadr = [m.jnt_qposadr[j] for j in jid]
    vadr = [m.jnt_dofadr[j] for j in jid]
    lo = np.array([m.jnt_range[j][0] if m.jnt_limited[j] else -1.0 for j in jid])
    hi = np.array([m.jnt_range[j][1] if m.jnt_limited[j] else 1.0 for j in jid])
    mid, half = (lo + hi) / 2, (hi - lo) / 2
    amp = np.minimum(0.35, 0.3 * half)

    # Per joint: steps (random levels, held 0.3-0.8 s) plus three sines.
    n = len(names)
    freqs = rng.uniform(0.2, 2.5, (n, 3))
    phases = rng.uniform(0, 2 * math.pi, (n, 3))
    step_times = [np.cumsum(rng.uniform(0.3, 0.8, int(duration / 0.3) + 2)) for _ in range(n)]
    step_levels = [rng.uniform(-1, 1, len(s)) for s in step_times]

    def command(t):
        c = np.empty(n)
        for i in range(n):
            k = np.searchsorted(step_times[i], t)
            s = step_levels[i][k] * 0.5 + 0.5 * np.sum(np.sin(2 * math.pi * freqs[i] * t + phases[i])) / 3
            c[i] = mid[i] + amp[i] * s
        return c

    # Start at rest on the first command.
    c0 = command(0.0)
    for i in range(n):
        d.qpos[qadr[i]] = c0[i]
    d.ctrl[:] = c0

    typestore = get_typestore(Stores.ROS2_HUMBLE)
    JointState = typestore.types["sensor_msgs/msg/JointState"]
    Header = typestore.types["std_msgs/msg/Header"]
    Time = typestore.types["builtin_interfaces/msg/Time"]
    Multi = typestore.types["std_msgs/msg/Float64MultiArray"]
    Layout = typestore.types["std_msgs/msg/MultiArrayLayout"]
    with Writer(out, version=8, storage_plugin=StoragePlugin.MCAP) as w:
        js = w.add_connection("/joint_states", JointState.__msgtype__, typestore=typestore)
        cmd = w.add_connection("/position_controller/commands", Multi.__msgtype__, typestore=typestore)
        steps = int(round(duration / DT))
        for k in range(steps):
            t = k * DT
            stamp = int(round(t * 1e9)) + 1_000_000_000
            if k % COMMAND_EVERY == 0:
                c = command(t)
                d.ctrl[:] = c
                msg = Multi(layout=Layout(dim=[], data_offset=0), data=np.asarray(c, dtype=np.float64))
                w.write(cmd, stamp, typestore.serialize_cdr(msg, Multi.__msgtype__))
            if k % STATE_EVERY == 0:
                # The state now (before this step); effort: the drive's torque over the last step.
                q = np.array([d.qpos[a] for a in qadr]) + rng.normal(0, POS_NOISE, n)
                v = np.array([d.qvel[a] for a in vadr]) + rng.normal(0, VEL_NOISE, n)
                e = np.array(d.actuator_force)
                header = Header(stamp=Time(sec=stamp // 1_000_000_000, nanosec=stamp % 1_000_000_000), frame_id="")
                msg = JointState(header=header, name=names, position=q, velocity=v, effort=e)
                w.write(js, stamp, typestore.serialize_cdr(msg, JointState.__msgtype__))
            mujoco.mj_step(m, d)
    used = {
        name: {
            "delay": float(m.actuator_delay[i]),
            "kp": float(m.actuator_gainprm[i][0]),
            "kd": float(-m.actuator_biasprm[i][2]),
            "armature": float(m.dof_armature[vadr[i]]),
            "damping": float(m.dof_damping[vadr[i]]),
        }
        for i, name in enumerate(names)
    }
    print(json.dumps(used))


if __name__ == "__main__":
    main()

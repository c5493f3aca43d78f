"""Held-out torque NRMSE of a URDF identified by `twin sysid` and of the published Franka Panda
model (Gaz et al. 2019: the paper's own code, data/panda_gaz2019/gaz2019_code/*.m, translated
to numpy), computed without twin: the bag read with mcap-ros2-support, the signals filtered with
SciPy, the identified URDF's rigid-body torques from MuJoCo's Python package (mj_inverse) plus
the friction of its <twin_sysid> block.

Usage: python sysid_heldout.py BAG URDF PAPER_CODE_DIR HELD_OUT_FRACTION CUTOFF_HZ EFFORT_CUTOFF_HZ
Prints JSON: {"twin": [per joint], "paper": [per joint], "samples": [per joint]}.

Both models are scored on the same samples: the last HELD_OUT_FRACTION of the log by time,
resampled on a uniform grid at the median step per gap-free piece (a step over 5 median
steps splits), positions low-passed at CUTOFF_HZ (Butterworth order 4, forward-backward) and
differentiated twice by central differences, the measured torque low-passed at
EFFORT_CUTOFF_HZ, 3 cut-off periods trimmed at each piece's ends, and per joint only samples
faster than 0.05 rad/s (Coulomb friction is set-valued at rest).
"""

import json
import math
import re
import sys
from pathlib import Path

import mujoco
import numpy as np
from mcap_ros2.reader import read_ros2_messages
from scipy.signal import butter, filtfilt

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "data" / "panda_gaz2019"))
from make_data import matlab_to_numpy  # noqa: E402  (the one translator of the paper's code)

ARM = [f"panda_joint{i}" for i in range(1, 8)]


def read_bag(path):
    t, q, qd, tau = [], [], [], []
    for m in read_ros2_messages(str(path)):
        if m.channel.topic != "/franka_state_controller/joint_states":
            continue
        msg = m.ros_msg
        idx = [list(msg.name).index(n) for n in ARM]
        t.append(msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9)
        q.append([msg.position[i] for i in idx])
        qd.append([msg.velocity[i] for i in idx])
        tau.append([msg.effort[i] for i in idx])
    return np.array(t), np.array(q), np.array(qd), np.array(tau)


def conditioned(t, q, tau, cutoff, effort_cutoff):
    """(q, qd, qdd, tau) on uniform grids per gap-free piece, filtered and trimmed, stacked."""
    dt = float(np.median(np.diff(t)))
    cuts = np.where(np.diff(t) > 5 * dt)[0] + 1
    out = [[], [], [], []]
    trim = int(math.ceil(3.0 / min(cutoff, effort_cutoff) / dt))
    b, a = butter(4, cutoff, fs=1.0 / dt)
    be, ae = butter(4, effort_cutoff, fs=1.0 / dt)
    for piece in np.split(np.arange(len(t)), cuts):
        tp = t[piece]
        m = int((tp[-1] - tp[0]) / dt) + 1
        if m < 2 * trim + 20:
            continue
        grid = tp[0] + dt * np.arange(m)
        qg = np.stack([np.interp(grid, tp, q[piece, j]) for j in range(7)], axis=1)
        tg = np.stack([np.interp(grid, tp, tau[piece, j]) for j in range(7)], axis=1)
        qf = filtfilt(b, a, qg, axis=0, padlen=trim)
        tf = filtfilt(be, ae, tg, axis=0, padlen=trim)
        qdf = np.gradient(qf, dt, axis=0)
        qddf = np.gradient(qdf, dt, axis=0)
        keep = slice(trim, m - trim)
        for lst, v in zip(out, (qf, qdf, qddf, tf)):
            lst.append(v[keep])
    return [np.concatenate(v) for v in out]


def friction_block(text):
    block = {}
    for m in re.finditer(r"<joint name=\"([^\"]+)\"([^/]*)/>", re.search(r"<twin_sysid.*?</twin_sysid>", text, re.S).group(0)):
        attrs = dict(re.findall(r"(\w+)=\"([^\"]+)\"", m.group(2)))
        block[m.group(1)] = {k: float(v) for k, v in attrs.items()}
    return block


def friction(f, qd, qdd):
    eps = f.get("smoothing", 0.0)
    v = qd + f.get("velocity_shift", 0.0)
    if eps > 0:
        s, bump = np.tanh(v / eps), 1.0 / np.cosh(qd / eps) ** 2
    else:
        s, bump = np.sign(v), 0.0
    return (f.get("offset", 0.0) + f.get("viscous", 0.0) * qd + f.get("coulomb", 0.0) * s
            + f.get("asymmetry", 0.0) * bump + f.get("armature", 0.0) * qdd)


def twin_torques(urdf, q, qd, qdd):
    text = Path(urdf).read_text()
    block = friction_block(text)
    plain = re.sub(r"<twin_sysid.*?</twin_sysid>", "", text, flags=re.S)
    plain = re.sub(r"<visual>.*?</visual>", "", plain, flags=re.S)
    plain = re.sub(r"<collision>.*?</collision>", "", plain, flags=re.S)
    model = mujoco.MjModel.from_xml_string(plain)
    data = mujoco.MjData(model)
    adr = [model.joint(n).qposadr[0] for n in ARM]
    dof = [model.joint(n).dofadr[0] for n in ARM]
    # MuJoCo's own damping/frictionloss would be in qfrc_passive, not in mj_inverse's output
    # with these off: friction comes from the block alone.
    model.dof_damping[:] = 0
    model.dof_frictionloss[:] = 0
    model.dof_armature[:] = 0
    out = np.zeros_like(q)
    for k in range(len(q)):
        data.qpos[:] = 0
        data.qvel[:] = 0
        data.qacc[:] = 0
        data.qpos[adr] = q[k]
        data.qvel[dof] = qd[k]
        data.qacc[dof] = qdd[k]
        mujoco.mj_inverse(model, data)
        out[k] = data.qfrc_inverse[dof]
    for j, n in enumerate(ARM):
        out[:, j] += friction(block[n], qd[:, j], qdd[:, j])
    return out


def paper_torques(code, q, qd, qdd):
    code = Path(code)
    grav = matlab_to_numpy(code / "get_GravityVector.m", "g")
    mass = matlab_to_numpy(code / "get_MassMatrix.m", "m")
    cori = matlab_to_numpy(code / "get_CoriolisVector.m", "c")
    text = (code / "get_FrictionTorque.m").read_text()
    rows = re.search(r"fp = \[(.*?)\];", text, re.S).group(1).replace("...", "").split(";")
    fp = [[float(v) for v in r.split(",") if v.strip()] for r in rows if r.strip()]
    a, phi, alpha = np.array(fp[0]), np.array(fp[2]), np.array(fp[3])
    qt, qdt = q.T, qd.T
    n = len(q)
    as_rows = lambda v: np.array([np.broadcast_to(np.asarray(x, dtype=float), (n,)) for x in v])
    g = as_rows(grav(qt)).T
    c = as_rows(cori(qt, qdt)).T
    mm = as_rows(mass(qt)).T.reshape(n, 7, 7)
    f = -a / (1 + np.exp(-alpha * phi)) + a / (1 + np.exp(-alpha * (qd + phi)))
    return np.einsum("kij,kj->ki", mm, qdd) + c + g + f


def main():
    bag, urdf, code = sys.argv[1:4]
    frac, cutoff, effort_cutoff = (float(x) for x in sys.argv[4:7])
    t, q, _, tau = read_bag(bag)
    start = t[0] + (1.0 - frac) * (t[-1] - t[0])
    sel = t >= start
    qf, qdf, qddf, tf = conditioned(t[sel], q[sel], tau[sel], cutoff, effort_cutoff)
    ours = twin_torques(urdf, qf, qdf, qddf)
    paper = paper_torques(code, qf, qdf, qddf)
    used = np.abs(qdf) >= 0.05
    nrmse = lambda pred: [float(np.sqrt(np.sum(((pred - tf)[used[:, j], j]) ** 2) / np.sum(tf[used[:, j], j] ** 2)))
                          for j in range(7)]
    print(json.dumps({"twin": nrmse(ours), "paper": nrmse(paper), "samples": [int(u) for u in used.sum(0)]}))


if __name__ == "__main__":
    main()

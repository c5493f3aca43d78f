"""Regenerates the real Franka Emika Panda identification data in this folder from its sources
(run from the repository root; needs a checkout of each source and a venv with the pinned
packages of .ci/requirements.txt plus mujoco):

    git clone https://github.com/marcocognetti/FrankaEmikaPandaDynModel /tmp/gaz2019   # GPL-3.0
    git clone https://github.com/Gepetto/example-robot-data /tmp/erd                   # Apache-2.0 (panda)
    python3 data/panda_gaz2019/make_data.py /tmp/gaz2019 /tmp/erd

Writes:
- panda_exciting_traj.mcap: the measured log of Gaz et al.'s exciting trajectory 1
  (matlab/data/Exciting_Traj/Trajectory_1/rbt_log: time, positions, velocity, torques), as
  franka_ros publishes it: sensor_msgs/msg/JointState on /franka_state_controller/joint_states,
  joints panda_joint1..7, position (rad), velocity (rad/s), effort = the link-side joint-torque
  sensors' tau_J (N·m, gravity included). Timestamps are the log's own (jitter and gaps kept),
  header.stamp = log time = 1 560 000 000 s + t. The gripper's finger joints are not in the
  source log (franka_gripper publishes them on a topic of its own): the bag has none.
- robot/example-robot-data/robots/panda_description/urdf/panda.urdf (unchanged) and the
  collision meshes it names (the visual meshes are not needed by twin sysid and are left out).
- gaz2019_model.urdf: the model the paper publishes (its Tables VIII/IX feasible parameters,
  which example-robot-data's panda.urdf carries for links 1-7, without the hand) with the
  paper's friction model (get_FrictionTorque.m) in a <twin_sysid> block:
  tau_f = A/(1+exp(-alpha(qd+phi))) - A/(1+exp(-alpha phi))
        = A/2·tanh((qd+phi)/(2/alpha)) + (A/2 - A/(1+exp(-alpha phi))).
  The script checks its gravity vector and mass matrix (MuJoCo's Python package on the URDF)
  against the paper's own code (get_GravityVector.m, get_MassMatrix.m, translated to numpy)
  at random configurations (they agree to about 5 % of M's largest entry and 0.08 N·m of
  gravity: the tables are rounded) and refuses to write it if they differ by more than 10 %.
- gaz2019_code/: the paper's own model code (get_*.m, GPL-3.0), which the test translates to numpy
  to compute the published model's torques on the held-out samples.
"""

import math
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
JOINT_STATE = (
    "std_msgs/Header header\n\nstring[] name\nfloat64[] position\nfloat64[] velocity\n"
    "float64[] effort\n"
    + "=" * 80 + "\nMSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
    + "=" * 80 + "\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
)
ARM = [f"panda_joint{i}" for i in range(1, 8)]
EPOCH_NS = 1_560_000_000 * 10**9


def matlab_to_numpy(path, fname):
    """The paper's symbolic MATLAB function at `path` as a numpy function of (q, dq)."""
    src = Path(path).read_text().replace("...\n", " ")
    body = []
    for line in src.split("\n"):
        line = line.split("%")[0].strip()
        m = re.match(r"^(\w+)\s*=\s*(.*);$", line, re.S)
        if not m or line.startswith("function"):
            continue
        name, expr = m.group(1), m.group(2)
        expr = expr.replace(".*", "*").replace("./", "/").replace(".^", "**").replace("^", "**")
        expr = re.sub(r"\b(q|dq)\((\d)\)", lambda mm: f"{mm.group(1)}[{int(mm.group(2)) - 1}]", expr)
        expr = re.sub(r"Bstack_hat\((\d+)\)", lambda mm: f"B[{int(mm.group(1)) - 1}]", expr)
        if name == "Bstack_hat":
            name = "B"
        if expr.startswith("["):
            parts = [p for p in re.split(r"[;,]", expr.strip()[1:-1]) if p.strip()]
            expr = "[" + ",".join(f"({p})" for p in parts) + "]"
        body.append(f"    {name} = {expr}")
    ret = body[-1].split("=")[0].strip()
    code = f"def {fname}(q, dq=None):\n    from numpy import sin, cos, sqrt\n" + "\n".join(body) + f"\n    return {ret}\n"
    scope = {}
    exec(compile(code, str(path), "exec"), scope)
    return scope[fname]


def friction_table(gaz):
    """(A, phi, alpha) per joint from get_FrictionTorque.m."""
    text = (gaz / "matlab/dyn_model_panda/get_FrictionTorque.m").read_text()
    rows = re.search(r"fp = \[(.*?)\];", text, re.S).group(1).replace("...", "").split(";")
    vals = [[float(v) for v in r.split(",") if v.strip()] for r in rows if r.strip()]
    return vals[0], vals[2], vals[3]


def write_bag(gaz):
    from mcap_ros2.writer import Writer

    d = gaz / "matlab/data/Exciting_Traj/Trajectory_1/rbt_log"
    t = np.loadtxt(d / "exciting_traj_time.txt")
    q = np.loadtxt(d / "exciting_traj_positions.txt").reshape(-1, 7)
    qd = np.loadtxt(d / "exciting_traj_velocity.txt").reshape(-1, 7)
    tau = np.loadtxt(d / "exciting_traj_torques.txt").reshape(-1, 7)
    assert len(t) == len(q) == len(qd) == len(tau), (len(t), len(q))
    out = HERE / "panda_exciting_traj.mcap"
    with open(out, "wb") as f:
        w = Writer(f, chunk_size=256 * 1024)
        schema = w.register_msgdef("sensor_msgs/msg/JointState", JOINT_STATE)
        for k in range(len(t)):
            ns = EPOCH_NS + int(round(t[k] * 1e9))
            msg = {
                "header": {"stamp": {"sec": ns // 10**9, "nanosec": ns % 10**9}, "frame_id": ""},
                "name": ARM,
                "position": [float(x) for x in q[k]],
                "velocity": [float(x) for x in qd[k]],
                "effort": [float(x) for x in tau[k]],
            }
            w.write_message("/franka_state_controller/joint_states", schema, msg, log_time=ns, publish_time=ns)
        w.finish()
    dt = np.diff(t)
    print(f"{out.name}: {len(t)} samples over {t[-1]:.3f} s, dt median {np.median(dt) * 1e3:.3f} ms, "
          f"min {dt.min() * 1e3:.2f}, max {dt.max() * 1e3:.2f}, {(np.round(dt * 1e9) > 2e6).sum()} steps > 2 ms")


def copy_urdf(erd):
    src = erd / "robots/panda_description"
    dst = HERE / "robot/example-robot-data/robots/panda_description"
    (dst / "urdf").mkdir(parents=True, exist_ok=True)
    (dst / "meshes/collision").mkdir(parents=True, exist_ok=True)
    shutil.copy(src / "urdf/panda.urdf", dst / "urdf/panda.urdf")
    for stl in sorted((src / "meshes/collision").glob("*.stl")):
        shutil.copy(stl, dst / "meshes/collision" / stl.name)
    shutil.copy(src / "LICENSE", dst / "LICENSE")
    (HERE / "robot/example-robot-data/package.xml").write_text(
        '<?xml version="1.0"?>\n<package format="3">\n  <name>example-robot-data</name>\n'
        "  <version>4.0.0</version>\n  <description>The Panda description of example-robot-data "
        "(collision meshes only), see ../../README.md</description>\n  <maintainer email=\"none@example.com\">"
        "twin</maintainer>\n  <license>BSD-3-Clause AND Apache-2.0</license>\n</package>\n")
    return dst / "urdf/panda.urdf"


def published_model(gaz, urdf):
    """The paper's model as a URDF with a <twin_sysid> friction block, checked against its code."""
    text = urdf.read_text()
    text = re.sub(r"<visual>.*?</visual>\s*", "", text, flags=re.S)
    text = re.sub(r"<collision>.*?</collision>\s*", "", text, flags=re.S)
    # The paper's model is the arm without the hand: drop the hand, its fingers and their joints.
    for link in ["panda_hand", "panda_hand_tcp", "panda_leftfinger", "panda_rightfinger"]:
        text = re.sub(rf'\s*<link name="{link}">.*?</link>', "", text, flags=re.S)
    for joint in ["panda_hand_joint", "panda_hand_tcp_joint", "panda_finger_joint1", "panda_finger_joint2"]:
        text = re.sub(rf'\s*<joint name="{joint}" .*?</joint>', "", text, flags=re.S)
    text = re.sub(r"\s*<safety_controller[^>]*/>", "", text)
    a, phi, alpha = friction_table(gaz)
    rows = []
    for j in range(7):
        coulomb = a[j] / 2.0
        offset = a[j] / 2.0 - a[j] / (1.0 + math.exp(-alpha[j] * phi[j]))
        rows.append(
            f'    <joint name="{ARM[j]}" offset="{offset:.9g}" coulomb="{coulomb:.9g}" viscous="0" '
            f'smoothing="{2.0 / alpha[j]:.9g}" velocity_shift="{phi[j]:.9g}" armature="0"/>')
    block = ("  <!-- twin sysid friction model (docs: sysid/src/extension.rs): tau_f = offset + viscous*qd"
             " + coulomb*tanh((qd + velocity_shift)/smoothing) + armature*qdd. Here: Gaz et al. 2019,"
             " get_FrictionTorque.m -->\n  <twin_sysid version=\"1\">\n" + "\n".join(rows) + "\n  </twin_sysid>\n")
    text = text.replace("</robot>", block + "</robot>")
    text = text.replace('<robot name="panda"', '<robot name="panda_gaz2019"', 1)
    header = ("<!-- The dynamic model published by C. Gaz, M. Cognetti, A. Oliva, P. Robuffo Giordano,"
              " A. De Luca, RA-L 2019 (github.com/marcocognetti/FrankaEmikaPandaDynModel, GPL-3.0):"
              " its feasible parameters (Tables VIII/IX) as example-robot-data's panda.urdf carries them"
              " for links 1-7, no hand, and its friction model. Written by make_data.py; checked"
              " against the paper's get_GravityVector.m and get_MassMatrix.m. -->\n")
    text = re.sub(r"(<\?xml[^>]*\?>\s*)", r"\1" + header.replace("\\", "\\\\"), text, count=1)
    check_against_paper(gaz, text)
    (HERE / "gaz2019_model.urdf").write_text(text)


def check_against_paper(gaz, text):
    import mujoco

    plain = re.sub(r"\s*<twin_sysid.*?</twin_sysid>", "", text, flags=re.S)
    model = mujoco.MjModel.from_xml_string(plain)
    assert model.nv == 7, model.nv
    data = mujoco.MjData(model)
    grav = matlab_to_numpy(gaz / "matlab/dyn_model_panda/get_GravityVector.m", "g")
    mass = matlab_to_numpy(gaz / "matlab/dyn_model_panda/get_MassMatrix.m", "m")
    rng = np.random.default_rng(2019)
    worst = 0.0
    for _ in range(20):
        q = rng.uniform(-2.0, 2.0, 7)
        data.qpos[:] = q
        data.qvel[:] = 0
        mujoco.mj_forward(model, data)
        g_mj = data.qfrc_bias.copy()
        m_mj = np.zeros((7, 7))
        mujoco.mj_fullM(model, data, m_mj)
        g_paper = np.array([float(x) for x in grav(q)])
        m_paper = np.array([float(x) for x in mass(q)], dtype=float).reshape(7, 7)
        worst = max(worst, np.abs(g_mj - g_paper).max() / np.abs(g_paper).max(),
                    np.abs(m_mj - m_paper).max() / np.abs(m_paper).max())
    # The tables' 5 significant digits and the code's unrounded values differ: a few per cent of
    # M's largest entry, under 0.1 N·m of gravity torque. A transcription error would be far more.
    print(f"gaz2019_model.urdf vs the paper's g(q), M(q): worst difference {worst:.2e} of the largest entry")
    if worst > 0.1:
        sys.exit(f"gaz2019_model.urdf does not reproduce the paper's model (worst {worst:.2e})")


def main():
    gaz, erd = Path(sys.argv[1]), Path(sys.argv[2])
    write_bag(gaz)
    urdf = copy_urdf(erd)
    published_model(gaz, urdf)
    code = HERE / "gaz2019_code"
    code.mkdir(exist_ok=True)
    for name in ["get_GravityVector.m", "get_MassMatrix.m", "get_CoriolisVector.m", "get_FrictionTorque.m"]:
        shutil.copy(gaz / "matlab/dyn_model_panda" / name, code / name)
    shutil.copy(gaz / "LICENSE", code / "LICENSE")


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""MuJoCo's own `mujoco.sysid` on the same synthetic log as `twin sysid`, for BENCHMARKS.md.

Configured as its documentation and tests intend: the robot's MjSpec (from the same starting
URDF twin gets) with motor actuators playing back the logged efforts and `jointpos` sensors
matching the logged positions; per moving link its default inertia parameter
(`body_inertia_param(spec, model, body)`: mass and centre of mass), per joint damping,
frictionloss and armature; the log cut into short windows, each a sequence starting from the
logged state (long open-loop rollouts of a chaotic arm drift away from any log); the MuJoCo
least-squares optimizer (`optimizer="mujoco"`, finite-difference Jacobians of rollouts).

Usage (pip install "mujoco[sysid]==4.0.0"):
    python benches/sysid_mujoco.py START.urdf TRAIN.csv OUT.json [--window 1.0] [--max-iters 50]
Writes the identified values as JSON (links: mass, com, inertia about the CoM; joints: damping,
frictionloss, armature) for `cargo run --release -p sysid --example score` to evaluate with the
same held-out metric as twin.
"""

import argparse
import json
import time

import mujoco
import numpy as np
from mujoco import sysid


def set_joint(joint, attr, value):
    """Sets a joint attribute; some are arrays in MuJoCo 4 (damping: polynomial coefficients)."""
    current = getattr(joint, attr)
    if isinstance(current, np.ndarray):
        current = current.copy()
        current.flat[0] = value
        setattr(joint, attr, current)
    else:
        setattr(joint, attr, value)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("urdf")
    ap.add_argument("log")
    ap.add_argument("out")
    ap.add_argument("--window", type=float, default=1.0, help="seconds per sequence")
    ap.add_argument("--windows", type=int, default=0, help="use only this many windows (0: all)")
    ap.add_argument("--max-iters", type=int, default=50)
    args = ap.parse_args()

    header = open(args.log).readline().strip().split(",")
    data = np.genfromtxt(args.log, delimiter=",", skip_header=1)
    t = data[:, 0]
    joints = [c[: -len("/position")] for c in header if c.endswith("/position")]
    col = {c: i for i, c in enumerate(header)}
    pos = np.stack([data[:, col[f"{j}/position"]] for j in joints], axis=1)
    vel = np.stack([data[:, col[f"{j}/velocity"]] for j in joints], axis=1)
    eff = np.stack([data[:, col[f"{j}/effort"]] for j in joints], axis=1)
    dt = float(np.median(np.diff(t)))

    spec = mujoco.MjSpec.from_file(args.urdf)
    # The synthetic robot's structure (what twin's simulation used): contacts off, 1 kHz, stiff
    # friction-loss constraint. Only the parameters below are unknown.
    spec.option.timestep = dt
    spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    for j in joints:
        js = spec.joint(j)
        js.solref_friction = [2 * dt, 1.0]
        js.solimp_friction = [0.99, 0.999, 0.001, 0.5, 2.0]
        a = spec.add_actuator(name=f"{j}_motor", target=j, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        a.gear[0] = 1.0
        spec.add_sensor(name=f"{j}_pos", type=mujoco.mjtSensor.mjSENS_JOINTPOS,
                        objtype=mujoco.mjtObj.mjOBJ_JOINT, objname=j)
    model = spec.compile()
    # The pseudo-inertia modifier re-derives each body's inertial from its geoms before
    # applying θ (`_infer_inertial`); URDF links without geometry need one to compile.
    for b in range(1, model.nbody):
        body = spec.body(model.body(b).name)
        if not body.geoms:
            # contype 1: the URDF compiler discards geoms that cannot collide as "visual";
            # contacts are disabled globally anyway.
            body.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.02, 0, 0])
    model = spec.compile()

    params = sysid.ParameterDict()
    moving = [model.body(b).name for b in range(1, model.nbody) if model.body_dofnum[b] > 0
              or model.body_parentid[b] != 0]
    for b in moving:
        # The default parameterisation (mass and centre of mass). InertiaType.Pseudo (the
        # physically consistent one) fails to compile in mujoco 4.0.0: apply_body_theta_inertia
        # zeroes `inertia` and relies on `fullinertia`, and MuJoCo rejects the body ("mass and
        # inertia of moving bodies must be larger than mjMINVAL").
        params.add(sysid.body_inertia_param(spec, model, b))
    for j in joints:
        jid = model.joint(j).id
        dof = model.jnt_dofadr[jid]
        for attr, field, hi in (("damping", "dof_damping", 20.0),
                                ("frictionloss", "dof_frictionloss", 20.0),
                                ("armature", "dof_armature", 1.0)):
            nominal = float(getattr(model, field)[dof])
            params.add(sysid.Parameter(
                f"{j}_{attr}", nominal=max(nominal, 1e-4), min_value=0.0, max_value=hi,
                modifier=lambda s, p, n=j, a=attr: set_joint(s.joint(n), a, float(p.value[0]))))

    # Sequences: windows of the log, each from the logged state.
    n = int(round(args.window / dt))
    starts = list(range(0, len(t) - n, n))
    if args.windows:
        starts = starts[: args.windows]
    qadr = [model.jnt_qposadr[model.joint(j).id] for j in joints]
    vadr = [model.jnt_dofadr[model.joint(j).id] for j in joints]
    names, inits, ctrls, sens = [], [], [], []
    for k, s in enumerate(starts):
        qpos = model.qpos0.copy()
        qvel = np.zeros(model.nv)
        qpos[qadr] = pos[s]
        qvel[vadr] = vel[s]
        inits.append(sysid.create_initial_state(model, qpos, qvel, np.zeros(model.na)))
        tw = t[s:s + n] - t[s]
        ctrls.append(sysid.TimeSeries(tw, eff[s:s + n]))
        sens.append(sysid.TimeSeries.from_names(tw, pos[s:s + n], model))
        names.append(f"w{k}")
    ms = sysid.ModelSequences("robot", spec, names, inits, ctrls, sens)
    residual_fn = sysid.build_residual_fn(models_sequences=[ms])

    t0 = time.perf_counter()
    opt, _ = sysid.optimize(initial_params=params, residual_fn=residual_fn, optimizer="mujoco",
                            verbose=False, max_iters=args.max_iters)
    wall = time.perf_counter() - t0

    fitted = sysid.apply_param_modifiers(opt, spec)
    out = {"wall_secs": wall, "windows": len(starts), "window_secs": args.window,
           "parameters": int(opt.as_vector().size), "links": {}, "joints": {}}
    for b in moving:
        bid = fitted.body(b).id
        q = fitted.body_iquat[bid]
        r = np.zeros(9)
        mujoco.mju_quat2Mat(r, q)
        r = r.reshape(3, 3)
        inertia = r @ np.diag(fitted.body_inertia[bid]) @ r.T
        out["links"][b] = {"mass": float(fitted.body_mass[bid]),
                           "com": fitted.body_ipos[bid].tolist(),
                           "inertia_com": inertia.tolist()}
    for j in joints:
        dof = fitted.jnt_dofadr[fitted.joint(j).id]
        out["joints"][j] = {"damping": float(fitted.dof_damping[dof]),
                            "frictionloss": float(fitted.dof_frictionloss[dof]),
                            "armature": float(fitted.dof_armature[dof])}
    with open(args.out, "w") as f:
        json.dump(out, f, indent=1)
    print(f"mujoco.sysid: {len(starts)} windows of {args.window} s, {out['parameters']} parameters, "
          f"{wall:.1f} s")


if __name__ == "__main__":
    main()

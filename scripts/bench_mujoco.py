#!/usr/bin/env python3
"""MuJoCo's throughput on vge's task, to compare with `vge bench sim`.

Loads the MJCF that `vge bench sim --write-mjcf` writes (vge_sim::mjcf: the same hand, object,
motors, and the settled grasp as keyframe `grasp`, for any hand) and steps it the way
`vge bench sim` steps one world: at the control rate, each control step adds a small
deterministic pseudo-random change to the motor targets (the table `vge bench sim
--write-actions` writes: vge_sim::bench's own actions, one column per actuator, clipped to the
joint limits), runs the physics steps of one control period, and reads the fingertip contacts
(position, normal, normal force per fingertip-object pair, as vge's observation does; the
fingertips are the geoms named `fingertip.*`). An episode ends when the object falls 3 cm
below its start height (along gravity) or after `--episode-steps`; then the settled grasp is
restored (cheaper than vge's reset, which simulates the grasp closing: that favours MuJoCo).
The settled grasp: the keyframe stepped for `--settle-s` untimed, so that MuJoCo's softer
contacts find their own equilibrium (vge15's cube stays within 1 mm of the keyframe on all
five fingertips).

The solver settings the model file carries (elliptic cones, impratio 10, no noslip) can be
overridden with --cone, --impratio, --noslip-iterations and --solver-iterations, so that
scripts/bench-vs-mujoco.sh can sweep MuJoCo's settings and compare against the fastest that
holds the grasp, not only against the one the file is written with.

Prints one JSON line: control_steps_per_s, sim_seconds_per_s (and per second of the thread's
CPU time), the settings, and whether the grasp held (drops, episode ends, mean fingertip contacts, the object's turn about z).
"""

import argparse
import json
import math
import time

import mujoco
import numpy as np

def load_actions(path, steps, joints):
    """The first `steps` rows of the action table `vge bench sim --write-actions` wrote, one
    column per joint."""
    raw = np.fromfile(path, dtype="<f4")
    if raw.size % joints:
        raise SystemExit(f"{path}: {raw.size} floats is not a whole number of {joints}-joint rows")
    table = raw.reshape(-1, joints).astype(np.float64)
    if len(table) < steps:
        raise SystemExit(f"{path}: {len(table)} control steps of actions, --steps asks for {steps}")
    return table[:steps]


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("mjcf", help="model written by `vge bench sim --write-mjcf FILE`")
    p.add_argument("--steps", type=int, default=2000, help="control steps to time (default 2000)")
    p.add_argument("--control-hz", type=float, default=20.0, help="control rate (default 20, as vge's env)")
    p.add_argument("--actions", required=True, metavar="FILE",
                   help="the action table (`vge bench sim --write-mjcf M --write-actions FILE`)")
    p.add_argument("--settle-s", type=float, default=1.0, help="settling time after the keyframe (default 1 s)")
    p.add_argument("--episode-steps", type=int, default=400, help="episode length in control steps (default 400)")
    p.add_argument("--cone", choices=["pyramidal", "elliptic"], help="friction cone (default: the file's)")
    p.add_argument("--impratio", type=float, help="frictional-to-normal impedance ratio (default: the file's)")
    p.add_argument("--noslip-iterations", type=int, help="noslip solver iterations (default: the file's)")
    p.add_argument("--solver-iterations", type=int, help="main solver's iteration cap (default: the file's)")
    args = p.parse_args()
    if args.steps < 1 or args.episode_steps < 1 or not args.control_hz > 0 or args.settle_s < 0:
        p.error("--steps and --episode-steps must be >= 1, --control-hz > 0, --settle-s >= 0")
    model = mujoco.MjModel.from_xml_path(args.mjcf)
    if args.cone is not None:
        model.opt.cone = {"pyramidal": mujoco.mjtCone.mjCONE_PYRAMIDAL,
                          "elliptic": mujoco.mjtCone.mjCONE_ELLIPTIC}[args.cone]
    if args.impratio is not None:
        model.opt.impratio = args.impratio
    if args.noslip_iterations is not None:
        model.opt.noslip_iterations = args.noslip_iterations
    if args.solver_iterations is not None:
        model.opt.iterations = args.solver_iterations
    data = mujoco.MjData(model)
    # Read before MuJoCo settles the grasp, so that a bad table fails first, and before
    # timing, so that Python's speed does not count against MuJoCo.
    table = load_actions(args.actions, args.steps, model.nu)
    key = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, "grasp")
    if key < 0:
        raise SystemExit(f"{args.mjcf}: no keyframe `grasp` (write it with vge bench sim --write-mjcf)")
    physics_per_control = round(1.0 / (args.control_hz * model.opt.timestep))
    if physics_per_control < 1:
        raise SystemExit("control rate above the physics rate")
    tips = [g for g in range(model.ngeom) if model.geom(g).name.startswith("fingertip.")]
    if not tips:
        raise SystemExit(f"{args.mjcf}: no fingertip geoms (named fingertip.*)")
    obj_geom = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "object")
    obj_body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "object")
    # Heights are measured against gravity (the hand may be held palm down or on its side).
    up = -np.asarray(model.opt.gravity, dtype=np.float64)
    up = up / np.linalg.norm(up) if np.linalg.norm(up) > 0 else np.array([0.0, 0.0, 1.0])
    lo, hi = model.actuator_ctrlrange[:, 0].copy(), model.actuator_ctrlrange[:, 1].copy()
    force = np.zeros(6)

    def read_contacts():
        """vge's readout: per fingertip the summed normal force and the force-weighted contact
        position and normal; returns how many fingertips touch the object."""
        n = np.zeros(len(tips))
        pos = np.zeros((len(tips), 3))
        nrm = np.zeros((len(tips), 3))
        for c in range(data.ncon):
            con = data.contact[c]
            pair = {con.geom1, con.geom2}
            if obj_geom not in pair:
                continue
            other = con.geom2 if con.geom1 == obj_geom else con.geom1
            if other not in tips:
                continue
            i = tips.index(other)
            mujoco.mj_contactForce(model, data, c, force)
            f = abs(force[0])
            n[i] += f
            pos[i] += f * con.pos
            nrm[i] += f * con.frame[:3]
        touching = n > 1e-6
        return int(touching.sum())

    # MuJoCo's softer contacts settle rapier's grasp slightly differently (within 1 mm):
    # settle first, and restart episodes from there.
    mujoco.mj_resetDataKeyframe(model, data, key)
    mujoco.mj_step(model, data, nstep=round(args.settle_s / model.opt.timestep))
    settled = mujoco.MjData(model)
    mujoco.mj_copyData(settled, model, data)
    settled_contacts = read_contacts()

    def height():
        return float(data.xpos[obj_body] @ up)

    def reset():
        mujoco.mj_copyData(data, model, settled)
        mujoco.mj_forward(model, data)
        return height()

    def yaw():
        q = data.xquat[obj_body]
        return math.atan2(2 * (q[0] * q[3] + q[1] * q[2]), 1 - 2 * (q[2] ** 2 + q[3] ** 2))

    def drive(steps):
        z0 = reset()
        resets, drops, contacts, turned, last_yaw, t = 0, 0, 0, 0.0, yaw(), 0
        for k in range(steps):
            data.ctrl[:] = np.clip(data.ctrl + table[k], lo, hi)
            mujoco.mj_step(model, data, nstep=physics_per_control)
            contacts += read_contacts()
            y = yaw()
            turned += (y - last_yaw + math.pi) % (2 * math.pi) - math.pi
            last_yaw = y
            t += 1
            dropped = height() < z0 - 0.03
            if dropped or t >= args.episode_steps:
                resets += 1
                drops += dropped
                reset()
                last_yaw, t = yaw(), 0
        return resets, drops, contacts / steps, turned

    drive(20)  # warm-up, as vge bench sim
    start, cpu_start = time.perf_counter(), time.thread_time()
    resets, drops, mean_contacts, turned = drive(args.steps)
    wall, cpu = time.perf_counter() - start, time.thread_time() - cpu_start
    print(json.dumps({
        "bench": "mujoco",
        "mujoco_version": mujoco.__version__,
        "model": model.names.split(b"\0", 1)[0].decode(),
        "control_steps_per_s_single": args.steps / wall,
        "sim_seconds_per_s": args.steps / wall / args.control_hz,
        # Per second of this thread's CPU time: what other processes on the core do not inflate.
        "sim_seconds_per_cpu_s": args.steps / cpu / args.control_hz,
        "physics_steps_per_control": physics_per_control,
        "timestep_s": model.opt.timestep,
        "cone": "elliptic" if model.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC else "pyramidal",
        "impratio": float(model.opt.impratio),
        "noslip_iterations": int(model.opt.noslip_iterations),
        "solver_iterations": int(model.opt.iterations),
        "resets_single": resets,
        "drops_single": drops,
        "mean_tip_contacts": mean_contacts,
        "joints": model.nu,
        "fingertips": len(tips),
        "settled_tip_contacts": settled_contacts,
        "settled_height_m": float(settled.xpos[obj_body] @ up),
        "object_turn_rad": turned,
        "steps": args.steps,
    }))


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Control steps per second of a Python loop over vge's env: one `vge.HandEnv`, and
`vge.VecHandEnv(N)` (N hands stepped in Rust on rayon's threads per call), for
scripts/bench-python-vs-mujoco.sh, beside scripts/bench_mujoco.py's loop over MuJoCo on the
same hand.

The workload is bench_mujoco.py's: from the settled grasp, each control step changes the
hand's joint targets (vge15's 15) by the same deterministic pseudo-random table (0.2 x max_action_rad, the file
`vge-python-reference bench-actions FILE STEPS` or `vge bench sim --write-actions` writes), and an
episode ends on a drop or after 400 steps. vge's reset simulates the grasp closing (MuJoCo's
restores a settled state): vge pays for its resets here, as in `vge bench sim`.

Prints one JSON line.
"""

import argparse
import json
import time

import numpy as np

import vge

def load_actions(path, steps, joints):
    """The first `steps` rows (`joints` float32 targets each) of the bench's action table."""
    raw = np.fromfile(path, dtype="<f4")
    if raw.size % joints or raw.size // joints < steps:
        raise SystemExit(f"{path}: {raw.size} floats; needs at least {steps} rows of {joints}")
    return raw.reshape(-1, joints)[:steps]


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--steps", type=int, default=2000, help="control steps to time per env (default 2000)")
    p.add_argument("--num-envs", type=int, default=8, help="envs of the VecHandEnv (default 8)")
    p.add_argument("--actions", required=True, metavar="FILE",
                   help="the action table (`vge-python-reference bench-actions FILE STEPS`)")
    args = p.parse_args()
    if args.steps < 1 or args.num_envs < 1:
        p.error("--steps and --num-envs must be >= 1")
    env = vge.HandEnv("cube")
    # Loaded before timing, as bench_mujoco.py does.
    table = load_actions(args.actions, args.steps, env.act_dim)

    env.reset(seed=0)
    for k in range(20):  # warm-up
        env.step(table[k])
    env.reset(seed=0)
    resets, contacts = 0, 0
    start = time.perf_counter()
    for k in range(args.steps):
        _, _, terminated, truncated, info = env.step(table[k])
        contacts += info["num_tip_contacts"]
        if terminated or truncated:
            resets += 1
            env.reset()
    single_s = time.perf_counter() - start

    n = args.num_envs
    venv = vge.VecHandEnv(n, "cube")
    venv.reset(seed=0)
    batch = np.repeat(table[:, None, :], n, axis=1)
    for k in range(20):
        venv.step(batch[k])
    venv.reset(seed=0)
    vec_resets = 0
    start = time.perf_counter()
    for k in range(args.steps):
        _, _, terminated, truncated, _ = venv.step(batch[k])
        vec_resets += int(terminated.sum() + truncated.sum())
    vec_s = time.perf_counter() - start

    print(json.dumps({
        "bench": "vge-python",
        "vge_version": vge.__version__,
        "control_steps_per_s_single": args.steps / single_s,
        "sim_seconds_per_s": args.steps / single_s / env.control_hz,
        "resets_single": resets,
        "mean_tip_contacts": contacts / args.steps,
        "num_envs": n,
        "control_steps_per_s_vec": n * args.steps / vec_s,
        "resets_vec": vec_resets,
        "steps": args.steps,
    }))


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Stable-Baselines3 on vge's hand: SB3's own env checker on `vge.HandEnv`, then SB3 SAC
trained on it for --steps env steps (default 5,000), its episode returns logged.

Needs stable-baselines3 (it pulls torch: install it into a venv of its own, e.g. .deps/sb3,
beside the `vge` package: `.deps/sb3/bin/pip install stable-baselines3 ./python`).

Writes OUT/check_env.txt (the checker's warnings, or "passed without warnings"),
OUT/progress.csv (SB3's logger) and OUT/summary.json.
"""

import argparse
import json
import time
import warnings
from pathlib import Path

import numpy as np
import stable_baselines3
from stable_baselines3 import SAC
from stable_baselines3.common.env_checker import check_env
from stable_baselines3.common.logger import configure
from stable_baselines3.common.monitor import Monitor

import vge


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="docs/results/python-sb3", help="output folder")
    p.add_argument("--steps", type=int, default=5000, help="SAC env steps (default 5000)")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(vge.HandEnv(episode_length=50), warn=True)
    lines = sorted({f"{w.category.__name__}: {w.message}" for w in caught})
    (out / "check_env.txt").write_text("\n".join(lines) + "\n" if lines else "passed without warnings\n")

    env = Monitor(vge.HandEnv("cube", episode_length=200))
    model = SAC("MlpPolicy", env, seed=args.seed, learning_starts=1000, verbose=0)
    model.set_logger(configure(str(out), ["csv"]))
    start = time.perf_counter()
    model.learn(total_timesteps=args.steps, log_interval=1)
    wall = time.perf_counter() - start
    returns = [float(r) for r in env.get_episode_rewards()]
    summary = {
        "stable_baselines3": stable_baselines3.__version__,
        "vge": vge.__version__,
        "env": "vge.HandEnv('cube', episode_length=200)",
        "algorithm": "SAC (SB3 defaults, learning_starts=1000)",
        "env_steps": args.steps,
        "episodes": len(returns),
        "episode_returns": returns,
        "episode_lengths": [int(n) for n in env.get_episode_lengths()],
        "wall_s": wall,
        "env_steps_per_s": args.steps / wall,
        "check_env_warnings": len(lines),
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
    print(json.dumps({k: v for k, v in summary.items() if k != "episode_returns"}))
    print("mean return of the first and last 5 episodes: %.3f, %.3f" % (np.mean(returns[:5]), np.mean(returns[-5:])))


if __name__ == "__main__":
    main()

"""Stable-Baselines3 SAC gradient updates per second at `vge bench update`'s sizes.

Called by scripts/bench-vs-sb3.sh; prints one JSON line. The same work as vge's benchmark:
observation 65, action 15, actor and twin critics of HIDDEN (default 256,256), batch 256, alpha 0 (SB3's
`ent_coef=0.0`, a fixed coefficient), tau 0.005, one target update per gradient step, on
batches drawn from a replay buffer of random transitions. SB3's critics have no layer norm:
compare with `vge bench update --layer-norm false` for the same networks.

Usage: bench_sb3.py THREADS UPDATES [HIDDEN]
"""

import json
import sys
import time

import gymnasium as gym
import numpy as np
import stable_baselines3
import torch
from stable_baselines3 import SAC
from stable_baselines3.common.logger import Logger

OBS_DIM, ACT_DIM, BATCH, BUFFER, WARMUP = 65, 15, 256, 100_000, 20


class ShapesOnly(gym.Env):
    """An env that only carries the spaces: the benchmark never steps it."""

    observation_space = gym.spaces.Box(-np.inf, np.inf, (OBS_DIM,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (ACT_DIM,), np.float32)

    def reset(self, *, seed=None, options=None):
        return np.zeros(OBS_DIM, np.float32), {}

    def step(self, action):
        return np.zeros(OBS_DIM, np.float32), 0.0, False, False, {}


def matmul_gflops():
    """A 1024^3 f32 matmul's rate, best of 5: the figure vge bench update reports beside."""
    n = 1024
    a, b = torch.randn(n, n), torch.randn(n, n)
    a @ b
    best = 0.0
    for _ in range(5):
        start = time.perf_counter()
        a @ b
        best = max(best, 2 * n**3 / (time.perf_counter() - start) / 1e9)
    return best


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    threads, updates = int(sys.argv[1]), int(sys.argv[2])
    hidden = [int(w) for w in (sys.argv[3] if len(sys.argv) > 3 else "256,256").split(",")]
    if threads < 1 or updates < 1 or not hidden or min(hidden) < 1:
        sys.exit("THREADS, UPDATES and the HIDDEN widths must be positive")
    torch.set_num_threads(threads)
    torch.manual_seed(0)
    model = SAC(
        "MlpPolicy",
        ShapesOnly(),
        policy_kwargs=dict(net_arch=hidden),
        batch_size=BATCH,
        buffer_size=BUFFER,
        ent_coef=0.0,
        learning_starts=0,
        tau=0.005,
        device="cpu",
        seed=0,
    )
    model.set_logger(Logger(folder=None, output_formats=[]))
    # Fill the buffer directly: its arrays are (size, n_envs, dim).
    rb, rng = model.replay_buffer, np.random.default_rng(0)
    rb.observations[:] = rng.standard_normal(rb.observations.shape, dtype=np.float32)
    rb.next_observations[:] = rng.standard_normal(rb.next_observations.shape, dtype=np.float32)
    rb.actions[:] = rng.uniform(-1, 1, rb.actions.shape).astype(np.float32)
    rb.rewards[:] = rng.standard_normal(rb.rewards.shape, dtype=np.float32)
    rb.full, rb.pos = True, 0

    model.train(gradient_steps=WARMUP, batch_size=BATCH)
    start = time.perf_counter()
    model.train(gradient_steps=updates, batch_size=BATCH)
    elapsed = time.perf_counter() - start
    print(json.dumps({
        "bench": "sb3_update",
        "threads": torch.get_num_threads(),
        "batch": BATCH,
        "hidden": hidden,
        "updates": updates,
        "updates_per_s": updates / elapsed,
        "matmul_gflops": matmul_gflops(),
        "torch_version": torch.__version__,
        "sb3_version": stable_baselines3.__version__,
    }))


if __name__ == "__main__":
    main()

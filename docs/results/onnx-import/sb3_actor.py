"""Stable-Baselines3 SAC on vge's hand, its actor exported to ONNX the way SB3's documentation
exports a policy ("Exporting models", SAC: `th.onnx.export` of `policy.actor` called with
`deterministic=True`, opset 17), and SB3's own deterministic actions on held-out observations
for the comparison with vge's runtime after `vge import`.

Run with .deps/sb3's Python (torch, stable-baselines3 and the `vge` package, which
scripts/bench-vs-sb3.sh and python/examples/sb3_check.py install, and `onnx`, which
torch.onnx.export needs: `.deps/sb3/bin/pip install onnx`):

  .deps/sb3/bin/python docs/results/onnx-import/sb3_actor.py --steps 1500 --learning-starts 500 --out DIR

Writes DIR/sb3_actor.onnx, DIR/sb3_obs.f32 and DIR/sb3_actions.f32 (float32 little-endian,
rows of 65 and 15), DIR/sb3_train.json.
"""

import argparse
import json
import time
from pathlib import Path

import numpy as np
import stable_baselines3
import torch as th
from stable_baselines3 import SAC

import vge


class OnnxableSB3Policy(th.nn.Module):
    """SB3's documented wrapper: the actor's deterministic action, tanh-squashed to [-1, 1]."""

    def __init__(self, actor: th.nn.Module):
        super().__init__()
        self.actor = actor

    def forward(self, observation: th.Tensor) -> th.Tensor:
        return self.actor(observation, deterministic=True)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--steps", type=int, default=5000)
    p.add_argument("--learning-starts", type=int, default=1000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", required=True)
    a = p.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)

    # One torch thread: the machine these results come from has 2 cores, shared.
    th.set_num_threads(1)
    env = vge.HandEnv("cube")
    model = SAC("MlpPolicy", env, seed=a.seed, learning_starts=a.learning_starts, verbose=0)
    start = time.perf_counter()
    model.learn(total_timesteps=a.steps)
    wall = time.perf_counter() - start

    onnx_path = out / "sb3_actor.onnx"
    dummy = th.randn(1, *model.observation_space.shape)
    th.onnx.export(OnnxableSB3Policy(model.policy.actor), dummy, str(onnx_path), opset_version=17,
                   input_names=["input"], dynamo=False)

    # Held-out observations from the env under the trained actor, and SB3's own actions
    # (predict unscales [-1, 1] to the action space, +-max_action_rad).
    obs_rows, act_rows = [], []
    for episode in range(5):
        obs, _ = env.reset(seed=1000 + episode)
        for _ in range(200):
            action, _ = model.predict(obs, deterministic=True)
            obs_rows.append(obs.astype(np.float32))
            act_rows.append(np.asarray(action, dtype=np.float32))
            obs, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                break
    np.asarray(obs_rows, dtype="<f4").tofile(out / "sb3_obs.f32")
    np.asarray(act_rows, dtype="<f4").tofile(out / "sb3_actions.f32")
    summary = {
        "stable_baselines3": stable_baselines3.__version__,
        "torch": th.__version__,
        "vge": vge.__version__,
        "env": "vge.HandEnv('cube')",
        "algorithm": f"SAC, SB3 defaults (MlpPolicy: 256, 256), learning_starts={a.learning_starts}",
        "seed": a.seed,
        "env_steps": a.steps,
        "train_wall_s": round(wall, 1),
        "held_out_observations": len(obs_rows),
        "max_action_rad": float(env.action_space.high[0]),
    }
    (out / "sb3_train.json").write_text(json.dumps(summary, indent=1) + "\n")
    print(json.dumps(summary))


if __name__ == "__main__":
    main()

import gymnasium as gym
import numpy as np
import vge

# The hand turning a cube, as a Gymnasium env (every [env] key of a vge config by name).
env = gym.make("vge/FingerGait-Cube-v0", episode_length=600)  # 30 s at 20 Hz
obs, info = env.reset(seed=0)

# The shipped finger gait on vge's own runtime (what `vge eval` and the robot run).
policy = vge.Policy.load("policies/cube.vgep")
print(policy.metadata["provenance"])

turned_rad = 0.0
while True:
    obs, reward, terminated, truncated, info = env.step(policy(obs))
    turned_rad += info["object_rotation_z_rad"]
    if terminated or truncated:
        break
print(f"turned {turned_rad:.2f} rad in {info['step']} steps, dropped: {terminated}")

# vge's finger-gaiting controller as an expert for your own learner.
fg = vge.controllers.FG(env)
obs, info = env.reset(seed=1)
expert_action = fg.act(env)  # float32 (15,), or None when FG has no action this step

# Eight hands stepped in Rust per call, with Gymnasium's next-step autoreset.
envs = vge.VecHandEnv(8, "cube")
obs, infos = envs.reset(seed=0)
obs, rewards, terminations, truncations, infos = envs.step(np.zeros((8, 15), np.float32))

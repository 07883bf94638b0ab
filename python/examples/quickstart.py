import gymnasium as gym
import numpy as np
import vge

# The hand turning a cube, as a Gymnasium env (every [env] key of a vge config by name).
env = gym.make("vge/FingerGait-Cube-v0", episode_length=600)  # 30 s at 20 Hz
obs, info = env.reset(seed=0)

# The shipped finger gait on vge's own runtime (what `vge eval` and the robot run), checked
# against the env it drives: its hand, its observation, its joints.
policy = vge.Policy.load("policies/cube.vgep", env=env)
print(policy.metadata["provenance"])

turned_rad = 0.0
while True:
    obs, reward, terminated, truncated, info = env.step(policy(obs))
    # The step's turn about z (what the reward and the success test count); the whole
    # rotation, as a world-frame rotation vector, is info["object_rotation_rad"].
    turned_rad += info["object_rotation_z_rad"]
    if terminated or truncated:
        break
print(f"turned {turned_rad:.2f} rad in {info['step']} steps, dropped: {terminated}")

# vge's finger-gaiting controller as an expert for your own learner.
fg = vge.controllers.FG(env)
obs, info = env.reset(seed=1)
expert_action = fg.act(env)  # float32 (env.act_dim,), or None when FG has no action this step

# Another hand: the sizes are the hand file's. The Allegro (16 joints, 4 fingers) observing
# what it measures, its joints now and at the last 3 steps; info["full_obs"] has the rest.
allegro = vge.HandEnv("cube", hand="allegro", observation="proprio:3")
obs, info = allegro.reset(seed=0)
print(allegro.obs_dim, allegro.act_dim, allegro.finger_names)  # 128 16 [...]
obs, reward, terminated, truncated, info = allegro.step(np.zeros(allegro.act_dim, np.float32))

# Eight hands stepped in Rust per call, with Gymnasium's next-step autoreset.
envs = vge.VecHandEnv(8, "cube")
obs, infos = envs.reset(seed=0)
obs, rewards, terminations, truncations, infos = envs.step(np.zeros((8, envs.act_dim), np.float32))

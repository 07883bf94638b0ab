"""Envs on every hand: the Allegro (16 joints, 4 fingers) from Python as vge15 is, its sizes
from the hand file, the proprioceptive observation a hand without fingertip sensing gives,
controllers on it, and a policy for another hand refused with the Rust message."""

import json
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import vge
from conftest import run_json

ALLEGRO_JOINTS, ALLEGRO_FINGERS = 16, 4


@pytest.fixture
def allegro():
    env = vge.HandEnv("cube", hand="allegro", episode_length=40)
    env.reset(seed=0)
    return env


def test_the_allegro_env_has_the_hands_sizes(allegro, repo):
    assert (allegro.obs_dim, allegro.act_dim) == (60, 16)
    assert allegro.action_space.shape == (16,) and allegro.observation_space.shape == (60,)
    assert allegro.joint_names == vge.Hand.load(repo / "hands/allegro.xml").joint_names
    assert len(allegro.joint_names) == ALLEGRO_JOINTS
    assert allegro.finger_names == allegro.hand.finger_names and len(allegro.finger_names) == ALLEGRO_FINGERS
    # The hand's name is its MJCF model's.
    assert allegro.hand.name == vge.Hand.named("allegro").name == "allegro_right"
    assert allegro.observation == "full"
    assert [s for s, *_ in allegro.obs_layout] == [
        "q_rad",
        "q_target_rad",
        "contact_position_m",
        "contact_normal",
        "contact_force_n",
    ]
    assert allegro.obs_layout[-1][2] == 60 and allegro.full_obs_layout == allegro.obs_layout
    vge15 = vge.HandEnv()
    assert (vge15.obs_dim, vge15.act_dim, len(vge15.finger_names)) == (65, 15, 5)
    assert vge15.hand.name == "vge15"


def test_reset_and_step_with_16_entry_actions(allegro):
    obs, info = allegro.reset(seed=3)
    assert obs.shape == (60,) and obs.dtype == np.float32
    assert info["tip_contacts"].shape == (4,) and info["grasping_fingers"].shape == (4,)
    assert "full_obs" not in info
    rng = np.random.default_rng(0)
    for _ in range(5):
        obs, reward, terminated, truncated, info = allegro.step(rng.uniform(-0.02, 0.02, 16).astype(np.float32))
        assert obs.shape == (60,) and np.isfinite(obs).all() and isinstance(reward, float)
        assert info["contact_forces_n"].shape == (4,) and info["tip_contacts"].dtype == np.bool_
    assert info["step"] == 5 and not terminated
    # The joint targets of the observation moved by the actions (the q_target_rad slice).
    start, end = dict((n, (a, b)) for n, a, b in allegro.obs_layout)["q_target_rad"]
    assert end - start == 16


def test_a_wrong_length_action_raises_with_the_rust_message(allegro):
    # The Python check names the expected shape; the extension's own check (reached past it)
    # carries vge_sim's message.
    with pytest.raises(ValueError, match=r"action has shape \(15,\), expected \(16,\)"):
        allegro.step(np.zeros(15, np.float32))
    with pytest.raises(ValueError, match="action has 15 entries, expected 16"):
        allegro._core.step(np.zeros(15, np.float32))
    with pytest.raises(ValueError, match="action entry 15 is not finite"):
        allegro._core.step(np.array([0.0] * 15 + [np.nan], np.float32))


def test_gymnasiums_checker_passes_on_the_allegro_with_no_other_warning():
    # As test_env's check of vge15: through gymnasium.make, so that the env has a spec.
    env = gym.make("vge/FingerGait-Cube-v0", hand="allegro", observation="proprio:1", episode_length=20).unwrapped
    assert (env.obs_dim, env.act_dim) == (64, 16)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env)
    advice = ("infinity", "symmetric and normalized")
    assert [str(w.message) for w in caught if not any(a in str(w.message) for a in advice)] == []


@pytest.mark.parametrize("k", [0, 1, 3])
def test_proprio_observation_is_the_joints_now_and_at_the_last_k_steps(k):
    observation = "proprio" if k == 0 else f"proprio:{k}"
    env = vge.HandEnv("cube", hand="allegro", observation=observation, episode_length=20)
    assert env.observation == observation
    assert env.obs_dim == 32 * (1 + k) and env.observation_space.shape == (32 * (1 + k),)
    assert env.full_obs_layout[-1][2] == 60
    obs, info = env.reset(seed=1)
    full = info["full_obs"]
    assert obs.shape == (32 * (1 + k),) and full.shape == (60,)
    # Now: the full observation's joint angles and targets; the past starts as the present.
    assert np.array_equal(obs[:32], full[:32])
    for i in range(k):
        assert np.array_equal(obs[32 + 16 * i : 48 + 16 * i], full[:16])
    previous = full
    rng = np.random.default_rng(2)
    for _ in range(4):
        obs, _, _, _, info = env.step(rng.uniform(-0.03, 0.03, 16).astype(np.float32))
        full = info["full_obs"]
        assert np.array_equal(obs[:32], full[:32])
        if k:
            # Newest first: the step before is the first past entry (angles, then targets).
            assert np.array_equal(obs[32:48], previous[:16])
            assert np.array_equal(obs[32 + 16 * k : 48 + 16 * k], previous[16:32])
        previous = full


def test_the_proprio_obs_of_a_vge15_env_is_sized_by_its_hand():
    env = vge.HandEnv(observation="proprio:2")
    obs, info = env.reset(seed=0)
    assert obs.shape == (30 * 3,) and info["full_obs"].shape == (65,)


def test_hand_and_observation_keys_are_checked_naming_the_key(repo):
    with pytest.raises(ValueError, match=r"env\.hand.*alegro.*allegro"):
        vge.HandEnv(hand="alegro")
    with pytest.raises(ValueError, match=r"env\.observation.*touch"):
        vge.HandEnv(observation="touch")
    with pytest.raises(ValueError, match=r"env\.reward_min_contacts = 5: the hand allegro_right has 4 fingertips"):
        vge.HandEnv(hand="allegro", reward_min_contacts=5)
    # A path to the MJCF file is the same hand.
    by_path = vge.HandEnv(hand=str(repo / "hands/allegro.xml"))
    assert by_path.hand.description_sha256 == vge.Hand.named("allegro").description_sha256
    assert vge.HANDS == ("vge15", "allegro")


def test_module_constants_of_one_hand_are_gone_with_a_pointer():
    with pytest.raises(AttributeError, match="env.obs_dim"):
        vge.OBS_DIM  # noqa: B018
    with pytest.raises(AttributeError, match="env.act_dim"):
        vge.NUM_JOINTS  # noqa: B018


def test_allegro_observations_are_bit_identical_to_the_rust_env(reference):
    rng = np.random.default_rng(5)
    actions = rng.uniform(-0.04, 0.04, size=(25, 16)).astype(np.float32)
    keys = {"hand": "allegro", "episode_length": 25, "noise_q_std_rad": 0.01}
    request = {"object": "cube", "env": keys, "seed": 9, "actions": actions.tolist()}
    want = run_json([reference, "env-trace"], stdin=json.dumps(request))
    env = vge.HandEnv("cube", **keys)
    obs, _ = env.reset(seed=9)
    observations, rewards = [obs], []
    for a in actions:
        obs, r, te, tr, _ = env.step(a)
        observations.append(obs)
        rewards.append(r)
        if te or tr:
            break
    assert np.array(observations).view(np.uint32).tolist() == want["obs_bits"]
    assert np.array(rewards, np.float32).view(np.uint32).tolist() == want["reward_bits"]


def test_vec_env_on_the_allegro_matches_sync_vector_env_with_proprio():
    keys = {"hand": "allegro", "observation": "proprio:2", "episode_length": 6}
    n = 3
    ours = vge.VecHandEnv(n, "cube", **keys)
    assert (ours.obs_dim, ours.act_dim) == (96, 16)
    assert ours.single_observation_space.shape == (96,) and ours.single_action_space.shape == (16,)
    assert ours.finger_names == vge.HandEnv(hand="allegro").finger_names
    theirs = gym.vector.SyncVectorEnv([lambda: vge.HandEnv("cube", **keys) for _ in range(n)])
    a_obs, a_info = ours.reset(seed=4)
    b_obs, b_info = theirs.reset(seed=4)
    assert a_obs.shape == (n, 96) and np.array_equal(a_obs, b_obs)
    assert a_info["full_obs"].shape == (n, 60) and np.array_equal(a_info["full_obs"], b_info["full_obs"])
    assert a_info["tip_contacts"].shape == (n, 4)
    rng = np.random.default_rng(1)
    for step in range(9):  # through an episode's end and the autoreset after it
        actions = rng.uniform(-0.02, 0.02, size=(n, 16)).astype(np.float32)
        a = ours.step(actions)
        b = theirs.step(actions)
        for x, y in zip(a[:4], b[:4]):
            assert np.array_equal(x, y), f"step {step}"
    with pytest.raises(ValueError, match=r"actions has shape \(3, 15\), expected \(3, 16\)"):
        ours.step(np.zeros((n, 15), np.float32))
    with pytest.raises(ValueError, match=r"expected \[3, 16\]"):
        ours._core.step(np.zeros((n, 15), np.float32), np.zeros(n, np.uint64))


def test_a_full_vec_env_has_no_full_obs_info():
    env = vge.VecHandEnv(2, hand="allegro")
    obs, info = env.reset(seed=0)
    assert obs.shape == (2, 60) and "full_obs" not in info


@pytest.mark.parametrize("kind", ["igm", "cs", "fg"])
def test_controllers_act_on_the_allegro(kind):
    env = vge.HandEnv("cube", hand="allegro", episode_length=30)
    controller = {"igm": vge.controllers.IGM, "cs": vge.controllers.CS, "fg": vge.controllers.FG}[kind](env)
    env.reset(seed=0)
    acted = 0
    for _ in range(30):
        a = controller.act(env)
        if a is not None:
            assert a.shape == (16,) and a.dtype == np.float32 and np.isfinite(a).all()
            acted += 1
        *_, terminated, truncated, _ = env.step(a if a is not None else np.zeros(16, np.float32))
        if terminated or truncated:
            break
    assert acted > 0, controller.last_error


def test_a_vge15_policy_is_refused_on_the_allegro_env(repo, allegro):
    path = repo / "policies/cube.vgep"
    with pytest.raises(vge.PolicyError, match="the policy drives the hand vge15, not allegro_right") as e:
        vge.Policy.load(path, env=allegro)
    assert str(path) in str(e.value) and isinstance(e.value, ValueError)
    policy = vge.Policy.load(path)
    with pytest.raises(vge.PolicyError, match="not allegro"):
        policy.check(gym.wrappers.TimeLimit(allegro, 10))
    with pytest.raises(vge.PolicyError, match="not allegro"):
        policy.check(vge.VecHandEnv(2, hand="allegro"))
    # On vge15 with the full observation it is the policy's env; with less, it is refused.
    policy.check(vge.HandEnv())
    policy.check(vge.VecHandEnv(2))
    with pytest.raises(vge.PolicyError, match="maps 65 observations to 15 actions, the hand vge15 needs 60 -> 15"):
        policy.check(vge.HandEnv(observation="proprio:1"))
    with pytest.raises(TypeError, match="vge.HandEnv or vge.VecHandEnv"):
        policy.check(object())


def test_a_policy_without_a_task_record_is_vge15_full(repo):
    policy = vge.Policy.load(repo / "policies/cube.vgep")
    assert policy.metadata["task"] is None
    assert (policy.hand, policy.observation_set) == ("vge15", "full")


def _allegro_actor_onnx(path, obs_dim, act_dim):
    """A two-layer MLP actor as ONNX (Gemm, Relu, Gemm), as torch.onnx.export writes one."""
    onnx = pytest.importorskip("onnx")
    from onnx import TensorProto, helper, numpy_helper

    rng = np.random.default_rng(0)
    w1 = rng.normal(0, 0.1, (obs_dim, 32)).astype(np.float32)
    w2 = rng.normal(0, 0.1, (32, act_dim)).astype(np.float32)
    graph = helper.make_graph(
        [
            helper.make_node("Gemm", ["obs", "w1", "b1"], ["h"]),
            helper.make_node("Relu", ["h"], ["r"]),
            helper.make_node("Gemm", ["r", "w2", "b2"], ["action"]),
        ],
        "actor",
        [helper.make_tensor_value_info("obs", TensorProto.FLOAT, [1, obs_dim])],
        [helper.make_tensor_value_info("action", TensorProto.FLOAT, [1, act_dim])],
        [
            numpy_helper.from_array(w1, "w1"),
            numpy_helper.from_array(np.zeros(32, np.float32), "b1"),
            numpy_helper.from_array(w2, "w2"),
            numpy_helper.from_array(np.zeros(act_dim, np.float32), "b2"),
        ],
    )
    onnx.save(helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)]), str(path))


def test_a_policy_for_the_allegro_carries_its_task_record_and_runs_on_its_env(vge_cli, tmp_path):
    """A policy file written for the Allegro with the proprio:2 observation (by `vge import`,
    from an ONNX actor): its task record reads back, it loads on the env it was made for and
    is refused on the others."""
    import subprocess

    help_text = subprocess.run([str(vge_cli), "import", "--help"], capture_output=True, text=True).stdout
    if "--hand" not in help_text:
        pytest.skip(f"{vge_cli} predates `vge import --hand` (rebuild it)")
    onnx_path, out = tmp_path / "actor.onnx", tmp_path / "allegro.vgep"
    _allegro_actor_onnx(onnx_path, 96, 16)
    args = ["import", "--onnx", onnx_path, "--out", out, "--hand", "allegro", "--observation", "proprio:2"]
    run = subprocess.run([str(vge_cli), *map(str, args), "--action-scale", "graph"], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    env = vge.HandEnv("cube", hand="allegro", observation="proprio:2")
    written = vge.Policy.load(out).metadata["task"]["hand_sha256"]
    if written != env.hand.description_sha256:
        # The test command builds both from one tree; a vge binary built before an edit of
        # hands/allegro.xml records the old description, which the check rightly refuses.
        pytest.skip(f"{vge_cli} was built from another hands/allegro.xml than this package (rebuild it)")
    policy = vge.Policy.load(out, env=env)
    task = policy.metadata["task"]
    assert task["hand"] == "allegro_right" and task["observation_set"] == "proprio:2"
    assert task["hand_sha256"] == env.hand.description_sha256
    assert (policy.hand, policy.observation_set) == ("allegro_right", "proprio:2")
    obs, _ = env.reset(seed=0)
    assert policy(obs).shape == (16,)
    with pytest.raises(vge.PolicyError, match="the policy drives the hand allegro_right, not vge15"):
        policy.check(vge.HandEnv(observation="proprio:2"))
    with pytest.raises(vge.PolicyError, match="maps 96 observations to 16 actions, the hand allegro_right needs 60 -> 16"):
        policy.check(vge.HandEnv(hand="allegro"))

"""python/examples/bench_loop.py, the Python side of scripts/bench-python-vs-mujoco.sh, replays
the action table vge_sim::bench writes (through the reference binary) on the real package."""

import json
import subprocess
import sys


def bench_loop(repo, actions, *args):
    return subprocess.run(
        [sys.executable, "python/examples/bench_loop.py", "--actions", str(actions), *args],
        cwd=repo,
        capture_output=True,
        text=True,
        timeout=600,
    )


def test_the_loop_replays_the_benchs_table_and_keeps_the_grasp(repo, reference, tmp_path):
    actions = tmp_path / "actions.f32"
    subprocess.run([str(reference), "bench-actions", str(actions), "40"], check=True)
    assert actions.stat().st_size == 40 * 15 * 4

    out = bench_loop(repo, actions, "--steps", "40", "--num-envs", "2")
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout)
    assert (r["bench"], r["steps"], r["num_envs"]) == ("vge-python", 40, 2)
    # Small target changes from the settled grasp: most steps keep >= 4 fingertips on the cube.
    assert r["mean_tip_contacts"] >= 4.0, r
    assert r["control_steps_per_s_single"] > 0 and r["control_steps_per_s_vec"] > 0


def test_a_table_shorter_than_the_steps_asked_for_is_refused_naming_the_file(repo, reference, tmp_path):
    actions = tmp_path / "short.f32"
    subprocess.run([str(reference), "bench-actions", str(actions), "10"], check=True)
    out = bench_loop(repo, actions, "--steps", "40")
    assert out.returncode != 0
    assert "short.f32" in out.stderr and "at least 40 rows" in out.stderr, out.stderr

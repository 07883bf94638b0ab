#!/usr/bin/env bash
# scripts/bench-python-vs-mujoco.sh [ROUNDS] [NUM_ENVS]: control steps per second of a Python
# loop over vge (the `vge` package: one HandEnv, and VecHandEnv(NUM_ENVS), default 8) beside a
# Python loop over MuJoCo on the same hand, timed in one run.
#
# MuJoCo (240 Hz) steps the model `vge bench sim --write-mjcf` writes, with scripts/bench_mujoco.py's
# loop (the same action table, written by vge_sim::bench, contact readout and episode ends as
# python/examples/bench_loop.py's). Rounds alternate the two (default 3), unpinned: the
# VecHandEnv uses every core, the single loops one. Prints the medians, the ratios, and the
# size of the installed extension; every round's JSON line is kept in
# target/bench-python-vs-mujoco.jsonl. Needs the package installed in .deps/py
# (`.deps/py/bin/pip install ./python`). Compare only figures from one run: the CPU model
# varies between machines.
set -euo pipefail
cd "$(dirname "$0")/.."
rounds=${1:-3}
num_envs=${2:-8}
venv=.deps/py
"$venv/bin/python" -c 'import vge, mujoco' || {
  echo "needs vge and mujoco in $venv: .deps/py/bin/pip install ./python mujoco==4.0.0" >&2
  exit 1
}
# The model `vge bench sim --write-mjcf` writes, by the same call, from python/'s reference
# binary: a Python bench needs no libtorch build.
reference=target/release/vge-python-reference
[ -x "$reference" ] || cargo build --release -p vge-python-reference >&2
model=target/vge-hand.mjcf.xml
mkdir -p target
"$reference" write-mjcf "$model"
# The bench's actions, from vge_sim::bench itself, for both loops (2000 steps, their default).
actions=target/bench-actions.f32
"$reference" bench-actions "$actions" 2000
out=target/bench-python-vs-mujoco.jsonl
: >"$out"
for r in $(seq 1 "$rounds"); do
  echo "round $r of $rounds..." >&2
  "$venv/bin/python" python/examples/bench_loop.py --num-envs "$num_envs" --actions "$actions" >>"$out"
  "$venv/bin/python" scripts/bench_mujoco.py "$model" --actions "$actions" >>"$out"
done
"$venv/bin/python" - "$out" <<'PY'
import json, os, statistics, sys
import vge
rows = [json.loads(l) for l in open(sys.argv[1])]
v = [r for r in rows if r["bench"] == "vge-python"]
m = [r for r in rows if r["bench"] == "mujoco"]
med = lambda rs, k: statistics.median(r[k] for r in rs)
vs, vv, ms = med(v, "control_steps_per_s_single"), med(v, "control_steps_per_s_vec"), med(m, "control_steps_per_s_single")
print("Python loop, control steps per second (20 Hz control, medians of %d rounds, %d CPUs):" % (len(v), os.cpu_count()))
print("  vge.HandEnv                 %8.0f" % vs)
print("  vge.VecHandEnv(%d)           %8.0f  (all envs together)" % (v[0]["num_envs"], vv))
print("  MuJoCo %s (240 Hz), mujoco.mj_step  %8.0f" % (m[0]["mujoco_version"], ms))
print("  ratio HandEnv / MuJoCo %.2f, VecHandEnv(%d) / MuJoCo %.2f" % (vs / ms, v[0]["num_envs"], vv / ms))
print("  grasp: vge %.2f fingertips on average, MuJoCo %.2f" % (med(v, "mean_tip_contacts"), med(m, "mean_tip_contacts")))
ext = vge._vge.__file__
print("  extension %s: %.1f MiB" % (os.path.basename(ext), os.path.getsize(ext) / 2**20))
PY

#!/usr/bin/env bash
# scripts/bench-vs-mujoco.sh [ROUNDS] [MUJOCO_HZ]: vge's simulator against MuJoCo on the same
# hand, grasp and contact readout, timed in one run, as simulated seconds per
# wall-clock second of one world on one thread.
#
# `vge bench sim --write-mjcf` writes the task as MJCF (generated from the hand model, so the
# two cannot disagree about the geometry); scripts/bench_mujoco.py steps it in MuJoCo (from
# PyPI, into .deps/py) with the same actions and contact readout. The two
# alternate ROUNDS times (default 3) pinned to one core; the medians and their ratio are
# printed, and every round's JSON line is kept in target/bench-vs-mujoco.jsonl.
# Compare only figures from one run: the CPU model varies between machines. Exits 2, saying so,
# when fewer than 4 fingertips hold the cube on average in MuJoCo (then the workloads differ).
set -euo pipefail
cd "$(dirname "$0")/.."
rounds=${1:-3}
mujoco_hz=${2:-240}
# The venv scripts/test.sh makes; MuJoCo pinned as there.
venv=.deps/py
if ! "$venv/bin/python" -c 'import mujoco; assert mujoco.__version__ == "4.0.0"' 2>/dev/null; then
  echo "installing mujoco 4.0.0 into $venv (PyPI)..." >&2
  [ -x "$venv/bin/python" ] || python3 -m venv "$venv"
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check mujoco==4.0.0
fi
cargo build --release -p vge-cli --bin vge >&2
vge=target/release/vge
model=target/vge-hand.mjcf.xml
actions=target/bench-actions.f32
"$vge" bench sim --write-mjcf "$model" --mujoco-timestep-s "$(python3 -c "print(1/$mujoco_hz)")" \
  --write-actions "$actions"
out=target/bench-vs-mujoco.jsonl
: >"$out"
core=$(($(nproc) - 1))
for r in $(seq 1 "$rounds"); do
  echo "round $r of $rounds..." >&2
  taskset -c "$core" "$vge" bench sim --json --worlds 1 --threads 1 >>"$out"
  taskset -c "$core" "$venv/bin/python" scripts/bench_mujoco.py "$model" --actions "$actions" >>"$out"
done
python3 - "$out" <<'EOF'
import json, statistics, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
vge = [r for r in rows if r["bench"] == "sim"]
mj = [r for r in rows if r["bench"] == "mujoco"]
med = lambda rs: statistics.median(r["sim_seconds_per_s"] for r in rs)
each = lambda rs: ", ".join("%.1f" % r["sim_seconds_per_s"] for r in rs)
v, m = med(vge), med(mj)
print("vge (rapier, %.0f Hz x %d substeps): %7.1f simulated s per s  (rounds: %s)"
      % (vge[0]["physics_hz"], vge[0]["solver_iterations"], v, each(vge)))
print("MuJoCo %s (%.0f Hz):            %7.1f simulated s per s  (rounds: %s)"
      % (mj[0]["mujoco_version"], 1 / mj[0]["timestep_s"], m, each(mj)))
print("ratio vge / MuJoCo: %.2f" % (v / m))
print("grasp in MuJoCo: %d fingertips after settling, %.2f on average, %.1f episode ends per run (vge: %.1f)"
      % (mj[0]["settled_tip_contacts"], statistics.mean(r["mean_tip_contacts"] for r in mj),
         statistics.mean(r["resets_single"] for r in mj), statistics.mean(r["resets_single"] for r in vge)))
# The comparison is about a held, contact-rich grasp: a model that keeps dropping the cube
# steps fewer contacts and is not the same workload.
held = statistics.mean(r["mean_tip_contacts"] for r in mj)
if held < 4.0:
    print("NOT COMPARABLE: the cube does not stay in MuJoCo's grasp (%.2f fingertips on average, "
          "fewer than 4), so MuJoCo steps a lighter workload than vge; the ratio is for reference only" % held)
    sys.exit(2)
EOF

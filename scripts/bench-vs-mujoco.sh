#!/usr/bin/env bash
# scripts/bench-vs-mujoco.sh [--hand HAND] [ROUNDS] [MUJOCO_HZ]: vge's simulator against MuJoCo
# on the same hand, grasp and contact readout, timed in one run, as simulated seconds per
# wall-clock second of one world on one thread.
#
# `vge bench sim --write-mjcf` writes the task as MJCF (generated from the hand's description
# and the task's servos and physics, as the rapier world is built, so the two cannot disagree
# about the geometry); scripts/bench_mujoco.py steps it in MuJoCo (from PyPI, into .deps/py)
# with the same actions (one column per joint) and contact readout. The two alternate ROUNDS
# times (default 3) pinned to one core; the medians and their ratio are printed, and every
# round's JSON line is kept in target/bench-vs-mujoco.jsonl. HAND: a shipped hand's name or an
# MJCF path (default vge15, the hand `vge bench sim` runs without --hand). Compare only figures from one run: the CPU model varies
# between machines. Exits 2, saying so, when more than one fingertip on average is off the
# object in MuJoCo (fewer than 4 of vge15's 5: then the workloads differ).
set -euo pipefail
cd "$(dirname "$0")/.."
hand=vge15
positional=()
while [ $# -gt 0 ]; do
  case "$1" in
    --hand) hand=${2:?--hand needs the name of a shipped hand or an MJCF path}; shift 2 ;;
    --hand=*) hand=${1#--hand=}; shift ;;
    *) positional+=("$1"); shift ;;
  esac
done
rounds=${positional[0]:-3}
mujoco_hz=${positional[1]:-240}
# The venv scripts/test.sh makes; MuJoCo pinned as there.
venv=.deps/py
if ! "$venv/bin/python" -c 'import mujoco; assert mujoco.__version__ == "4.0.0"' 2>/dev/null; then
  echo "installing mujoco 4.0.0 into $venv (PyPI)..." >&2
  [ -x "$venv/bin/python" ] || python3 -m venv "$venv"
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check mujoco==4.0.0
fi
# The vge binary: VGE if set (bench sim needs no libtorch: a `--no-default-features` build
# will do), else built here.
vge=${VGE:-}
if [ -z "$vge" ]; then
  cargo build --release -p vge-cli --bin vge >&2
  vge=${CARGO_TARGET_DIR:-target}/release/vge
fi
hand_args=()
if [ "$hand" != vge15 ]; then
  if ! "$vge" bench sim --help | grep -q -- '--hand'; then
    echo "this vge's bench sim runs vge15 only (no --hand): cannot bench $hand" >&2
    exit 1
  fi
  hand_args=(--hand "$hand")
fi
model=target/vge-hand.mjcf.xml
actions=target/bench-actions.f32
"$vge" bench sim "${hand_args[@]}" --write-mjcf "$model" \
  --mujoco-timestep-s "$(python3 -c "print(1/$mujoco_hz)")" --write-actions "$actions"
out=target/bench-vs-mujoco.jsonl
: >"$out"
core=$(($(nproc) - 1))
for r in $(seq 1 "$rounds"); do
  echo "round $r of $rounds..." >&2
  taskset -c "$core" "$vge" bench sim "${hand_args[@]}" --json --worlds 1 --threads 1 >>"$out"
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
print("hand %s: %d joints, %d fingertips" % (mj[0]["model"], mj[0]["joints"], mj[0]["fingertips"]))
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
least = mj[0]["fingertips"] - 1
if held < least:
    print("NOT COMPARABLE: the cube does not stay in MuJoCo's grasp (%.2f fingertips on average, "
          "fewer than %d), so MuJoCo steps a lighter workload than vge; the ratio is for reference only"
          % (held, least))
    sys.exit(2)
EOF

#!/usr/bin/env bash
# scripts/bench-vs-mujoco.sh [--hand HAND] [ROUNDS] [MUJOCO_HZ...]: vge's simulator against MuJoCo
# on the same hand, grasp and contact readout, timed in one run, as simulated seconds per second
# of one world on one thread.
#
# `vge bench sim --write-mjcf` writes the task as MJCF (generated from the hand's description
# and the task's servos and physics, as the rapier world is built, so the two cannot disagree
# about the geometry), one model per MuJoCo rate (default 240 and 120 Hz: the joint armature
# depends on the time step); scripts/bench_mujoco.py steps it in MuJoCo (from PyPI, into
# .deps/py) with the same actions (one column per joint) and contact readout, under each of
# MuJoCo's solver settings below (friction cone, impratio, noslip iterations). The runs
# alternate ROUNDS times (default 3) pinned to one core; every round's JSON line is kept in
# target/bench-vs-mujoco.jsonl.
#
# Printed: per MuJoCo setting the median speed (per second of the benchmark thread's CPU time,
# which a loaded machine's other work does not inflate; per wall-clock second beside it),
# fingertips on the object and drops; vge's ratio against the fastest setting that holds the grasp (on average no more than one
# fingertip off the object) and against the one that holds it best (fewest drops under the
# target walk; the fastest of equals). HAND: a shipped hand's name or an MJCF path (default
# vge15, the hand `vge bench sim` runs without --hand). Compare only figures from one run: the
# CPU model varies between machines. Exits 2, saying so, when no MuJoCo setting holds the
# grasp (then the workloads differ).
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
mujoco_rates=("${positional[@]:1}")
[ ${#mujoco_rates[@]} -gt 0 ] || mujoco_rates=(240 120)
# MuJoCo's solver settings swept at each rate (bench_mujoco.py's options): the file's own
# (elliptic cones, impratio 10: MuJoCo's advice for grasping), its default pyramidal cones, and
# each with 3 noslip iterations (a post-pass that removes contact slip).
settings=("--cone elliptic --impratio 10 --noslip-iterations 0"
          "--cone pyramidal --impratio 1 --noslip-iterations 0"
          "--cone elliptic --impratio 10 --noslip-iterations 3"
          "--cone pyramidal --impratio 1 --noslip-iterations 3")
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
actions=target/bench-actions.f32
for hz in "${mujoco_rates[@]}"; do
  "$vge" bench sim "${hand_args[@]}" --write-mjcf "target/vge-hand-${hz}hz.mjcf.xml" \
    --mujoco-timestep-s "$(python3 -c "print(1/$hz)")" --write-actions "$actions"
done
out=target/bench-vs-mujoco.jsonl
: >"$out"
core=$(($(nproc) - 1))
for r in $(seq 1 "$rounds"); do
  echo "round $r of $rounds..." >&2
  taskset -c "$core" "$vge" bench sim "${hand_args[@]}" --json --worlds 1 --threads 1 >>"$out"
  for hz in "${mujoco_rates[@]}"; do
    for s in "${settings[@]}"; do
      # shellcheck disable=SC2086 # each setting is a list of options
      taskset -c "$core" "$venv/bin/python" scripts/bench_mujoco.py "target/vge-hand-${hz}hz.mjcf.xml" \
        --actions "$actions" $s >>"$out"
    done
  done
done
python3 - "$out" <<'EOF'
import json, statistics, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
vge = [r for r in rows if r["bench"] == "sim"]
mj = [r for r in rows if r["bench"] == "mujoco"]
# Speeds per second of the benchmark thread's CPU time where both sides report it (a loaded
# machine inflates wall-clock time by its run queue, and not alike for both), else per
# wall-clock second; the wall-clock medians are printed beside them.
k = "sim_seconds_per_cpu_s" if all(r.get("sim_seconds_per_cpu_s") for r in rows) else "sim_seconds_per_s"
med = lambda rs, key=k: statistics.median(r[key] for r in rs)
each = lambda rs: ", ".join("%.1f" % r[k] for r in rs)
mean = lambda rs, key: statistics.mean(r[key] for r in rs)
groups = {}
for r in mj:
    groups.setdefault((r["timestep_s"], r["cone"], r["impratio"], r["noslip_iterations"]), []).append(r)
v = med(vge)
tips = mj[0]["fingertips"]
print("hand %s: %d joints, %d fingertips; simulated s per %s (rounds), [per wall-clock s]"
      % (mj[0]["model"], mj[0]["joints"], tips, "CPU s" if k == "sim_seconds_per_cpu_s" else "wall-clock s"))
print("vge (rapier, %.0f Hz x %d substeps): %.1f (%s) [%.1f]; fingertips %.2f, drops %.1f, episode ends %.1f per run"
      % (vge[0]["physics_hz"], vge[0]["solver_iterations"], v, each(vge), med(vge, "sim_seconds_per_s"),
         mean(vge, "mean_tip_contacts"), mean(vge, "drops_single"), mean(vge, "resets_single")))
print("MuJoCo %s per setting: speed (rounds) [wall], fingertips on average, drops and episode ends per run, "
      "vge / MuJoCo:" % mj[0]["mujoco_version"])
summary = []
for (dt, cone, imp, noslip), rs in groups.items():
    s = dict(hz=1 / dt, cone=cone, impratio=imp, noslip=noslip, speed=med(rs), tips=mean(rs, "mean_tip_contacts"),
             drops=mean(rs, "drops_single"), ends=mean(rs, "resets_single"))
    s["holds"] = s["tips"] >= tips - 1
    summary.append(s)
    print("  %3.0f Hz %-9s impratio %-3g noslip %d: %6.1f (%s) [%.1f]  fingertips %.2f  drops %4.1f  ends %4.1f  x%.2f%s"
          % (s["hz"], cone, imp, noslip, s["speed"], each(rs), med(rs, "sim_seconds_per_s"), s["tips"], s["drops"],
             s["ends"], v / s["speed"], "" if s["holds"] else "  (does not hold the grasp)"))
name = lambda s: "%.0f Hz, %s cones, impratio %g, noslip %d" % (s["hz"], s["cone"], s["impratio"], s["noslip"])
holding = [s for s in summary if s["holds"]]
if not holding:
    print("NOT COMPARABLE: no MuJoCo setting keeps the cube in the grasp (more than one fingertip off it "
          "on average), so MuJoCo steps a lighter workload than vge; the ratios are for reference only")
    sys.exit(2)
fastest = max(holding, key=lambda s: s["speed"])
best = min(holding, key=lambda s: (s["drops"], -s["speed"]))
print("ratio vge / MuJoCo against the fastest setting that holds the grasp (%s): %.2f" % (name(fastest), v / fastest["speed"]))
print("ratio vge / MuJoCo against the setting that holds it best (%s): %.2f" % (name(best), v / best["speed"]))
EOF

#!/usr/bin/env bash
# Screens a training run's snapshots for the one to ship: each snapshot whose periodic test
# passed (success >= MIN_SUCCESS in RUN_DIR/eval.csv), and the final policy, runs the success
# test (`vge eval`) and the robustness test on the pushes only (`vge robustness --axes
# perturbation_magnitude_n,perturbation_force_n --levels 2`), all on episodes the run was
# never tested on (seed SEED):
#
#   scripts/screen-snapshots.sh RUN_DIR [SEED] [EPISODES] [MIN_SUCCESS]
#
# Defaults: SEED 11000, EPISODES 20 per test, MIN_SUCCESS 0.8. Writes RUN_DIR/screen.csv,
# one row per policy: step, success, drops, rotation_rad, and for each push (the cube's
# weight in size; the weight as each component's std) the return as a fraction of the clean
# return and the success under it. The sensor-noise axes are left out: every robust-config
# gait so far holds them (docs/results/README.md); ship-policy.sh measures all five.
# VGE_BIN chooses the vge binary (default target/release/vge). About 20 s per policy at
# 20 episodes on 2 cores.
set -euo pipefail
if [[ ${1:-} == -h || ${1:-} == --help ]]; then
  sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'
  exit 0
fi
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
[[ $# -ge 1 && $# -le 4 ]] || { echo "usage: $0 RUN_DIR [SEED] [EPISODES] [MIN_SUCCESS]" >&2; exit 2; }
run=$1
seed=${2:-11000}
episodes=${3:-20}
min_success=${4:-0.8}
vge=${VGE_BIN:-$repo/target/release/vge}
[[ -f $run/eval.csv ]] || { echo "$run/eval.csv is missing: no periodic tests to screen" >&2; exit 1; }
[[ -x $vge ]] || { echo "$vge is not an executable vge (build it, or set VGE_BIN)" >&2; exit 1; }
# Which policies: the passing snapshots present, then the final policy if the run finished.
mapfile -t policies < <(python3 - "$run" "$min_success" <<'PY'
import csv, filecmp, os, sys
run, min_success = sys.argv[1], float(sys.argv[2])
listed = []
with open(os.path.join(run, "eval.csv")) as f:
    for row in csv.DictReader(f):
        path = os.path.join(run, "snapshots", f"policy-{row['step']}.vgep")
        if float(row["success"]) >= min_success and os.path.exists(path):
            print(f"{row['step']} {path}")
            listed.append(path)
final = os.path.join(run, "policy.vgep")
# The final policy is often the last snapshot itself: screen it once.
if os.path.exists(final) and not any(filecmp.cmp(final, p, shallow=False) for p in listed):
    print(f"final {final}")
PY
)
[[ ${#policies[@]} -gt 0 ]] || { echo "no snapshot in $run passed (success >= $min_success)" >&2; exit 1; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
out=$run/screen.csv
echo "step,success,drops,rotation_rad,push_magnitude_return_fraction,push_magnitude_success,push_std_return_fraction,push_std_success" >"$out.part"
for entry in "${policies[@]}"; do
  step=${entry%% *}
  policy=${entry#* }
  echo "==> $step ($policy)" >&2
  "$vge" eval --policy "$policy" --episodes "$episodes" --seed "$seed" --json >"$tmp/eval.json"
  "$vge" robustness --policy "$policy" --episodes "$episodes" --levels 2 --seed "$seed" \
    --axes perturbation_magnitude_n,perturbation_force_n --out "$tmp/rob" >/dev/null 2>&1
  python3 - "$step" "$tmp/eval.json" "$tmp/rob/robustness.json" <<'PY' | tee -a "$out.part"
import json, sys
step, eval_path, rob_path = sys.argv[1:]
e = json.load(open(eval_path))
full = {r["axis"]: r for r in json.load(open(rob_path))["rows"] if r["fraction_of_max"] == 1.0}
m, s = full["perturbation_magnitude_n"], full["perturbation_force_n"]
# A clean return at or below zero has no fraction (null in robustness.json).
frac = lambda r: "nan" if r["return_fraction"] is None else f"{r['return_fraction']:.2f}"
print(f"{step},{e['success_rate']:.2f},{e['drop_rate']:.2f},{e['mean_rotation_rad']:.1f},"
      f"{frac(m)},{m['success_rate']:.2f},{frac(s)},{s['success_rate']:.2f}")
PY
done
mv "$out.part" "$out"
echo "wrote $out" >&2

#!/usr/bin/env bash
# Ships a policy of a finished training run (its final one unless told) as the gait that
# comes with vge, measured:
#
#   scripts/ship-policy.sh RUN_DIR [NAME] [POLICY]   # NAME: cube (default)
#
# POLICY is the run's policy file to ship, relative to RUN_DIR: policy.vgep (the final one,
# default), policy-best.vgep (the snapshot the run's selection picked on its validation
# grasps) or snapshots/policy-STEP.vgep; its training step is in its provenance line.
# Copies it and RUN_DIR/config.toml to policies/NAME.vgep and NAME.toml,
# then measures the copy with the success test (`vge eval`: 20 randomised 30 s episodes) and
# the robustness test (`vge robustness`: 10 episodes per level, 5 levels per axis up to the
# paper's), and writes both, the run it came from and the issue's goals with whether each
# holds (the push at the object's weight read as the paper's, a force of its size; the
# per-component Gaussian beside them), to policies/NAME.json (the robustness figure to
# policies/NAME-robustness.png).
# VGE_BIN chooses the vge binary (default target/release/vge). About 5 min on 2 cores.
set -euo pipefail
if [[ ${1:-} == -h || ${1:-} == --help ]]; then
  sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'
  exit 0
fi
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
[[ $# -ge 1 && $# -le 3 ]] || { echo "usage: $0 RUN_DIR [NAME] [POLICY]" >&2; exit 2; }
run=$(cd "$1" && pwd)
name=${2:-cube}
policy=${3:-policy.vgep}
vge=${VGE_BIN:-$repo/target/release/vge}
for f in "$policy" config.toml final-eval.json; do
  [[ -f $run/$f ]] || { echo "$run/$f is missing: not a finished training run" >&2; exit 1; }
done
cd "$repo"
mkdir -p policies
cp "$run/$policy" "policies/$name.vgep"
cp "$run/config.toml" "policies/$name.toml"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
echo "==> the success test of policies/$name.vgep"
"$vge" eval --policy "policies/$name.vgep" --json >"$tmp/eval.json"
echo "==> the robustness test"
"$vge" robustness --policy "policies/$name.vgep" --out "$tmp/robustness"
cp "$tmp/robustness/robustness.png" "policies/$name-robustness.png"
provenance=$("$vge" inspect "policies/$name.vgep" | sed -n 's/^provenance: *//p')
python3 - "$run" "$policy" "$provenance" "$tmp/eval.json" "$tmp/robustness/robustness.json" "policies/$name.json" <<'PY'
import json, os, sys
run, policy, provenance, eval_path, robustness_path, out = sys.argv[1:]
success = json.load(open(eval_path))
robustness = json.load(open(robustness_path))
# Issue 12's goals: success >= 80% of 20 randomised 30 s episodes, and >= 75% of the clean
# return at each axis's paper level (the last level of each axis), "perturbation at the
# object's full weight included": a force of the weight's size (perturbation_magnitude_n),
# the paper's "perturbation forces equivalent to the full weight of the object". The
# Gaussian with the weight as each component's std (perturbation_force_n) averages 1.6
# times the weight; it is measured and reported beside the goals, not as one of them.
at_paper_level = {}
for row in robustness["rows"]:
    if row["fraction_of_max"] == 1.0:
        at_paper_level[row["axis"]] = row["return_fraction"]
held = lambda fraction: fraction is not None and fraction >= 0.75
goals = {"success_rate >= 0.8": success["success_rate"] >= 0.8}
beside_goals = {}
for axis, fraction in at_paper_level.items():
    key = f"{axis}: return at the paper's level >= 0.75 of clean"
    (beside_goals if axis == "perturbation_force_n" else goals)[key] = held(fraction)
doc = {
    "source_run": os.path.relpath(run),
    "source_policy": policy,
    "provenance": provenance,
    "success_test": success,
    "robustness": robustness,
    "return_fraction_at_paper_level": at_paper_level,
    "goals": goals,
    "beside_goals": beside_goals,
}
json.dump(doc, open(out, "w"), indent=2)
open(out, "a").write("\n")
for goal, ok in goals.items():
    print(f"  {'holds' if ok else 'FAILS'}  {goal}")
for goal, ok in beside_goals.items():
    print(f"  ({'holds' if ok else 'fails'}, beside the goals: 1.6x the weight on average)  {goal}")
PY
echo "wrote policies/$name.vgep, $name.toml, $name.json, $name-robustness.png"

#!/usr/bin/env bash
# The paper's Table I on this machine: every (controller, method) cell of configs/ over seeds,
# then the table and its figures from the run folders (vge plot --table1).
#
#   scripts/table1.sh OUT                # all cells, seeds 0..5 (IGM: 0..3), 2 jobs at once
#   VGE_JOBS=4 VGE_SEEDS=0..10 scripts/table1.sh OUT
#   VGE_CELLS="cube-fg-rl cube-cs-vge" scripts/table1.sh OUT
#   VGE_SET="total_steps=20000 sac.warmup=2000" scripts/table1.sh /tmp/t1   # a smoke test
#
# Each run is 1M env steps (25-50 minutes for one one-thread job beside another on this
# project's 2-core machines: 1,400-2,850 s measured, docs/results/README.md), so the whole
# table (43 runs) is most of a day of compute: run it in the background
# and call it again after an interruption: vge sweep skips finished seeds and resumes
# unfinished ones from their last checkpoint (every 50k steps here). Writes OUT/cube-<c>-<m>/
# seed-N/ and OUT/table1.csv, table1.md, curves-fg.png, curves-cs.png; the controllers alone
# go to OUT/controllers/ first (a minute each).
set -euo pipefail
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
out=${1:?usage: scripts/table1.sh OUT}
jobs=${VGE_JOBS:-2}
seeds=${VGE_SEEDS:-0..5}
cells=${VGE_CELLS:-cube-fg-rl cube-fg-rl-bc cube-fg-fge cube-fg-vge cube-fg-vge-bc cube-cs-fge cube-cs-vge cube-cs-vge-bc cube-igm-vge}
vge=${VGE_BIN:-$repo/target/release/vge}
extra=()
for kv in ${VGE_SET:-}; do extra+=(--set "$kv"); done
if [ ! -x "$vge" ]; then
  (cd "$repo" && scripts/setup-libtorch.sh && cargo build --release -p vge-cli --bin vge)
fi
mkdir -p "$out/controllers"
for kind in fg cs igm; do
  f="$out/controllers/$kind.json"
  [ -s "$f" ] || "$vge" controller --kind "$kind" --episodes 20 --episode-s 30 --json > "$f"
done
for cell in $cells; do
  cell_seeds=$seeds
  # The paper's IGM cell is a side note (3 seeds unless asked otherwise).
  [ "$cell" = cube-igm-vge ] && [ -z "${VGE_SEEDS:-}" ] && cell_seeds=0..3
  echo "==> $cell, seeds $cell_seeds"
  "$vge" sweep --config "$repo/configs/$cell.toml" --seeds "$cell_seeds" --out "$out/$cell" \
    --jobs "$jobs" --threads-per-job 1 --set run.checkpoint_interval=50000 ${extra[@]+"${extra[@]}"}
done
"$vge" plot --table1 "$out" "$out"

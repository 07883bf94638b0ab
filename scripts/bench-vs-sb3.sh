#!/usr/bin/env bash
# scripts/bench-vs-sb3.sh [ROUNDS] [THREADS...]: vge's SAC updates against Stable-Baselines3's,
# timed in one run, at `vge bench update`'s sizes with both learners' hidden widths HIDDEN
# (env, default 256,256: the sizes the stored comparison used; the training default is 128,128).
#
# For each thread count (default: 1 and 2) the rounds alternate vge with its training
# defaults (critic layer norm), vge without layer norm (SB3's networks), vge with bf16
# matmuls (`sac.matmul = "bf16"`, opt-in) and SB3 SAC
# (scripts/bench_sb3.py, torch 2.13.0, the libtorch vge links, from PyPI into .deps/sb3:
# about 5 GB, as PyPI's torch wheel is the CUDA build). Prints the medians and the ratios;
# every round's JSON line is kept in target/bench-vs-sb3.jsonl. Compare only figures from
# one run: the CPU model varies between machines. Stop other work first: a training run on
# the same cores halves every figure.
set -euo pipefail
if [[ ${1:-} == -h || ${1:-} == --help ]]; then
  sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'
  exit 0
fi
cd "$(dirname "$0")/.."
rounds=${1:-3}
[ $# -gt 0 ] && shift
if [ $# -gt 0 ]; then threads=("$@"); else threads=(1 2); fi
[[ $rounds =~ ^[1-9][0-9]*$ ]] || { echo "ROUNDS must be a positive integer, got '$rounds'" >&2; exit 1; }
for t in "${threads[@]}"; do
  [[ $t =~ ^[1-9][0-9]*$ ]] || { echo "THREADS must be positive integers, got '$t'" >&2; exit 1; }
done
venv=.deps/sb3
if ! "$venv/bin/python" -c 'import torch, stable_baselines3; assert torch.__version__.startswith("2.13.0")' 2>/dev/null; then
  echo "installing torch 2.13.0 and stable-baselines3 into $venv (PyPI, about 5 GB)..." >&2
  [ -x "$venv/bin/python" ] || python3 -m venv "$venv"
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check torch==2.13.0 stable-baselines3
fi
scripts/setup-libtorch.sh
# The vge binary: VGE if set (built with the default `train` feature), else built here (into
# CARGO_TARGET_DIR when set).
vge=${VGE:-}
if [ -z "$vge" ]; then
  cargo build --release -p vge-cli --bin vge >&2
  vge=${CARGO_TARGET_DIR:-target}/release/vge
fi
updates=400
hidden=${HIDDEN:-256,256}
out=target/bench-vs-sb3.jsonl
: >"$out"
tag() { python3 -c 'import json,sys; d=json.loads(sys.stdin.read()); d.update(json.loads(sys.argv[1])); print(json.dumps(d))' "$1"; }
for t in "${threads[@]}"; do
  for r in $(seq 1 "$rounds"); do
    echo "threads $t, round $r of $rounds..." >&2
    # libtorch takes its thread count from OMP_NUM_THREADS at start.
    OMP_NUM_THREADS=$t "$vge" bench update --json --hidden "$hidden" --updates $updates |
      tag "{\"bench\": \"vge_update\", \"layer_norm\": true, \"round\": $r}" >>"$out"
    OMP_NUM_THREADS=$t "$vge" bench update --json --hidden "$hidden" --updates $updates --layer-norm false |
      tag "{\"bench\": \"vge_update\", \"layer_norm\": false, \"round\": $r}" >>"$out"
    OMP_NUM_THREADS=$t "$vge" bench update --json --hidden "$hidden" --updates $updates --matmul bf16 |
      tag "{\"bench\": \"vge_update_bf16\", \"layer_norm\": true, \"round\": $r}" >>"$out"
    OMP_NUM_THREADS=$t "$venv/bin/python" scripts/bench_sb3.py "$t" $updates "$hidden" |
      tag "{\"layer_norm\": false, \"round\": $r}" >>"$out"
  done
done
python3 - "$out" <<'EOF'
import json, statistics, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
def pick(bench, threads, ln):
    return [r for r in rows if r["bench"] == bench and r["threads"] == threads and r["layer_norm"] == ln]
for t in sorted({r["threads"] for r in rows}):
    sb3 = pick("sb3_update", t, False)
    ref = statistics.median(r["updates_per_s"] for r in sb3)
    print(f"{t} thread(s), updates/s (rounds), ratio of medians to SB3:")
    for name, rs in [("vge, layer norm (training default)", pick("vge_update", t, True)),
                     ("vge, no layer norm (SB3's networks)", pick("vge_update", t, False)),
                     ("vge, layer norm, sac.matmul = bf16", pick("vge_update_bf16", t, True)),
                     (f"SB3 {sb3[0]['sb3_version']}, torch {sb3[0]['torch_version']}", sb3)]:
        med = statistics.median(r["updates_per_s"] for r in rs)
        each = ", ".join("%.1f" % r["updates_per_s"] for r in rs)
        print(f"  {name:40s} {med:7.1f}  ({each})  x{med / ref:.2f}")
    for name, bench in [("vge's libtorch", "vge_update"), ("SB3's torch", "sb3_update")]:
        mm = statistics.median(r["matmul_gflops"] for r in rows if r["threads"] == t and r["bench"] == bench)
        print(f"  1024^3 f32 matmul in {name}: {mm:.0f} GFLOP/s (median)")
EOF

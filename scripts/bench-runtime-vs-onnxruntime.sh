#!/usr/bin/env bash
# scripts/bench-runtime-vs-onnxruntime.sh [POLICY] [ROUNDS]: the runtime's batch-1 forward against
# onnxruntime's on the same policy (default policies/cube.vgep), timed in one run.
#
# The runtime twice: its default build (the portable kernel, which firmware runs bit for bit;
# on x86-64 with `std` compiled for AVX-512F when the CPU has it) and with the `simd` feature
# (fused multiply-adds, within `simd_tolerance` of the portable kernel), both timing
# `Policy::forward` (runtime/examples/forward_bench.rs). onnxruntime (.deps/py) runs the
# policy's ONNX export (`vge export --format onnx`: the same normalisation, layers and action
# scaling) from Python with one thread (scripts/bench_onnxruntime.py): per call with
# `run`, with bound input and output, and the floor of a bound call on an Identity graph.
# The runs alternate ROUNDS times (default 3) pinned to one core; every line is kept in
# target/bench-runtime-vs-onnxruntime.jsonl. VGE: a vge binary for the export (else built here).
set -euo pipefail
cd "$(dirname "$0")/.."
policy=${1:-policies/cube.vgep}
rounds=${2:-3}
[[ $rounds =~ ^[1-9][0-9]*$ ]] || { echo "ROUNDS must be a positive integer, got '$rounds'" >&2; exit 1; }
py=.deps/py/bin/python
"$py" -c 'import onnx, onnxruntime' 2>/dev/null || {
  echo "needs onnx and onnxruntime in $py (scripts/test.sh installs them)" >&2
  exit 1
}
target=${CARGO_TARGET_DIR:-target}
vge=${VGE:-}
if [ -z "$vge" ]; then
  cargo build --release -p vge-cli --bin vge --no-default-features >&2
  vge=$target/release/vge
fi
onnx=target/bench-runtime-policy.onnx
mkdir -p target
"$vge" export --policy "$policy" --format onnx --out "$onnx" >&2
# Two builds of the example: the feature changes the library, so each goes to its own copy.
bins=()
for features in std std,simd; do
  cargo build --release -p vge-runtime --features "$features" --example forward_bench >&2
  cp "$target/release/examples/forward_bench" "target/forward_bench-${features/,/-}"
  bins+=("target/forward_bench-${features/,/-}")
done
out=target/bench-runtime-vs-onnxruntime.jsonl
: >"$out"
core=$(($(nproc) - 1))
for r in $(seq 1 "$rounds"); do
  echo "round $r of $rounds..." >&2
  for b in "${bins[@]}"; do taskset -c "$core" "$b" "$policy" >>"$out"; done
  taskset -c "$core" "$py" scripts/bench_onnxruntime.py "$onnx" >>"$out"
done
python3 - "$out" <<'PYEOF'
import json, statistics, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
ort = [r for r in rows if r["bench"] == "onnxruntime"]
med = lambda rs, k: statistics.median(r[k] for r in rs)
each = lambda rs, k: ", ".join("%.2f" % (r[k] / 1000) for r in rs)
bound = med(ort, "iobinding_median_ns")
compute = bound - med(ort, "floor_median_ns")
vge = [r for r in rows if r["bench"] == "vge_runtime"]
print("batch-1 forward of %s, us per call (median of rounds; rounds in brackets):" % (vge[0]["dims"],))
for kernel in dict.fromkeys(r["kernel"] for r in vge):
    rs = [r for r in vge if r["kernel"] == kernel]
    m = med(rs, "median_ns")
    print("  vge runtime, %-16s %6.2f  (%s)  onnxruntime bound / vge %.2f, (bound - floor) / vge %.2f"
          % (kernel, m / 1000, each(rs, "median_ns"), bound / m, compute / m))
print("  onnxruntime %s, run          %6.2f  (%s)" % (ort[0]["onnxruntime_version"], med(ort, "run_median_ns") / 1000, each(ort, "run_median_ns")))
print("  onnxruntime, bound in and out    %6.2f  (%s)" % (bound / 1000, each(ort, "iobinding_median_ns")))
print("  onnxruntime, floor (Identity)    %6.2f  (%s); bound - floor %.2f" % (med(ort, "floor_median_ns") / 1000, each(ort, "floor_median_ns"), compute / 1000))
PYEOF

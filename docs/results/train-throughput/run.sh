#!/usr/bin/env bash
# One measurement: run.sh NAME BIN CONFIG [--set ...]; prints the 10k-20k window's env steps/s.
set -euo pipefail
name=$1; bin=$2; config=$3; shift 3
out=/root/sb/out/$name; rm -rf "$out"
"$bin" train --config "$config" --out "$out" --set total_steps=20000 --set sac.warmup=1000 \
  --set run.eval_interval=1000000 --set run.eval_episodes=1 --set run.checkpoint_interval=1000000 \
  --set run.save_replay=false --set run.log_interval=10000 "$@" > "$out.log" 2>&1
python3 - "$out/metrics.csv" "$name" <<'PY'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
r = {int(float(x["step"])): float(x["steps_per_s"]) for x in rows}
t10, t20 = 10000 / r[10000], 20000 / r[20000]
print(f"{sys.argv[2]}: window 10k-20k {10000 / (t20 - t10):.1f} env steps/s, updates {rows[-1]['updates']}")
PY

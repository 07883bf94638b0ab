#!/usr/bin/env bash
# ema-check.sh RUN_DIR...: final actor vs TD3 target actor (Polyak average) of finished runs,
# on the run's own validation episodes (its final test) and on 20 fresh ones (seed 5000). One CSV line per run.
vge=/root/vge-bin/vge
ev() { nice -n 10 $vge eval --policy $1 --seed $2 --json 2>/dev/null | python3 -c "import json,sys;d=json.load(sys.stdin);print(f\"{d['success_rate']:.2f},{d['drop_rate']:.2f},{d['mean_rotation_rad']:.1f}\")"; }
for r in "$@"; do
  seed=$(grep '^seed' $r/config.toml | head -1 | awk '{print $3}')
  test_seed=$(( seed * 1000003 + 0xe7a1 ))
  $vge export --actor $r/checkpoint/actor.ot --out /tmp/ema-a.vgep >/dev/null 2>&1 || { echo "$r,export failed"; continue; }
  $vge export --actor $r/checkpoint/target_actor.ot --out /tmp/ema-t.vgep >/dev/null 2>&1 || { echo "$r,export failed"; continue; }
  stored=$(python3 -c "import json;d=json.load(open('$r/final-eval.json'));print(f\"{d['success_rate']:.2f}\")")
  echo "$r,$stored,$(ev /tmp/ema-a.vgep $test_seed),$(ev /tmp/ema-t.vgep $test_seed),$(ev /tmp/ema-a.vgep 5000),$(ev /tmp/ema-t.vgep 5000)"
done

#!/usr/bin/env bash
# The controllers alone (IGM, CS, FG) on every task variant: 20 episodes each, seed 0, in the
# variant config's env as the success test runs it (vge controller --config). Writes
# controllers.csv and controllers.md beside this script; the reference row is the base
# config, configs/cube-fg-rl.toml.
# Usage: docs/results/variants/controllers.sh [path/to/vge]
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../../.." && pwd)"
vge="${1:-$root/target/release/vge}"
csv="$here/controllers.csv"
echo "variant,controller,episodes,success_rate,drops,drop_rate,mean_rotation_rad,mean_return,mean_contacts,mean_steps" > "$csv"
for variant in base heavy-cube low-friction torque-2x side-on fixed-start-paper-reward sac-alpha0; do
    if [ "$variant" = base ]; then config="$root/configs/cube-fg-rl.toml"; else config="$root/configs/variants/$variant.toml"; fi
    for kind in igm cs fg; do
        line="$("$vge" controller --kind "$kind" --object cube --episodes 20 --seed 0 --config "$config" --json)"
        python3 - "$variant" "$kind" "$line" >> "$csv" <<'PY'
import json, sys
variant, kind, line = sys.argv[1], sys.argv[2], sys.argv[3]
s = json.loads(line)
n = s["episodes"]
print(f'{variant},{kind},{n},{s["success_rate"]:.2f},{s["drops"]},{s["drops"] / n:.2f},'
      f'{s["mean_rotation_rad"]:.2f},{s["mean_return"]:.2f},{s["mean_contacts"]:.2f},{s["mean_steps"]:.0f}')
PY
        tail -1 "$csv"
    done
done

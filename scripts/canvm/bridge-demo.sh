#!/usr/bin/env bash
# The deployment path on a real CAN bus: run inside scripts/canvm/run.sh (vcan0 up).
#
#   scripts/canvm/run.sh scripts/canvm/bridge-demo.sh BRIDGE POLICY DURATION_S [SEED]
#
# `vge-bridge emulate` puts the hand's five finger nodes on vcan0, their joints driven by the
# simulated hand holding the cube (docs/can-protocol.md); `vge-bridge run --backend can`
# runs POLICY on the no_std runtime at its control rate against them for DURATION_S. Prints
# the bridge's report (rate, jitter, frames) and what the emulated hand did with the cube
# (rotation about z, contact switches, whether it dropped).
set -euo pipefail
[[ $# -ge 3 ]] || { echo "usage: $0 BRIDGE POLICY DURATION_S [SEED]" >&2; exit 2; }
bridge=$1 policy=$2 duration=$3 seed=${4:-0}
iface=${VGE_HIL_IFACE:-vcan0}
log=$(mktemp -d)
trap 'rm -rf "$log"' EXIT
"$bridge" emulate --iface "$iface" --model sim --json --seed "$seed" --idle-timeout-s 2 \
  >"$log/emulator.json" 2>"$log/emulator.err" &
emulator=$!
sleep 0.5 # the emulator grasps the cube (sim reset) before the first command
# A safety halt exits non-zero (its stop reason's status: docs/can-protocol.md): report what the
# hand did all the same, then pass the status on.
bridge_status=0
"$bridge" run --policy "$policy" --backend can --iface "$iface" --duration "$duration" || bridge_status=$?
if ! wait "$emulator"; then
  cat "$log/emulator.err" >&2
  exit 1
fi
field() { sed -E "s/.*\"$1\":([^,}]*).*/\1/" "$log/emulator.json"; }
rotation=$(field rotation_rad)
printf 'emulated hand on %s: the cube turned %s rad about z (%s turns), %s contact switches, dropped: %s, %s sim steps, %s bad frames\n' \
  "$iface" "$rotation" "$(awk -v r="$rotation" 'BEGIN { printf "%.2f", r / 6.283185 }')" \
  "$(field contact_switches)" "$(field terminated)" "$(field sim_steps)" "$(field bad_frames)"
if [[ $bridge_status != 0 ]]; then
  echo "bridge-demo: vge-bridge run ended with status $bridge_status (a safety halt: see its summary above)" >&2
  exit "$bridge_status"
fi

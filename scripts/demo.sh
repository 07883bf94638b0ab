#!/usr/bin/env bash
# vge's main job, end to end, on a fresh machine:
#  1. the gait that ships with vge (policies/cube.vgep) runs on the no_std runtime through
#     vge-bridge against the hand's five joint-controller nodes on a real CAN bus (vcan0;
#     the nodes emulated by the simulated hand holding the cube), at its 20 Hz control rate,
#     printing rate, jitter, frames, and how far the cube turned with how many contact
#     switches;
#  2. a brief VGE + FG training run on the cube from scratch, exported, evaluated on the
#     runtime and run through vge-bridge against the simulated hand;
#  3. the Allegro's gait, once one ships (policies/allegro-cube.vgep): evaluated on the
#     simulated Allegro (vge eval), run through vge-bridge against its simulated env, and
#     over the Allegro's own CAN protocol against the emulated Allegro on vcan0 (where a
#     CAN-capable guest or vcan0 is at hand), each printing the cube's turn about z, the
#     contact switches and whether it dropped. Skipped, saying so, while none ships.
#
#   scripts/demo.sh                  # ~2 min of training after the build
#   VGE_DEMO_STEPS=200000 scripts/demo.sh
#   VGE_DEMO_ONLY=allegro scripts/demo.sh      # the Allegro's part alone (builds vge and vge-bridge)
#   VGE_DEMO_ALLEGRO_POLICY=F.vgep ...         # another Allegro policy file for part 3
#
# The brief run does not learn to gait (that takes about a million steps: docs/results/);
# it shows the whole path from training to deployment on real components. The build is the
# test command's (scripts/test.sh): after the tests, the demo starts at once.
set -euo pipefail

# Inside a CAN-capable guest (scripts/canvm/run.sh runs this script again with these
# arguments): the emulated Allegro on vcan0 and vge-bridge driving it with POLICY over the
# Allegro's protocol for DURATION_S; prints the bridge's report and what the emulated hand did
# with the cube.
if [[ ${1:-} == --allegro-over-can ]]; then
  [[ $# -eq 4 ]] || { echo "usage: $0 --allegro-over-can BRIDGE POLICY DURATION_S" >&2; exit 2; }
  bridge=$2 policy=$3 duration=$4
  iface=${VGE_HIL_IFACE:-vcan0}
  log=$(mktemp -d)
  trap 'rm -rf "$log"' EXIT
  "$bridge" emulate --hand allegro --iface "$iface" --json --idle-timeout-s 2 \
    >"$log/emulator.json" 2>"$log/emulator.err" &
  emulator=$!
  sleep 0.5
  bridge_status=0
  # A guest on a loaded host stalls for hundreds of milliseconds (the HIL tests' reason for the
  # same setting): 1000 periods (3 s) without position frames halt it, not the default 10.
  "$bridge" run --hand allegro --backend can --iface "$iface" --policy "$policy" --duration "$duration" \
    --watchdog-periods 1000 || bridge_status=$?
  if ! wait "$emulator"; then
    cat "$log/emulator.err" >&2
    exit 1
  fi
  # The emulator's summary: "hold" is how the cube fared from when the stand went (null if the
  # hand never gripped it).
  hold=$(sed -E 's/.*"hold":(\{[^}]*\}|null).*/\1/' "$log/emulator.json")
  field() { sed -E "s/.*\"$1\":([^,}]*).*/\1/" <<<"$hold"; }
  if [[ $hold == null ]]; then
    echo "emulated Allegro on $iface: the hand never gripped the cube (the stand stayed)"
  else
    printf 'emulated Allegro on %s: the cube turned %s rad about z in %s s of the hand'"'"'s time, %s contact switches, dropped: %s, %s fingertips on it at the end\n' \
      "$iface" "$(field rotation_rad)" "$(field held_s)" "$(field contact_switches)" "$(field dropped)" \
      "$(field tips_touching)"
  fi
  if [[ $bridge_status != 0 ]]; then
    echo "demo: vge-bridge run ended with status $bridge_status (a safety halt: see its summary above)" >&2
    exit "$bridge_status"
  fi
  exit 0
fi

repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
caller_dir=$PWD
cd "$repo"
unset LIBTORCH_USE_PYTORCH LIBTORCH_INCLUDE LIBTORCH_LIB LIBTORCH_BYPASS_VERSION_CHECK

steps=${VGE_DEMO_STEPS:-30000}
out=${VGE_DEMO_OUT:-$repo/runs/demo-$(date +%Y%m%d-%H%M%S)}
# A relative VGE_DEMO_OUT is taken from where the demo was called, like any path argument.
[[ $out == /* ]] || out=$caller_dir/$out
allegro_policy=${VGE_DEMO_ALLEGRO_POLICY:-policies/allegro-cube.vgep}
[[ $allegro_policy == /* || ! -e $caller_dir/$allegro_policy ]] || allegro_policy=$caller_dir/$allegro_policy
only=${VGE_DEMO_ONLY:-}
[[ -z $only || $only == allegro ]] || { echo "demo: VGE_DEMO_ONLY is empty or allegro, not $only" >&2; exit 2; }
target=${CARGO_TARGET_DIR:-$repo/target}

# The Allegro's gait (part 3): on its simulated env, through vge-bridge in process, and over
# its own CAN protocol against the emulated hand on vcan0.
allegro_demo() {
  if [[ ! -f $allegro_policy ]]; then
    echo "==> the Allegro: skipped, no Allegro gait ships yet ($allegro_policy does not exist;"
    echo "    docs/results/allegro/ says where its training stands)"
    return 0
  fi
  echo "==> the Allegro's gait: $allegro_policy"
  "$vge" inspect "$allegro_policy" | head -6
  echo "==> $allegro_policy on the simulated Allegro (vge eval: the success test, 20 episodes of 30 s)"
  "$vge" eval --policy "$allegro_policy"
  echo "==> through vge-bridge against the simulated Allegro's env, 10 s at its control rate"
  local status=0
  "$bridge" run --hand allegro --backend sim --policy "$allegro_policy" --duration 10 || status=$?
  # A safety halt (the object's fate included) is part of what the demo shows, not its failure.
  [[ $status == 0 || $status -ge 10 ]] || return "$status"
  echo "==> over the Allegro's CAN protocol: the emulated Allegro on vcan0, 20 s"
  if ! scripts/canvm/run.sh --which >/dev/null 2>&1; then
    echo "    skipped: no vcan0 here and no CAN-capable guest (scripts/canvm/run.sh --which)"
    return 0
  fi
  status=0
  scripts/canvm/run.sh "$repo/scripts/demo.sh" --allegro-over-can "$bridge" "$allegro_policy" 20 || status=$?
  [[ $status == 0 || $status -ge 10 ]] || return "$status"
}

if [[ $only == allegro ]]; then
  echo "==> build vge and vge-bridge (release)"
  cargo build --release -p vge-cli -p vge-bridge
  vge=$target/release/vge
  bridge=$target/release/vge-bridge
  allegro_demo
  exit 0
fi

echo "==> system packages (user-mode-linux: a CAN-capable guest where this kernel has no vcan)"
scripts/ensure-packages.sh user-mode-linux kmod iproute2
echo "==> libtorch"
scripts/setup-libtorch.sh
echo "==> build (release, as scripts/test.sh builds it, so one build serves both)"
# The test command compiles the workspace through clippy-driver (its lint pass); the same
# wrapper here reuses that build instead of recompiling every crate of ours.
clippy_driver="$(rustc --print sysroot)/bin/clippy-driver"
if [[ -x $clippy_driver ]]; then
  export RUSTC_WORKSPACE_WRAPPER=$clippy_driver CLIPPY_ARGS="-D__CLIPPY_HACKERY__warnings__CLIPPY_HACKERY__"
fi
cargo test --release --workspace --no-run
vge=$target/release/vge
bridge=$target/release/vge-bridge

echo "==> the gait that ships with vge: policies/cube.vgep (policies/README.md)"
"$vge" inspect policies/cube.vgep | head -5
echo "==> policies/cube.vgep through vge-bridge over CAN: the hand's nodes emulated on vcan0, 30 s at 20 Hz"
scripts/canvm/run.sh scripts/canvm/bridge-demo.sh "$bridge" policies/cube.vgep 30 "${VGE_DEMO_SEED:-0}"

# Two libtorch threads train fastest on an idle machine and stall beside a busy core
# (docs/libtorch.md): `vge bench cores` measures the idle cores and says how many threads fit.
cores=$("$vge" bench cores --json)
echo "==> how busy the cores are (vge bench cores): $cores"
fit=$(sed -n 's/.*"threads_that_fit":\([0-9]*\).*/\1/p' <<<"$cores")
[[ $fit =~ ^[0-9]+$ ]] || { echo "demo: no threads_that_fit in vge bench cores' output: $cores" >&2; exit 1; }
threads=$((fit < 2 ? fit : 2))
echo "==> train: VGE + FG on the cube, $steps env steps, into $out ($threads libtorch thread(s))"
"$vge" train --config configs/cube-fg-vge.toml --out "$out" --steps "$steps" --set sac.threads="$threads" \
  --set sac.warmup=2000 --set run.log_interval=2000 --set run.eval_interval=10000 --set run.eval_episodes=4 --set run.eval_episode_s=10 \
  --set run.checkpoint_interval=10000 --set run.save_replay=false \
  --set run.score_episodes=0  # the held-out score of 100 episodes is for real runs (vge score)
echo "==> the exported policy file"
"$vge" inspect "$out/policy.vgep" | head -8
echo "==> evaluate it on vge-runtime (the success test: 20 episodes of 30 s from randomised grasps)"
"$vge" eval --policy "$out/policy.vgep"
echo "==> run it through vge-bridge against the simulated hand, 10 s at its control rate"
"$bridge" run --policy "$out/policy.vgep" --backend sim --duration 10

allegro_demo

cat <<NEXT

==> done. The brief run's files are in $out:
    config.toml (the resolved config), metrics.csv and eval.csv (training curves),
    policy.vgep (the exported actor), checkpoint/ (resume with \`vge train --resume $out\`).
    The binaries are $vge and $bridge. Next, from any directory:
  - the success test on more episodes:   $vge eval --policy $out/policy.vgep --episodes 100
  - its gait diagram and curves:         $vge eval --policy $out/policy.vgep --plot gait.png
                                         $vge plot $out --out curves.png
  - the shipped gait over CAN (vcan0):   $repo/scripts/canvm/run.sh $repo/scripts/canvm/bridge-demo.sh $bridge $repo/policies/cube.vgep 30
  - train to a gait (about 1M steps):    $vge train --config $repo/configs/cube-fg-vge.toml --out my-run
NEXT

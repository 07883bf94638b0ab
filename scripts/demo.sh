#!/usr/bin/env bash
# vge's main job, end to end, on a fresh machine:
#  1. the gait that ships with vge (policies/cube.vgep) runs on the no_std runtime through
#     vge-bridge against the hand's five joint-controller nodes on a real CAN bus (vcan0;
#     the nodes emulated by the simulated hand holding the cube), at its 20 Hz control rate,
#     printing rate, jitter, frames, and how far the cube turned with how many contact
#     switches;
#  2. a brief VGE + FG training run on the cube from scratch, exported, evaluated on the
#     runtime and run through vge-bridge against the simulated hand.
#
#   scripts/demo.sh                  # ~2 min of training after the build
#   VGE_DEMO_STEPS=200000 scripts/demo.sh
#
# The brief run does not learn to gait (that takes about a million steps: docs/results/);
# it shows the whole path from training to deployment on real components. The build is the
# test command's (scripts/test.sh): after the tests, the demo starts at once.
set -euo pipefail
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
caller_dir=$PWD
cd "$repo"
unset LIBTORCH_USE_PYTORCH LIBTORCH_INCLUDE LIBTORCH_LIB LIBTORCH_BYPASS_VERSION_CHECK

steps=${VGE_DEMO_STEPS:-30000}
out=${VGE_DEMO_OUT:-$repo/runs/demo-$(date +%Y%m%d-%H%M%S)}
# A relative VGE_DEMO_OUT is taken from where the demo was called, like any path argument.
[[ $out == /* ]] || out=$caller_dir/$out

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
vge=$repo/target/release/vge
bridge=$repo/target/release/vge-bridge

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

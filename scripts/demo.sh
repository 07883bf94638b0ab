#!/usr/bin/env bash
# vge's main job, end to end, on a fresh machine: set up libtorch, build, train a VGE + FG
# policy on the cube briefly, export it, evaluate it on the no_std runtime, and run it
# through vge-bridge against the simulated hand at its fixed control rate, printing rate,
# jitter and the object's rotation.
#
#   scripts/demo.sh                  # ~2 min of training after the build
#   VGE_DEMO_STEPS=200000 scripts/demo.sh
#
# A brief run does not learn to gait (that takes millions of steps: see docs/results/);
# it shows the whole path from training to deployment on real components.
set -euo pipefail
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$repo"
unset LIBTORCH_USE_PYTORCH LIBTORCH_INCLUDE LIBTORCH_LIB LIBTORCH_BYPASS_VERSION_CHECK

steps=${VGE_DEMO_STEPS:-30000}
out=${VGE_DEMO_OUT:-runs/demo-$(date +%Y%m%d-%H%M%S)}

echo "==> libtorch"
scripts/setup-libtorch.sh
echo "==> build (release)"
cargo build --release -p vge-trainer -p vge-bridge --bins
vge=target/release/vge
bridge=target/release/vge-bridge

echo "==> train: VGE + FG on the cube, $steps env steps, into $out"
"$vge" train --config configs/cube-fg-vge.toml --out "$out" --steps "$steps" \
  --set sac.warmup=2000 --set run.log_interval=2000 --set run.eval_interval=10000 --set run.eval_episodes=4 --set run.eval_episode_s=10 \
  --set run.checkpoint_interval=10000 --set run.save_replay=false
echo "==> the exported policy file"
"$vge" inspect "$out/policy.vgep" | head -8
echo "==> evaluate it on vge-runtime (the success test: 20 episodes of 30 s from randomised grasps)"
"$vge" eval --policy "$out/policy.vgep"
echo "==> run it through vge-bridge against the simulated hand, 10 s at its control rate"
"$bridge" run --policy "$out/policy.vgep" --backend sim --duration 10

#!/usr/bin/env bash
# The loop of docs/onnx.md, run once: Stable-Baselines3 SAC trained on vge's hand (the `vge`
# Python package), its actor exported as SB3's documentation exports one (torch.onnx.export,
# opset 17), imported with `vge import`, compared with SB3's own actions, scored by `vge eval`
# (the success test's 20 episodes) and driven by `vge-bridge run` on the simulated hand and over
# vcan0 (scripts/canvm/run.sh); then the shipped policy out as ONNX and back in.
#
#   docs/results/onnx-import/run.sh    (from the repository root; needs .deps/sb3 with torch,
#                                       stable-baselines3 and the vge package, .deps/py with onnx
#                                       and onnxruntime, and target/release/{vge,vge-bridge})
#
# Keeps each command and its output in NAME.txt beside this script.
set -euo pipefail
here=docs/results/onnx-import
vge=target/release/vge
bridge=target/release/vge-bridge
py=.deps/py/bin/python
sb3=.deps/sb3/bin/python
check=export/tch/tests/onnx_check.py
run() { # run NAME CMD...: print the command, run it, keep both in $here/NAME.txt
  local name=$1; shift
  echo "\$ $*" | tee "$here/$name.txt"
  "$@" 2>&1 | tee -a "$here/$name.txt"
}

# 1. SB3 SAC on the hand (1,500 env steps, 1,000 updates: far from a gait), the actor out as ONNX.
run 1-sb3-train "$sb3" "$here/sb3_actor.py" --steps 1500 --learning-starts 500 --out "$here"
run 1-onnx-check "$py" "$check" check "$here/sb3_actor.onnx"
# 2. In: SB3's actor outputs its normalised action in [-1, 1]; `hand` scales it to the hand's
#    +-0.05 rad, as SB3's predict() unscales it to the env's action space.
run 2-import "$vge" import --onnx "$here/sb3_actor.onnx" --out "$here/sb3_actor.vgep" --action-scale hand
run 2-inspect "$vge" inspect "$here/sb3_actor.vgep"
# 3. The same actions: SB3's predict(deterministic=True) against vge's runtime (the vge
#    package's Policy) on the imported file, and onnxruntime on the ONNX file.
"$py" "$check" run "$here/sb3_actor.onnx" "$here/sb3_obs.f32" "$here/ort_actions.f32" >/dev/null
run 3-compare "$sb3" -c "
import numpy as np, vge
obs = np.fromfile('$here/sb3_obs.f32', '<f4').reshape(-1, 65)
sb3 = np.fromfile('$here/sb3_actions.f32', '<f4').reshape(-1, 15)
ort = np.fromfile('$here/ort_actions.f32', '<f4').reshape(-1, 15) * np.float32(0.05)
policy = vge.Policy.load('$here/sb3_actor.vgep')
ours = np.stack([policy(o) for o in obs])
print(f'{len(obs)} observations of the trained actor on the hand; actions up to {np.abs(sb3).max():.4f} rad')
print(f'max |vge runtime - SB3 predict| = {np.abs(ours - sb3).max():.3e} rad')
print(f'max |vge runtime - onnxruntime x 0.05| = {np.abs(ours - ort).max():.3e} rad')
"
rm -f "$here/ort_actions.f32"
# 4. The success test and the bridge on the simulated hand, then over vcan0.
run 4-eval "$vge" eval --policy "$here/sb3_actor.vgep" --episodes 20
run 4-bridge-sim "$bridge" run --policy "$here/sb3_actor.vgep" --backend sim --duration 10 || true
run 4-bridge-vcan scripts/canvm/run.sh scripts/canvm/bridge-demo.sh "$bridge" "$here/sb3_actor.vgep" 10 || true
# 5. The shipped gait out as ONNX and back in: the same file, byte for byte.
run 5-export "$vge" export --policy policies/cube.vgep --format onnx --out "$here/cube.onnx"
run 5-onnx-check "$py" "$check" check "$here/cube.onnx"
run 5-import "$vge" import --onnx "$here/cube.onnx" --out "$here/cube-from-onnx.vgep"
run 5-cmp cmp policies/cube.vgep "$here/cube-from-onnx.vgep"
echo "policies/cube.vgep and cube-from-onnx.vgep are byte-identical" | tee -a "$here/5-cmp.txt"
run 5-bridge-vcan scripts/canvm/run.sh scripts/canvm/bridge-demo.sh "$bridge" "$here/cube-from-onnx.vgep" 10 || true
rm -f "$here/cube-from-onnx.vgep" # byte-identical to policies/cube.vgep
# 6. Refused: the actor with an op the runtime lacks, named with its node; nothing written.
"$py" "$check" build "$here/elu_actor.onnx" --variant elu >/dev/null
run 6-refused "$vge" import --onnx "$here/elu_actor.onnx" --out "$here/elu_actor.vgep" --action-scale hand || true
test ! -e "$here/elu_actor.vgep" && echo "no elu_actor.vgep written" | tee -a "$here/6-refused.txt"
rm -f "$here/elu_actor.onnx"

#!/usr/bin/env bash
# vge's whole test suite: the README's test command, and what .ci/run calls.
#
# On first use it installs what it needs (Debian packages, the thumbv7em rustup target,
# libtorch from PyPI wheels); later runs find them in place and go straight to the checks:
#   formatting, clippy (-D warnings), the dependency rules (no libtorch in the bridge or the
#   controllers, no rapier3d in the CAN-only bridge), the no_std runtime built for a Cortex-M4F,
#   the workspace tests in release, the hardware-in-the-loop tests on vcan0, and
#   `vge sweep --slurm` on a one-node Slurm cluster started on localhost.
set -euo pipefail
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$repo"

t0=$SECONDS
step() { printf '\n==> %s  [%ds]\n' "$*" $((SECONDS - t0)); }

# torch-sys treats these as set whatever their value; they would send it to another libtorch.
unset LIBTORCH_USE_PYTORCH LIBTORCH_INCLUDE LIBTORCH_LIB LIBTORCH_BYPASS_VERSION_CHECK

step "system packages"
# user-mode-linux: a CAN-capable guest for HIL tests where this kernel has no vcan.
# kmod/iproute2: insmod and ip inside that guest.
# qemu-system-arm: runs the Cortex-M4F firmware (mps2-an386) in the export tests.
scripts/ensure-packages.sh user-mode-linux kmod iproute2 gcc python3 python3-venv qemu-system-arm

step "python tools (cantools, tensorboard, rerun-sdk, mujoco, rliable, in .deps/py)"
# export/tests/onnx.rs checks exported ONNX files with onnx's checker and runs them (and
# imported actors) in onnxruntime.
# The HIL tests decode captured CAN frames with cantools and docs/vge-hand.dbc; the trainer's
# event files are read back with TensorBoard's own reader, and `--record`'s .rrd files with
# the Rerun SDK of the `rerun` crate's version (sim/tests/rrd_summary.py); MuJoCo steps the
# model `vge bench sim --write-mjcf` writes (sim/tests/mujoco_model.rs). rliable computes the
# aggregates of vge_trainer::stats for comparison (trainer/tests/stats_vs_rliable.rs; its arch 7
# needs pandas < 3).
if ! .deps/py/bin/python -c 'import cantools, tensorboard, rerun, mujoco, rliable.library, onnx, onnxruntime; assert rerun.__version__ == "0.36.3"; assert mujoco.__version__ == "4.0.0"' 2>/dev/null; then
  python3 -m venv .deps/py
  .deps/py/bin/python -m pip install --quiet --disable-pip-version-check cantools tensorboard rerun-sdk==0.36.3 mujoco==4.0.0 rliable "pandas<3" onnx onnxruntime
fi
.deps/py/bin/python -c 'import importlib.metadata, cantools, tensorboard, rerun, mujoco, rliable.library; print("cantools", cantools.__version__, "tensorboard", tensorboard.__version__, "rerun-sdk", rerun.__version__, "mujoco", mujoco.__version__, "rliable", importlib.metadata.version("rliable"))'

step "rust components and targets"
for c in rustfmt clippy; do rustup component list --installed | grep -q "^$c" || rustup component add "$c"; done
rustup target list --installed | grep -qx thumbv7em-none-eabihf || rustup target add thumbv7em-none-eabihf
echo "$(rustc --version); targets: $(rustup target list --installed | tr '\n' ' ')"

step "libtorch (scripts/setup-libtorch.sh)"
scripts/setup-libtorch.sh
echo "LIBTORCH -> $(readlink .deps/libtorch)"

step "cargo fmt --check"
cargo fmt --all --check

step "cargo clippy --workspace --all-targets -- -D warnings"
# --release shares build-script outputs (torch-sys' C++) with the test build below.
cargo clippy --release --workspace --all-targets -- -D warnings

step "dependency rule: vge-controllers and vge-bridge never link libtorch"
for crate in vge-controllers vge-bridge; do
  tree=$(cargo tree -p "$crate" -e normal,build --prefix none)
  if grep -q '^torch-sys ' <<<"$tree"; then
    echo "$crate depends on torch-sys:"; cargo tree -p "$crate" -i torch-sys; exit 1
  fi
  echo "$crate: $(wc -l <<<"$tree") dependency lines, no torch-sys"
done

step "vge-bridge for real hands builds without the simulator (no rapier3d, no rayon, no rerun)"
# Without its `sim` feature the bridge drives hands over CAN only and needs vge-sim's hand
# description alone, not its physics (firmware-bridge/Cargo.toml). This overwrites
# target/release/vge-bridge with the CAN-only binary; the test builds below put the full one back.
can_only=(-p vge-bridge --no-default-features --features std)
tree=$(cargo tree "${can_only[@]}" -e normal --prefix none)
for dep in rapier3d rayon rerun; do
  if grep -q "^$dep " <<<"$tree"; then
    echo "vge-bridge without its sim feature depends on $dep:"; cargo tree "${can_only[@]}" -e normal -i "$dep"; exit 1
  fi
done
cargo clippy --release "${can_only[@]}" --all-targets -- -D warnings
cargo build --release "${can_only[@]}"
ls -l target/release/vge-bridge
# Its command line: hand files, and a clear refusal of the simulator it does not have.
cargo test --release "${can_only[@]}" --test cli

step "no_std builds for thumbv7em-none-eabihf (Cortex-M4F): runtime, CAN protocol"
cargo build --release -p vge-runtime --target thumbv7em-none-eabihf
cargo build --release -p vge-bridge --lib --no-default-features --target thumbv7em-none-eabihf
ls -l target/thumbv7em-none-eabihf/release/libvge_runtime.rlib target/thumbv7em-none-eabihf/release/libvge_bridge.rlib

step "cargo test --workspace (release)"
cargo test --release --workspace

step "HIL runner passes the guest's exit status back"
set +e; scripts/canvm/run.sh /bin/sh -c 'exit 7'; rc=$?; set -e
[[ $rc == 7 ]] || { echo "scripts/canvm/run.sh returned $rc for a program that exited 7"; exit 1; }
echo "exit status 7 came back"

step "hardware-in-the-loop tests on vcan0 (scripts/hil.sh)"
scripts/hil.sh

step "Slurm sweep test (scripts/slurm/test.sh: a one-node cluster on localhost)"
# Installs slurmctld, slurmd, slurm-client and munge when missing, starts a throw-away
# cluster, runs trainer/tests/slurm.rs (vge sweep --slurm, scancel, resume) and stops it.
scripts/slurm/test.sh

step "all checks passed in $((SECONDS - t0)) s"

#!/usr/bin/env bash
# vge's whole test suite: the README's test command, and what .ci/run calls.
#
# On first use it installs what it needs (Debian packages, the thumbv7em rustup target,
# libtorch from PyPI wheels); later runs find them in place and go straight to the checks:
#   formatting, the dependency rules (no libtorch in the bridge or the controllers, no
#   rapier3d in the CAN-only bridge), the no_std runtime built for a Cortex-M4F, the
#   workspace tests in release with clippy (-D warnings) on every target as it compiles (run
#   by cargo-nextest), the Python package, the hardware-in-the-loop tests on vcan0, and
#   `vge sweep --slurm` on a one-node Slurm cluster started on localhost. It ends with each
#   step's time.
set -euo pipefail
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$repo"

t0=$SECONDS
# Build outputs newer than this marker were made by this run (the rapier3d check at the end).
mkdir -p target; started_marker=target/.test-run-started; touch "$started_marker"
# Each step's name and start time; the breakdown is printed at the end, and on failure too.
step_names=() step_starts=()
step() {
  step_names+=("$*") step_starts+=($((SECONDS - t0)))
  printf '\n==> %s  [%ds]\n' "$*" $((SECONDS - t0))
}
breakdown() {
  local rc=$? end=$((SECONDS - t0)) i next
  # A step that failed leaves no background build behind.
  local bg
  for bg in ${hil_run:-} ${slurm_run:-}; do pkill -P "$bg" 2>/dev/null || true; kill "$bg" 2>/dev/null || true; done
  if [[ -n ${py_install:-} ]]; then kill "$py_install" 2>/dev/null || true; fi
  # Only a run that reached the end passed (one ended by a signal may leave $? at 0).
  local verdict="all passed"
  [[ ${finished:-0} == 1 && $rc == 0 ]] || verdict="FAILED (exit $rc) in the last step"
  printf '\n==> step times (s), %s\n' "$verdict"
  for i in "${!step_names[@]}"; do
    next=${step_starts[i + 1]:-$end}
    printf '%6d  %s\n' $((next - step_starts[i])) "${step_names[i]}"
  done
  printf '%6d  total\n' "$end"
  # A build that runs out of disk fails as a linker crash (lld: signal 7, Bus error), not as
  # "no space left": the disk left and the build's size say which it was.
  printf 'disk: %s free under target/, target/ holds %s\n' \
    "$(df -h --output=avail target 2>/dev/null | tail -n 1 | tr -d ' ')" "$(du -sh target 2>/dev/null | cut -f1)"
  # CPU time of this script and everything it ran: a fresh machine's wall time is bounded
  # below by the children's CPU time over its cores.
  printf 'CPU time (user, system) of the shell, then of its children:\n'; times
}
trap breakdown EXIT

# torch-sys treats these as set whatever their value; they would send it to another libtorch.
unset LIBTORCH_USE_PYTORCH LIBTORCH_INCLUDE LIBTORCH_LIB LIBTORCH_BYPASS_VERSION_CHECK

step "system packages"
# user-mode-linux: a CAN-capable guest for HIL tests where this kernel has no vcan.
# kmod/iproute2: insmod and ip inside that guest.
# qemu-system-arm: runs the Cortex-M4F firmware (mps2-an386) in the export tests.
# strace: the run-folder crash tests kill vge and inject ENOSPC at chosen system calls with it.
scripts/ensure-packages.sh user-mode-linux kmod iproute2 gcc python3 python3-venv qemu-system-arm strace

step "python tools (cantools, tensorboard, rerun-sdk, mujoco, rliable, onnx, in .deps/py; a first install in the background)"
# export/tch/tests/onnx.rs checks exported ONNX files with onnx's checker and runs them (and
# imported actors) in onnxruntime.
# The HIL tests decode captured CAN frames with cantools and docs/vge-hand.dbc; the trainer's
# event files are read back with TensorBoard's own reader; `--record`'s recordings are drawn
# into .rrd files by python/vge/recording.py and read back with the Rerun SDK
# (sim/tests/rrd_summary.py); MuJoCo steps the
# model `vge bench sim --write-mjcf` writes (sim/tests/mujoco_model.rs); rliable computes the
# aggregates of vge_lab::stats for comparison (lab/tests/stats_vs_rliable.rs; its arch
# 7 needs pandas < 3).
# A first install downloads about 400 MB: it runs in the background while the Rust steps
# below compile (it mostly waits on the network and the disk), and the workspace tests wait
# for it (python_tools_ready).
py_log=$repo/.deps/py-install.log
if ! .deps/py/bin/python -c 'import cantools, tensorboard, rerun, mujoco, rliable.library, onnx, onnxruntime, maturin, gymnasium, pytest; assert rerun.__version__ == "0.36.3"; assert mujoco.__version__ == "4.0.0"' 2>/dev/null; then
  python3 -m venv .deps/py
  echo "installing in the background (log: $py_log)"
  .deps/py/bin/python -m pip install --quiet --disable-pip-version-check cantools tensorboard rerun-sdk==0.36.3 mujoco==4.0.0 rliable "pandas<3" onnx onnxruntime maturin gymnasium pytest \
    >"$py_log" 2>&1 &
  py_install=$!
fi
python_tools_ready() {
  if [[ -n ${py_install:-} ]]; then
    local waited=$SECONDS
    if ! wait "$py_install"; then cat "$py_log"; echo "pip install into .deps/py failed (log: $py_log)"; exit 1; fi
    py_install=
    echo "python tools installed (waited $((SECONDS - waited)) s for pip)"
  fi
  .deps/py/bin/python -c 'import importlib.metadata, cantools, tensorboard, rerun, mujoco, rliable.library; print("cantools", cantools.__version__, "tensorboard", tensorboard.__version__, "rerun-sdk", rerun.__version__, "mujoco", mujoco.__version__, "rliable", importlib.metadata.version("rliable"))'
}

step "rust components, targets and cargo-nextest"
for c in rustfmt clippy; do rustup component list --installed | grep -q "^$c" || rustup component add "$c"; done
rustup target list --installed | grep -qx thumbv7em-none-eabihf || rustup target add thumbv7em-none-eabihf
echo "$(rustc --version); targets: $(rustup target list --installed | tr '\n' ' ')"
# The workspace's test runner (.config/nextest.toml): tests side by side across binaries.
if ! cargo nextest --version >/dev/null 2>&1; then
  echo "cargo-nextest is missing: installing it from crates.io (cargo install --locked, a few minutes)"
  cargo install --locked cargo-nextest
fi
cargo nextest --version | head -1

step "libtorch (scripts/setup-libtorch.sh)"
scripts/setup-libtorch.sh
echo "LIBTORCH -> $(readlink .deps/libtorch)"

step "cargo fmt --check"
cargo fmt --all --check

# Clippy lints (-D warnings) every workspace crate while it is compiled for the tests, instead
# of in a separate `cargo clippy` pass that would compile everything a second time: this is
# what `cargo clippy` itself does (clippy-driver as the workspace's rustc wrapper), with the
# test build as the compile. Dependencies are built once, by plain rustc. Exported so that
# scripts/hil.sh reuses the same build.
RUSTC_WORKSPACE_WRAPPER="$(rustc --print sysroot)/bin/clippy-driver"
export RUSTC_WORKSPACE_WRAPPER CLIPPY_ARGS="-D__CLIPPY_HACKERY__warnings__CLIPPY_HACKERY__"
[[ -x $RUSTC_WORKSPACE_WRAPPER ]] || { echo "clippy-driver not found at $RUSTC_WORKSPACE_WRAPPER"; exit 1; }

# The Python package's build script (pyo3) asks this interpreter for its configuration.
export PYO3_PYTHON=$repo/.deps/py/bin/python

step "dependency rules: only the learner links libtorch (vge-export, vge-run, vge-lab, vge-controllers, vge-bridge, the Python package and vge without training never do); the learner builds no plots, statistics or Slurm code"
# `vge-cli --no-default-features`: the vge command without its `train` feature (eval, score,
# compare, plot, inspect, import, controller, ...).
for crate in vge-export vge-run vge-lab vge-controllers vge-bridge "vge-cli --no-default-features" vge-python vge-python-reference; do
  # shellcheck disable=SC2086
  tree=$(cargo tree -p $crate -e normal,build --prefix none)
  if grep -q '^torch-sys ' <<<"$tree"; then
    # shellcheck disable=SC2086
    echo "$crate depends on torch-sys:"; cargo tree -p $crate -i torch-sys; exit 1
  fi
  echo "$crate: $(wc -l <<<"$tree") dependency lines, no torch-sys"
done
# The learner uses runs (vge-run: config, run folder, success test, scores), not the tooling
# above them: no plots, statistics, sweeps or Slurm (vge-lab) in what it compiles.
tree=$(cargo tree -p vge-trainer -e normal,build --prefix none)
for dep in vge-lab plotters; do
  if grep -q "^$dep " <<<"$tree"; then
    echo "vge-trainer depends on $dep:"; cargo tree -p vge-trainer -e normal,build -i "$dep"; exit 1
  fi
done
echo "vge-trainer: $(wc -l <<<"$tree") dependency lines, no vge-lab, no plotters"
# ...and that it builds, linted through the clippy wrapper. Everything it compiles but the vge
# binary is what the test build below uses as it is: every crate under vge-cli has one
# configuration (libtorch's half of policy export is vge-export-tch, not a feature of
# vge-export) and vge-workspace-hack gives every dependency the same features. The test
# build's vge binary then replaces this one.
cargo build --release -p vge-cli --no-default-features

step "vge-bridge for real hands builds without the simulator (no rapier3d, no rayon)"
# Without its `sim` feature the bridge drives hands over CAN only and needs vge-sim's hand
# description alone, not its physics (firmware-bridge/Cargo.toml). This overwrites
# target/release/vge-bridge with the CAN-only binary; the test builds below put the full one back.
can_only=(-p vge-bridge --no-default-features --features std)
tree=$(cargo tree "${can_only[@]}" -e normal --prefix none)
for dep in rapier3d rayon; do
  if grep -q "^$dep " <<<"$tree"; then
    echo "vge-bridge without its sim feature depends on $dep:"; cargo tree "${can_only[@]}" -e normal -i "$dep"; exit 1
  fi
done
# Every target built (and linted, through the wrapper above); the binary is the CAN-only one.
# Its dependencies are builds the workspace's tests reuse (vge-workspace-hack).
cargo test --release "${can_only[@]}" --no-run
ls -l target/release/vge-bridge
# Its command line: hand files, and a clear refusal of the simulator it does not have.
cargo test --release "${can_only[@]}" --test integration cli::

step "no_std builds for thumbv7em-none-eabihf (Cortex-M4F): runtime, CAN protocol"
cargo build --release -p vge-runtime --target thumbv7em-none-eabihf
cargo build --release -p vge-bridge --lib --no-default-features --target thumbv7em-none-eabihf
ls -l target/thumbv7em-none-eabihf/release/libvge_runtime.rlib target/thumbv7em-none-eabihf/release/libvge_bridge.rlib

step "the runtime's opt-in fused multiply-add kernel (feature simd) against the portable one"
# The workspace build leaves `simd` off (the portable kernel is the default and bit-exact with
# the firmware's), so its tests run here, in a build of the runtime alone.
cargo test --release -p vge-runtime --features simd,std

step "workspace tests (release, cargo nextest; clippy -D warnings on every target as it builds)"
# --no-run first builds (and lints) every target, examples included, as `cargo clippy
# --workspace --all-targets` would: the workspace has no benches.
cargo test --release --workspace --no-run
python_tools_ready
# The HIL tests (scripts/hil.sh: a guest, a test at a time) run in the background from here,
# beside the workspace's tests and the Python package's; their step below waits for them.
set +e; scripts/canvm/run.sh /bin/sh -c 'exit 7'; rc=$?; set -e
[[ $rc == 7 ]] || { echo "scripts/canvm/run.sh returned $rc for a program that exited 7"; exit 1; }
echo "HIL runner: exit status 7 came back"
hil_log=$repo/target/hil.log
scripts/hil.sh >"$hil_log" 2>&1 &
hil_run=$!
# nextest runs every test in a process of its own, two at a time on two cores, the longest
# first (.config/nextest.toml); `cargo test` ran one binary after another and left a core
# idle through each long single-threaded test. Doctests are cargo test's alone.
# One libtorch thread per test unless a test sets its own: with libtorch's default (a thread
# per core) two tests side by side put four spinning OpenMP threads on two cores, and a test's
# updates took 42 s instead of 4-5 s (docs/testing.md).
OMP_NUM_THREADS=1 cargo nextest run --release --workspace
cargo test --release --workspace --doc

# The Slurm test (step below) runs beside the Python step: each is mostly one process at a
# time, and they share no build directory.
slurm_log=$repo/target/slurm-test.log
scripts/slurm/test.sh >"$slurm_log" 2>&1 &
slurm_run=$!

step "Python package (python/: pyo3 + numpy, built by maturin; pytest python/tests)"
# The reference binary the tests compare the package with; then the package, built by pip
# through maturin in the workspace's target dir (reusing the workspace's dependency builds;
# linted, as the environment's clippy wrapper reaches maturin's cargo) and installed into
# .deps/py.
cargo build --release -p vge-python-reference
PATH="$repo/.deps/py/bin:$PATH" .deps/py/bin/python -m pip install --quiet --disable-pip-version-check \
  --no-build-isolation --no-deps --force-reinstall ./python
ls -l target/wheels/
.deps/py/bin/python -m pytest -q python/tests
# Every build above shares one build of the simulator's physics: a second rapier3d means that
# some build's dependency features differ from the others' (a dependency added without
# `cargo hakari generate`), which costs minutes on a fresh machine.
# One build of each library on the host: a second build of one means that two builds of this
# run resolved different features (the dependency rules' `vge` without training, the CAN-only
# bridge, the workspace's tests, maturin's). vge-sim (without physics for the CAN-only
# bridge), vge-runtime (its simd kernel) and vge-bridge (CAN-only) are built twice on purpose.
# A package's library fingerprint is `<package>-<hash>/lib-<crate>`, the crate its name with `_`.
for pkg in rapier3d vge-export vge-export-tch vge-hand vge-controllers vge-config-file vge-run vge-lab vge-trainer; do
  builds=$(find target/release/.fingerprint -maxdepth 2 -path "*/$pkg-*/lib-${pkg//-/_}" -newer "$started_marker" | wc -l)
  echo "$pkg compiled $builds time(s) in this run"
  if ((builds > 1)); then
    echo "$pkg was compiled $builds times: the builds' features differ; regenerate workspace-hack/ (cargo hakari generate; docs/testing.md, \"One build of each dependency\")"
    exit 1
  fi
done

step "Slurm sweep test (scripts/slurm/test.sh: a one-node cluster on localhost; running since the Python step began)"
# Installs slurmctld, slurmd, slurm-client and munge when missing, starts a throw-away
# cluster, runs cli/tests/slurm.rs (vge sweep --slurm, scancel, resume) and stops it.
slurm_status=0; wait "$slurm_run" || slurm_status=$?
slurm_run=
cat "$slurm_log"
[[ $slurm_status == 0 ]] || { echo "the Slurm test failed (log: $slurm_log)"; exit 1; }

step "hardware-in-the-loop tests on vcan0 (scripts/hil.sh, running since the workspace tests began)"
waited=$SECONDS
hil_status=0; wait "$hil_run" || hil_status=$?
hil_run=
cat "$hil_log"
echo "(waited $((SECONDS - waited)) s for the HIL tests)"
[[ $hil_status == 0 ]] || { echo "the HIL tests failed (log: $hil_log)"; exit 1; }

finished=1

#!/usr/bin/env bash
# Build and run vge's hardware-in-the-loop tests (crate vge-tests, test target `hil`) on a real
# SocketCAN interface, vcan0. Where this kernel can create vcan0 the tests run directly;
# where it has no CAN (WSL2, many containers and CI runners) scripts/canvm/run.sh boots a
# user-mode-linux (or QEMU) guest with vcan0 up and runs the test binary inside it, passing
# its exit status back. Extra arguments go to the test binary (e.g. a test name filter).
set -euo pipefail
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$repo"
export CARGO_TARGET_X86_64_UNKNOWN_LINUX_GNU_RUNNER="$repo/scripts/canvm/run.sh"
# The DBC test decodes frames with cantools: scripts/test.sh puts it in .deps/py.
if [[ -z ${VGE_PYTHON:-} && -x $repo/.deps/py/bin/python ]]; then export VGE_PYTHON=$repo/.deps/py/bin/python; fi
# --workspace (not -p) keeps feature unification identical to the main test build: no rebuild.
# The HIL tests run the vge and vge-bridge binaries as separate processes on vcan0. Building
# them as `cargo test` does (with dev-dependency features) reuses the test build; a plain
# `cargo build --bins` resolves features differently and recompiles half the workspace.
cargo test --release --workspace --no-run
# One test at a time: they share the bus, and each checks what it sees on it.
exec cargo test --release --workspace --test hil -- --ignored --test-threads=1 "$@"

#!/usr/bin/env bash
# Build and run vge's hardware-in-the-loop tests (crate vge-tests, test target `hil`: vge's own
# protocol; crate vge-bridge, test target `allegro_hil`: the Allegro Hand's) on a real SocketCAN
# interface, vcan0. Where this kernel can create vcan0 the tests run directly;
# where it has no CAN (WSL2, many containers and CI runners) scripts/canvm/run.sh boots a
# guest with vcan0 up (QEMU under KVM where hardware KVM works, else user-mode-linux) and runs
# the test binary inside it, passing its exit status back. Prints which backend ran and how
# long the step took. Extra arguments go to the test binary (e.g. a test name filter).
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
start=$SECONDS
backend=$(scripts/canvm/run.sh --which)
echo "hil: CAN backend: $backend (scripts/canvm/run.sh)"
# The test binaries' paths from cargo (vge-tests' `hil`, vge-bridge's `allegro_hil`), then
# each binary run by the runner directly, as `cargo test` would (from its crate's folder):
# cargo would hold the build directory's lock for as long as the guest runs, and
# scripts/test.sh runs the other tests meanwhile.
targets=$(cargo test --release --workspace --test hil --test allegro_hil --no-run --message-format=json |
  python3 -c 'import json, sys
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m["target"]["name"] in ("hil", "allegro_hil") and m.get("executable"):
        print(m["target"]["name"], m["executable"], m["manifest_path"].rsplit("/", 1)[0])')
for name in hil allegro_hil; do
  grep -q "^$name " <<<"$targets" || { echo "hil: cargo named no test binary for the $name target"; exit 1; }
done
# One test at a time: they share the bus, and each checks what it sees on it. --nocapture:
# the tests print the timing figures they measure (rate, jitter, misses), which they do not
# assert (they depend on the host the guest runs on). One guest per test binary; the runner's
# stdin is not the list being read.
status=0
while read -r name bin dir; do
  echo "hil: $name"
  (cd "$dir" && "$CARGO_TARGET_X86_64_UNKNOWN_LINUX_GNU_RUNNER" "$bin" --ignored --test-threads=1 --nocapture "$@" </dev/null) || status=$?
done <<<"$targets"
if [[ $status == 0 ]]; then verdict=passed; else verdict="FAILED (status $status)"; fi
echo "hil: $verdict in $((SECONDS - start)) s, CAN backend $backend"
exit "$status"

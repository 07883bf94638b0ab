#!/usr/bin/env bash
# Coverage-guided fuzzing of the no_std policy decoder (fuzz/fuzz_targets/decode_policy.rs)
# without cargo-fuzz: builds the target with the sanitizer-coverage flags cargo-fuzz passes,
# then runs libFuzzer from fuzz/seeds for SECONDS (default 600). Crashes land in
# fuzz/artifacts/. Usage: scripts/fuzz.sh [SECONDS] [extra libFuzzer flags...]
set -euo pipefail
cd "$(dirname "$0")/.."
seconds="${1:-600}"
shift || true
target_dir="${CARGO_TARGET_DIR:-$PWD/fuzz/target}/coverage"
export RUSTFLAGS="-Cpasses=sancov-module -Cllvm-args=-sanitizer-coverage-level=4 \
-Cllvm-args=-sanitizer-coverage-inline-8bit-counters -Cllvm-args=-sanitizer-coverage-pc-table \
-Cllvm-args=-sanitizer-coverage-trace-compares --cfg fuzzing -Cdebug-assertions -Coverflow-checks"
# libfuzzer-sys needs nightly features only for its optional parts; the toolchain cargo-fuzz
# uses is nightly, and this was tested with it.
toolchain=(+nightly)
rustup toolchain list | grep -q '^nightly' || toolchain=()
(cd fuzz && CARGO_TARGET_DIR="$target_dir" cargo "${toolchain[@]}" build --release \
  --target "$(rustc -vV | sed -n 's/^host: //p')" --bin decode_policy)
bin="$(find "$target_dir" -path '*/release/decode_policy' -type f | head -1)"
corpus="fuzz/corpus/decode_policy"
mkdir -p "$corpus" fuzz/artifacts
cp -n fuzz/seeds/* "$corpus/" 2>/dev/null || true
exec "$bin" "$corpus" -max_total_time="$seconds" -max_len=8192 -print_final_stats=1 \
  -artifact_prefix=fuzz/artifacts/ "$@"

#!/usr/bin/env bash
# Run vge's Slurm test (cli/tests/slurm.rs) on a throw-away one-node Slurm cluster on
# localhost: scripts/slurm/start.sh (installs slurm-wlm's daemons and munge when missing),
# the test, scripts/slurm/stop.sh. Fails, with the reason, where Slurm cannot be started.
# Prints the seconds each part took. Extra arguments go to the test binary.
set -euo pipefail
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
cd "$repo"
t0=$SECONDS
dir=$(scripts/slurm/start.sh) || { echo "slurm/test: Slurm could not be started (see above)" >&2; exit 1; }
t_start=$((SECONDS - t0))
trap 'scripts/slurm/stop.sh "$dir"' EXIT
export SLURM_CONF=$dir/slurm.conf
# --workspace keeps feature unification identical to the main test build: no rebuild.
cargo test --release --workspace --test slurm -- --ignored --nocapture "$@"
echo "slurm/test: install + start ${t_start} s, test $((SECONDS - t0 - t_start)) s, total $((SECONDS - t0)) s" >&2

#!/usr/bin/env bash
# Stop the throw-away Slurm cluster that scripts/slurm/start.sh started and remove its
# directory. Stops the daemons by their pid files, never by name (other Slurm daemons on
# this machine are left alone). munged stays up: it is harmless and other users may need it.
#
#   scripts/slurm/stop.sh [DIR]     # DIR: what start.sh printed (default: the last one)
set -uo pipefail
current=${TMPDIR:-/tmp}/vge-slurm.current
d=${1:-$(cat "$current" 2>/dev/null)}
[[ -n $d && -f $d/slurm.conf ]] || { echo "slurm/stop: no cluster directory given or recorded" >&2; exit 1; }
for f in "$d/d.pid" "$d/ctld.pid"; do
  [[ -f $f ]] || continue
  pid=$(cat "$f")
  kill "$pid" 2>/dev/null || continue
  for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
done
[[ $(cat "$current" 2>/dev/null) == "$d" ]] && rm -f "$current"
[[ ${VGE_SLURM_KEEP:-0} == 1 ]] || rm -rf "$d"
echo "slurm/stop: stopped ($d)" >&2

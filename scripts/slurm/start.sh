#!/usr/bin/env bash
# Start a throw-away one-node Slurm cluster on localhost for vge's Slurm test, and print
# its directory (slurm.conf, state, logs) on stdout: `export SLURM_CONF=$dir/slurm.conf`.
#
#   dir=$(scripts/slurm/start.sh) && export SLURM_CONF=$dir/slurm.conf
#   ...
#   scripts/slurm/stop.sh "$dir"
#
# Installs Debian's slurmctld, slurmd, slurm-client and munge when missing (apt-get update
# only when the install needs it). Idempotent: while the cluster it started last is up, it
# prints that one's directory again. Runs the daemons as root without systemd or cgroups
# (proctrack/linuxproc), as /work/shared/notes/slurm-single-node.md describes.
# Exits non-zero with a message on stderr when Slurm cannot be started.
set -euo pipefail
say() { echo "slurm/start: $*" >&2; }
fail() { say "$*"; exit 1; }

current=${TMPDIR:-/tmp}/vge-slurm.current   # the directory of the cluster we started last
sudo=(); [[ $(id -u) == 0 ]] || sudo=(sudo)

install_packages() {
  local packages=(slurmctld slurmd slurm-client munge) missing=() p
  for p in "${packages[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "ok installed" || missing+=("$p")
  done
  ((${#missing[@]})) || return 0
  command -v apt-get >/dev/null || fail "missing ${missing[*]} and no apt-get to install them"
  say "installing ${missing[*]}"
  local t=$SECONDS apt=("${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends)
  # An install from stale or absent package lists fails quickly: update then, not always.
  if ! "${apt[@]}" "${missing[@]}" >/dev/null 2>&1; then
    "${sudo[@]}" apt-get update -qq || fail "apt-get update failed"
    "${apt[@]}" "${missing[@]}" >/dev/null || fail "apt-get install ${missing[*]} failed"
  fi
  say "installed in $((SECONDS - t)) s"
}

cluster_up() {  # $1: directory; true when its daemons run and sinfo answers
  local d=$1 f
  for f in "$d/ctld.pid" "$d/d.pid"; do
    [[ -f $f ]] && kill -0 "$(cat "$f")" 2>/dev/null || return 1
  done
  SLURM_CONF=$d/slurm.conf sinfo -h >/dev/null 2>&1
}

if [[ -f $current ]] && d=$(cat "$current") && cluster_up "$d"; then
  say "already up ($d)"; echo "$d"; exit 0
fi

install_packages
[[ $(id -u) == 0 ]] || fail "the test cluster runs its daemons as root (SlurmUser=root): run as root"

# munge: Slurm's authentication. One key per machine; a running munged is reused.
mkdir -p /etc/munge /run/munge
[[ -f /etc/munge/munge.key ]] || dd if=/dev/urandom bs=1 count=1024 of=/etc/munge/munge.key 2>/dev/null
chown -R munge:munge /etc/munge /run/munge
chmod 400 /etc/munge/munge.key
if ! munge -n 2>/dev/null | unmunge >/dev/null 2>&1; then
  munged --force 2>/dev/null || fail "munged did not start"
  munge -n | unmunge >/dev/null 2>&1 || fail "munge does not work (munge -n | unmunge)"
fi

d=$(mktemp -d "${TMPDIR:-/tmp}/vge-slurm.XXXXXX")
chmod 755 "$d"
mkdir -p "$d/state" "$d/spool" "$d/log"
host=$(hostname -s)
cpus=$(nproc)
# slurmd drains a node that has less memory than the config claims: claim 90 %.
mem_mb=$(awk '/MemTotal/ { printf "%d", $2 / 1024 * 0.9 }' /proc/meminfo)
# KillWait: seconds between SIGTERM and SIGKILL on scancel, preemption or time limit; vge
# needs them to write its checkpoint. DefMemPerCPU: without it a task claims all the
# node's memory and array tasks run one at a time. MinJobAge: finished jobs leave squeue
# after a minute, so that a test's state stays small.
cat > "$d/slurm.conf" <<CONF
ClusterName=vgetest
SlurmctldHost=$host
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation=$d/state
SlurmdSpoolDir=$d/spool
SlurmctldLogFile=$d/log/ctld.log
SlurmdLogFile=$d/log/d.log
SlurmctldPidFile=$d/ctld.pid
SlurmdPidFile=$d/d.pid
SlurmctldPort=${VGE_SLURMCTLD_PORT:-6817}
SlurmdPort=${VGE_SLURMD_PORT:-6818}
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
ReturnToService=2
KillWait=120
DefMemPerCPU=1000
MinJobAge=60
NodeName=$host CPUs=$cpus RealMemory=$mem_mb State=UNKNOWN
PartitionName=debug Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF
export SLURM_CONF=$d/slurm.conf
slurmctld || fail "slurmctld did not start (log: $d/log/ctld.log)"
slurmd || fail "slurmd did not start (log: $d/log/d.log)"
for _ in $(seq 60); do
  if sinfo -h -o '%t' 2>/dev/null | grep -qx idle; then
    echo "$d" > "$current"
    say "up: $(sinfo -h -o '%P %a %D %t %C') (SLURM_CONF=$d/slurm.conf)"
    echo "$d"
    exit 0
  fi
  sleep 0.5
done
fail "the node did not become idle in 30 s: $(sinfo 2>&1 | tail -2); logs in $d/log"

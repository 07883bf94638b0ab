#!/usr/bin/env bash
# Run one program where a virtual CAN interface (vcan0) is up, passing its exit status back.
#
#   scripts/canvm/run.sh PROGRAM [ARGS...]
#   scripts/canvm/run.sh --which      # prints the backend auto picks here: host, qemu-kvm, uml, qemu-tcg
#
# vge's hardware-in-the-loop tests talk SocketCAN on vcan0. Many kernels have no CAN at all
# (this project's CI machines, WSL2's stock kernel, many containers), so this runner picks a
# backend:
#   host  vcan0 already exists, or `ip link add dev vcan0 type vcan` works: run directly.
#   qemu  qemu-system-x86_64 boots Debian's stock kernel with a busybox initramfs and the
#         host's / over virtio-9p, under KVM where hardware KVM (VMX/SVM) is usable: a real
#         kernel on real cores, far fewer stalls than UML. Else TCG (software emulation).
#   uml   Debian's user-mode-linux (kernel 6.1 with CAN modules) boots with the host's / as
#         its root (hostfs), creates vcan0 and runs PROGRAM in place. ~3-4 s per run. Every
#         guest syscall is a ptrace round trip through the host, so a loaded host stalls it.
# VGE_CAN_BACKEND=auto|host|uml|qemu chooses (auto: host, then qemu under KVM if a probe
# boot succeeds here (cached), then uml, then qemu under TCG).
# KVM-PVM (/sys/module/kvm_pvm: software nested virtualisation, as on Firecracker VMs) is not
# hardware KVM: it runs only kernels built as PVM guests, and Debian's stock kernel hangs at
# boot there, so it counts as no KVM.
# The guest gets the caller's environment and working directory; PROGRAM's stdout/stderr
# come out here. Exit status: PROGRAM's; 124 if the guest timed out; 125 if the guest failed
# before PROGRAM reported a status. Used as a cargo runner by scripts/hil.sh.
#
# Knobs: VGE_CAN_IFACES (default "vcan0"), VGE_CANVM_TIMEOUT (s, default 600),
# VGE_CANVM_MEM (MiB, default 1024), VGE_CANVM_VERBOSE=1 (guest console on failure and
# success), VGE_CACHE (default ~/.cache/vge: shim, qemu kernel and initramfs, KVM probe),
# VGE_CANVM_ACCEL=kvm|tcg (qemu's accelerator; default: kvm where hardware KVM is usable).
set -uo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
fail() { echo "canvm: $*" >&2; exit 125; }
note() { echo "canvm: $*" >&2; }

[[ $# -ge 1 ]] || fail "usage: $0 PROGRAM [ARGS...] | --which"
which_only=0
if [[ $1 == --which ]]; then
  which_only=1
else
  prog=$1; shift
  if [[ $prog != */* ]]; then prog=$(command -v -- "$prog") || fail "not found: $prog"; fi
  prog=$(readlink -f -- "$prog")
  [[ -f $prog && -x $prog ]] || fail "not an executable file: $prog"
fi

backend=${VGE_CAN_BACKEND:-auto}
ifaces=${VGE_CAN_IFACES-vcan0}
timeout_s=${VGE_CANVM_TIMEOUT:-600}
mem_mib=${VGE_CANVM_MEM:-1024}
cache=${VGE_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/vge}/canvm
uml_kernel=/usr/bin/linux.uml
can_modules="can can-raw can-bcm can-dev vcan"

# ------------------------------------------------------------------ backend choice
host_has_ifaces() {
  local i
  for i in $ifaces; do
    [[ -e /sys/class/net/$i ]] && continue
    command -v ip >/dev/null || return 1
    ip link add dev "$i" type vcan 2>/dev/null && ip link set up "$i" 2>/dev/null || return 1
  done
}
# Hardware KVM: /dev/kvm writable and kvm_intel or kvm_amd loaded, not KVM-PVM (see above).
hw_kvm() {
  [[ -w /dev/kvm && ! -d /sys/module/kvm_pvm ]] && [[ -d /sys/module/kvm_intel || -d /sys/module/kvm_amd ]]
}
# Whether a qemu guest boots under KVM here: one probe boot running /bin/true, its outcome
# cached per host kernel (a failed probe costs up to a minute once, not every run).
kvm_boots() {
  hw_kvm && command -v qemu-system-x86_64 >/dev/null || return 1
  local mark=$cache/kvm-probe-$(uname -r)
  if [[ ! -f $mark ]]; then
    mkdir -p "$cache" || return 1
    note "probing a qemu guest under KVM (once per host kernel)"
    if VGE_CAN_BACKEND=qemu VGE_CANVM_ACCEL=kvm VGE_CANVM_TIMEOUT=60 "$here/run.sh" /bin/true >/dev/null 2>&1; then
      echo ok > "$mark"
    else
      echo failed > "$mark"
    fi
  fi
  [[ $(cat "$mark") == ok ]]
}
if [[ $backend == auto || $backend == host ]]; then
  if host_has_ifaces; then
    if [[ $which_only == 1 ]]; then echo host; exit 0; fi
    note "backend=host ($ifaces up on this kernel)"
    exec "$prog" "$@"
  fi
  [[ $backend == host ]] && fail "VGE_CAN_BACKEND=host but this kernel cannot create vcan ($ifaces)"
  if kvm_boots; then backend=qemu; export VGE_CANVM_ACCEL=kvm
  elif [[ -x $uml_kernel ]]; then backend=uml
  else backend=qemu
  fi
  [[ $which_only == 1 ]] || note "backend=$backend (this kernel has no vcan: 'ip link add type vcan' failed)"
else
  [[ $which_only == 1 ]] || note "backend=$backend (VGE_CAN_BACKEND)"
fi
qemu_accel=${VGE_CANVM_ACCEL:-}
if [[ -z $qemu_accel ]]; then if hw_kvm; then qemu_accel=kvm; else qemu_accel=tcg; fi; fi
if [[ $which_only == 1 ]]; then
  if [[ $backend == qemu ]]; then echo "qemu-$qemu_accel"; else echo "$backend"; fi
  exit 0
fi

mkdir -p "$cache" || fail "cannot create $cache"
job=$(mktemp -d "${TMPDIR:-/tmp}/vge-canvm.XXXXXX") || fail "mktemp failed"
trap '[[ ${VGE_CANVM_VERBOSE:-0} == 1 ]] || rm -rf "$job"' EXIT

# The job runs inside the guest: caller's environment and cwd, then PROGRAM, then its status.
{
  echo '#!/bin/bash'
  for v in $(compgen -e); do
    case $v in BASH_*|SHLVL|PWD|OLDPWD|_|SHELLOPTS|BASHOPTS|LD_PRELOAD) continue ;; esac
    printf 'export %s=%q\n' "$v" "${!v}"
  done
  printf 'export VGE_CANVM=%q\n' "$backend"
  printf 'cd %q || exit 125\n' "$PWD"
  printf '%q' "$prog"; printf ' %q' "$@"; printf ' </dev/null\n'
  printf 'echo $? > %q\n' "$job/status"
} > "$job/job.sh"

out_mode=pipe; [[ -t 1 ]] && out_mode=tty

# Lines that create the interfaces and run the job with stdout/stderr on two guest
# consoles ($1, $2). Shared by both guests' init scripts.
run_job_lines() {
  cat <<EOS
ok=1; ip link set lo up
for i in $ifaces; do ip link add dev "\$i" type vcan && ip link set up "\$i" || ok=0; done
stty -F $1 -opost 2>/dev/null; stty -F $2 -opost 2>/dev/null
if [ \$ok != 1 ]; then echo "canvm: creating '$ifaces' in the guest failed" > $2; echo 125 > $job/status
elif [ $out_mode = tty ]; then $3 /bin/bash $job/job.sh > $1 2> $2
else
  # The caller's stdout is not a terminal: give the program pipes too, so that it prints as
  # it would on the host (test harnesses colour their output on terminals).
  mkfifo /dev/canvm-out /dev/canvm-err
  cat /dev/canvm-out > $1 & cat /dev/canvm-err > $2 &
  $3 /bin/bash $job/job.sh > /dev/canvm-out 2> /dev/canvm-err; wait
fi
sync
EOS
}

# modules.dep lists each module's dependencies; print the wanted ones, dependencies first.
resolve_modules() {
  local dep_file=$1; shift
  declare -A seen=()
  visit() {
    local name=$1 line path d
    [[ -n ${seen[$name]:-} ]] && return; seen[$name]=1
    line=$(grep -E "(^|/)${name}\.ko(\.[a-z]+)?:" "$dep_file" | head -1)
    [[ -n $line ]] || return 0   # built in
    path=${line%%:*}
    for d in ${line#*:}; do visit "$(basename "${d%%.ko*}")"; done
    echo "$path"
  }
  local m; for m in "$@"; do visit "$m"; done
}

# ------------------------------------------------------------------ UML
run_uml() {
  [[ -x $uml_kernel ]] || fail "$uml_kernel missing: apt-get install user-mode-linux"
  local kver moddir shim
  kver=$(ls /usr/lib/uml/modules/ | sort -V | tail -1)
  moddir=/usr/lib/uml/modules/$kver
  [[ -f $moddir/modules.dep ]] || fail "no UML modules under /usr/lib/uml/modules"
  shim=$cache/uml-xstate-shim-$(sha1sum < "$here/uml-xstate-shim.c" | cut -c1-12).so
  if [[ ! -f $shim ]]; then
    cc -O2 -shared -fPIC -o "$shim.$$" "$here/uml-xstate-shim.c" -ldl && mv "$shim.$$" "$shim" ||
      fail "building the UML ptrace shim failed (needs cc)"
  fi
  {
    echo '#!/bin/bash'
    echo 'export PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin'
    echo 'mount -t proc proc /proc; mount -t sysfs sys /sys; mountpoint -q /dev || mount -t devtmpfs dev /dev'
    echo 'exec 2>/dev/tty2'
    for m in $(resolve_modules "$moddir/modules.dep" $can_modules); do
      printf 'insmod %q || echo "canvm: insmod %q failed"\n' "$moddir/$m" "$m"
    done
    echo 'ln -sf /proc/self/fd /dev/fd; mkdir -p /dev/shm; mount -t tmpfs shm /dev/shm'
    run_job_lines /dev/tty1 /dev/tty2 ""
    echo 'echo o > /proc/sysrq-trigger; sleep 10'
  } > "$job/init"
  chmod +x "$job/init"
  # con0: kernel console -> log; con1/con2: the program's stdout/stderr.
  LD_PRELOAD=$shim timeout -k 5 "$timeout_s" "$uml_kernel" \
    mem=${mem_mib}M root=/dev/root rootfstype=hostfs rootflags=/ rw init="$job/init" \
    umid="vge-canvm-$$" uml_dir="$job" con0=null,fd:5 con1=null,fd:3 con2=null,fd:4 \
    con=null ssl=null quiet 3>&1 4>&2 5>"$job/console.log" >"$job/vm.log" 2>&1 </dev/null
}

# ------------------------------------------------------------------ QEMU
# Debian's stock kernel (fetched with apt-get download, not installed) and a busybox initramfs
# with the 9p and CAN modules, cached under $cache/qemu.
prepare_qemu() {
  command -v qemu-system-x86_64 >/dev/null || fail "qemu-system-x86_64 missing: apt-get install qemu-system-x86 busybox-static"
  local busybox=/bin/busybox kdir=$cache/qemu
  [[ -x $busybox ]] && ! ldd "$busybox" >/dev/null 2>&1 || fail "$busybox is not static: apt-get install busybox-static"
  if [[ ! -f $kdir/ready ]]; then
    local pkg tmp kver moddir root m
    pkg=$(apt-cache depends linux-image-amd64 2>/dev/null | sed -n 's/^ *Depends: \(linux-image-[0-9][^ ]*-amd64\)$/\1/p' | head -1)
    [[ -n $pkg ]] || fail "cannot find Debian's linux-image-*-amd64 (run apt-get update)"
    note "preparing the qemu guest from $pkg (once)"
    rm -rf "$kdir"; mkdir -p "$kdir"; tmp=$job/kernel; mkdir -p "$tmp"
    (cd "$tmp" && apt-get download "$pkg" >/dev/null 2>&1) || fail "apt-get download $pkg failed"
    dpkg-deb -x "$tmp"/*.deb "$tmp/x" || fail "unpacking $pkg failed"
    kver=$(ls "$tmp/x/lib/modules/" | head -1); moddir=$tmp/x/lib/modules/$kver
    grep -q '^CONFIG_CAN_VCAN=[ym]' "$tmp/x/boot/config-$kver" || fail "$pkg has no vcan"
    depmod -b "$tmp/x" "$kver" 2>/dev/null || fail "depmod failed (apt-get install kmod)"
    cp "$tmp/x/boot/vmlinuz-$kver" "$kdir/vmlinuz"
    root=$tmp/initramfs; mkdir -p "$root"/{bin,proc,sys,dev,host,modules}
    cp "$busybox" "$root/bin/busybox"
    for m in $(resolve_modules "$moddir/modules.dep" virtio_pci 9pnet_virtio 9p $can_modules); do
      case $m in
        *.xz) xz -dc "$moddir/$m" > "$root/modules/$(basename "${m%.xz}")" ;;
        *.zst) zstd -qdc "$moddir/$m" > "$root/modules/$(basename "${m%.zst}")" ;;
        *) cp "$moddir/$m" "$root/modules/" ;;
      esac
      echo "$(basename "${m%.*z*}")" | sed 's/\.ko$//' >> "$root/modules/order"
    done
    cat > "$root/init" <<'EOI'
#!/bin/busybox sh
/bin/busybox --install -s /bin
export PATH=/bin
mount -t proc proc /proc; mount -t sysfs sys /sys; mount -t devtmpfs dev /dev
exec 2>/dev/ttyS2
for m in $(cat /modules/order); do insmod /modules/$m.ko || echo "canvm: insmod $m failed"; done
if mount -t 9p -o trans=virtio,version=9p2000.L,msize=512000 hostroot /host; then
  mount -t proc proc /host/proc; mount -t sysfs sys /host/sys; mount -t devtmpfs dev /host/dev
  ln -sf /proc/self/fd /host/dev/fd; mkdir -p /host/dev/shm; mount -t tmpfs shm /host/dev/shm
  sh /host/$(sed -n 's/.*canvm.job=\([^ ]*\).*/\1/p' /proc/cmdline)/run-job.sh
else
  echo "canvm: mounting the host filesystem over 9p failed" > /dev/ttyS2
fi
poweroff -f
EOI
    chmod +x "$root/init"
    (cd "$root" && find . | "$busybox" cpio -o -H newc 2>/dev/null | gzip -1 > "$kdir/initrd.gz") ||
      fail "building the initramfs failed"
    echo "$pkg $kver" > "$kdir/ready"
  fi
}

run_qemu() {
  prepare_qemu
  local accel=(-accel tcg -cpu max -smp 1)   # 1 vCPU: 2 under TCG made CAN round trips slower
  if [[ $qemu_accel == kvm ]]; then
    accel=(-accel kvm -cpu host -smp 2)
  fi
  note "qemu: ${accel[*]}"
  run_job_lines /dev/ttyS1 /dev/ttyS2 "chroot /host" > "$job/run-job.sh"
  mkfifo "$job/out" "$job/err" || fail "mkfifo failed"
  cat "$job/out" & local out_pid=$!
  cat "$job/err" >&2 & local err_pid=$!
  timeout -k 5 "$timeout_s" qemu-system-x86_64 "${accel[@]}" -m "$mem_mib" \
    -nodefaults -no-user-config -display none -no-reboot \
    -kernel "$cache/qemu/vmlinuz" -initrd "$cache/qemu/initrd.gz" \
    -append "console=ttyS0 panic=-1 quiet canvm.job=$job" \
    -serial file:"$job/console.log" -serial file:"$job/out" -serial file:"$job/err" \
    -virtfs local,path=/,mount_tag=hostroot,security_model=none,multidevs=remap \
    >"$job/vm.log" 2>&1 </dev/null
  local rc=$?
  exec 7<>"$job/out" 8<>"$job/err"; exec 7>&- 8>&-   # unblock the readers if qemu never opened them
  wait "$out_pid" "$err_pid" 2>/dev/null
  return $rc
}

case $backend in
  uml) run_uml; vm_rc=$? ;;
  qemu) run_qemu; vm_rc=$? ;;
  *) fail "unknown VGE_CAN_BACKEND=$backend (auto|host|uml|qemu)" ;;
esac

if [[ ${VGE_CANVM_VERBOSE:-0} == 1 ]]; then
  note "guest files kept in $job"; cat "$job/console.log" >&2 2>/dev/null
fi
if [[ -s $job/status ]]; then exit "$(cat "$job/status")"; fi
if [[ $vm_rc == 124 || $vm_rc == 137 ]]; then
  note "the $backend guest timed out after ${timeout_s}s"; exit 124
fi
note "the $backend guest ended (status $vm_rc) without the program's exit status; its last console lines:"
tail -n 25 "$job/console.log" "$job/vm.log" >&2 2>/dev/null
exit 125

#!/usr/bin/env bash
# Assemble a CPU-only libtorch 2.13.0 (the version tch 0.26 pins) from PyPI wheels.
#
# PyPI is the only reachable host that serves libtorch, and its x86_64 torch wheel is the
# CUDA build (~4.7 GB with its nvidia-* dependencies). We download three wheels without
# installing them (~515 MB), unpack only the CPU libraries, and replace libtorch.so (which
# only adds a DT_NEEDED on libtorch_cuda.so) with an empty library of the same SONAME.
# See docs/libtorch.md.
#
# Installs into $VGE_CACHE (default ~/.cache/vge)/libtorch-2.13.0 and links it as
# <repo>/.deps/libtorch, which .cargo/config.toml points LIBTORCH at.
# A no-op (well under a second) when it is already in place.
set -euo pipefail

TORCH_VERSION=2.13.0
CUDART_VERSION=13.0.96
CUPTI_VERSION=13.0.85

repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cache=${VGE_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/vge}
dest=$cache/libtorch-$TORCH_VERSION
link=$repo/.deps/libtorch

say() { echo "setup-libtorch: $*" >&2; }

if [[ -f $dest/.complete && $(cat "$dest/build-version" 2>/dev/null) == "$TORCH_VERSION" ]]; then
  mkdir -p "$repo/.deps"
  [[ $(readlink "$link" 2>/dev/null) == "$dest" ]] || ln -sfn "$dest" "$link"
  exit 0
fi

[[ $(uname -m) == x86_64 && $(uname -s) == Linux ]] ||
  { say "only x86_64 Linux is supported by this script; set LIBTORCH by hand (docs/libtorch.md)"; exit 1; }
command -v python3 >/dev/null || { say "python3 with pip is needed to download the wheels"; exit 1; }
command -v cc >/dev/null || { say "a C compiler (cc) is needed"; exit 1; }

start=$SECONDS
mkdir -p "$cache"
work=$(mktemp -d "$cache/libtorch-dl.XXXXXX")
trap 'rm -rf "$work"' EXIT

say "downloading torch==$TORCH_VERSION and two CUDA runtime wheels from PyPI (~515 MB)"
python3 -m pip download --quiet --no-deps --only-binary=:all: --dest "$work/wheels" \
  "torch==$TORCH_VERSION" "nvidia-cuda-runtime==$CUDART_VERSION" "nvidia-cuda-cupti==$CUPTI_VERSION"
size_mb=$(du -sm "$work/wheels" | cut -f1)

say "unpacking the CPU libraries and headers"
stage=$work/libtorch
mkdir -p "$stage/lib" "$stage/include"
python3 - "$work/wheels" "$stage" <<'PY'
import pathlib, shutil, sys, zipfile
wheels, stage = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])
want_lib = {"libtorch_cpu.so", "libc10.so", "libgomp.so.1", "libcudart.so.13", "libcupti.so.13"}
found = set()
for whl in sorted(wheels.glob("*.whl")):
    with zipfile.ZipFile(whl) as z:
        for info in z.infolist():
            name = info.filename
            base = name.rsplit("/", 1)[-1]
            if name.startswith("torch/include/") and not info.is_dir():
                out = stage / "include" / name[len("torch/include/"):]
            elif base in want_lib and "/lib/" in name:
                out = stage / "lib" / base
                found.add(base)
            else:
                continue
            out.parent.mkdir(parents=True, exist_ok=True)
            with z.open(info) as src, open(out, "wb") as dst:
                shutil.copyfileobj(src, dst)
missing = want_lib - found
if missing:
    sys.exit(f"missing from the wheels: {sorted(missing)}")
PY

# An empty libtorch.so: torch-sys links -ltorch, the wheel's copy pulls in libtorch_cuda.so.
echo 'void vge_libtorch_cpu_only(void) {}' > "$work/empty.c"
cc -shared -fPIC -Wl,-soname,libtorch.so -o "$stage/lib/libtorch.so" "$work/empty.c"
echo "$TORCH_VERSION" > "$stage/build-version"

if LD_LIBRARY_PATH=$stage/lib ldd "$stage/lib/libtorch_cpu.so" | grep -q "not found"; then
  LD_LIBRARY_PATH=$stage/lib ldd "$stage/lib/libtorch_cpu.so" | grep "not found" >&2
  say "libtorch_cpu.so has unresolved libraries"; exit 1
fi

rm -rf "$dest"
mv "$stage" "$dest"
touch "$dest/.complete"
mkdir -p "$repo/.deps"
ln -sfn "$dest" "$link"
say "libtorch $TORCH_VERSION ready in $dest ($(du -sm "$dest" | cut -f1) MB on disk, ${size_mb} MB downloaded, $((SECONDS - start)) s)"

#!/usr/bin/env bash
# Assembles a CUDA toolkit from NVIDIA's PyPI wheels (no GPU, no system CUDA needed) and
# compile-checks the `cuda` feature:
#   scripts/cuda_toolkit_from_pypi.sh            # toolkit + `cargo check --features cuda`
#   LINK_STUB=1 scripts/cuda_toolkit_from_pypi.sh build --release --features cuda --bin vectorfusion
# Any arguments replace the cargo command (default: check --features cuda).
#
# Why CUDA 13: the cu12 `nvidia-cuda-nvcc-cu12` wheels (12.0 .. 12.9) ship only ptxas + libnvvm,
# no `nvcc`/`cicc`/`cudafe++`; the CUDA 13 wheels (`nvidia-cuda-nvcc`, `nvidia-nvvm`,
# `nvidia-cuda-crt`) are a complete compiler. 13.0 is the oldest 13.x: its PTX needs the
# smallest driver (R580+). cudarc 0.19.10 (candle 0.11.1) knows CUDA up to 13.4.
#
# libcuda.so (the driver) is in no wheel. `cargo check`/`clippy` do not link and need none.
# Linking a binary does (candle enables cudarc's `dynamic-linking`): LINK_STUB=1 builds a
# link-time stub from the wheel's cuda.h (every declared cu* entry point returns
# CUDA_ERROR_STUB_LIBRARY, soname libcuda.so.1), the way the toolkit's own lib64/stubs does.
# It lives in lib64/stubs, which is never put on the run-time library path: the binary loads
# the real libcuda.so.1 of the machine's driver. At run time the binary also needs
# LD_LIBRARY_PATH=$CUDA_DIR/lib64 (cudart, cublas, cublasLt, curand, nvrtc).
#
# Env: CUDA_DIR (default /work/cuda-toolkit), CUDA_VENV (default /work/cuda-venv),
#      CUDA_TOOLKIT_VERSION (default 13.0.2), CUDA_COMPUTE_CAP (default 90 = H100; 80 = A100),
#      CARGO_TARGET_DIR (default target-cuda beside the repo).
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
CUDA_DIR="${CUDA_DIR:-/work/cuda-toolkit}"
CUDA_VENV="${CUDA_VENV:-/work/cuda-venv}"
CUDA_TOOLKIT_VERSION="${CUDA_TOOLKIT_VERSION:-13.0.2}"

if [ ! -x "$CUDA_VENV/bin/python" ]; then python3 -m venv "$CUDA_VENV"; fi
"$CUDA_VENV/bin/pip" install -q \
  "cuda-toolkit[nvcc,crt,nvvm,cudart,cccl,cublas,curand,nvrtc]==$CUDA_TOOLKIT_VERSION"
CU="$("$CUDA_VENV/bin/python" -c 'import nvidia, os; print(os.path.join(nvidia.__path__[0], "cu13"))')"
[ -x "$CU/bin/nvcc" ] || { echo "no nvcc in $CU/bin" >&2; exit 1; }

# CUDA_HOME layout: bin/ include/ nvvm/ from the wheels, lib64/ with the unversioned .so names
# the linker looks for.
mkdir -p "$CUDA_DIR/lib64"
for d in bin include nvvm; do ln -sfn "$CU/$d" "$CUDA_DIR/$d"; done
for f in "$CU"/lib/*.so.*; do ln -sfn "$f" "$CUDA_DIR/lib64/"; done
for l in cudart cublas cublasLt curand nvrtc; do
  ln -sfn "$(basename "$(ls "$CU"/lib/lib$l.so.[0-9]* | head -1)")" "$CUDA_DIR/lib64/lib$l.so"
done

if [ "${LINK_STUB:-0}" = 1 ]; then
  mkdir -p "$CUDA_DIR/lib64/stubs"
  STUB_C="$CUDA_DIR/lib64/stubs/libcuda_stub.c"
  {
    echo "/* link-time stub of libcuda.so.1 generated from cuda.h; never on the run-time path */"
    for def in "" "-D__CUDA_API_VERSION_INTERNAL"; do
      gcc -E -P $def -I"$CUDA_DIR/include" "$CUDA_DIR/include/cuda.h"
    done | tr '\n' ' ' | grep -oE '\bCUresult +cu[A-Za-z0-9_]+ *\(' | sed -E 's/^CUresult +//; s/ *\($//' \
      | sort -u | sed -E 's/.*/int &(void) { return 34; }/'
  } > "$STUB_C"
  gcc -shared -fPIC -Wl,-soname,libcuda.so.1 -o "$CUDA_DIR/lib64/stubs/libcuda.so" "$STUB_C"
fi

export CUDA_HOME="$CUDA_DIR" CUDA_ROOT="$CUDA_DIR" CUDA_TOOLKIT_ROOT_DIR="$CUDA_DIR"
export PATH="$CUDA_DIR/bin:$PATH"
export CUDA_COMPUTE_CAP="${CUDA_COMPUTE_CAP:-90}"
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$ROOT/../target-cuda}"
nvcc --version | tail -2
cd "$ROOT"
if [ $# -eq 0 ]; then set -- check --features cuda; fi
exec cargo "$@"

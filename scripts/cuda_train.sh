#!/bin/bash
# Builds the CUDA training binary (train/examples/nelf_train.rs, `--features cuda`) on a
# machine WITHOUT a GPU, for a lent H100/H200, and packs it with a run script into
# .gpu/ (git-ignored): carry `.gpu/nelf_train.xz` and `.gpu/train.sh` to the GPU and
# run `bash .gpu/train.sh` there (it writes the run folder under $OUT/run).
#
#   bash scripts/cuda_train.sh            # toolchain (once, ~1.2 GB), build, pack
#
# CUDA_DIR: where the toolchain is (installed there if missing; default
# ~/.cache/nelf/cuda13). CUDA_TARGET_DIR: its own cargo target folder (default
# target/cuda inside the clone). docs/PLATFORM.md, "candle's CUDA backend".
#
# What it takes (measured 2026-11-26): a CUDA 13.0 toolchain from PyPI wheels (nvcc
# 13.0.x matches the lent machines' driver 580); plain-named .so links beside the
# wheels' numbered ones; a link-time stub libcuda.so (cudarc 0.19 as candle 0.11 uses
# it links the driver API dynamically; the stub is never shipped); a separate target
# dir (a clean build takes ~21 min on 2 cores). The stripped binary is 59 MB, 6.7 MB
# under xz; it needs glibc >= 2.35 and runs against PyTorch's cu13 libraries on the
# GPU machine (/opt/torch/.venv/.../nvidia/cu13/lib, found through its rpath).
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
CUDA_DIR=${CUDA_DIR:-${XDG_CACHE_HOME:-$HOME/.cache}/nelf/cuda13}
C=$CUDA_DIR/nvidia/cu13
if [ ! -x "$C/bin/nvcc" ]; then
  pip install --no-deps --target "$CUDA_DIR" nvidia-cuda-nvcc==13.0.88 nvidia-cuda-crt==13.0.88 \
    nvidia-nvvm==13.0.88 nvidia-cuda-runtime==13.0.88 nvidia-cuda-cccl==13.0.85 \
    nvidia-cublas==13.0.2.14 nvidia-curand==10.4.0.35 nvidia-cuda-nvrtc==13.0.88
  (cd "$C/lib" && ln -sf libcudart.so.13 libcudart.so && ln -sf libcublas.so.13 libcublas.so \
    && ln -sf libcublasLt.so.13 libcublasLt.so && ln -sf libcurand.so.10 libcurand.so \
    && ln -sf libnvrtc.so.13 libnvrtc.so)
fi
if [ ! -f "$C/lib/stubs/libcuda.so" ]; then
  mkdir -p "$C/lib/stubs"
  syms=$(grep -ohE '^pub unsafe fn cu[A-Za-z0-9_]+' ~/.cargo/registry/src/*/cudarc-0.19.*/src/driver/sys/mod.rs | awk '{print $4}' | sort -u)
  for s in $syms; do echo "int $s(void) { return 999; }"; done > "$C/lib/stubs/cuda_stub.c"
  cc -shared -fPIC -O1 -Wl,-soname,libcuda.so.1 -o "$C/lib/stubs/libcuda.so" "$C/lib/stubs/cuda_stub.c"
fi
export CUDA_HOME=$C CUDA_ROOT=$C CUDA_PATH=$C PATH=$C/bin:$PATH CUDA_COMPUTE_CAP=90 CUDARC_CUDA_VERSION=13000
export LIBRARY_PATH=$C/lib:$C/lib/stubs${LIBRARY_PATH:+:$LIBRARY_PATH}
export CARGO_TARGET_DIR=${CUDA_TARGET_DIR:-$ROOT/target/cuda}
cd "$ROOT"
cargo build --release -p nelf-train --features cuda --example nelf_train
D=$ROOT/.gpu; mkdir -p "$D"
grep -qx '/.gpu/' "$(git rev-parse --git-path info/exclude)" 2>/dev/null || echo '/.gpu/' >> "$(git rev-parse --git-path info/exclude)"
cp "$CARGO_TARGET_DIR/release/examples/nelf_train" "$D/nelf_train"
strip "$D/nelf_train"
S=/opt/torch/.venv/lib/python3.12/site-packages/nvidia
patchelf --set-rpath "\$ORIGIN:$S/cu13/lib:$S/cublas/lib:$S/curand/lib:$S/cuda_runtime/lib" "$D/nelf_train"
xz -9 -T1 -c "$D/nelf_train" > "$D/nelf_train.xz"
rm "$D/nelf_train"
cat > "$D/train.sh" <<'RUN'
#!/bin/bash
# On the GPU machine: unpack, render the dataset, train (resuming from .gpu/run if carried).
set -u
xz -dc .gpu/nelf_train.xz > /tmp/nelf_train && chmod +x /tmp/nelf_train
SP=/opt/torch/.venv/lib/python3.12/site-packages/nvidia
export LD_LIBRARY_PATH="$(ls -d $SP/*/lib 2>/dev/null | tr '\n' ':')${LD_LIBRARY_PATH:-}" RAYON_NUM_THREADS=16
mkdir -p "$OUT/run"; [ -d .gpu/run ] && cp .gpu/run/checkpoint.* .gpu/run/*.csv "$OUT/run/" 2>/dev/null
timeout "${DATA_SECS:-150}" /tmp/nelf_train data -o /tmp/data --heads 200 --val-heads 8 --size 64 > "$OUT/data.log" 2>&1
/tmp/nelf_train run --data /tmp/data -o "$OUT/run" --arch small --image-size 64 --rays 512 --coarse-samples 64 \
  --fine-samples 64 --distill-weight 0 --distill-sigma-weight 1.0 --free-space-weight 0.5 --ema-decay 0.995 --colour-loss srgb-l2 --source-relative-light --max-secs "${TRAIN_SECS:-270}" --checkpoint-secs 60 --val-every 250 \
  --val-heads 4 --steps 1000000 2>&1 | grep -v '^ *[0-9]*: '
RUN
chmod +x "$D/train.sh"
ls -la "$D"

#!/usr/bin/env bash
# GPU benchmark for BENCHMARKS.md (issue 5). Run from the repository root on the GPU machine with a
# prebuilt release binary (cargo build --release); needs no network.
#   bash scripts/gpu-bench.sh            # writes results to stdout and to $OUT (or ./gpu-bench-out)
# Each command is capped at 180 s. Measures: batched linearize/energy throughput of the shipped model at 1k/10k/100k frames per call
# on cpu and wgpu (f32; f64 at 10k/100k), with wgpu's phase breakdown (pack, upload, device wait,
# read-back, unpack), and whole-solve frames/s of a 100k-frame synthetic trial on both backends.
set -uo pipefail
cd "$(dirname "$0")/.."
BIN=${BIN:-target/release/smocap}
OUTDIR=${OUT:-gpu-bench-out}
mkdir -p "$OUTDIR"
[ -x "$BIN" ] || { echo "missing $BIN: build it with cargo build --release" >&2; exit 1; }
{
  echo "# date: $(date -u +%Y-%m-%dT%H:%MZ)"
  echo "# host: $(uname -srm), $(nproc) cores"
  command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader
  timeout 180 "$BIN" bench-batch --backend cpu --sizes 1000,10000,100000 --repeats 5 || echo "bench-batch cpu failed: $?"
  # wgpu: the default 32k frames per dispatch, then 128k (more invocations resident on a big GPU).
  for cap in 32768 131072; do
    timeout 180 "$BIN" bench-batch --backend wgpu --cap "$cap" --sizes 1000,10000,100000 --repeats 5 \
      || echo "bench-batch wgpu --cap $cap failed: $?"
  done
  # f64 shaders (SHADER_F64): parity 1e-12; the H100 runs f64 at half its f32 rate.
  timeout 180 "$BIN" bench-batch --backend wgpu-f64 --cap 65536 --sizes 10000,100000 --repeats 3 \
    || echo "bench-batch wgpu-f64 failed: $?"
  for b in cpu wgpu; do
    for lanes in 250 1000; do
      echo "# whole solve: demo --frames 100000 --backend $b --lanes $lanes"
      timeout 180 "$BIN" demo --frames 100000 --backend "$b" --lanes "$lanes" 2>&1 | tail -5 \
        || echo "demo $b failed: $?"
    done
  done
} 2>&1 | tee "$OUTDIR/gpu-bench.txt"

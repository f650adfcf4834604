#!/usr/bin/env bash
# GPU benchmark for BENCHMARKS.md (issues 5 and 14). Run from the repository root on the GPU machine
# with a prebuilt release binary (cargo build --release); needs no network; about 4 minutes.
#   bash scripts/gpu-bench.sh            # writes results to stdout and to $OUT (or ./gpu-bench-out)
# Measures: batched linearize / handoff / energy throughput of the shipped model at 10k, 100k and
# 1M frames per call on cpu and wgpu (f32; f64 at 10k/100k), with wgpu's phase breakdown (pack,
# upload, device wait, read-back mapping, unpack, host CPU time per frame), and whole-solve
# frames/s of a 100k-frame synthetic trial on both backends on the same machine. wgpu runs the
# cooperative kernel (the default, one workgroup per frame) and, for comparison at 10k/100k, the
# per-frame kernel, then smocap render at 1280x720. Worst case (every timeout) 5 min 50 s.
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
  # 1M frames: linearize (owned copies) is skipped above 100k frames; handoff and energy run.
  timeout 60 "$BIN" bench-batch --backend cpu --sizes 10000,100000,1000000 --repeats 3 || echo "bench-batch cpu failed: $?"
  timeout 60 "$BIN" bench-batch --backend wgpu --cap 131072 --sizes 10000,100000,1000000 --repeats 3 \
    || echo "bench-batch wgpu failed: $?"
  timeout 40 "$BIN" bench-batch --backend wgpu --kernel per-frame --cap 131072 --sizes 10000,100000 --repeats 3 \
    || echo "bench-batch wgpu per-frame failed: $?"
  timeout 30 "$BIN" bench-batch --backend wgpu-f64 --cap 65536 --sizes 10000,100000 --repeats 3 \
    || echo "bench-batch wgpu-f64 failed: $?"
  for b in cpu wgpu; do
    echo "# whole solve: demo --frames 100000 --backend $b --lanes 1000"
    timeout 50 "$BIN" demo --frames 100000 --backend "$b" --lanes 1000 2>&1 | tail -5 \
      || echo "demo $b failed: $?"
  done
  # smocap render (issue 30): RGB + mask + depth + keypoints of the synthetic walk, 1280x720, the
  # default rig's two cameras; frames/s in render.json's timings and on stderr
  echo "# render: synthetic walk01, 1280x720, default rig"
  timeout 20 "$BIN" convert datasets.toml --dataset synthetic --quiet --out "$OUTDIR/convert" >/dev/null 2>&1 \
    && timeout 40 "$BIN" render "$OUTDIR/convert/synthetic/subj01/walk01.mcap" --size 1280x720 --quiet \
      --out "$OUTDIR/render" 2>&1 | tail -3 || echo "render failed: $?"
  [ -f "$OUTDIR/render/render.json" ] && head -c 1500 "$OUTDIR/render/render.json"
} 2>&1 | tee "$OUTDIR/gpu-bench.txt"

#!/usr/bin/env bash
# Convert a whole archive on a Slurm cluster: one array task per shard.
#
#   sbatch --array=0-15 examples/slurm-array.sh /path/to/datasets.toml /path/to/out
#
# Each task converts shard $SLURM_ARRAY_TASK_ID of $SLURM_ARRAY_TASK_COUNT (smocap reads both from
# the environment; subjects are kept whole and shards balanced by frame count), writes its
# summary to <out>/reports/shard-<i>.json (shards run side by side into one --out, each holding its
# own lock; `smocap merge-reports <out>/reports/shard-*.json` joins them), and can be resubmitted: --resume skips trials already
# converted from the same input. Exit code 3 marks a shard with failed trials (listed in its summary).
#SBATCH --job-name=smocap-convert
#SBATCH --cpus-per-task=8
#SBATCH --mem=8G
#SBATCH --time=04:00:00
#SBATCH --output=smocap-%A_%a.log
set -euo pipefail
DATASETS=${1:-datasets.toml}
OUT=${2:-smocap-out}
SMOCAP=${SMOCAP:-smocap}   # the release binary (cargo build --release → target/release/smocap)
mkdir -p "$OUT/reports"
"$SMOCAP" convert "$DATASETS" --out "$OUT" --jobs "${SLURM_CPUS_PER_TASK:-8}" --resume \
    --report-json "$OUT/reports/shard-${SLURM_ARRAY_TASK_ID:-0}.json"

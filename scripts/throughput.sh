#!/usr/bin/env bash
# Whole-path throughput of `smocap convert` (issue 22, item 6): a synthetic archive of SUBJECTS
# subjects (default 20), each a static trial and 5 walks of 1,000 frames (shipped model), converted
# with JOBS workers (default 2). Prints convert's summary: frames/s end to end, the solver's
# capacity (frames/s per worker × workers, same run) and their ratio, and calibration per subject
# by stage. Usage: scripts/throughput.sh [path/to/smocap] (default: target/release/smocap).
set -euo pipefail
bin=${1:-target/release/smocap}
subjects=${SUBJECTS:-20}
jobs=${JOBS:-2}
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
cat >"$dir/datasets.toml" <<TOML
[[dataset]]
name = "synthetic"
trials = ["*/walk*.trc"]
subject = "{subject}/{trial}.trc"
static = "{subject}/static.trc"
synthetic = { subjects = $subjects, trials = 5, frames = 1000, seed = 3 }
TOML
echo "machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs); $(date -u +%Y-%m-%d)"
# The archive is generated before convert's clock starts (its wall time covers the conversion).
"$bin" convert "$dir/datasets.toml" --out "$dir/out" --jobs "$jobs" -q

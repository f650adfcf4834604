#!/usr/bin/env bash
# Khronos' glTF validator on smocap's glTF exports: the datasets of datasets.toml converted
# (the shipped model's synthetic trials; the shared gait2354 and Rajagopal trials where
# ../shared is present), each exported with `smocap export --gltf` (Y up, and Z up for the
# first), plus a `smocap solve --gltf-dir` export of a synthetic trial. Every file must have
# 0 errors and 0 warnings.
#
# Needs node and npm; skips with a note otherwise. The validator (npm `gltf-validator`) is
# installed outside the repository, into $GLTF_VALIDATOR_DIR (default
# ~/.cache/smocap-gltf-validator). SMOCAP_BIN names a built smocap (else cargo builds one).
set -euo pipefail
cd "$(dirname "$0")/.."
if ! command -v node >/dev/null || ! command -v npm >/dev/null; then
    echo "validate_gltf: skipped: node and npm are needed (apt-get install nodejs npm)"
    exit 0
fi
VDIR=${GLTF_VALIDATOR_DIR:-${XDG_CACHE_HOME:-$HOME/.cache}/smocap-gltf-validator}
if [ ! -d "$VDIR/node_modules/gltf-validator" ]; then
    mkdir -p "$VDIR"
    if ! npm install --prefix "$VDIR" --no-audit --no-fund --silent gltf-validator@2.0.0-dev.3.10; then
        echo "validate_gltf: skipped: could not install gltf-validator with npm"
        exit 0
    fi
fi
BIN=${SMOCAP_BIN:-}
if [ -z "$BIN" ]; then
    cargo build --release --locked -q
    BIN=${CARGO_TARGET_DIR:-target}/release/smocap
fi
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT
rc=0
"$BIN" convert datasets.toml --out "$OUT/conv" --quiet >/dev/null || rc=$?
[ "$rc" -eq 0 ] || [ "$rc" -eq 3 ] || { echo "validate_gltf: convert failed ($rc)"; exit 1; }
mkdir -p "$OUT/glb"
first=1
while IFS= read -r f; do
    name=$(echo "${f#"$OUT/conv/"}" | tr '/' '_')
    "$BIN" export "$f" --gltf "$OUT/glb/${name%.mcap}.glb" 2>/dev/null
    if [ "$first" = 1 ]; then
        "$BIN" export "$f" --gltf "$OUT/glb/${name%.mcap}.zup.glb" --up z 2>/dev/null
        first=0
    fi
done < <(find "$OUT/conv" -name '*.mcap' | LC_ALL=C sort)
"$BIN" synth --frames 120 --seed 3 --out "$OUT/walk.trc" --truth "$OUT/walk.json" 2>/dev/null
"$BIN" solve "$OUT/walk.trc" --gltf-dir "$OUT/glb/solve" >/dev/null 2>&1 || [ $? -eq 3 ]
GLTF_VALIDATOR_DIR="$VDIR" node scripts/validate_gltf.mjs "$OUT"/glb/*.glb "$OUT"/glb/solve/*.glb

#!/usr/bin/env bash
# Same outputs from two builds: runs one fixed set of commands with each binary and compares every
# file they write byte for byte. For changes that must not change results (moving code, renaming
# modules): build the base, copy its binary aside, build the change, then
#
#   bash scripts/same_outputs.sh /tmp/smocap-base target/debug/smocap
#
# from the repository root with ../shared beside it. The commands: `convert` of datasets.toml (the
# shared trials and the embedded synthetic archive) and of the shared OpenCap subject (all six
# trials, no static trial) and the Vicon Plug-in Gait subject; `export` of every .mcap to .mot, .csv and .glb; `solve` of the shared
# gait2354 and Rajagopal subjects with their setups (.mot, scaled .osim, .glb; the report JSON
# with its timings and paths removed); `project` and `preview` of one trial; `synth` + `solve` on
# the shipped model and the dog; `compare` against the gait2354 reference; the demo's stdout
# without its timings. Exit 0 when every file is identical, 1 with the differing files listed.
set -euo pipefail
cd "$(dirname "$0")/.."
[ $# -eq 2 ] || { echo "usage: $0 BASE_BINARY NEW_BINARY" >&2; exit 2; }
A=$(realpath "$1"); B=$(realpath "$2")
SHARED=$(cd .. && pwd)/shared/datasets
[ -d "$SHARED" ] || { echo "same_outputs: ../shared/datasets is missing" >&2; exit 2; }
WORK=$(mktemp -d "${TMPDIR:-/tmp}/smocap-same.XXXXXX")
trap 'rm -rf "$WORK"' EXIT

# One datasets file for both runs; the synthetic archive generated once into a folder both read.
cp datasets.toml "$WORK/datasets.toml"
sed -i "s#\.\./shared/datasets#$SHARED#g" "$WORK/datasets.toml"
sed -i "s#^name = \"synthetic\"#name = \"synthetic\"\nroot = \"$WORK/synthetic-data\"#" "$WORK/datasets.toml"
cat >>"$WORK/datasets.toml" <<TOML

[[dataset]]
name = "opencap"
root = "$SHARED/opencap_addbiomechanics"
trials = ["MarkerData/*.trc"]
model = "$SHARED/opencap_addbiomechanics/unscaled_generic.osim"

[[dataset]]
name = "vicon"
root = "$SHARED/vicon_plugingait_flatfoot"
trials = ["PiG_Motion3_FF.c3d"]
static = "PiG_Calibration3_FF.c3d"
TOML
G=$SHARED/gait2354_subject01
R=$SHARED/rajagopal2016_walk

ok3() { "$@" || [ $? -eq 3 ]; }   # exit 3 (a suspect trial) still writes every output
strip_json() { # strip_json FILE OUT: drop timings and durations, and name OUT as <out>
    python3 - "$1" "$2" <<'PY'
import json, re, sys
out = sys.argv[2]
def walk(v):
    if isinstance(v, str):
        return v.replace(out, '<out>')
    if isinstance(v, dict):
        return {k: walk(x) for k, x in v.items()
                if not re.search(r'(second|_s$|_ms$|time|elapsed|duration|per_s|ms_per|fps|version|threads|jobs|started|finished)', k)}
    if isinstance(v, list):
        return [walk(x) for x in v]
    return v
p = sys.argv[1]
json.dump(walk(json.load(open(p))), open(p, 'w'), indent=1, sort_keys=True)
PY
}

run() { # run BIN DIR
    local bin=$1 out=$2
    mkdir -p "$out"/{gait,raj,synth,dog}
    ok3 "$bin" convert "$WORK/datasets.toml" --out "$out/convert" --jobs 2 --quiet --allow-empty >/dev/null
    find "$out/convert" -name '*.mcap' -not -path '*/.synthetic/*' | sort | while read -r f; do
        "$bin" export "$f" --mot "${f%.mcap}.mot" --csv "${f%.mcap}.csv" >/dev/null
        "$bin" export "$f" --gltf "${f%.mcap}.glb" >/dev/null
    done
    local walk=$out/convert/rajagopal2016_walk/motion_capture_walk.mcap
    "$bin" project "$walk" --out "$out/project" --stride 5 >/dev/null
    "$bin" preview "$walk" --out "$out/preview.png" >/dev/null 2>&1
    ok3 "$bin" solve --model "$G/gait2354_simbody.osim" --scale-setup "$G/subject01_Setup_Scale.xml" \
        --static "$G/subject01_static.trc" --ik-setup "$G/subject01_Setup_IK.xml" "$G/subject01_walk1.trc" \
        --mot-dir "$out/gait" --scaled-model "$out/gait/subject01.osim" --gltf-dir "$out/gait" \
        --report-json "$out/gait/report.json" >/dev/null 2>&1
    ok3 "$bin" solve --model "$R/Rajagopal2016.osim" --markerset "$R/markerset_walk_preScale.xml" \
        --scale-setup "$R/scale_setup_walk_scaleOnly.xml" --static "$R/static_walk_1.trc" \
        --ik-setup "$R/ik_setup_walk.xml" "$R/motion_capture_walk.trc" \
        --mot-dir "$out/raj" --report-json "$out/raj/report.json" >/dev/null 2>&1
    "$bin" synth --frames 300 --noise-mm 2 --seed 7 --out "$out/synth/walk.trc" --truth "$out/synth/walk.json" >/dev/null
    ok3 "$bin" solve "$out/synth/walk.trc" --truth "$out/synth/walk.json" --report-json "$out/synth/report.json" >/dev/null 2>&1
    "$bin" synth --model models/dog.xml --profile models/dog.toml --frames 200 --out "$out/dog/dog.trc" --truth "$out/dog/dog.json" >/dev/null
    ok3 "$bin" solve --model models/dog.xml --profile models/dog.toml "$out/dog/dog.trc" --truth "$out/dog/dog.json" \
        --report-json "$out/dog/report.json" >/dev/null 2>&1
    ok3 "$bin" compare "$out/gait/subject01_walk1.mot" "$G/subject01_walk1.trc" --json "$out/compare.json" >/dev/null 2>&1 || true
    "$bin" markers "$G/subject01_walk1.trc" >"$out/markers.txt"
    find "$out" -name '*.json' -path '*report*' | while read -r j; do strip_json "$j" "$out"; done
    find "$out/convert" -name '*.json' | while read -r j; do strip_json "$j" "$out"; done
}
run "$A" "$WORK/a"
run "$B" "$WORK/b"

status=0; count=0
while read -r rel; do
    count=$((count + 1))
    if ! cmp -s "$WORK/a/$rel" "$WORK/b/$rel"; then echo "differs: $rel"; status=1; fi
done < <(cd "$WORK/a" && find . -type f -not -path '*/.synthetic/*' -not -name '*.lock' | sort)
if ! diff <(cd "$WORK/a" && find . -type f -not -name '*.lock' | sort) <(cd "$WORK/b" && find . -type f -not -name '*.lock' | sort) >/dev/null; then
    echo "the two runs wrote different files:"
    diff <(cd "$WORK/a" && find . -type f -not -name '*.lock' | sort) <(cd "$WORK/b" && find . -type f -not -name '*.lock' | sort) || true
    status=1
fi
[ $count -gt 0 ] || { echo "same_outputs: nothing was written"; exit 1; }
[ $status -eq 0 ] && echo "same_outputs: $count files identical"
exit $status

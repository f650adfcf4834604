#!/usr/bin/env bash
# Same bytes on every CPU: builds smocap twice, as usual (matrixmultiply picks its f64 kernel at
# run time: AVX-512, FMA+AVX2, AVX or generic) and with matrixmultiply forced to its generic
# kernel (its documented build-time switch MMTEST_FEATURE, set to a feature no CPU has, in a
# target folder of its own), converts the datasets of datasets.toml (the shared trials and the
# embedded synthetic one) with both, and with glibc's libm forced to its SSE2 variants, exports
# every .mcap to .mot, and compares every file byte for byte. Exit 0 when all are identical; 1
# with the differing files otherwise.
#
#   bash scripts/cpu_check.sh            # from the repository root, ../shared beside it
#
# Uses the dev profile (as the tests) and the tests' target folder (CARGO_TARGET_DIR honoured):
# the second build recompiles only matrixmultiply and what depends on it (it reads
# MMTEST_FEATURE with option_env!, which cargo tracks), about 3 minutes on 2 cores instead of a
# whole second build. It leaves that folder built with the generic kernel: the next cargo
# command rebuilds those few crates.
set -euo pipefail
cd "$(dirname "$0")/.."
TARGET=${CARGO_TARGET_DIR:-target}
WORK=$(mktemp -d "${TMPDIR:-/tmp}/smocap-cpu-check.XXXXXX")
trap 'rm -rf "$WORK"' EXIT

# --workspace: the features the tests were built with, so the first build reuses them.
env -u MMTEST_FEATURE cargo build --locked --workspace --bin smocap
cp "$TARGET/debug/smocap" "$WORK/smocap-normal"
MMTEST_FEATURE=generic cargo build --locked --workspace --bin smocap
cp "$TARGET/debug/smocap" "$WORK/smocap-generic"
if cmp -s "$WORK/smocap-normal" "$WORK/smocap-generic"; then
    echo "cpu_check: the build with MMTEST_FEATURE=generic gave the same binary: nothing was checked"
    exit 1
fi

# The repository's datasets, and the shared OpenCap subject's walking2 trial (registration of 49
# markers on the generic model: the calibration the issue found kernel-dependent).
SHARED=$(cd .. && pwd)/shared/datasets
cp datasets.toml "$WORK/datasets.toml"
sed -i "s#\.\./shared/datasets#$SHARED#g" "$WORK/datasets.toml"
# The synthetic dataset is generated into one folder both builds read (by default each run
# generates it under its own --out, and the source path the .mcap records would differ).
sed -i "s#^name = \"synthetic\"#name = \"synthetic\"\nroot = \"$WORK/synthetic-data\"#" "$WORK/datasets.toml"
if [ -d "$SHARED/opencap_addbiomechanics" ]; then
    cat >>"$WORK/datasets.toml" <<TOML

[[dataset]]
name = "opencap_walking2"
root = "$SHARED/opencap_addbiomechanics"
trials = ["MarkerData/walking2.trc"]
model = "$SHARED/opencap_addbiomechanics/unscaled_generic.osim"
TOML
fi

run() { # run <binary> <folder>
    local bin=$1 out=$2
    # Exit 3 (some trial failed or is suspect) still writes every other output: compared too.
    "$bin" convert "$WORK/datasets.toml" --out "$out" --jobs 2 --quiet --allow-empty >/dev/null || [ $? -eq 3 ]
    find "$out" -name '*.mcap' -not -path '*/.synthetic/*' | sort | while read -r f; do
        "$bin" export "$f" --mot "${f%.mcap}.mot" >/dev/null
    done
}
run "$WORK/smocap-normal" "$WORK/normal"
run "$WORK/smocap-generic" "$WORK/generic"

# glibc's libm picks sin, cos, atan2, exp, log… per CPU (FMA or SSE2 variants, which round
# differently: src/model/math.rs). The normal binary again with the FMA and AVX2 variants switched
# off (the names of glibc ≥ 2.33 and older ones; unknown names are ignored), when that switch
# changes libm's results on this machine (a CPU without FMA runs the SSE2 variants anyway).
NO_FMA='glibc.cpu.hwcaps=-AVX2_Usable,-FMA_Usable,-AVX2,-FMA'
libm_probe='import math, hashlib, struct
h = hashlib.sha256()
for i in range(200000):
    h.update(struct.pack("<dd", math.sin(i * 0.37 - 4000.0), math.cos(i * 0.37 - 4000.0)))
print(h.hexdigest())'
libm_switch=0
if command -v python3 >/dev/null \
    && [ "$(python3 -c "$libm_probe")" != "$(GLIBC_TUNABLES=$NO_FMA python3 -c "$libm_probe")" ]; then
    libm_switch=1
    GLIBC_TUNABLES=$NO_FMA run "$WORK/smocap-normal" "$WORK/sse2"
fi

status=0
count=0
compare() { # compare <folder> <what>
    local other=$1 what=$2 rel missing
    count=0
    while read -r rel; do
        count=$((count + 1))
        if ! cmp -s "$WORK/normal/$rel" "$other/$rel"; then
            echo "differs $what: $rel"
            status=1
        fi
    done < <(cd "$WORK/normal" && find . \( -name '*.mcap' -o -name '*.mot' \) -not -path './.synthetic/*' | sort)
    missing=$(diff <(cd "$WORK/normal" && find . \( -name '*.mcap' -o -name '*.mot' \) | sort) \
        <(cd "$other" && find . \( -name '*.mcap' -o -name '*.mot' \) | sort) || true)
    if [ -n "$missing" ]; then
        echo "the runs wrote different files ($what):"; echo "$missing"
        status=1
    fi
    if [ "$count" -eq 0 ]; then
        echo "cpu_check: no output to compare"; exit 1
    fi
}
compare "$WORK/generic" "with matrixmultiply's generic kernel"
[ $status -eq 0 ] && echo "cpu_check: $count files identical with matrixmultiply's generic kernel"
if [ $libm_switch -eq 1 ]; then
    before=$status
    compare "$WORK/sse2" "with glibc's SSE2 libm (GLIBC_TUNABLES=$NO_FMA)"
    [ $status -eq $before ] && echo "cpu_check: $count files identical with glibc's SSE2 libm variants"
else
    echo "cpu_check: glibc's libm variants cannot be switched here (no FMA, or no python3): that part not checked"
fi
exit $status

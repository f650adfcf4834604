#!/usr/bin/env bash
# A real Slurm run of examples/slurm-array.sh: brings up a single-node Slurm cluster on this
# machine (Debian's slurm-wlm and munge, installed with apt where missing; slurmctld and slurmd
# configured for localhost, started here and stopped on exit), submits the example over a small
# synthetic archive as a 4-task job array, waits for it, joins the shards' summaries with
# `merge-reports`, and compares every output file with a single-machine `convert` of the same
# archive. Exit 0 when all are identical; 1 with a message otherwise; 0 with a note where Slurm
# cannot be installed or started (no apt, not root).
#
#   bash scripts/slurm_check.sh [path/to/smocap]     # default: $SMOCAP_BIN, else target/debug
set -euo pipefail
cd "$(dirname "$0")/.."
REPO=$PWD
SMOCAP=$(realpath "${1:-${SMOCAP_BIN:-${CARGO_TARGET_DIR:-target}/debug/smocap}}")
[ -x "$SMOCAP" ] || { echo "slurm_check: no smocap binary at $SMOCAP (cargo build first)"; exit 1; }
note() { echo "note: slurm_check skipped: $*"; exit 0; }

if ! command -v slurmctld >/dev/null || ! command -v munged >/dev/null; then
    [ "$(id -u)" -eq 0 ] || note "slurm-wlm/munge missing and not root"
    command -v apt-get >/dev/null || note "slurm-wlm/munge missing and no apt-get"
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq slurm-wlm munge >/dev/null) ||
        note "could not install slurm-wlm and munge with apt"
fi
[ "$(id -u)" -eq 0 ] || note "starting slurmctld/slurmd needs root"

WORK=$(mktemp -d "${TMPDIR:-/tmp}/smocap-slurm.XXXXXX")
chmod 755 "$WORK"
CONF=$WORK/etc
mkdir -p "$CONF" "$WORK/spool/ctld" "$WORK/spool/d" "$WORK/log" "$WORK/munge"
HOST=$(hostname -s)
CPUS=$(nproc)
MEM=$(awk '/MemTotal/ {print int($2 / 1024 * 0.8)}' /proc/meminfo)
cat >"$CONF/slurm.conf" <<CONFEOF
ClusterName=smocapcheck
SlurmctldHost=$HOST
SlurmctldPort=16817
SlurmdPort=16818
AuthType=auth/munge
CredType=cred/munge
SlurmUser=root
SlurmdUser=root
StateSaveLocation=$WORK/spool/ctld
SlurmdSpoolDir=$WORK/spool/d
SlurmctldPidFile=$WORK/slurmctld.pid
SlurmdPidFile=$WORK/slurmd.pid
SlurmctldLogFile=$WORK/log/slurmctld.log
SlurmdLogFile=$WORK/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SchedulerType=sched/backfill
ReturnToService=2
MpiDefault=none
JobCompType=jobcomp/none
AccountingStorageType=accounting_storage/none
NodeName=$HOST CPUs=$CPUS RealMemory=$MEM State=UNKNOWN
PartitionName=check Nodes=$HOST Default=YES MaxTime=INFINITE State=UP OverSubscribe=FORCE:4
CONFEOF
export SLURM_CONF=$CONF/slurm.conf

# munge: a key of our own, a daemon with its own socket.
dd if=/dev/urandom of="$WORK/munge/munge.key" bs=1024 count=1 status=none
chmod 400 "$WORK/munge/munge.key"
MUNGE_SOCKET=$WORK/munge/munge.socket
munged --key-file="$WORK/munge/munge.key" --socket="$MUNGE_SOCKET" --pid-file="$WORK/munge/munged.pid" \
    --log-file="$WORK/munge/munged.log" --seed-file="$WORK/munge/munged.seed" -f 2>/dev/null ||
    note "munged did not start"
# slurm's auth/munge plugin finds the socket through its AuthInfo.
sed -i "s#^AuthType=auth/munge#AuthType=auth/munge\nAuthInfo=socket=$MUNGE_SOCKET#" "$CONF/slurm.conf"

cleanup() {
    for p in slurmd slurmctld; do
        [ -f "$WORK/$p.pid" ] && kill "$(cat "$WORK/$p.pid")" 2>/dev/null || true
    done
    [ -f "$WORK/munge/munged.pid" ] && kill "$(cat "$WORK/munge/munged.pid")" 2>/dev/null || true
    sleep 1
    [ -n "${KEEP:-}" ] || rm -rf "$WORK"
}
trap cleanup EXIT
slurmctld -f "$SLURM_CONF" || note "slurmctld did not start (see its log)"
slurmd -f "$SLURM_CONF" || note "slurmd did not start"
for _ in $(seq 60); do
    sinfo -h -o %T 2>/dev/null | grep -q idle && break
    scontrol update nodename="$HOST" state=resume >/dev/null 2>&1 || true
    sleep 1
done
sinfo -h -o %T | grep -q idle || { echo "slurm_check: the node never became idle"; sinfo; cat "$WORK/log/slurmd.log" | tail -20; exit 1; }

# A small archive: 6 synthetic subjects (2 walks each) generated once, read by every run.
ARCH=$WORK/archive
mkdir -p "$ARCH"
cat >"$ARCH/datasets.toml" <<TOML
[[dataset]]
name = "syn"
root = "data"
trials = ["*/walk*.trc"]
subject = "{subject}/{trial}.trc"
static = "{subject}/static.trc"
synthetic = { subjects = 6, trials = 2, frames = 120, seed = 11 }
TOML
"$SMOCAP" convert "$ARCH/datasets.toml" --out "$WORK/single" --jobs 2 --quiet \
    --report-json "$WORK/single.json" >/dev/null

# The example, as a 4-task array, 1 CPU each: every task writes into the same --out.
OUT=$WORK/cluster
JOB=$(cd "$WORK" && SMOCAP=$SMOCAP sbatch --parsable --array=0-3 --cpus-per-task=1 --mem=500M \
    --export=ALL,SLURM_CPUS_PER_TASK=1 "$REPO/examples/slurm-array.sh" "$ARCH/datasets.toml" "$OUT")
JOB=${JOB%%;*}
echo "submitted job array $JOB (4 tasks)"
for _ in $(seq 600); do
    [ -z "$(squeue -h -j "$JOB" 2>/dev/null)" ] && break
    sleep 1
done
[ -z "$(squeue -h -j "$JOB" 2>/dev/null)" ] || { echo "slurm_check: job $JOB did not finish in 10 minutes"; exit 1; }
for i in 0 1 2 3; do
    log=$WORK/smocap-${JOB}_$i.log
    [ -f "$OUT/reports/shard-$i.json" ] || { echo "slurm_check: task $i wrote no summary"; cat "$log" 2>/dev/null; exit 1; }
done
# The tasks ran side by side: all four allocated before the first ended.
started=$(awk '/_job_complete/ {exit} /sched: Allocate JobId='"$JOB"'_/ {n++} END {print n + 0}' "$WORK/log/slurmctld.log")
[ "$started" -eq 4 ] || { echo "slurm_check: only $started of 4 tasks ran at once"; status_together=1; }
"$SMOCAP" merge-reports "$OUT"/reports/shard-*.json --out "$WORK/merged.json" >/dev/null

status=${status_together:-0}
while read -r rel; do
    cmp -s "$WORK/single/$rel" "$OUT/$rel" || { echo "differs from the single-machine run: $rel"; status=1; }
done < <(cd "$WORK/single" && find . -name '*.mcap' | sort)
if ! diff <(cd "$WORK/single" && find . -name '*.mcap' | sort) <(cd "$OUT" && find . -name '*.mcap' | sort); then
    echo "slurm_check: the cluster run wrote other files"; status=1
fi
n=$(cd "$WORK/single" && find . -name '*.mcap' | wc -l)
[ $status -eq 0 ] && echo "slurm_check: 4 array tasks at once into one --out, merged summary, $n files identical to the single-machine run"
exit $status

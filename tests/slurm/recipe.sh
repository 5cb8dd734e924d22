#!/usr/bin/env bash
# The Slurm recipe of docs/scenes.md ("Sharded bakes on a cluster's scheduler"), run as
# written against a real single-node Slurm (Debian's slurm-wlm and munge; scripts/test installs them): a private munged and a
# slurmctld + slurmd with their own configuration, sockets, ports and spool in a temporary
# directory, stopped at the end. The scene has 2 fields and the recipe's array 4 tasks (two
# get no field); the task with the costliest field is killed mid-bake and requeued
# (`scontrol requeue`) and runs again; the merged tables must be byte-identical to a bake
# without shards. Prints how long the scheduler took to start and the recipe to run.
#
# Usage: tests/slurm/recipe.sh [PHOTOMETEOR_BINARY] (default: target/debug/photometeor).
# Needs root (the daemons run as root); elsewhere it says so and skips, except under CI=true,
# where a skip would hide the test, so it fails.
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
bin=$(realpath "${1:-${CARGO_TARGET_DIR:-$root/target}/debug/photometeor}")
skip() {
    if [ "${CI:-}" = true ]; then
        echo "slurm recipe: FAILED: $1 (CI runs this test as root with slurm-wlm and munge)" >&2
        exit 1
    fi
    echo "slurm recipe: skipped: $1"
    exit 0
}
[ "$(id -u)" = 0 ] || skip "needs root to run slurmctld, slurmd and munged"
for c in munged munge slurmctld slurmd sbatch squeue scontrol; do
    command -v "$c" >/dev/null || skip "$c not found (apt-get install slurm-wlm munge)"
done
[ -x "$bin" ] || { echo "slurm recipe: no binary $bin (cargo build first)" >&2; exit 1; }

d=$(mktemp -d /tmp/photometeor-slurm.XXXXXX)
chmod 755 "$d"
stop() {
    # Only what this script started, by its pid file.
    for f in "$d/slurmd.pid" "$d/slurmctld.pid" "$d/munge/munged.pid"; do
        [ -s "$f" ] && kill "$(cat "$f")" 2>/dev/null || true
    done
    sleep 0.5
    rm -rf "$d"
}
trap stop EXIT
fail() {
    echo "slurm recipe: FAILED: $1" >&2
    for log in "$d"/log/*.log "$d"/work/slurm-*.out; do
        [ -f "$log" ] && { echo "--- $log" >&2; tail -n 20 "$log" >&2; }
    done
    exit 1
}
now() { date +%s.%N; }
since() { awk -v a="$1" -v b="$(now)" 'BEGIN { printf "%.1f", b - a }'; }

t0=$(now)
# munge: a key of our own and a socket of our own.
mkdir -p "$d/munge" "$d/state" "$d/spool" "$d/log" "$d/work"
head -c 1024 /dev/urandom > "$d/munge.key"
chmod 600 "$d/munge.key"
munged --force --key-file="$d/munge.key" --socket="$d/munge/munge.sock" \
    --pid-file="$d/munge/munged.pid" --log-file="$d/log/munged.log" \
    --seed-file="$d/munge/seed"
host=$(hostname -s)
port=$((20000 + $$ % 20000))
cat > "$d/slurm.conf" <<CONF
ClusterName=photometeor-test
SlurmctldHost=$host
SlurmctldPort=$port
SlurmdPort=$((port + 1))
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$d/munge/munge.sock
SlurmUser=root
SlurmdUser=root
StateSaveLocation=$d/state
SlurmdSpoolDir=$d/spool
SlurmctldPidFile=$d/slurmctld.pid
SlurmdPidFile=$d/slurmd.pid
SlurmctldLogFile=$d/log/slurmctld.log
SlurmdLogFile=$d/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MpiDefault=none
SchedulerType=sched/builtin
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
MinJobAge=600
NodeName=$host CPUs=$(nproc) State=UNKNOWN
PartitionName=test Nodes=ALL Default=YES MaxTime=INFINITE State=UP
CONF
export SLURM_CONF="$d/slurm.conf"
slurmctld -i
slurmd
for _ in $(seq 150); do
    sinfo -h -o %T 2>/dev/null | grep -qx idle && break
    sleep 0.2
done
sinfo -h -o %T | grep -qx idle || fail "the node did not come up"
startup=$(since "$t0")

# The recipe, as docs/scenes.md has it: the lines from "# Slurm:" to the first blank line.
recipe=$(awk '/^# Slurm: /{on=1} on && /^$/{exit} on' "$root/docs/scenes.md")
echo "$recipe" | grep -q 'sbatch --parsable --array' || fail "no Slurm recipe found in docs/scenes.md"
cd "$d/work"
cat > scene.toml <<'SCENE'
[scene]
name = "slurm"
spectral = "rgb3"
n_max = 4
quality = "draft"

[[field]]
name = "cloud"
kind = "cloud"
distribution = { kind = "gamma", r_eff_um = 8, v_eff = 0.1 }

[[field]]
name = "rain"
kind = "rain"
distribution = { kind = "lognormal", median_radius_um = 2000, sigma_g = 1.4 }
SCENE
mkdir -p bin
ln -s "$bin" bin/photometeor
export PATH="$d/work/bin:$PATH"

t1=$(now)
eval "$recipe" > recipe.out
merge=$(awk '/Submitted batch job/ { print $NF }' recipe.out | tail -n 1)
[ -n "${jid:-}" ] && [ -n "$merge" ] || fail "the recipe did not submit its two jobs: $(cat recipe.out)"
# Shard 1/4 (task 0) holds the rain, the costliest field (2 mm drops: about 3 s on 2 cores;
# 0.15 mm ones finished within the second this waits): kill it a moment into its bake and
# requeue it. A requeued task waits (BeginTime) before it may start again; it is let go now.
for _ in $(seq 300); do
    [ "$(squeue -h -j "${jid}_0" -o %T 2>/dev/null)" = RUNNING ] && break
    sleep 0.1
done
[ "$(squeue -h -j "${jid}_0" -o %T)" = RUNNING ] || fail "task 0 never ran"
sleep 1
scontrol requeue "${jid}_0"
for _ in $(seq 100); do
    [ "$(squeue -h -j "${jid}_0" -o %T 2>/dev/null)" = PENDING ] && break
    sleep 0.1
done
scontrol update JobId="${jid}_0" StartTime=now
for _ in $(seq 1200); do
    state=$(scontrol show job "$merge" | sed -n 's/.*JobState=\([A-Z_]*\).*/\1/p')
    case "$state" in
        COMPLETED) break ;;
        FAILED | CANCELLED | TIMEOUT | NODE_FAIL | OUT_OF_MEMORY) fail "the merge job ended $state" ;;
    esac
    sleep 0.1
done
[ "$state" = COMPLETED ] || fail "the merge did not complete within 120 s (state $state)"
run=$(since "$t1")
scontrol show job "${jid}_0" | grep -q 'Restarts=1' || fail "task 0 was not requeued"
grep -q 'CANCELLED AT .* DUE TO JOB REQUEUE' "$d/log/slurmd.log" ||
    fail "task 0 was not killed by the requeue"

# The merge against a bake without shards: the same published files, byte for byte.
photometeor bake scene.toml --out full --quiet
published() { (cd "$1" && find . -maxdepth 1 -type f ! -name '.*' | sort); }
[ "$(published tables)" = "$(published full)" ] || fail "the merge holds other files than the bake"
count=0
while read -r f; do
    cmp -s "tables/$f" "full/$f" || fail "$f differs from the bake without shards"
    count=$((count + 1))
done < <(published full)
[ "$count" -ge 9 ] || fail "only $count published files"
echo "slurm recipe: ok: 4 tasks for 2 fields, task 0 killed and requeued, the merge's $count" \
    "files byte-identical to the bake without shards; Slurm up in $startup s, the recipe" \
    "(submit to merged) $run s"

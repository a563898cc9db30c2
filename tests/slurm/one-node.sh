#!/usr/bin/env bash
# A one-node Slurm cluster on loopback, started and stopped here, renders CONFIG as a job
# array of PARTS parts with docs/distributed/slurm-array.sh under a per-task memory limit,
# kills one task and resubmits it, and merges the parts into OUT. Everything lives in
# WORK (state, spool, logs, munge key and socket); every daemon started is stopped on exit.
# Exit 77 with a line "skip: <reason>" when this machine cannot run it (not root, no Slurm).
#
#   FLOWLIGHT=path/to/flowlight CONFIG=scene.toml OUT=merged.exr WORK=/tmp/x PARTS=4 \
#       bash tests/slurm/one-node.sh
set -euo pipefail
: "${FLOWLIGHT:?}" "${CONFIG:?}" "${OUT:?}" "${WORK:?}"
parts=${PARTS:-4}
# Each task's address space (KiB), the limit `ulimit -v` enforces where no cgroup task
# plugin can run (containers without a writable cgroup hierarchy): ample for a small render.
task_vsize_kib=${TASK_VSIZE_KIB:-8000000}
recipe="$(cd "$(dirname "$0")/../.." && pwd)/docs/distributed/slurm-array.sh"

skip() { echo "skip: $*"; exit 77; }
[ "$(id -u)" = 0 ] || skip "the one-node cluster runs its daemons as root (SlurmUser=root); this is uid $(id -u)"
for c in slurmctld slurmd sbatch squeue scancel sinfo munged; do
    command -v "$c" >/dev/null || skip "$c is not installed (Debian: apt-get install slurmd slurmctld slurm-client munge)"
done

mkdir -p "$WORK"/{state,spool,parts,logs}
pids=()
cleanup() {
    for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
    sleep 0.5
    for p in "${pids[@]}"; do kill -9 "$p" 2>/dev/null || true; done
}
trap cleanup EXIT

# munge: a fresh key, its own socket.
dd if=/dev/urandom of="$WORK/munge.key" bs=1024 count=1 status=none
chmod 0400 "$WORK/munge.key"
munged --force --key-file="$WORK/munge.key" --socket="$WORK/munge.socket" \
    --pid-file="$WORK/munged.pid" --log-file="$WORK/logs/munged.log" \
    --seed-file="$WORK/munged.seed"
for _ in $(seq 50); do [ -s "$WORK/munged.pid" ] && break; sleep 0.1; done
pids+=("$(cat "$WORK/munged.pid")")

# Two free ports on loopback for the controller and the node daemon.
port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
ctld_port=$(port)
node_port=$(port)
cpus=$(nproc)
export SLURM_CONF="$WORK/slurm.conf"
cat >"$SLURM_CONF" <<CONF
ClusterName=flowlight
SlurmctldHost=localhost(127.0.0.1)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$WORK/munge.socket
CredType=cred/munge
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SwitchType=switch/none
MpiDefault=none
SlurmctldPort=$ctld_port
SlurmdPort=$node_port
StateSaveLocation=$WORK/state
SlurmdSpoolDir=$WORK/spool
SlurmctldPidFile=$WORK/slurmctld.pid
SlurmdPidFile=$WORK/slurmd.pid
SlurmctldLogFile=$WORK/logs/slurmctld.log
SlurmdLogFile=$WORK/logs/slurmd.log
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
ReturnToService=2
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/none
NodeName=localhost NodeAddr=127.0.0.1 CPUs=$cpus State=UNKNOWN
PartitionName=flowlight Nodes=localhost Default=YES MaxTime=INFINITE State=UP
CONF

slurmctld -D -i >"$WORK/logs/slurmctld.out" 2>&1 &
pids+=($!)
slurmd -D -N localhost >"$WORK/logs/slurmd.out" 2>&1 &
pids+=($!)
wait_for() { # seconds, description, command...
    local t=$1 what=$2; shift 2
    for _ in $(seq $((t * 5))); do "$@" >/dev/null 2>&1 && return 0; sleep 0.2; done
    echo "timed out after ${t}s waiting for $what" >&2
    tail -n 20 "$WORK"/logs/*.log "$WORK"/logs/*.out >&2 || true
    exit 1
}
idle() { sinfo -h -N -o %t | grep -q idle; }
wait_for 60 "the node to come up idle" idle

# The job script: the recipe under `ulimit -v`; task 2's first run waits to be killed.
cat >"$WORK/job.sh" <<JOB
#!/usr/bin/env bash
ulimit -v $task_vsize_kib
if [ "\${SLURM_ARRAY_TASK_ID}" = 2 ] && mkdir "$WORK/task2-first-run" 2>/dev/null; then
    sleep 600
fi
exec bash "$recipe"
JOB
export CONFIG FLOWLIGHT PARTS_DIR="$WORK/parts"
submit() { sbatch --parsable --cpus-per-task=1 --output="$WORK/logs/task-%A_%a.log" "$@" "$WORK/job.sh"; }
jid=$(submit --array=0-$((parts - 1)))
echo "submitted array job $jid of $parts tasks"
running2() { squeue -h -j "${jid}_2" -t R -o %i | grep -q .; }
wait_for 120 "task 2 to run" running2
scancel "${jid}_2"
echo "killed task ${jid}_2"
done_all() { [ -z "$(squeue -h -j "$jid" -o %i)" ]; }
wait_for 300 "the array to finish" done_all
[ ! -e "$WORK/parts/part-2.exr" ] || { echo "the killed task left a part" >&2; exit 1; }
# The resubmitted task keeps the array's part count: PARTS overrides the one-task array's.
jid2=$(PARTS=$parts submit --array=2)
echo "resubmitted task 2 as job $jid2"
done2() { [ -z "$(squeue -h -j "$jid2" -o %i)" ]; }
wait_for 300 "the resubmitted task to finish" done2
for k in $(seq 0 $((parts - 1))); do
    [ -s "$WORK/parts/part-$k.exr" ] || { echo "part $k is missing" >&2; cat "$WORK"/logs/task-*.log >&2; exit 1; }
done
"$FLOWLIGHT" merge "$OUT" "$WORK"/parts/part-*.exr

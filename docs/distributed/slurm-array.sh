#!/usr/bin/env bash
# One part of a distributed render per Slurm array task. See docs/distributed.md.
#
#   export CONFIG=/shared/shot/scene.toml PARTS_DIR=/shared/shot/parts
#   jid=$(sbatch --parsable --array=0-15 slurm-array.sh)
#   sbatch --dependency=afterok:$jid --wrap \
#       "flowlight merge /shared/shot/final.exr $PARTS_DIR/part-*.exr"
#
# Task K of an array of N renders `--part K/N` with all the task's CPUs. Array indices must
# run from 0 to N-1 (--array=0-15, not 1-16). sbatch passes the environment on, so CONFIG,
# PARTS_DIR, PARTS, FLOWLIGHT and FLOWLIGHT_ARGS reach the tasks.
#SBATCH --job-name=flowlight-part
#SBATCH --cpus-per-task=16
#SBATCH --output=flowlight-part-%A_%a.log
set -euo pipefail
: "${CONFIG:?set CONFIG to the render config}" "${PARTS_DIR:?set PARTS_DIR to a shared folder}"
k=${SLURM_ARRAY_TASK_ID:?not a Slurm array task}
# PARTS, when set, is N: a failed task resubmitted alone (`PARTS=16 sbatch --array=5 ...`)
# runs in an array of one task, whose SLURM_ARRAY_TASK_COUNT is 1.
n=${PARTS:-${SLURM_ARRAY_TASK_COUNT:?not a Slurm array task}}
read -r -a extra <<<"${FLOWLIGHT_ARGS:-}"
mkdir -p "$PARTS_DIR"
exec "${FLOWLIGHT:-flowlight}" render "$CONFIG" --part "$k/$n" \
    --threads "${SLURM_CPUS_PER_TASK:-0}" --out "$PARTS_DIR/part-$k.exr" -q "${extra[@]}"

#!/usr/bin/env bash
# Train on a Slurm cluster, MMSeg's interface:
#
#   bash tools/slurm_train.sh PARTITION JOB_NAME CONFIG [GPUS] [train.py arguments...]
#
# GPUS (default 8) tasks of one GPU each, GPUS_PER_NODE (8) per node, CPUS_PER_TASK
# (5) cores each; SRUN_ARGS are passed to srun. Slurm runs need GPUs.
set -euo pipefail
if [ $# -lt 3 ]; then
    echo "usage: bash $0 PARTITION JOB_NAME CONFIG [GPUS] [train.py arguments...]" >&2
    exit 2
fi
PARTITION=$1
JOB_NAME=$2
CONFIG=$3
shift 3
GPUS=8
if [ $# -gt 0 ] && [[ $1 =~ ^[0-9]+$ ]]; then
    GPUS=$1
    shift
fi
GPUS_PER_NODE=${GPUS_PER_NODE:-$(( GPUS < 8 ? GPUS : 8 ))}
# SRUN_ARGS is split into words on purpose: it holds several srun options.
# shellcheck disable=SC2086
exec srun -p "$PARTITION" --job-name="$JOB_NAME" \
    --gres=gpu:"$GPUS_PER_NODE" --ntasks="$GPUS" \
    --ntasks-per-node="$GPUS_PER_NODE" --cpus-per-task="${CPUS_PER_TASK:-5}" \
    --kill-on-bad-exit=1 ${SRUN_ARGS:-} \
    "${PYTHON:-python}" -u "$(dirname "$0")/train.py" "$CONFIG" --launcher slurm "$@"

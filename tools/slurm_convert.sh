#!/usr/bin/env bash
# Build Spike-Cityscapes on a Slurm cluster, one shard per array task:
#
#   sbatch --array=1-N [sbatch options] tools/slurm_convert.sh CITYSCAPES_ROOT OUT_DIR [spike_cityscapes.py arguments...]
#
# Task K of the N tasks runs tools/dataset_converters/spike_cityscapes.py with
# --shard K/N (K and N from SLURM_ARRAY_TASK_ID, _MIN and _COUNT, so any
# contiguous range works: --array=0-15 gives 16 shards), all writing into the
# shared OUT_DIR; together they write what one run writes. A failed or killed
# task leaves its unfinished samples absent: resubmit it (or the whole array),
# done samples are skipped. CPUs per task: the converter's --nproc (default 1).
# Run with bash outside Slurm for one shard: SLURM_ARRAY_TASK_ID=2
# SLURM_ARRAY_TASK_MIN=1 SLURM_ARRAY_TASK_COUNT=4 bash tools/slurm_convert.sh ...
#SBATCH --job-name=spike_cityscapes
#SBATCH --ntasks=1
set -euo pipefail
if [ $# -lt 2 ]; then
    echo "usage: sbatch --array=1-N $0 CITYSCAPES_ROOT OUT_DIR [spike_cityscapes.py arguments...]" >&2
    exit 2
fi
if [ -z "${SLURM_ARRAY_TASK_ID:-}" ] || [ -z "${SLURM_ARRAY_TASK_COUNT:-}" ]; then
    echo "$0: not an array task (SLURM_ARRAY_TASK_ID/_COUNT unset); submit with sbatch --array=1-N" >&2
    exit 2
fi
SHARD_INDEX=$(( SLURM_ARRAY_TASK_ID - ${SLURM_ARRAY_TASK_MIN:-1} + 1 ))
# sbatch runs a copy of this script from its spool directory: find the tools
# from the submission directory unless WGSE_MMSEG_ROOT says where.
ROOT=${WGSE_MMSEG_ROOT:-${SLURM_SUBMIT_DIR:-$(cd "$(dirname "$0")/.." && pwd)}}
exec "${PYTHON:-python}" -u "$ROOT/tools/dataset_converters/spike_cityscapes.py" \
    "$@" --shard "$SHARD_INDEX/$SLURM_ARRAY_TASK_COUNT"

#!/usr/bin/env bash
# Train on GPUS processes of this machine (or NNODES machines), MMSeg's interface:
#
#   bash tools/dist_train.sh CONFIG GPUS [train.py arguments...]
#   bash tools/dist_train.sh configs/pspnet_wgse.py 8 --cfg-options data_root=DIR
#
# One process per GPU; the batch in the config is per process (MMSeg's convention:
# 8 GPUs x batch 2 is a total batch of 16), and BN becomes SyncBN (`sync_bn` in
# configs/_base_/default_runtime.py). Without CUDA the processes run on the CPU with
# gloo: the way to try a multi-process run without GPUs (docs/user_guide.md, "Train and test").
# Variables: NNODES (1), NODE_RANK (0), MASTER_ADDR (127.0.0.1), PORT (29500),
# PYTHON (python).
set -euo pipefail
if [ $# -lt 2 ]; then
    echo "usage: bash $0 CONFIG GPUS [train.py arguments...]" >&2
    exit 2
fi
CONFIG=$1
GPUS=$2
shift 2
exec "${PYTHON:-python}" -m torch.distributed.run \
    --nnodes="${NNODES:-1}" --node_rank="${NODE_RANK:-0}" \
    --master_addr="${MASTER_ADDR:-127.0.0.1}" --master_port="${PORT:-29500}" \
    --nproc_per_node="$GPUS" \
    "$(dirname "$0")/train.py" "$CONFIG" --launcher pytorch "$@"

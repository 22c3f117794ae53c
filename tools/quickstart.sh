#!/usr/bin/env bash
# The main job on a fresh machine, start to finish on CPU:
#   1. the pinned environment (tools/setup_env.sh, idempotent: .venv, or
#      .venv-onedl with STACK=onedl),
#   2. the embedded dataset (procedural street scenes as spikes, T=41),
#   3. SegFormer-B0 + WGSE trained on it (resumes if interrupted),
#   4. the final checkpoint evaluated: mIoU, mAcc and aAcc.
# Variables: CONFIG (default configs/segformer_b0_wgse.py), EPOCHS (default 5),
# DATA (dataset root), NUM_TRAIN and NUM_VAL (its training and validation
# samples, default 48 and 12), WORK (work dir); STACK, VENV as for
# tools/setup_env.sh.
set -euo pipefail
cd "$(dirname "$0")/.."

CONFIG=${CONFIG:-configs/segformer_b0_wgse.py}
EPOCHS=${EPOCHS:-5}
DATA=${DATA:-data/synthetic_spike_cityscapes}
NUM_TRAIN=${NUM_TRAIN:-48}
NUM_VAL=${NUM_VAL:-12}
WORK=${WORK:-work_dirs/quickstart_$(basename "$CONFIG" .py)}
# check_count NAME LEAST [WHY]: stop unless variable NAME is an integer >= LEAST
check_count() {
    if ! [[ "${!1}" =~ ^[0-9]+$ ]] || [ "${!1}" -lt "$2" ]; then
        echo "quickstart.sh: $1 must be an integer >= $2${3:+ ($3)}, got '${!1}'" >&2
        exit 2
    fi
}
# a one-epoch warm-up, then the decay: two epochs at least
check_count EPOCHS 2 'one warm-up epoch, then the decay'
check_count NUM_TRAIN 1
check_count NUM_VAL 1

source tools/setup_env.sh  # sets VENV
PY=$VENV/bin/python
"$PY" tools/dataset_converters/make_synthetic_dataset.py "$DATA" --num-steps 41 \
    --num-train "$NUM_TRAIN" --num-val "$NUM_VAL"

# The embedded data: T=41, 128x256 frames, 64x128 crops; a one-epoch warm-up
# and a short schedule instead of the paper's 10 of 100 epochs; no
# validation during training (step 4 evaluates the final checkpoint); a
# fixed seed (randomness.seed=0), so a rerun prints the same metrics.
DATA_OPTS=(data_root="$DATA" num_steps=41 crop_size=64,128)
"$PY" tools/train.py "$CONFIG" --work-dir "$WORK" --resume --cfg-options \
    "${DATA_OPTS[@]}" \
    train_cfg.max_epochs="$EPOCHS" train_cfg.val_begin=$((EPOCHS + 1)) \
    param_scheduler.0.end=1 param_scheduler.1.begin=1 \
    param_scheduler.1.end="$EPOCHS" \
    default_hooks.checkpoint.interval=1 default_hooks.checkpoint.max_keep_ckpts=2 \
    default_hooks.logger.interval=4 randomness.seed=0
"$PY" tools/test.py "$CONFIG" "$WORK/epoch_$EPOCHS.pth" \
    --work-dir "$WORK/test" --cfg-options "${DATA_OPTS[@]}"

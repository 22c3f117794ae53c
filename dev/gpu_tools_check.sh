#!/usr/bin/env bash
# The training tools on one GPU, end to end, as a user runs them: a small synthetic set
# (16 + 4 samples, T=41, 128x256), then tools/train.py (PSPNet + WGSE, 2 epochs, a
# checkpoint and a validation each), tools/test.py on its last checkpoint, SegFormer-B0 +
# WGSE with --amp, and tools/dist_train.sh with one GPU (NCCL). On a machine with torch
# alone, from a copy of the tree with gpu_bundle/ (bash dev/gpu_bundle.sh build here,
# as for dev/gpu_report.sh). Each run's whole log is kept in OUT_DIR, its progress,
# first-use check and metric lines are printed; the exit status is the number of runs
# that failed. About 3 minutes on one H200 (docs/wgse_speed.md, "On a GPU").
#
#   bash dev/gpu_tools_check.sh [OUT_DIR]      # default gpu_tools_check
set -uo pipefail
cd "$(dirname "$0")/.."
OUT_DIR=${1:-gpu_tools_check}
mkdir -p "$OUT_DIR"
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
DIR=${GPU_BUNDLE:-gpu_bundle}
[ -d "$DIR/site" ] || bash dev/gpu_bundle.sh install "$DIR" > "$OUT_DIR/bundle.log" 2>&1 ||
    { echo "[gpu_tools_check] the bundle did not install: $OUT_DIR/bundle.log" >&2; exit 99; }
export PYTHONPATH="$PWD/$DIR/site:$PWD${PYTHONPATH:+:$PYTHONPATH}" PYTHON=${PYTHON:-python3}
"$PYTHON" tools/dataset_converters/make_synthetic_dataset.py "$WORK/data" --num-train 16 \
    --num-val 4 --num-steps 41 || exit 99
SETTINGS=(data_root="$WORK/data" num_steps=41 crop_size=128,256 train_cfg.max_epochs=2
          train_cfg.val_interval=1 default_hooks.checkpoint.interval=1
          default_hooks.logger.interval=2 randomness.seed=0)
FAILED=0
run() {  # NAME COMMAND...: one run, its log in OUT_DIR/NAME.log
    local name=$1 start=$SECONDS status
    shift
    echo "== $name: $*"
    "$@" > "$OUT_DIR/$name.log" 2>&1
    status=$?
    grep -E 'Epoch\(|WGSE: |rror|Traceback' "$OUT_DIR/$name.log" | cut -c1-200 | tail -8
    echo "== $name: exit $status in $((SECONDS - start)) s"
    [ "$status" -eq 0 ] || FAILED=$((FAILED + 1))
}
run train "$PYTHON" tools/train.py configs/pspnet_wgse.py --work-dir "$WORK/train" \
    --cfg-options "${SETTINGS[@]}"
run test "$PYTHON" tools/test.py configs/pspnet_wgse.py "$WORK/train/epoch_2.pth" \
    --work-dir "$WORK/test" --cfg-options data_root="$WORK/data" num_steps=41
run train_amp "$PYTHON" tools/train.py configs/segformer_b0_wgse.py --amp \
    --work-dir "$WORK/amp" --cfg-options "${SETTINGS[@]}"
run dist_train bash tools/dist_train.sh configs/pspnet_wgse.py 1 --work-dir "$WORK/dist" \
    --cfg-options "${SETTINGS[@]}"
echo "[gpu_tools_check] $FAILED of 4 runs failed; logs in $OUT_DIR"
exit "$FAILED"

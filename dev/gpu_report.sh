#!/usr/bin/env bash
# WGSE on a GPU in one command, on a machine that has torch and triton but nothing of
# OpenMMLab and no network: installs dev/gpu_bundle.sh's wheels (offline, into
# DIR/site), then runs dev/gpu_report.py, which writes docs/gpu.md
# and gpu.json beside it, the most telling sections first, within a time budget (--budget,
# 420 s by default); the sections it leaves, a second run with --resume measures.
#
#   bash dev/gpu_bundle.sh build        # first, here, with network (wheels for Python 3.12)
#   bash dev/gpu_report.sh [ARGS]       # there, from a copy of the tree with gpu_bundle/
#
# GPU_BUNDLE (default gpu_bundle) names the wheel directory; ARGS go to gpu_report.py
# (--out-dir DIR; --budget SECONDS; --resume: after a run its budget or a time limit stopped,
# measure only the sections it did not finish; --dry-run: the CPU check, into a temporary
# folder). If the bundle does not install or import, the report still runs: its WGSE
# sections need torch alone, and the segmentation sections record the error.
set -uo pipefail
cd "$(dirname "$0")/.."
DIR=${GPU_BUNDLE:-gpu_bundle}
if [ -d "$DIR/site" ]; then
    echo "[gpu_report] using the wheels already installed in $DIR/site"
else
    bash dev/gpu_bundle.sh install "$DIR" || echo "[gpu_report] the bundle did not install (see above): the segmentation sections will fail" >&2
fi
export PYTHONPATH="$PWD/$DIR/site:$PWD${PYTHONPATH:+:$PYTHONPATH}"
exec python3 dev/gpu_report.py "$@"

#!/usr/bin/env bash
# Run the benchmarks and training on a GPU machine that has torch (and triton) but
# nothing of OpenMMLab and no network: the pure-Python stack as wheels (about 10 MB).
#
#   bash dev/gpu_bundle.sh build [DIR]     # here, with network: download the wheels into DIR
#   bash dev/gpu_bundle.sh install [DIR]   # there, offline: install them into DIR/site
#   export PYTHONPATH=$PWD/DIR/site:$PWD     # there: then tools/*.py run as usual
#
# DIR defaults to gpu_bundle (git-ignored: carry it to the GPU machine with the tree).
# PYVER (default 3.12) is the GPU machine's Python. See docs/wgse_speed.md, "On a GPU".
set -euo pipefail
cd "$(dirname "$0")/.."

ACTION=${1:-}
DIR=${2:-gpu_bundle}
PYVER=${PYVER:-3.12}
# What the package needs beyond torch, numpy, opencv, matplotlib, scipy, pyyaml and
# rich, which such a machine has. mmcv-lite: mmcv without compiled ops
# (wgse_mmseg supplies the mmcv.ops that mmseg imports); setuptools < 81 keeps the
# pkg_resources that mmengine imports.
PACKAGES=(
    mmengine==0.10.7 mmsegmentation==1.2.2 mmcv-lite==2.1.0 pytorch_wavelets==1.3.0
    addict yapf platformdirs termcolor prettytable wcwidth ftfy regex tqdm PyWavelets
    "setuptools>=61,<81"
)

case "$ACTION" in
  build)
    mkdir -p "$DIR"
    python3 -m pip download --quiet --no-deps --only-binary=:all: \
        --python-version "$PYVER" --platform manylinux2014_x86_64 --platform any \
        --dest "$DIR" "${PACKAGES[@]}"
    echo "[gpu_bundle] $(ls "$DIR"/*.whl | wc -l) wheels, $(du -sh "$DIR" | cut -f1) in $DIR (Python $PYVER)"
    ;;
  install)
    ls "$DIR"/*.whl >/dev/null 2>&1 || { echo "[gpu_bundle] no wheels in $DIR: run 'build' first" >&2; exit 2; }
    python3 -m pip install --quiet --no-deps --no-index --disable-pip-version-check \
        --target "$DIR/site" "$DIR"/*.whl
    PYTHONPATH="$DIR/site:$PWD" python3 -c "import torch, mmengine, mmseg, wgse_mmseg; print('[gpu_bundle] ready: torch', torch.__version__, '| cuda', torch.cuda.is_available(), '| mmseg', mmseg.__version__)"
    echo "[gpu_bundle] export PYTHONPATH=$PWD/$DIR/site:$PWD"
    ;;
  *)
    echo "usage: bash dev/gpu_bundle.sh build|install [DIR]" >&2
    exit 2
    ;;
esac

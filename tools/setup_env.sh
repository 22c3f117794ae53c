#!/usr/bin/env bash
# Create (or bring up to date) the project's virtual environment in .venv.
#
#   bash tools/setup_env.sh            # mmcv-lite + bundled op fallbacks: ~3 minutes
#   MMCV=full bash tools/setup_env.sh  # full mmcv 2.1.0 with compiled ops: ~30 minutes on 2 cores
#
# Idempotent: a second run only checks the pins. Variables: VENV (default .venv),
# MMCV (lite|full), PYTHON (default python3.11, else python3).
set -euo pipefail
cd "$(dirname "$0")/.."

VENV=${VENV:-.venv}
MMCV=${MMCV:-lite}
PYTHON=${PYTHON:-$(command -v python3.11 || command -v python3)}
TORCH_PIN=torch==2.13.0
MMCV_VERSION=2.1.0

if [ ! -x "$VENV/bin/python" ]; then
    echo "[setup_env] creating $VENV with $PYTHON"
    "$PYTHON" -m venv "$VENV"
fi
PIP=("$VENV/bin/python" -m pip --disable-pip-version-check)

# torch first and pinned exactly: an unpinned torch pulls several GB of CUDA wheels.
# setuptools < 80 keeps pkg_resources (mmengine, mim) and `setup.py develop`'s
# egg-link (below); pip < 25.3 still runs it; wheel and ninja build mmcv.
"${PIP[@]}" install -q "$TORCH_PIN" "setuptools>=61,<80" "pip>=21,<25.3" wheel ninja

installed_mmcv() { "$VENV/bin/python" - <<'PY'
import importlib.metadata as md
for name in ("mmcv", "mmcv-lite"):
    try:
        print(name, md.version(name)); break
    except md.PackageNotFoundError:
        pass
PY
}

case "$MMCV" in
  lite)
    if [ "$(installed_mmcv)" != "mmcv-lite $MMCV_VERSION" ]; then
        "${PIP[@]}" uninstall -q -y mmcv mmcv-lite >/dev/null 2>&1 || true
        "${PIP[@]}" install -q "mmcv-lite==$MMCV_VERSION"
    fi ;;
  full)
    if [ "$(installed_mmcv)" != "mmcv $MMCV_VERSION" ]; then
        "${PIP[@]}" uninstall -q -y mmcv mmcv-lite >/dev/null 2>&1 || true
        echo "[setup_env] compiling mmcv $MMCV_VERSION with ops (about 30 minutes on 2 cores; pip caches the wheel)"
        MMCV_WITH_OPS=1 "${PIP[@]}" install --no-build-isolation "mmcv==$MMCV_VERSION"
    fi ;;
  *) echo "[setup_env] MMCV must be 'lite' or 'full', not '$MMCV'" >&2; exit 2 ;;
esac

# The rest of the stack; the torch constraint stops any dependency from upgrading torch.
echo "$TORCH_PIN" > "$VENV/torch-constraint.txt"
"${PIP[@]}" install -q -c "$VENV/torch-constraint.txt" -r requirements/runtime.txt -r requirements/tests.txt -r requirements/docs.txt
# Editable, as `setup.py develop` (an egg-link to this checkout), not PEP 660:
# mim finds configs/ and tools/ through pkg_resources' location of the package,
# which is this checkout for an egg-link but site-packages for a PEP 660 install.
"${PIP[@]}" install -q --no-build-isolation --no-deps --no-use-pep517 -e .

"$VENV/bin/python" -c "import wgse_mmseg, mmseg, mmcv, torch; print('[setup_env] ready: torch', torch.__version__, '| mmcv', mmcv.__version__, '| mmseg', mmseg.__version__, '| wgse_mmseg', wgse_mmseg.__version__)"

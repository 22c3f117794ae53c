#!/usr/bin/env bash
# Create (or bring up to date) a virtual environment with one of the two
# OpenMMLab stacks the package runs on (docs/install.md):
#
#   bash tools/setup_env.sh                  # STACK=openmmlab in .venv: OpenMMLab's final releases
#   STACK=onedl bash tools/setup_env.sh      # the maintained onedl-* fork, in .venv-onedl
#   MMCV=full bash tools/setup_env.sh        # mmcv with compiled ops, built from source (~30 min on 2 cores)
#   STACK=onedl MMCV=full MMCV_WHEELS=URL bash tools/setup_env.sh   # the fork's prebuilt CUDA wheels
#
# Idempotent: a second run only checks the pins (pip only when a requirement
# file, this script, a setting or an installed distribution changed). Variables: STACK (openmmlab|onedl),
# VENV (default .venv, .venv-onedl for onedl), MMCV (lite|full), MMCV_WHEELS (the fork's
# wheel index for your torch and CUDA, https://mmwheels.onedl.ai/), TORCH (default 2.13.0),
# PYTHON (default python3.11, else python3). Sourced (tools/run_tests.sh), it leaves VENV set.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

STACK=${STACK:-openmmlab}
MMCV=${MMCV:-lite}
TORCH_PIN=torch==${TORCH:-2.13.0}
PYTHON=${PYTHON:-$(command -v python3.11 || command -v python3)}
# What differs between the stacks: the venv's default place, the requirements
# file with the stack's pins, the mmcv distribution and version, the tools pip
# needs for the editable install (see "Editable install" below).
case "$STACK" in
  openmmlab)
    VENV=${VENV:-.venv}
    MMCV_LITE=mmcv-lite MMCV_FULL=mmcv MMCV_VERSION=2.1.0 MMCV_CACHE=()
    # setuptools < 80 keeps pkg_resources (mmengine 0.10.7, mim 0.3.8) and
    # `setup.py develop`'s egg-link; pip < 25.3 still runs it.
    BUILD_TOOLS=("setuptools>=61,<80" "pip>=21,<25.3") ;;
  onedl)
    VENV=${VENV:-.venv-onedl}
    # onedl-mmcv is one distribution: without torch in pip's isolated build
    # environment it builds without its compiled ops (the lite install).
    # pip's wheel cache does not tell the two builds apart: no cache.
    MMCV_LITE=onedl-mmcv MMCV_FULL=onedl-mmcv MMCV_VERSION=2.3.6 MMCV_CACHE=(--no-cache-dir)
    BUILD_TOOLS=("setuptools>=80" "pip>=25") ;;  # onedl-mim needs setuptools >= 80
  *) echo "[setup_env] STACK must be 'openmmlab' or 'onedl', not '$STACK'" >&2; exit 2 ;;
esac
case "$MMCV" in lite|full) ;; *) echo "[setup_env] MMCV must be 'lite' or 'full', not '$MMCV'" >&2; exit 2 ;; esac

if [ ! -x "$VENV/bin/python" ]; then
    echo "[setup_env] creating $VENV ($STACK stack) with $PYTHON"
    "$PYTHON" -m venv "$VENV"
    echo "$STACK" > "$VENV/wgse-stack"
fi
# One stack per venv: pip would install the other's distributions over the
# same import packages (mmseg, mmengine, mmcv, mim).
if [ "$(cat "$VENV/wgse-stack" 2>/dev/null || echo openmmlab)" != "$STACK" ]; then
    echo "[setup_env] $VENV holds the $(cat "$VENV/wgse-stack") stack, not $STACK: give another VENV=..., or remove $VENV" >&2
    exit 2
fi
PIP=("$VENV/bin/python" -m pip --disable-pip-version-check)

# pip checks the pins below only when something it reads has changed since
# its last check passed here: this script, the requirement files, the
# settings, or the distributions installed in the venv (their names and
# versions); otherwise its answer would be the same "all satisfied".
pins_stamp() {
    { echo "$STACK $MMCV ${MMCV_WHEELS:-} $TORCH_PIN"
      cat tools/setup_env.sh "requirements/$STACK.txt" requirements/runtime.txt \
          requirements/tests.txt requirements/docs.txt
      "$VENV/bin/python" -c 'import importlib.metadata as md
print(sorted(f"{d.metadata['"'"'Name'"'"']}=={d.version}" for d in md.distributions()))'
    } | sha256sum | cut -d' ' -f1
}
if [ "$(cat "$VENV/wgse-pins" 2>/dev/null)" = "$(pins_stamp)" ]; then
    PINS_CHECKED=1
else
    PINS_CHECKED=0
fi

# torch first and pinned exactly: an unpinned torch pulls several GB of CUDA
# wheels. wheel and ninja build mmcv's ops.
[ "$PINS_CHECKED" = 1 ] || "${PIP[@]}" install -q "$TORCH_PIN" "${BUILD_TOOLS[@]}" wheel ninja
# opencv-python 5 (what onedl-mmcv brings) rejects arrays of more than 128
# channels; the paper's T is 129.
printf '%s\n' "$TORCH_PIN" "opencv-python<5" > "$VENV/constraints.txt"

# (Extension modules are looked for as files, with the suffixes Python's
# import takes: find_spec of a submodule would import its package, and torch.)
installed_mmcv() { "$VENV/bin/python" - <<'PY'
import importlib.machinery, importlib.metadata as md, importlib.util, os.path as osp
for name in ("mmcv", "mmcv-lite", "onedl-mmcv"):
    try:
        version = md.version(name)
    except md.PackageNotFoundError:
        continue
    spec = importlib.util.find_spec("mmcv")
    ops = spec is not None and any(
        osp.isfile(osp.join(folder, "_ext" + suffix))
        for folder in spec.submodule_search_locations or ()
        for suffix in importlib.machinery.EXTENSION_SUFFIXES)
    print(name, version, "full" if ops else "lite"); break
PY
}

if [ "$MMCV" = lite ]; then MMCV_DIST=$MMCV_LITE; else MMCV_DIST=$MMCV_FULL; fi
if [ "$(installed_mmcv)" != "$MMCV_DIST $MMCV_VERSION $MMCV" ]; then
    PINS_CHECKED=0  # (a full and a lite onedl-mmcv have one name and version)
    "${PIP[@]}" uninstall -q -y mmcv mmcv-lite onedl-mmcv >/dev/null 2>&1 || true
    if [ "$MMCV" = lite ]; then
        # onedl-mmcv's sdist, built in isolation, has no torch: no ops
        "${PIP[@]}" install -q "${MMCV_CACHE[@]}" -c "$VENV/constraints.txt" "$MMCV_DIST==$MMCV_VERSION"
    elif [ -n "${MMCV_WHEELS:-}" ]; then
        "${PIP[@]}" install -c "$VENV/constraints.txt" --only-binary "$MMCV_DIST" \
            -f "$MMCV_WHEELS" "$MMCV_DIST==$MMCV_VERSION"
    else
        echo "[setup_env] compiling $MMCV_DIST $MMCV_VERSION with ops (about 30 minutes on 2 cores; pip caches the wheel)"
        MMCV_WITH_OPS=1 "${PIP[@]}" install "${MMCV_CACHE[@]}" --no-build-isolation -c "$VENV/constraints.txt" "$MMCV_DIST==$MMCV_VERSION"
    fi
fi

# The rest of the stack; the constraints stop any dependency from upgrading torch or opencv.
if [ "$PINS_CHECKED" = 0 ]; then
    "${PIP[@]}" install -q -c "$VENV/constraints.txt" -r "requirements/$STACK.txt" \
        -r requirements/runtime.txt -r requirements/tests.txt -r requirements/docs.txt
fi
# Editable: each stack's mim finds configs/ and tools/ where its own lookup
# says the package is. mim 0.3.8 asks pkg_resources, which names this checkout
# for `setup.py develop`'s egg-link (site-packages for a PEP 660 install);
# onedl-mim reads a PEP 660 install's direct_url.json: this checkout's root.
# Redone only when it no longer matches the checkout, so that a rerun (every
# tools/run_tests.sh and tools/quickstart.sh) rewrites nothing that running
# processes import: the stamp holds what the install was built from.
C_SOURCES=$(find wgse_mmseg -name '*.c' | sort)  # setup.py's extensions, one a file
editable_stamp() {
    # shellcheck disable=SC2086
    { echo "$STACK $PWD"; cat setup.py wgse_mmseg/version.py $C_SOURCES; } | sha256sum | cut -d' ' -f1
}
editable_in_place() {  # asked outside the checkout, as an installed command asks
    local python; python="$(cd "$VENV" && pwd)/bin/python"
    # shellcheck disable=SC2086
    (cd / && "$python" - "$1" "$STACK" $C_SOURCES <<'PY'
import importlib.machinery, importlib.util, os.path as osp, sys
root, stack, sources = sys.argv[1], sys.argv[2], sys.argv[3:]
spec = importlib.util.find_spec("wgse_mmseg")
if spec is None or spec.origin != osp.join(root, "wgse_mmseg", "__init__.py"):
    sys.exit(1)
# the C kernels built (optional: without a compiler every run tries again)
built = all(any(osp.isfile(osp.join(root, source[:-len(".c")] + suffix))
                for suffix in importlib.machinery.EXTENSION_SUFFIXES)
            for source in sources)
mim = osp.join(root, "wgse_mmseg", ".mim")
linked = all(osp.islink(osp.join(mim, name)) for name in ("configs", "tools"))
sys.exit(not (built and (linked if stack == "openmmlab" else not osp.exists(mim))))
PY
    )
}
if [ "$(cat "$VENV/wgse-editable" 2>/dev/null)" != "$(editable_stamp)" ] || ! editable_in_place "$PWD"; then
    if [ "$STACK" = openmmlab ]; then
        "${PIP[@]}" install -q --no-build-isolation --no-deps --no-use-pep517 -e .
    else
        "${PIP[@]}" install -q --no-build-isolation --no-deps -e .
    fi
    editable_stamp > "$VENV/wgse-editable"
fi

"$VENV/bin/python" -c "import wgse_mmseg, mmseg, mmcv, torch; print('[setup_env] ready ($STACK in $VENV): torch', torch.__version__, '| mmcv', mmcv.__version__, '| mmseg', mmseg.__version__, '| wgse_mmseg', wgse_mmseg.__version__)"
[ "$PINS_CHECKED" = 1 ] || pins_stamp > "$VENV/wgse-pins"

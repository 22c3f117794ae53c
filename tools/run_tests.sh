#!/usr/bin/env bash
# The test command (what CI runs): the pinned environment, then pytest.
#   bash tools/run_tests.sh               # OpenMMLab's final releases, in .venv
#   STACK=onedl bash tools/run_tests.sh   # the onedl-* fork, in .venv-onedl
# STACK, VENV and MMCV as for tools/setup_env.sh; arguments go to pytest. The
# tests run in one pytest-xdist worker per core (`-n 0` runs them in one process).
set -euo pipefail
cd "$(dirname "$0")/.."
source tools/setup_env.sh  # sets VENV
# The suite starts a Python process for every tool it runs; where
# PYTHONDONTWRITEBYTECODE is set (as on CI) each would compile the package's
# modules again (0.2 s of CPU a process on the 2-core machine): compile them
# once, here.
"$VENV/bin/python" -m compileall -q wgse_mmseg wgse_bench > /dev/null
exec "$VENV/bin/python" -m pytest tests -p no:cacheprovider -n auto --dist worksteal "$@"

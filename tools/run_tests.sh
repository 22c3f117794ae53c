#!/usr/bin/env bash
# The test command (what CI runs): the pinned environment, then pytest.
#   bash tools/run_tests.sh               # OpenMMLab's final releases, in .venv
#   STACK=onedl bash tools/run_tests.sh   # the onedl-* fork, in .venv-onedl
#   bash tools/run_tests.sh tests/core/test_wavelets.py -k gradcheck   # just those
#   bash tools/run_tests.sh --lf          # the tests that failed last time
# STACK, VENV and MMCV as for tools/setup_env.sh; arguments go to pytest
# (without a test path it runs setup.cfg's testpaths, the whole suite). The
# tests run in one pytest-xdist worker per core (`-n 0` runs them in one
# process); pytest's cache (what --lf reads) is .pytest_cache/ in the
# checkout, which git ignores.
set -euo pipefail
cd "$(dirname "$0")/.."
source tools/setup_env.sh  # sets VENV
# The suite starts a Python process for every tool it runs; where
# PYTHONDONTWRITEBYTECODE is set (as on CI) each would compile the package's
# modules again (0.2 s of CPU a process on the 2-core machine): compile them
# once, here.
"$VENV/bin/python" -m compileall -q wgse_mmseg wgse_bench > /dev/null
exec "$VENV/bin/python" -m pytest -n auto --dist worksteal "$@"

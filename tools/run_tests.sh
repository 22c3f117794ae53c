#!/usr/bin/env bash
# The test command (what CI runs): the pinned environment, then pytest.
#   bash tools/run_tests.sh               # OpenMMLab's final releases, in .venv
#   STACK=onedl bash tools/run_tests.sh   # the onedl-* fork, in .venv-onedl
#   bash tools/run_tests.sh tests/core/test_wavelets.py -k gradcheck   # just those
#   bash tools/run_tests.sh --lf          # the tests that failed last time
#   bash tools/run_tests.sh --gpu-targets -m gpu_targets   # the kernels
#       compiled for GPU targets, which the suite skips (CI's own step)
# STACK, VENV and MMCV as for tools/setup_env.sh; arguments go to pytest
# (without a test path it runs setup.cfg's testpaths, the whole suite).
# The whole suite runs in one pytest-xdist worker per core; tests picked by a
# path, -k, -m or --lf run in this one process, which starts in seconds
# where workers take tens (-n auto or -n 0 chooses either way); the value of
# an option such as -p, -o or -W (-p no:randomly) is no test path. pytest's
# cache (what --lf reads) is .pytest_cache/ in the checkout, which git ignores.
set -euo pipefail
cd "$(dirname "$0")/.."
source tools/setup_env.sh  # sets VENV
# The suite starts a Python process for every tool it runs; where
# PYTHONDONTWRITEBYTECODE is set (as on CI) each would compile the package's
# modules again (0.2 s of CPU a process on the 2-core machine): compile them
# once, here.
"$VENV/bin/python" -m compileall -q wgse_mmseg wgse_bench > /dev/null
workers=(-n auto --dist worksteal)
value_next=0  # the word after an option that takes a value is that value
for arg in "$@"; do
    if [ "$value_next" = 1 ]; then value_next=0; continue; fi
    case "$arg" in
        -p|-o|-W|-c|-n|-r|--tb|--durations|--dist|--maxfail|--basetemp|\
        --junitxml|--timeout|--color|--rootdir|--confcutdir|--log-level)
            value_next=1 ;;
        -k*|-m*|--lf|--last-failed|--deselect*|[!-]*) workers=(-n 0) ;;
    esac
done
exec "$VENV/bin/python" -m pytest "${workers[@]}" "$@"

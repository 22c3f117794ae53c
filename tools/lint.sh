#!/usr/bin/env bash
# The repository's checks that read its text rather than run it (CI's step
# before the suite), in the pinned environment of tools/setup_env.sh:
#   flake8       the code's style (setup.cfg's [flake8])
#   references   every docstring cross-reference and docs path exists (dev/check_references.py)
#   floors       no import runs up a floor or into wgse_bench (dev/check_floors.py)
#   api          the API pages and the __all__ lists agree (dev/check_api.py)
#   docs         the Sphinx build, warnings as errors, shows only API names (dev/check_docs.py)
#   bash tools/lint.sh                 # every check
#   bash tools/lint.sh flake8 floors   # those named
# STACK, VENV and MMCV as for tools/setup_env.sh. Every check named runs,
# whatever the others find; the exit status is 1 where any failed.
set -euo pipefail
cd "$(dirname "$0")/.."
CHECKS=(flake8 references floors api docs)
[ "$#" -gt 0 ] || set -- "${CHECKS[@]}"
for check in "$@"; do
    case " ${CHECKS[*]} " in
        *" $check "*) ;;
        *) echo "[lint] no check '$check': one of ${CHECKS[*]}" >&2; exit 2 ;;
    esac
done
source tools/setup_env.sh  # sets VENV
failed=()
for check in "$@"; do
    echo "[lint] $check"
    if [ "$check" = flake8 ]; then
        command=("$VENV/bin/python" -m flake8)
    else
        command=("$VENV/bin/python" "dev/check_$check.py")
    fi
    "${command[@]}" || failed+=("$check")
done
if [ "${#failed[@]}" -gt 0 ]; then
    echo "[lint] failed: ${failed[*]}" >&2
    exit 1
fi
echo "[lint] all passed"

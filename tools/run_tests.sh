#!/usr/bin/env bash
# The test command (what CI runs): the pinned environment, then pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup_env.sh
exec .venv/bin/python -m pytest tests -p no:cacheprovider "$@"

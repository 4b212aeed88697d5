#!/usr/bin/env bash
# Sets everything up (tools/bootstrap.sh) and runs the test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/bootstrap.sh
.venv/bin/python -m pytest -p no:cacheprovider "$@"

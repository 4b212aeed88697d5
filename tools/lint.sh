#!/usr/bin/env bash
# Lint the Python code: ruff (style, imports, likely bugs) and mypy (types of python/evomesh).
# Installs ruff and mypy into .venv if missing. Run from anywhere; exits non-zero on any finding.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=.venv/bin/python
if [ ! -x "$PY" ]; then
  echo "lint.sh: .venv missing; run tools/bootstrap.sh first" >&2
  exit 2
fi
if ! "$PY" -m ruff --version >/dev/null 2>&1 || ! "$PY" -m mypy --version >/dev/null 2>&1; then
  "$PY" -m pip install -q ruff mypy
fi
status=0
echo "== ruff"
"$PY" -m ruff check python tests benchmarks examples || status=1
echo "== mypy"
"$PY" -m mypy python/evomesh || status=1
exit $status

#!/usr/bin/env bash
# Install addb with its test and mlp extras into .venv (PyTorch CPU for the benchmark's
# networks, which are optional for users) and run the whole test suite.
# Usage: bash scripts/run-tests.sh [pytest arguments]
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
[ -x .venv/bin/python ] || "$PY" -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q -e ".[test,mlp]"
exec .venv/bin/python -m pytest -q "$@"

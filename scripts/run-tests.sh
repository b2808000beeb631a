#!/usr/bin/env bash
# Install addb with its test, mlp and plot extras into .venv (PyTorch CPU for the benchmark's
# networks and matplotlib for its filtering study's plot, both optional for users) and run the
# whole test suite.
# Usage: bash scripts/run-tests.sh [pytest arguments]
# The tests run in ADDB_TEST_WORKERS processes (default 2, this machine's cores; pytest-xdist),
# each test file on one worker (--dist loadfile: module and session fixtures, such as the
# diagnosis's neutral bases, are built once). With two workers the suite took 8.5 min on
# 2026-11-24 (14 min on 2026-11-23, before the dynamics fit's speed-ups); ADDB_TEST_WORKERS=0
# runs it serially.
# -rfEs lists failures, errors and every skipped test with its reason at the end. A test that
# needs Chromium, Playwright, OpenSim or PyTorch skips without it, but fails under CI=true
# (tests/conftest.py: require_tool).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
[ -x .venv/bin/python ] || "$PY" -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q -e ".[test,mlp,plot]"
exec .venv/bin/python -m pytest -q -rfEs -n "${ADDB_TEST_WORKERS:-2}" --dist loadfile "$@"

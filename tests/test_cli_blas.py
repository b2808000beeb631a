"""The ``addb`` console script starts OpenBLAS with one thread, unless the user chose."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

# What OpenBLAS reports in a fresh interpreter after the CLI's start-up step (and after the
# libraries' imports, as `addb process` has them).
_PROBE = """
import json, sys
from addb_viewer.cli import one_blas_thread
one_blas_thread()
import numpy, scipy.linalg
from threadpoolctl import threadpool_info
print(json.dumps([p["num_threads"] for p in threadpool_info() if p["internal_api"] == "openblas"]))
"""


def _openblas_threads(env_value: str | None) -> list[int]:
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
    if env_value is not None:
        env["OPENBLAS_NUM_THREADS"] = env_value
    out = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True, env=env, check=True)
    return json.loads(out.stdout)


def test_the_console_script_starts_openblas_single_threaded() -> None:
    threads = _openblas_threads(None)
    assert len(threads) == 2  # numpy's and scipy's OpenBLAS
    assert threads == [1, 1]


def test_a_users_openblas_setting_is_kept() -> None:
    assert _openblas_threads("2") == [2, 2]


def test_main_called_from_python_leaves_the_environment_alone(monkeypatch: pytest.MonkeyPatch) -> None:
    import numpy  # noqa: F401  (loaded, as in any process that calls main from Python)

    from addb_viewer import cli

    monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    cli.one_blas_thread()
    assert "OPENBLAS_NUM_THREADS" not in os.environ

"""solver.scipy_imports: scipy.signal and scipy.interpolate imported without scipy 1.17's
import-time docstring notes give the same functions, the same numbers and the same
capabilities table as a plain import, put scipy's decorator back, and fall back to a plain
import when the decorator is not the one the module knows. Each import runs in a fresh
interpreter (an import happens once per process)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

_PROBE = """
import json, sys
import numpy as np
import scipy._lib._array_api as a
original = a.xp_capabilities
mode = sys.argv[1]
if mode == "plain":
    import scipy.signal as signal, scipy.interpolate as interpolate
else:
    if mode == "unknown":  # a scipy whose decorator this module does not know
        scipy_own = original
        def xp_capabilities(**kw):
            return scipy_own(**kw)
        a.xp_capabilities = original = xp_capabilities
    from solver.scipy_imports import import_scipy
    signal = import_scipy("scipy.signal")
    interpolate = import_scipy("scipy.interpolate")
sos = signal.butter(3, 30 / 50, btype="low", output="sos")
x = np.sin(np.linspace(0, 20, 300))[:, None] * np.arange(1, 4)
y = signal.sosfiltfilt(sos, x, axis=0, padlen=21)
spline = interpolate.BSpline(np.arange(12.0), np.linspace(0, 1, 6), 5)
table = {f"{getattr(f, '__module__', '')}.{getattr(f, '__qualname__', repr(f))}": repr(sorted(c.items()))
         for f, c in a.xp_capabilities_table.items()}
print(json.dumps({
    "restored": a.xp_capabilities is original,
    "sos": sos.tolist(), "filtered": y.tolist(), "spline": spline(np.linspace(5, 6, 7)).tolist(),
    "table": table, "noted": "Array API Standard Support" in (signal.butter.__doc__ or ""),
}))
"""


def _probe(mode: str) -> dict:
    out = subprocess.run(
        [sys.executable, "-c", _PROBE, mode], cwd=ROOT, capture_output=True, text=True, timeout=120, check=False
    )
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


@pytest.fixture(scope="module")
def plain() -> dict:
    return _probe("plain")


def test_the_quiet_import_gives_the_same_functions_numbers_and_table_without_the_notes(plain: dict) -> None:
    quiet = _probe("quiet")
    assert quiet["restored"]  # scipy's decorator is back after the import
    assert quiet["sos"] == plain["sos"] and quiet["filtered"] == plain["filtered"]  # bit for bit
    assert quiet["spline"] == plain["spline"]
    assert len(plain["table"]) > 100 and quiet["table"] == plain["table"]  # every function, same capabilities
    assert plain["noted"] and not quiet["noted"]  # the docstring note is what is left out


def test_an_unknown_decorator_falls_back_to_the_plain_import(plain: dict) -> None:
    unknown = _probe("unknown")
    assert unknown["restored"] and unknown["sos"] == plain["sos"] and unknown["filtered"] == plain["filtered"]
    assert unknown["noted"]  # imported plainly: scipy's own decorator wrote its notes

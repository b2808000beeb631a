"""Import scipy's ``signal`` and ``interpolate`` without their import-time docstring notes.

scipy 1.17 decorates about 800 functions of ``scipy.signal``, ``scipy.interpolate`` and the
``scipy.stats`` they import with ``scipy._lib._array_api.xp_capabilities``, which parses each
function's docstring (numpydoc's ``FunctionDoc``) at import time to append a table of the
array-API backends it supports. That is about half of a fresh ``addb process``'s import time
(tests/benchmarks/RESULTS.md, blocks ``imports`` and ``imports-scipy-1.16``), and the
decorator has no switch. :func:`import_scipy` swaps it, for the one import, for a decorator
that records the same capabilities in scipy's table (``xp_capabilities_table``) and leaves the
docstring as written, then puts the original back. The functions are the same objects with
the same code; only their ``__doc__`` lacks the backend table.

The decorator is a private scipy API: when it is missing, takes arguments this module does
not know, or the import fails with the swap in place, the module is imported plainly.
"""

from __future__ import annotations

import importlib
import inspect
import sys
import threading
from types import ModuleType

_LOCK = threading.Lock()


def import_scipy(name: str) -> ModuleType:
    """The scipy module ``name`` (``"scipy.signal"``, ``"scipy.interpolate"``), imported
    without scipy 1.17's import-time docstring notes (module docstring); an already imported
    module is returned as is.

    Raises
    ------
    ImportError
        ``name`` cannot be imported (as a plain ``import`` would).
    """
    if name in sys.modules:
        return sys.modules[name]
    with _LOCK:
        try:
            import scipy._lib._array_api as array_api

            original = array_api.xp_capabilities
            table = array_api.xp_capabilities_table
            defaults = {
                key: p.default
                for key, p in inspect.signature(original).parameters.items()
                if p.kind is inspect.Parameter.KEYWORD_ONLY and key not in ("capabilities_table", "extra_note")
            }
            if not {"out_of_scope", "np_only"} <= set(defaults):
                raise ValueError("not the decorator this module knows")
        except (ImportError, AttributeError, TypeError, ValueError):
            return importlib.import_module(name)

        def record_only(*, capabilities_table=None, extra_note=None, **given):
            unknown = set(given) - set(defaults)
            if unknown:  # a newer scipy's argument: let its own decorator handle it
                return original(capabilities_table=capabilities_table, extra_note=extra_note, **given)
            capabilities = {**defaults, **given}
            if capabilities["out_of_scope"]:  # as scipy's own decorator records it
                capabilities["np_only"] = True
            target = table if capabilities_table is None else capabilities_table

            def record(f):
                target[f] = capabilities
                return f

            return record

        array_api.xp_capabilities = record_only
        try:
            return importlib.import_module(name)
        except Exception:  # noqa: BLE001, S110 (anything the swap broke: import it plainly below)
            pass
        finally:
            array_api.xp_capabilities = original
        sys.modules.pop(name, None)
        return importlib.import_module(name)

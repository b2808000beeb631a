"""Exact number text for the file formats: decimal shifts (mm <-> m) and degrees <-> radians.

The writers promise ``read(write(x)) == x`` bit for bit. Two conversions make that
non-trivial in float64:

* **Powers of ten** (mm, cm). ``float(s) / 1000`` rounds twice and cannot reach every
  float64. Instead the reader parses the *decimal text* scaled by ``10**-3`` in one
  correctly rounded step (``float("1234.5e-3")``), and the writer prints the shortest
  repr of the value in metres with the decimal point moved three places, which is the
  same decimal number. The result is also the most accurate reading of a lab file.
* **Degrees**. ``pi/180`` is irrational; a float64 in degrees carries too little
  information to come back to every float64 in radians. The reader multiplies the
  decimal text by ``pi/180`` in 50-digit decimal arithmetic and rounds once, and the
  writer prints as many significant digits (17 to 25) as needed for that reading to
  return the original radians. The cost is a few microseconds per value.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from decimal import MAX_EMAX, MIN_EMIN, Context, Decimal, InvalidOperation

import numpy as np

from solver.io._text import FloatArray, TokenError, parse_floats

_CTX = Context(prec=60, Emax=MAX_EMAX, Emin=MIN_EMIN)  # no overflow: 1e9999999 -> inf
_PI = Decimal("3.14159265358979323846264338327950288419716939937510582097494459230781640628620899")
_RAD_PER_DEG = _CTX.divide(_PI, Decimal(180))
_DEG_PER_RAD = _CTX.divide(Decimal(180), _PI)
_SPECIAL = re.compile(r"[eEnNiI]")
_SPACE_AROUND_NEWLINE = re.compile(r"[ \t]*\n[ \t]*")


def format_float(x: float) -> str:
    """Shortest decimal text that parses back to exactly ``x`` (``nan``, ``inf`` as Python)."""
    return repr(float(x))


def format_shifted(x: float, shift: int) -> str:
    """Decimal text of ``x * 10**shift``, exact, so that ``parse_shifted`` returns ``x``.

    ``format_shifted(1.2345, 3) == "1234.5"``. NaN gives ``""`` is *not* done here: the
    caller decides how to write missing values; NaN and infinities come back as
    ``nan``/``inf``.
    """
    x = float(x)
    if not math.isfinite(x):
        return repr(x)
    dec = Decimal(repr(x)).scaleb(shift, _CTX)
    if -20 <= dec.adjusted() <= 20:
        text = format(dec, "f")
    else:
        text = format(dec, "e")
    return text


def _shift_token(token: str, shift: int) -> float:
    """``float(token) * 10**-shift`` rounded once (slow path: exponents, nan, inf)."""
    mantissa, sep, exponent = token.lower().partition("e")
    if sep:
        return float(f"{mantissa}e{int(exponent) - shift}")
    if any(c in mantissa for c in "ni"):  # nan, inf, infinity
        return float(token)
    return float(f"{token}e{-shift}")


def parse_shifted(tokens: Sequence[str], shift: int, *, empty_is_nan: bool = False) -> FloatArray:
    """``(N,)`` values of decimal ``tokens`` times ``10**-shift``, each correctly rounded.

    ``parse_shifted(["1234.5"], 3) == [1.2345]``. Surrounding spaces are ignored.

    Parameters
    ----------
    tokens
        Decimal texts (``nan``, ``inf`` and exponents accepted).
    shift
        Power of ten to divide by (3 for mm -> m, 0 for none).
    empty_is_nan
        Read an empty token as NaN (TRC missing markers) instead of an error.

    Raises
    ------
    TokenError
        A token is not a number (the first one, with its index).
    """
    tokens = list(tokens)
    if not tokens:
        return np.zeros(0)
    joined = "\n".join(tokens)
    if " " in joined or "\t" in joined:
        joined = _SPACE_AROUND_NEWLINE.sub("\n", joined).strip(" \t")
        tokens = joined.split("\n")
    missing = None
    if "" in tokens:
        if not empty_is_nan:
            raise TokenError(tokens.index(""), "")
        missing = np.array([t == "" for t in tokens])
    if shift != 0 and ("n" in joined or "N" in joined):
        nan_words = np.array([t.lower().lstrip("+-") == "nan" for t in tokens])
        missing = nan_words if missing is None else missing | nan_words
    if missing is not None:
        tokens = ["0" if m else t for t, m in zip(tokens, missing.tolist(), strict=True)]
        joined = "\n".join(tokens)
    if shift == 0:
        values = parse_floats(tokens)
    elif _SPECIAL.search(joined) is None:
        suffix = f"e{-shift}"
        try:
            values = np.array(
                (joined.replace("\n", suffix + "\n") + suffix).split("\n"), dtype=np.float64
            )
        except ValueError:
            raise _first_bad_shifted(tokens, shift) from None
    else:
        values = np.empty(len(tokens))
        for i, tok in enumerate(tokens):
            try:
                values[i] = _shift_token(tok, shift)
            except (ValueError, OverflowError):
                raise TokenError(i, tok) from None
    if missing is not None:
        values[missing] = np.nan
    return values


def _first_bad_shifted(tokens: Sequence[str], shift: int) -> TokenError:
    for i, tok in enumerate(tokens):
        try:
            _shift_token(tok, shift)
        except (ValueError, OverflowError):
            return TokenError(i, tok)
    return TokenError(0, tokens[0])  # pragma: no cover - numpy and float agree


def _rad_from_deg_text(token: str) -> float:
    """Radians of a decimal text in degrees, rounded once from 60-digit arithmetic."""
    try:
        dec = Decimal(token.strip())
    except InvalidOperation:
        raise ValueError(token) from None
    if not dec.is_finite():
        return float(dec)
    return float(_CTX.multiply(dec, _RAD_PER_DEG))


def parse_degrees(tokens: Sequence[str]) -> FloatArray:
    """``(N,)`` radians of decimal ``tokens`` in degrees (see module docstring).

    Raises
    ------
    TokenError
        A token is not a number.
    """
    out = np.empty(len(tokens))
    for i, tok in enumerate(tokens):
        try:
            out[i] = _rad_from_deg_text(tok)
        except ValueError:
            raise TokenError(i, tok) from None
    return out


#: The precisions format_degrees tries, shortest first (17 digits always read back, 25 never needed).
_FORMAT_CONTEXTS = tuple(Context(prec=digits) for digits in range(17, 26))


def format_degrees(x: float) -> str:
    """Degrees text of ``x`` radians that :func:`parse_degrees` reads back as exactly ``x``."""
    x = float(x)
    if not math.isfinite(x):
        return repr(x)
    if x == 0.0:
        return repr(x)  # keeps the sign of -0.0
    exact = _CTX.multiply(Decimal(x), _DEG_PER_RAD)
    for context in _FORMAT_CONTEXTS:
        text = format(context.plus(exact), "g")
        if _rad_from_deg_text(text) == x:
            return text
    raise AssertionError(f"no degree text reads back as {x!r}")  # pragma: no cover

"""Checks of what users feed the tool, in one place (layer 0: imports only ``sim.errors``).

Every reader (scenarios, motions and AT2 records, run files; CSV maps and sweep files
alike) checks its input with these helpers, so that every mistake a user can make is
reported the same way: one line naming the file, the field and what was expected,
raised as a :class:`sim.errors.UserError` subclass (the CLI prints it, exit code 2).

The table and payload descriptions are read by ``mjcf`` (which imports nothing from
``sim``); ``mjcf.description._Section`` applies the same rules with the same
:func:`suggest` logic (closest known key) in its own words.
"""

from __future__ import annotations

import difflib
import math
from typing import Iterable, Mapping

import numpy as np

from sim.errors import UserError

#: Largest number of samples one signal may have: 2**23 (64 MiB per float64 column; 2.3 h
#: at 1024 Hz, 35 min at 4000 Hz; assumed: a table test lasts minutes, and a run keeps
#: ~60 columns of state per sample, ~4 GiB at this length). A longer request is a typo
#: (a duration of 1e7 s); it is refused with one line before anything is allocated.
MAX_SAMPLES = 2**23


def one_line(text) -> str:
    """``text`` with every run of white space (newlines too) as one space."""
    return " ".join(str(text).split())


def suggest(key: str, known: Iterable[str]) -> str:
    """`` (did you mean 'x'?)`` for the closest known key, or ``""`` when none is close."""
    close = difflib.get_close_matches(str(key), sorted(str(k) for k in known), n=1, cutoff=0.6)
    return f" (did you mean '{close[0]}'?)" if close else ""


def check_keys(data: Mapping, known: Iterable[str], where: str, src, error: type[UserError] = UserError) -> None:
    """Refuse a key of ``data`` not in ``known``: names the file, the table, the closest
    known key and lists the known ones."""
    known = sorted(known)
    extra = sorted(str(k) for k in set(data) - set(known))
    if extra:
        raise error(
            f"{src}: unknown key '{extra[0]}' in [{where}]{suggest(extra[0], known)}; known keys: {', '.join(known)}"
        )


def require_table(
    data: Mapping, key: str, where: str, src, error: type[UserError] = UserError, *, what: str = "keys"
) -> dict:
    """``data[key]`` when it is a TOML table; a one-line error when absent or not a table."""
    v = data.get(key)
    if not isinstance(v, dict):
        found = "missing" if v is None else f"a {type(v).__name__}, not a table"
        raise error(f"{src}: [{where}] is {found}; give a [{where}] table ({what})")
    return v


def number(
    value,
    field: str,
    src,
    error: type[UserError] = UserError,
    *,
    unit: str = "",
    positive: bool = False,
    nonneg: bool = False,
    integer: bool = False,
    lo: float | None = None,
    hi: float | None = None,
) -> float:
    """A finite number (int when ``integer``) within the stated bounds, or a one-line error
    naming the file and the field. ``unit`` (e.g. "s", "Hz") only words the message."""
    u = f" {unit}" if unit else ""
    if integer:
        ok = isinstance(value, (int, np.integer)) and not isinstance(value, bool)
        need = "a whole number"
    else:
        ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
        need = "a number"
    if not ok:
        raise error(f"{src}: '{field}' must be {need}{u and ' in' + u} (got {value!r})")
    v = int(value) if integer else float(value)
    if not math.isfinite(v):
        raise error(f"{src}: '{field}' must be finite (got {v!r})")
    if positive and not v > 0:
        raise error(f"{src}: '{field}' must be > 0{u} (got {v:g})")
    if nonneg and v < 0:
        raise error(f"{src}: '{field}' must be >= 0{u} (got {v:g})")
    if lo is not None and v < lo:
        raise error(f"{src}: '{field}' must be >= {lo:g}{u} (got {v:g})")
    if hi is not None and v > hi:
        raise error(f"{src}: '{field}' must be <= {hi:g}{u} (got {v:g})")
    return v


def text(value, field: str, src, error: type[UserError] = UserError, *, choices: Iterable[str] | None = None) -> str:
    """A non-empty string (one of ``choices`` when given)."""
    if not isinstance(value, str) or not value.strip():
        raise error(f"{src}: '{field}' must be text (got {value!r})")
    if choices is not None:
        choices = list(choices)
        if value not in choices:
            raise error(f"{src}: '{field}' is {value!r}{suggest(value, choices)}; use one of {', '.join(choices)}")
    return value


def boolean(value, field: str, src, error: type[UserError] = UserError) -> bool:
    if not isinstance(value, bool):
        raise error(f"{src}: '{field}' must be true or false (got {value!r})")
    return value


def numbers(
    value,
    field: str,
    src,
    error: type[UserError] = UserError,
    *,
    n: int | None = None,
    positive: bool = False,
    increasing: bool = False,
) -> list[float]:
    """A list of finite numbers (``n`` of them when given)."""
    if not isinstance(value, (list, tuple)) or (n is not None and len(value) != n) or not value:
        need = f"a list of {n} numbers" if n is not None else "a list of numbers"
        raise error(f"{src}: '{field}' must be {need} (got {value!r})")
    out = [number(x, field, src, error, positive=positive) for x in value]
    if increasing and any(b <= a for a, b in zip(out, out[1:])):
        raise error(f"{src}: '{field}' must be increasing (got {value!r})")
    return out


def sample_rate(value, field: str, src, error: type[UserError] = UserError) -> float:
    """A sample rate in Hz: finite, between 1 Hz and 1 MHz."""
    return number(value, field, src, error, unit="Hz", lo=1.0, hi=1e6)


def check_samples(n: float, what: str, src, error: type[UserError] = UserError) -> int:
    """``n`` samples as an int, refused over :data:`MAX_SAMPLES` before any allocation
    (``src`` None: the caller names the file)."""
    if not math.isfinite(n) or n > MAX_SAMPLES:
        where = f"{src}: " if src else ""
        raise error(
            f"{where}{what} needs {n:.3g} samples, over the maximum of {MAX_SAMPLES} "
            f"({MAX_SAMPLES * 8 / 2**30:.0f} GiB per channel); shorten the duration or lower the rate"
        )
    return int(n)


def finite_array(
    arr,
    field: str,
    src,
    error: type[UserError] = UserError,
    *,
    ndim: int | None = None,
    columns: int | None = None,
    min_rows: int = 0,
    t=None,
) -> np.ndarray:
    """``arr`` as float64, refusing a wrong shape or a NaN/Inf (named by sample and time)."""
    a = np.asarray(arr)
    if a.dtype.kind not in "fiu":
        raise error(f"{src}: '{field}' has type {a.dtype}; store numbers (float64)")
    a = a.astype(np.float64, copy=False)
    if ndim is not None and a.ndim != ndim:
        raise error(f"{src}: '{field}' has shape {a.shape}; need {ndim} dimension(s)")
    if columns is not None and (a.ndim != 2 or a.shape[1] != columns):
        raise error(f"{src}: '{field}' has shape {a.shape}; need (N, {columns})")
    if a.shape[:1] and a.shape[0] < min_rows:
        raise error(f"{src}: '{field}' has {a.shape[0]} samples; need at least {min_rows}")
    bad = ~np.isfinite(a)
    if np.any(bad):
        idx = np.argwhere(bad)[0]
        i = int(idx[0])
        at = f" (t = {float(t[i]):.6g} s)" if t is not None and i < len(t) else ""
        kind = "NaN" if np.isnan(a[tuple(idx)]) else "an infinite value"
        raise error(f"{src}: '{field}' has {kind} at sample {i}{at}; fill or cut the missing samples")
    return a


__all__ = [
    "MAX_SAMPLES",
    "boolean",
    "check_keys",
    "check_samples",
    "finite_array",
    "number",
    "numbers",
    "one_line",
    "require_table",
    "sample_rate",
    "suggest",
    "text",
]

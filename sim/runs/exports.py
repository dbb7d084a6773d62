"""Reading a lab's recorder exports (CSV, MAT-file, NI TDMS) into raw columns by name,
and checking a time column is a uniform grid; used by :mod:`sim.runs.importer`. Every
problem is one line naming the file, the line or column and the fix."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from sim.errors import UserError


def _err(where: str, problem: str, fix: str) -> UserError:
    return UserError(" ".join(f"{where}: {problem}; {fix}".split()))


# ------------------------------------------------------------------ reading exports
def _read_csv(path: Path, mp, wanted: list[str]) -> dict:
    try:
        text = path.read_text(errors="strict")
    except OSError as e:
        raise _err(str(path), f"cannot be read ({e.strerror})", "give an existing export file") from None
    except UnicodeDecodeError:
        raise _err(str(path), "is not a text file", "export as CSV text (or give a .mat file)") from None
    lines = text.splitlines()[mp.skip_rows :]
    if not lines:
        raise _err(str(path), "is empty", "export with a header line and the samples")
    delim = mp.delimiter
    if delim is None:
        delim = max((",", ";", "\t"), key=lines[0].count)
    rows = csv.reader(lines, delimiter=delim)
    header = next(rows)
    idx = _header_index(header, wanted, f"{path} (map {mp.path})")
    out = {w: [] for w in wanted}
    for ln, row in enumerate(rows, start=mp.skip_rows + 2):
        if not row or all(not x.strip() for x in row):
            continue
        if len(row) != len(header):
            raise _err(
                str(path),
                f"line {ln} has {len(row)} fields but the header has {len(header)}",
                "fix or cut the ragged line (a truncated export?)",
            )
        for w, j in idx.items():
            cell = row[j].strip()
            if cell == "":
                out[w].append(math.nan)  # missing sample (the format's NaN)
                continue
            try:
                out[w].append(float(cell))
            except ValueError:
                raise _err(
                    str(path),
                    f"line {ln} column '{w}' holds {cell!r}, not a number",
                    "fix the cell, or skip_rows the lines above the header in the map",
                ) from None
    if not out[wanted[0]]:
        raise _err(str(path), "has a header but no samples", "export the samples too")
    return {w: np.asarray(v, float) for w, v in out.items()}


def _header_index(header: list[str], wanted: list[str], where: str) -> dict:
    """Column index of each map name in a CSV header. Names are compared with leading
    and trailing spaces stripped on both sides (a recorder that writes ``" Acc 2F"``
    after a comma, a map that copied the name with or without the space)."""
    bare = [h.strip() for h in header]
    idx = {}
    for w in wanted:
        hits = [j for j, h in enumerate(bare) if h == w.strip()]
        if not hits:
            raise _err(
                where,
                f"has no column {w!r} (header: {', '.join(repr(h) for h in header)}; "
                "names are compared with leading and trailing spaces stripped)",
                "fix the column's name in the map or export that column",
            )
        if len(hits) > 1:
            raise _err(
                where,
                f"has {len(hits)} columns named {w.strip()!r} (names compared stripped of spaces)",
                "rename one of them in the export",
            )
        idx[w] = hits[0]
    return idx


def _read_mat(path: Path, mp, wanted: list[str]) -> dict:
    from scipy.io import loadmat

    try:
        data = loadmat(str(path), squeeze_me=True)
    except (OSError, ValueError, NotImplementedError) as e:
        raise _err(
            str(path),
            f"cannot be read as a MAT-file ({' '.join(str(e).split())})",
            "save it with MATLAB's save -v7 (or export CSV)",
        ) from None
    out = {}
    for w in wanted:
        if w not in data:
            have = ", ".join(k for k in data if not k.startswith("__"))
            raise _err(
                f"{path} (map {mp.path})",
                f"has no variable '{w}' (variables: {have})",
                "fix the column's name in the map or save that variable",
            )
        a = np.asarray(data[w])
        if a.ndim != 1 or not np.issubdtype(a.dtype, np.number):
            raise _err(
                str(path),
                f"variable '{w}' has shape {a.shape} and type {a.dtype}",
                "save each channel as a numeric vector",
            )
        out[w] = a.astype(float)
    n = {len(v) for v in out.values()}
    if len(n) != 1:
        raise _err(str(path), "variables of different lengths", "save every channel over the same samples")
    return out


def _read_tdms(path: Path, mp, wanted: list[str]) -> dict:
    """Channels of an NI TDMS file (npTDMS) by name: ``"channel"`` when the name is
    unique over the file's groups, else ``"group/channel"``."""
    try:
        from nptdms import TdmsFile
    except ImportError:
        raise _err(
            str(path), "is a TDMS file and npTDMS is not installed", "pip install nptdms (or export CSV)"
        ) from None
    try:
        f = TdmsFile.read(str(path))
    except Exception as e:  # npTDMS raises ValueError, KeyError, struct.error ... on a damaged file
        raise _err(
            str(path), f"cannot be read as a TDMS file ({' '.join(str(e).split())[:120]})", "export it again (or CSV)"
        ) from None
    by_name: dict[str, list] = {}
    for g in f.groups():
        for c in g.channels():
            by_name.setdefault(f"{g.name}/{c.name}", []).append(c)
            by_name.setdefault(c.name, []).append(c)
    if not by_name:  # npTDMS reads a file without TDMS segments as an empty one
        raise _err(str(path), "cannot be read as a TDMS file (no channels in it)", "export it again (or CSV)")
    out = {}
    for w in wanted:
        found = by_name.get(w, [])
        if len(found) != 1:
            have = ", ".join(k for k in by_name if "/" in k)
            problem = (
                f"has no channel '{w}' (channels: {have})"
                if not found
                else f"has {len(found)} channels named '{w}' (in different groups)"
            )
            raise _err(f"{path} (map {mp.path})", problem, "name the column 'group/channel' in the map")
        a = np.asarray(found[0][:])
        if a.ndim != 1 or not np.issubdtype(a.dtype, np.number):
            raise _err(str(path), f"channel '{w}' holds {a.dtype} data", "record each channel as numbers")
        out[w] = a.astype(float)
    if len({len(v) for v in out.values()}) != 1:
        raise _err(str(path), "channels of different lengths", "record every channel over the same samples")
    return out


def uniform_time(t: np.ndarray, where: str) -> tuple[float, float]:
    """(t0, sample rate) of a time column that is a uniform grid up to its rounding;
    one-line error naming the first bad sample otherwise."""
    if len(t) < 2:
        raise _err(where, "has fewer than 2 samples", "export a longer record")
    if not np.all(np.isfinite(t)):
        i = int(np.flatnonzero(~np.isfinite(t))[0])
        raise _err(where, f"time column is empty or not finite at sample {i}", "export every sample's time")
    d = np.diff(t)
    if np.any(d <= 0):
        i = int(np.flatnonzero(d <= 0)[0]) + 1
        raise _err(
            where,
            f"time is not increasing at sample {i} (t = {t[i]:.6g} s after {t[i - 1]:.6g} s)",
            "export one continuous record per file, sorted in time",
        )
    n = len(t)
    k = np.arange(n)
    slope, t0 = np.polyfit(k, t, 1)
    dev = np.abs(t - (t0 + slope * k))
    tol = 0.02 * slope + 1e-5
    if dev.max() > tol:
        i = int(np.argmax(dev))
        raise _err(
            where,
            f"time step is not uniform (sample {i} is {dev[i] * 1e3:.3g} ms off the {slope * 1e3:.6g} ms grid)",
            "export at a fixed sample rate, without gaps",
        )
    fs = 1.0 / slope
    nice = round(fs, 3)
    if abs(nice - fs) <= 1e-6 * fs + 2e-5 / (slope * n) * fs:
        fs = nice
    return float(t[0]), float(fs)


__all__ = ["uniform_time"]

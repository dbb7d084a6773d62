"""Output files written in one way: a folder checked before the work starts, and files
that appear complete or not at all (temporary file in the same folder, then rename)."""

from __future__ import annotations

import json
import math
import os
import tempfile
from pathlib import Path

from sim.errors import UserError


def out_dir(path) -> Path:
    """The output folder, created and probed for writing (one-line error if it cannot be)."""
    out = Path(path)
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = tempfile.NamedTemporaryFile(dir=out, prefix=".probe", delete=True)
        probe.close()
    except OSError as e:
        raise UserError(f"cannot write to output folder {out}: {e.strerror}; choose a writable --out folder") from None
    return out


def jsonable(obj):
    """``obj`` with NaN and infinities as ``null`` and numpy scalars/arrays as plain
    Python (strict JSON parsers reject bare ``NaN``)."""
    import numpy as np

    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def write_text_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file and a rename."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        tmp.write_text(text)
        os.replace(tmp, path)
    except OSError as e:
        try:
            tmp.unlink()
        except OSError:
            pass
        raise UserError(f"cannot write {path}: {e.strerror}") from None


def write_json_atomic(path: Path, obj) -> None:
    """Strict JSON (NaN -> null), written atomically."""
    write_text_atomic(path, json.dumps(jsonable(obj), indent=2, allow_nan=False))

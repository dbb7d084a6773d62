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


def atomic_write(path: Path, write, error=None) -> None:
    """Call ``write(fh)`` on a temporary file beside ``path``, then rename it onto ``path``.

    A failure or an interruption (Ctrl-C included) at any point removes the temporary
    file and leaves ``path`` as it was: the complete old file, the complete new one, or
    none. Never a half-written file under the final name."""
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    tmp = None
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=folder)
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
        tmp = None
    except OSError as e:
        if error is not None:  # the caller's one-line error for this file kind
            raise error(e) from None
        raise UserError(f"cannot write {path}: {e.strerror or e}; choose a writable folder with free space") from None
    finally:
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass


def write_bytes_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file and a rename."""
    atomic_write(path, lambda fh: fh.write(data))


def write_text_atomic(path: Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` through a temporary file and a rename."""
    write_bytes_atomic(path, text.encode("utf-8"))


def save_figure_atomic(fig, path: Path, **kwargs) -> None:
    """``fig.savefig(path, **kwargs)`` through a temporary file and a rename (the format
    is taken from ``path``'s suffix, not from the temporary name)."""
    fmt = kwargs.pop("format", None) or Path(path).suffix.lstrip(".") or "png"
    atomic_write(path, lambda fh: fig.savefig(fh, format=fmt, **kwargs))


def json_text(obj, indent: int = 2) -> str:
    """Strict JSON text of ``obj`` (NaN and infinities as null, numpy as plain Python):
    what every JSON writer and every ``--json`` print uses."""
    return json.dumps(jsonable(obj), indent=indent, allow_nan=False)


def write_json_atomic(path: Path, obj) -> None:
    """Strict JSON (NaN -> null), written atomically."""
    write_text_atomic(path, json.dumps(jsonable(obj), indent=2, allow_nan=False))

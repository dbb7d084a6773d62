"""Errors of the model layer. ``mjcf`` imports nothing from ``sim``; the CLI reports these
as one line with exit code 2, as it does ``sim``'s own user errors."""


class MjcfError(ValueError):
    """Anything wrong with what ``mjcf`` was asked to build (a user can fix it)."""


class DescriptionError(MjcfError):
    """A table or payload description that is incomplete or inconsistent."""


def write_text_replacing(path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file beside it and a rename: the
    complete old file or the complete new one, never half of either; a failure or a
    Ctrl-C removes the temporary file (``mjcf`` imports nothing from ``sim``, whose
    ``sim.runs.files`` writers do the same). OSError propagates to the caller."""
    import os
    import tempfile
    from pathlib import Path

    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
        tmp = None
    finally:
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass

"""Progress of long commands on stderr: a bar on a terminal, one line per stage in a log.

Every long command (run, replay, characterize) reports through :class:`Progress`:
``stage(text)`` starts a stage (one line, on a terminal or in a log alike);
``count(done, total)`` reports finished jobs of a stage: on a terminal a bar rewritten
in place, elsewhere (a log, a CI job) one line per finished job, so a log is never
silent for minutes; ``close()`` ends a bar. With ``enabled=False`` (``--json``) it says
nothing, so stdout and stderr stay clean for a machine reader.
"""

from __future__ import annotations

import sys
import time


class Progress:
    def __init__(self, *, enabled: bool = True, stream=None, tty: bool | None = None, unit: str = "jobs"):
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = enabled
        self.tty = bool(self.stream.isatty()) if tty is None else tty
        self.unit = unit
        self.t0 = time.perf_counter()
        self._bar = False

    @property
    def elapsed_s(self) -> float:
        return time.perf_counter() - self.t0

    def _write(self, text: str) -> None:
        self.stream.write(text)
        self.stream.flush()

    def stage(self, text: str) -> None:
        """One line for a stage (ends a bar first)."""
        if not self.enabled:
            return
        self.close()
        self._write(f"  {text}  ({self.elapsed_s:.0f} s)\n")

    def count(self, done: int, total: int) -> None:
        """``done`` of ``total`` jobs finished."""
        if not self.enabled:
            return
        if self.tty:
            n = int(30 * done / max(total, 1))
            self._write(f"\r  [{'#' * n:<30s}] {done}/{total} {self.unit}  ({self.elapsed_s:5.0f} s)")
            self._bar = True
            if done >= total:
                self.close()
        else:
            self._write(f"  {done}/{total} {self.unit} done  ({self.elapsed_s:.0f} s)\n")

    def close(self) -> None:
        if self._bar:
            self._write("\n")
            self._bar = False

    # the call signatures the library takes
    def text_callback(self):
        """``progress(text)`` for library functions that report stages, or None when disabled."""
        return self.stage if self.enabled else None

    def count_callback(self):
        """``progress(done, total)`` for library functions that report jobs, or None when disabled."""
        return self.count if self.enabled else None


__all__ = ["Progress"]

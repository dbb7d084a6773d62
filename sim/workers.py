"""Worker pools that stop at Ctrl-C (layer 0: imports nothing from ``sim``).

A plain ``multiprocessing.Pool`` or ``ProcessPoolExecutor`` handles Ctrl-C badly: every
worker is in the terminal's process group, gets the SIGINT too and prints its own
KeyboardInterrupt traceback, and ``ProcessPoolExecutor.__exit__`` waits for the tests
already running (minutes) before the command can stop. :func:`parallel_map` runs the
workers with SIGINT ignored, so only the parent sees Ctrl-C; the parent then terminates
the workers at once and re-raises, and the command stops within a second.
"""

from __future__ import annotations

import signal
from typing import Callable, Iterable


def _ignore_sigint() -> None:  # pragma: no cover - runs in the worker processes
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def parallel_map(fn: Callable, items: Iterable, workers: int, *, ordered: bool = True,
                 progress: Callable[[int, int], None] | None = None) -> list:
    """``[fn(x) for x in items]`` on ``workers`` processes (in order when ``ordered``,
    else in the order they finish). ``progress(done, total)`` after each result.
    ``workers <= 1`` runs here, in this process. On any exception (Ctrl-C included) the
    workers are terminated before it propagates."""
    items = list(items)
    total = len(items)
    out: list = []
    if workers <= 1 or total <= 1:
        for x in items:
            out.append(fn(x))
            if progress:
                progress(len(out), total)
        return out
    import multiprocessing as mp

    pool = mp.get_context("fork").Pool(min(workers, total), initializer=_ignore_sigint)
    try:
        results = pool.imap(fn, items) if ordered else pool.imap_unordered(fn, items)
        for r in results:
            out.append(r)
            if progress:
                progress(len(out), total)
        pool.close()
        pool.join()
    except BaseException:
        pool.terminate()
        pool.join()
        raise
    return out


__all__ = ["parallel_map"]

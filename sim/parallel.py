"""One process-pool helper for every programme that runs independent simulations.

:func:`map_jobs` is used by the CGS identification programme (``sim.identify``), its
calibration (``sim.calibrate``) and the papers' programmes (``sim.papers``);
:func:`iter_jobs` (each result as it finishes) by sweeps (``sim.sweep``) and feasibility
suites (``sim.assess.study``), which keep each case as soon as it exists. It sits at
the bottom layer (rank 0, beside ``sim.errors``) because its users sit at ranks 5 to 8
and a layer may only import its own or lower ones: in ``sim.sweep`` (rank 7) the
identification programme could not import it. It knows nothing of tables or models:
it maps a function over jobs.

Spawn-safe: ``fn`` and the jobs must be picklable (a module-level function, or a
``functools.partial`` of one) and nothing may rely on state a forked child would
inherit, so the programmes run alike under every start method: ``fork`` (Linux's
default until Python 3.14, the fastest start), ``spawn`` (macOS and Windows; a script
that calls it needs the ``if __name__ == "__main__":`` guard) or ``forkserver``.
``context`` picks one (default: the platform's). Results come back in the jobs' order,
whatever order the workers finish in; ``workers=1`` runs serially in this process (no
pickling, exceptions with their full traceback).

Ctrl-C: a plain pool handles it badly (every worker is in the terminal's process group,
gets the SIGINT too and prints its own traceback, and ``ProcessPoolExecutor.__exit__``
waits for the jobs already running). The workers here ignore SIGINT, so only the parent
sees it; the parent then terminates the workers at once and re-raises, and the command
stops within a second. A terminated worker ends its job through Python (SIGTERM raises
SystemExit there), so a file it was writing leaves no temporary behind.
"""

from __future__ import annotations

import os
import signal
from collections.abc import Callable, Iterable


def _ignore_sigint() -> None:  # pragma: no cover - runs in the worker processes
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _exit_through_python)


def _exit_through_python(signum, frame):  # pragma: no cover - runs in the worker processes
    """``Pool.terminate`` sends SIGTERM. Its default action kills the worker on the spot,
    in the middle of an atomic write, leaving the temporary file beside the target; ending
    the job through Python runs its ``finally`` blocks (the writer removes the temporary)."""
    raise SystemExit(128 + signum)


def _call(task):  # pragma: no cover - runs in the worker processes
    fn, i, job = task
    return i, fn(job)


def usable_cores() -> int:
    """The CPUs this process may run on: its affinity mask where the platform has one
    (``taskset``, a container's CPU set, a batch scheduler's allocation), else every CPU
    of the machine. ``os.cpu_count()`` counts the machine's CPUs whatever the mask, so a
    job pinned to 2 of 16 CPUs would start 16 workers on 2 CPUs."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # macOS and Windows have no affinity call
        return os.cpu_count() or 1


def default_workers(n_jobs: int) -> int:
    """As many workers as usable CPUs, never more than jobs (at least 1)."""
    return max(1, min(n_jobs, usable_cores()))


def map_jobs(
    fn: Callable,
    jobs: Iterable,
    *,
    workers: int | None = None,
    progress: Callable[[int, int], None] | None = None,
    context: str | None = None,
) -> list:
    """``[fn(job) for job in jobs]``, in parallel processes, in the jobs' order.

    Args:
        fn: a picklable function of one argument.
        jobs: the arguments.
        workers: processes (default :func:`default_workers`); 1 runs serially here.
        progress: ``progress(done, total)`` after each finished job (in finishing order).
        context: multiprocessing start method (``"fork"``, ``"spawn"``, ``"forkserver"``);
            default the platform's.
    """
    jobs = list(jobs)
    out: list = [None] * len(jobs)
    for done, (i, r) in enumerate(iter_jobs(fn, jobs, workers=workers, context=context), start=1):
        out[i] = r
        if progress:
            progress(done, len(jobs))
    return out


def iter_jobs(fn: Callable, jobs: Iterable, *, workers: int | None = None, context: str | None = None):
    """``(i, fn(jobs[i]))`` for every job, as each finishes (in parallel processes as
    :func:`map_jobs`; serially here, in order, with ``workers=1``): for a caller that
    keeps each result as soon as it exists."""
    jobs = list(jobs)
    if not jobs:
        return
    workers = default_workers(len(jobs)) if workers is None else max(1, min(int(workers), len(jobs)))
    if workers == 1:
        for i, j in enumerate(jobs):
            yield i, fn(j)
        return
    import multiprocessing as mp

    pool = mp.get_context(context).Pool(workers, initializer=_ignore_sigint)
    try:
        yield from pool.imap_unordered(_call, [(fn, i, j) for i, j in enumerate(jobs)])
        pool.close()
        pool.join()
    except BaseException:  # Ctrl-C, a failed job, a caller that left early (GeneratorExit): stop the workers now
        pool.terminate()
        pool.join()
        raise


__all__ = ["default_workers", "iter_jobs", "map_jobs", "usable_cores"]

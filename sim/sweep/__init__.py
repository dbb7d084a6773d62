"""Many simulations of one scenario: sweep files (:mod:`.spec`), the runner with its
local (batched) and Dask executors (:mod:`.run`), the report (:mod:`.report`)."""

from __future__ import annotations


def sweep_file(
    path, *, out=None, workers=None, executor="local", address=None, progress_stream=None, every: int = 10
) -> dict:
    """Load the sweep file ``path``, run it into ``out`` (default ``out/sweeps/<name>``),
    write the results table and ``report.md``; returns :func:`.run.run_sweep`'s info plus
    ``report``. ``progress_stream``: where the progress bar goes (None: silent)."""
    from sim.sweep.report import write_report
    from sim.sweep.run import ProgressLine, run_sweep
    from sim.sweep.spec import load_sweep

    sw = load_sweep(path)
    out = out or f"out/sweeps/{sw.name}"
    prog = ProgressLine(progress_stream, every) if progress_stream is not None else None
    res = run_sweep(sw, out, workers=workers, executor=executor, address=address, progress=prog)
    res["report"] = str(write_report(out, res, res["rows"]))
    return res


__all__ = ["sweep_file"]

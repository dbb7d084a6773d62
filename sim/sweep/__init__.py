"""Many simulations of one scenario: sweep files (:mod:`.spec`), how the cases are dealt
out over processes and batch threads (:mod:`.split`), the runner with its local and Dask
executors (:mod:`.run`), the report (:mod:`.report`)."""

from __future__ import annotations


def sweep_file(
    path,
    *,
    out=None,
    workers=None,
    executor="local",
    address=None,
    progress_stream=None,
    every: int = 10,
    warn_stream=None,
    **split,
) -> dict:
    """Load the sweep file ``path``, run it into ``out`` (default ``out/sweeps/<name>``),
    write the results table and ``report.md``; returns :func:`.run.run_sweep`'s info plus
    ``report``. ``split``: ``processes``, ``threads``, ``task``, ``batch``
    (:func:`.run.run_sweep`). ``progress_stream``: where the progress bar goes (None:
    silent); ``warn_stream``: where the file's warnings go (None: not shown)."""
    from sim.sweep.report import write_report
    from sim.sweep.run import ProgressLine, run_sweep
    from sim.sweep.spec import load_sweep

    sw = load_sweep(path)
    for w in sw.warnings if warn_stream is not None else ():
        print(f"warning: {w}", file=warn_stream)
    out = out or f"out/sweeps/{sw.name}"
    prog = ProgressLine(progress_stream, every) if progress_stream is not None else None
    res = run_sweep(sw, out, workers=workers, executor=executor, address=address, progress=prog, **split)
    res["report"] = str(write_report(out, res, res["rows"]))
    return res


__all__ = ["sweep_file"]

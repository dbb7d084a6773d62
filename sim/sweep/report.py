"""A sweep's report: the distribution of the limiting utilisation (``report.md`` and a
histogram), from the rows of :func:`sim.sweep.run.run_sweep`."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np


def summarize(rows: list) -> dict:
    """Figures of the limiting utilisation over the cases (failed cases apart)."""
    u = np.array(
        [r["limiting_utilisation"] for r in rows if r.get("error") == "" and r.get("limiting_utilisation") is not None],
        float,
    )
    fin = u[np.isfinite(u)]
    q = (lambda p: float(np.percentile(fin, p))) if len(fin) else (lambda p: float("nan"))
    return {
        "cases": len(rows),
        "simulated": int(len(u)),
        "errors": sum(1 for r in rows if r.get("error")),
        "feasible": sum(1 for r in rows if r.get("feasible")),
        "limiting": dict(Counter(r.get("limiting") for r in rows).most_common()),
        "utilisation": {
            "min": q(0),
            "p5": q(5),
            "median": q(50),
            "mean": float(fin.mean()) if len(fin) else float("nan"),
            "p95": q(95),
            "max": q(100),
        },
        "values": fin,
    }


def write_report(out, info: dict, rows: list, title: str = "") -> Path:
    """``OUT/report.md`` with ``OUT/limiting_utilisation.png``; returns the report path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sim.runs.files import write_text_atomic

    out = Path(out)
    s = summarize(rows)
    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    if len(s["values"]):
        ax.hist(s["values"], bins=min(40, max(5, len(s["values"]) // 10)), color="#4477aa")
    ax.axvline(1.0, color="#cc3311", lw=1, label="limit")
    ax.set_xlabel("limiting utilisation (peak / limit of the most used check)")
    ax.set_ylabel("cases")
    ax.legend()
    fig.tight_layout()
    png = out / "limiting_utilisation.png"
    tmp = out / ".limiting_utilisation.tmp.png"
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    tmp.replace(png)
    u = s["utilisation"]
    lines = [
        f"# Sweep {info['sweep']}" + (f": {title}" if title else ""),
        "",
        f"Scenario `{info['scenario']}`, {s['cases']} cases ({info['ran']} run now, {info['skipped']} "
        f"already done), executor `{info['executor']}` with {info['workers']} workers, wall time of this "
        f"invocation {info['wall_s']:.1f} s.",
        "",
        f"- feasible: {s['feasible']} of {s['cases']}; errors: {s['errors']}",
        f"- limiting utilisation: min {u['min']:.4g}, 5 % {u['p5']:.4g}, median {u['median']:.4g}, "
        f"mean {u['mean']:.4g}, 95 % {u['p95']:.4g}, max {u['max']:.4g}",
        "- limiting check: " + ", ".join(f"{k} {v}" for k, v in s["limiting"].items()),
        "",
        "![limiting utilisation](limiting_utilisation.png)",
        "",
        "Utilisation of a check: its peak over its limit (stroke, force, valve saturation time, "
        "overturning moment, loop gap) or the supply-pressure drop over the allowed drop; "
        "1 is at the limit. Per-case values: `results.csv`.",
        "",
    ]
    path = out / "report.md"
    write_text_atomic(path, "\n".join(lines))
    return path


__all__ = ["summarize", "write_report"]

"""A sweep's report: the distribution of the limiting utilisation (``report.md`` and a
histogram), from the rows of :func:`sim.sweep.run.run_sweep`: over every check, and over
the checks computed from the simulation only (the envelope of the demanded motion and the
static specimen checks do not change with the table's parameters, so a Monte Carlo over
those parameters shows its spread there)."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np


def summarize(rows: list, column: str = "limiting_utilisation", check: str = "limiting") -> dict:
    """Figures of the utilisation ``column`` over the cases (failed cases apart), and
    how often each ``check`` column value was the limiting one."""
    u = np.array([r[column] for r in rows if r.get("error") == "" and r.get(column) is not None], float)
    fin = u[np.isfinite(u)]
    q = (lambda p: float(np.percentile(fin, p))) if len(fin) else (lambda p: float("nan"))
    return {
        "cases": len(rows),
        "simulated": int(len(u)),
        "errors": sum(1 for r in rows if r.get("error")),
        "feasible": sum(1 for r in rows if r.get("feasible")),
        "limiting": dict(Counter(r.get(check) for r in rows if r.get(check) is not None).most_common()),
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


def _split_text(info: dict) -> str:
    """`` (P processes x T threads, tasks of N cases)`` when ``info`` has the split."""
    sp = info.get("split")
    if not sp:
        return ""
    return f" ({sp['processes']} processes x {sp['threads']} threads, tasks of {sp['task']}, batches of {sp['batch']})"


def write_report(out, info: dict, rows: list, title: str = "") -> Path:
    """``OUT/report.md`` with ``OUT/limiting_utilisation.png``; returns the report path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sim.runs.files import write_text_atomic

    out = Path(out)
    s = summarize(rows)
    r = summarize(rows, "run_limiting_utilisation", "run_limiting")
    panels = [
        (s["values"], "limiting utilisation, every check"),
        (r["values"], "limiting utilisation, checks from the simulation"),
    ]
    spread = _widest(rows)
    if spread is not None:
        panels.append((spread[1], f"utilisation of {spread[0]} (the widest spread)"))
    fig, axes = plt.subplots(1, len(panels), figsize=(5.2 * len(panels), 3.8))
    for ax, (vals, what) in zip(np.atleast_1d(axes), panels):
        if len(vals):
            lo, hi = float(np.min(vals)), float(np.max(vals))
            if hi - lo > 1e-9 * max(abs(hi), 1.0):
                ax.hist(vals, bins=min(40, max(5, len(vals) // 10)))
            else:  # the same value in every case: one visible bar
                ax.bar([lo], [len(vals)], width=0.02 * max(abs(lo), 0.05))
            if hi >= 0.7:  # the limit on the axis only when the values come near it
                ax.axvline(1.0, color="#cc3311", lw=1, label="limit (1)")
                ax.legend()
            ax.set_xlabel(f"{what}\n(min {lo:.4g}, max {hi:.4g})", fontsize=9)
        ax.set_ylabel("cases")
    fig.tight_layout()
    png = out / "limiting_utilisation.png"
    tmp = out / ".limiting_utilisation.tmp.png"
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    tmp.replace(png)
    u, ru = s["utilisation"], r["utilisation"]
    lines = [
        f"# Sweep {info['sweep']}" + (f": {title}" if title else ""),
        "",
        f"Scenario `{info['scenario']}`, {s['cases']} cases ({info['ran']} run now, {info['skipped']} "
        f"already done), executor `{info['executor']}` with {info['workers']} workers{_split_text(info)}, "
        f"wall time of this invocation {info['wall_s']:.1f} s.",
        "",
        f"- feasible: {s['feasible']} of {s['cases']}; errors: {s['errors']}",
        f"- limiting utilisation: min {u['min']:.4g}, 5 % {u['p5']:.4g}, median {u['median']:.4g}, "
        f"mean {u['mean']:.4g}, 95 % {u['p95']:.4g}, max {u['max']:.4g}",
        "- limiting check: " + ", ".join(f"{k} {v}" for k, v in s["limiting"].items()),
        f"- limiting utilisation of the checks computed from the simulation (not the demanded motion's "
        f"envelope nor the static specimen checks): min {ru['min']:.4g}, 5 % {ru['p5']:.4g}, median "
        f"{ru['median']:.4g}, mean {ru['mean']:.4g}, 95 % {ru['p95']:.4g}, max {ru['max']:.4g}",
        "- its limiting check: " + ", ".join(f"{k} {v}" for k, v in r["limiting"].items()),
        "",
        *_per_check(rows, info.get("varied") or []),
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


def _widest(rows: list):
    """(check kind, values) of the simulated capability check (a ``util_*`` column other
    than the demanded motion's envelope, the static and the tracking checks) whose
    utilisation varies most over the cases (standard deviation, in utilisation: how much
    closer to its limit the inputs can bring it); None without one."""
    from sim.assess.feasibility import TRACKING_PREFIXES
    from sim.sweep.run import is_demand_check

    ok = [r for r in rows if r.get("error") == ""]
    best = None
    for c in sorted({k for r in ok for k in r if k.startswith("util_")}):
        kind = c[5:]
        if is_demand_check(kind) or kind.startswith(TRACKING_PREFIXES):
            continue
        v = np.array([r[c] for r in ok if r.get(c) is not None], float)
        v = v[np.isfinite(v)]
        if len(v) < 2 or not v.mean() > 0:
            continue
        cv = float(v.std())
        if cv > 0 and (best is None or cv > best[0]):
            best = (cv, kind, v)
    return None if best is None else (best[1], best[2])


def _per_check(rows: list, varied: list) -> list:
    """Markdown lines: per kind of check (the rows' ``util_*`` columns), the spread of its
    utilisation over the cases and its correlation with each varied input."""
    ok = [r for r in rows if r.get("error") == ""]
    cols = sorted({k for r in ok for k in r if k.startswith("util_")})
    if not ok or not cols:
        return []
    head = "| check | min | 5 % | median | 95 % | max |" + "".join(f" corr. {v} |" for v in varied)
    lines = [
        "Per kind of check (the largest over its instances, e.g. over the actuators):",
        "",
        head,
        "|---" * (6 + len(varied)) + "|",
    ]
    for c in cols:
        pairs = [(r.get(c), [r.get(v) for v in varied]) for r in ok]
        pairs = [(u, xs) for u, xs in pairs if u is not None and np.isfinite(u)]
        if not pairs:
            continue
        u = np.array([p[0] for p in pairs], float)
        q = np.percentile(u, [0, 5, 50, 95, 100])
        cells = [f"{x:.4g}" for x in q]
        for j in range(len(varied)):
            x = np.array([p[1][j] if p[1][j] is not None else np.nan for p in pairs], float)
            good = np.isfinite(x)
            if good.sum() > 2 and np.std(u[good]) > 0 and np.std(x[good]) > 0:
                cells.append(f"{np.corrcoef(x[good], u[good])[0, 1]:+.2f}")
            else:
                cells.append("-")
        lines.append(f"| {c[5:]} | " + " | ".join(cells) + " |")
    return lines + [""]


__all__ = ["summarize", "write_report"]

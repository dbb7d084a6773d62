"""``shaketable calibrate --strategy scale`` presented: ``report.md`` and one figure (the
held-out error per channel before and after) from the
:class:`sim.calibrate.search.CalibrationResult` of :func:`sim.calibrate.fit.calibrate_scale`."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sim.runs.files import save_figure_atomic, write_text_atomic


def figure(res, out: Path) -> str | None:
    """Held-out NRMSE per run, channel and column, before/after; the file name (None: no channel)."""
    keys = [k for k, v in res.per_channel.items() if v["before"] is not None]
    if not keys:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(max(5, 0.5 * len(keys) + 2), 3.8))
    x = np.arange(len(keys))
    after = [res.per_channel[k]["after"] for k in keys]
    ax.bar(x - 0.2, [100 * res.per_channel[k]["before"] for k in keys], 0.4, label="declared model")
    ax.bar(x + 0.2, [100 * (a if a is not None else np.nan) for a in after], 0.4, label="calibrated")
    ax.set_xticks(x, [k.split(":", 1)[1] for k in keys], rotation=60, ha="right", fontsize=7)
    ax.set_ylabel("held-out replay NRMSE (%)")
    ax.set_title(f"held-out error {100 * res.error_before:.2f} % -> {100 * res.error_after:.2f} %")
    ax.legend()
    fig.tight_layout()
    save_figure_atomic(fig, out / "holdout_error.png", dpi=110)
    plt.close(fig)
    return "holdout_error.png"


def report_md(res, fig: str | None, toml_name: str) -> str:
    lines = [
        f"# Calibration of `{res.table}` (strategy: scale, replay path)",
        "",
        f"Runs: {', '.join(Path(r).name for r in res.runs)}. {res.holdout_note}.",
        "",
        f"Held-out error (mean NRMSE of the replayed force, acceleration, displacement): "
        f"**{100 * res.error_before:.2f} % -> {100 * res.error_after:.2f} %**.",
        "",
        "A knob is accepted only off its bounds and when the held-out error falls by the margin.",
        "",
        "## Added",
        "",
    ]
    if res.effects_added:
        lines += ["| knob | value | 95 % | held-out before | after |", "|---|---|---|---|---|"]
        for e in res.effects_added:
            for k, v in e["parameters"].items():
                lines.append(
                    f"| {e['name']} ({e['what']}) | {k} = {v:.6g} {e['units'][k]} | +/-{e['uncertainty'][k]:.3g} | "
                    f"{100 * e['error_before']:.2f} % | {100 * e['error_after']:.2f} % |"
                )
    else:
        lines.append("Nothing: no knob lowered the held-out error by the margin off its bounds.")
    lines += ["", "## Tried", "", "| round | knob | value | fit error | held-out | accepted / why not |"]
    lines.append("|---|---|---|---|---|---|")
    for c in res.candidates:
        ((k, v),) = c["parameters"].items()
        ho = "-" if c["holdout_error"] is None else f"{100 * c['holdout_error']:.2f} %"
        lines.append(
            f"| {c['round'] + 1} | {c['name']} | {k} = {v:.6g} | {100 * c['fit_error']:.2f} % | {ho} | "
            + ("accepted" if c["accepted"] else c["reason"])
            + " |"
        )
    if fig:
        lines += ["", f"![held-out error]({fig})"]
    lines += ["", f"Calibrated description: `{toml_name}` (the original, comments kept, changed values tagged)."]
    return "\n".join(lines) + "\n"


def write_scale_report(res, out, toml_name: str) -> list[str]:
    out = Path(out)
    fig = figure(res, out)
    write_text_atomic(out / "report.md", report_md(res, fig, toml_name))
    return ([fig] if fig else []) + ["report.md"]


__all__ = ["figure", "report_md", "write_scale_report"]

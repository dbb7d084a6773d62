"""``report.md`` of ``shaketable feasibility``: a utilisation bar chart, time histories
of the limiting quantities, the rated displacement-velocity-acceleration envelope with
the demand drawn on it, and the response-spectrum comparison."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mjcf.description import DOFS6


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path) -> str:
    tmp = path.with_suffix(".tmp.png")
    fig.savefig(tmp, dpi=90)
    tmp.replace(path)
    _plt().close(fig)
    return path.name


def utilisation_chart(res: dict, path: Path) -> str:
    plt = _plt()
    checks = sorted(res["checks"], key=lambda c: c["utilisation"] if np.isfinite(c["utilisation"]) else 1e9)
    u = np.array([min(c["utilisation"], 3.0) if np.isfinite(c["utilisation"]) else 3.0 for c in checks])
    fig, ax = plt.subplots(figsize=(7, 0.25 * len(checks) + 1.2))
    ax.barh([c["name"] for c in checks], 100 * u, color=["tab:red" if not c["pass"] else "tab:blue" for c in checks])
    ax.axvline(100, color="k", lw=1)
    ax.set_xlabel("utilisation, % (capped at 300)")
    fig.tight_layout()
    return _save(fig, path)


def envelope_chart(res: dict, outcome, path: Path) -> str | None:
    """Per translational DOF, the rated displacement-velocity-acceleration box with the
    demand of the simulated reference drawn in it: |v| against |d| (top), |a| against
    |v| (bottom); the peaks of the whole motion are in the checks."""
    if outcome is None:
        return None
    plt = _plt()
    run = outcome.run
    ref = run.reference
    desc = outcome.tm.desc
    lim = desc.limits
    dofs = [d for d in ("x", "y", "z") if d in desc.dofs and np.max(np.abs(ref[:, DOFS6.index(d)])) > 0]
    if not dofs:
        return None
    fig, axes = plt.subplots(2, len(dofs), figsize=(3.6 * len(dofs), 6), squeeze=False)
    dt = run.dt
    for j, d in enumerate(dofs):
        i = DOFS6.index(d)
        dd = ref[:, i]
        vv = np.gradient(dd, dt)
        aa = np.gradient(vv, dt)
        top, bot = axes[0][j], axes[1][j]
        top.plot(1e3 * np.abs(dd), np.abs(vv), ".", ms=1, alpha=0.3)
        top.add_patch(plt.Rectangle((0, 0), 1e3 * lim.stroke_m[i], lim.velocity_m_s[i], fill=False, ec="r"))
        top.set_xlabel(f"|d_{d}|, mm")
        top.set_ylabel(f"|v_{d}|, m/s")
        top.set_title(f"{d}: rated box in red")
        bot.plot(np.abs(vv), np.abs(aa) / 9.81, ".", ms=1, alpha=0.3)
        bot.add_patch(plt.Rectangle((0, 0), lim.velocity_m_s[i], lim.acceleration_m_s2[i] / 9.81, fill=False, ec="r"))
        bot.set_xlabel(f"|v_{d}|, m/s")
        bot.set_ylabel(f"|a_{d}|, g")
        for ax in (top, bot):
            ax.autoscale()
            ax.set_xlim(left=0)
            ax.set_ylim(bottom=0)
    fig.tight_layout()
    return _save(fig, path)


def histories_chart(res: dict, outcome, path: Path) -> str | None:
    """The limiting actuator's force against its capacity, stroke, supply pressure and flow."""
    if outcome is None:
        return None
    from sim.assess.feasibility import flow_demand, force_utilisation

    plt = _plt()
    r = outcome.result
    from hydraulics import HydraulicParams

    hp = HydraulicParams.from_table(outcome.tm.desc.raw)
    fu, cap = force_utilisation(r, hp)
    a = int(np.nanargmax(np.nanmax(np.where(np.isfinite(fu), fu, 0), axis=0)))
    name = outcome.tm.actuator_names[a]
    fig, ax = plt.subplots(4, 1, figsize=(8, 8), sharex=True)
    ax[0].plot(r.t, r.channels["actuator_force"][:, a] / 1e3, label=f"{name} force")
    ax[0].plot(
        r.t, cap[:, a] / 1e3 * np.sign(r.channels["actuator_force"][:, a]), "r--", lw=1, label="capacity A p_s(t)"
    )
    ax[0].set_ylabel("kN")
    ax[0].legend(fontsize=7, loc="upper right")
    ax[1].plot(r.t, 1e3 * r.channels["actuator_displacement"])
    ax[1].axhline(1e3 * (hp.half_stroke_m[a] - hp.cushion_length_m[a]), color="r", lw=1)
    ax[1].axhline(-1e3 * (hp.half_stroke_m[a] - hp.cushion_length_m[a]), color="r", lw=1)
    ax[1].set_ylabel("strokes, mm")
    ax[2].plot(r.t, r.extras["supply_pressure"] / 1e6)
    ax[2].axhline(hp.accumulator_precharge_pa / 1e6, color="r", lw=1)
    ax[2].set_ylabel("supply, MPa")
    ax[3].plot(r.t, 1e3 * flow_demand(r, hp), label="flow demand")
    ax[3].axhline(1e3 * hp.pump_flow_m3_s, color="r", lw=1, label="pumps")
    ax[3].set_ylabel("l/s")
    ax[3].set_xlabel("t, s")
    ax[3].legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    return _save(fig, path)


def spectrum_chart(res: dict, outcome, path: Path) -> str | None:
    if outcome is None:
        return None
    from sim.assess.metrics import SPECTRUM_BAND_HZ
    from sim.scenario.motions import response_spectrum

    plt = _plt()
    r = outcome.result
    run = outcome.run
    dt = run.dt
    dofs = [d for d in ("x", "y", "z") if d in outcome.tm.desc.dofs]
    f = np.geomspace(SPECTRUM_BAND_HZ[0], SPECTRUM_BAND_HZ[1], 60)
    fig, ax = plt.subplots(figsize=(7, 4))
    for d in dofs:
        i = DOFS6.index(d)
        ref_a = np.gradient(np.gradient(run.reference[:, i], dt), dt)
        if np.max(np.abs(ref_a)) == 0:
            continue
        ach = np.nan_to_num(r.channels["table_acceleration"][: len(ref_a), i])
        ax.loglog(f, response_spectrum(ref_a, dt, freqs=f, damping=0.05) / 9.81, "--", label=f"{d} target")
        ax.loglog(f, response_spectrum(ach, dt, freqs=f, damping=0.05) / 9.81, label=f"{d} achieved")
    ax.set_xlabel("frequency, Hz")
    ax.set_ylabel("Sa (5 %), g")
    ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    return _save(fig, path)


def write_report(out: Path, res: dict, outcome=None) -> Path:
    """Write ``report.md`` and its figures to ``out``; returns the report's path."""
    from sim.runs.files import write_text_atomic

    out = Path(out)
    figs = [
        ("Utilisation of every check", utilisation_chart(res, out / "utilisation.png")),
        ("Limiting quantities over time", histories_chart(res, outcome, out / "histories.png")),
        ("Rated envelope and demand", envelope_chart(res, outcome, out / "envelope.png")),
        ("Response spectrum, achieved against target", spectrum_chart(res, outcome, out / "spectrum.png")),
    ]
    lines = [
        f"# Feasibility: {res.get('motion')} x {res.get('scale', 1.0):g} on {res.get('table')}"
        f" with {res.get('payload') or 'the bare table'}",
        "",
        f"**{'Feasible' if res['feasible'] else 'Not feasible'}**; limiting check: `{res['limiting']}` at "
        f"{100 * res['limiting_utilisation']:.0f} %.",
    ]
    if res.get("failed"):
        lines.append(f"Failed: {', '.join('`' + f + '`' for f in res['failed'])}.")
    if "max_scale" in res:
        lines.append(
            f"Largest scale: {res['max_scale']}"
            + (f" (limited by `{res['limiting_above']}`)" if res.get("limiting_above") else "")
        )
    if res.get("figures_scale") is not None:
        lines.append(f"The figures show the run at the largest scale, {res['figures_scale']:.3f}.")
    if res.get("note"):
        lines.append(res["note"])
    lines += ["", "| check | demand | capacity | unit | utilisation | pass |", "|---|---|---|---|---|---|"]
    for c in sorted(res["checks"], key=lambda c: -c["utilisation"] if np.isfinite(c["utilisation"]) else -1e9):
        lines.append(
            f"| {c['name']} | {c['demand']:.4g} | {c['capacity']:.4g} | {c['unit']} | "
            f"{100 * c['utilisation']:.1f} % | {'yes' if c['pass'] else 'no (tracking)' if c['name'].startswith(('pga_error_', 'spectrum_')) else 'NO'} |"
        )
    for w in res.get("warnings", []):
        lines.append(f"\nWarning: {w}")
    inter = res.get("interaction")
    if inter:
        lines += [
            "",
            "## Table-specimen interaction",
            "",
            "Oil columns with the specimen: "
            + ", ".join(f"{d} {f:.1f} Hz" for d, f in inter["oil_columns_hz"].items()),
            "Specimen modes: "
            + (
                ", ".join(f"{m['frequency_hz']:.2f} Hz ({m['direction']})" for m in inter["specimen_modes"])
                or "none (rigid)"
            ),
            "Inertia ratio (specimen / table effective mass): "
            + ", ".join(f"{d} {r:.2f}" for d, r in inter["inertia_ratio"].items()),
        ]
    spec = res.get("figures", {}).get("specimen")
    if spec:
        lines += ["", "## Specimen response", ""] + [f"- {k}: {v:.4g}" for k, v in spec.items() if k != "kind"]
    for title, name in figs:
        if name:
            lines += ["", f"## {title}", "", f"![{title}]({name})"]
    path = out / "report.md"
    write_text_atomic(path, "\n".join(lines) + "\n")
    return path


__all__ = ["write_report"]

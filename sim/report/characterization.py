"""The characterisation programme presented: figures and ``report.md`` from the summary of
:func:`sim.identify.characterize.characterize`, and ``characterization.json``."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sim.identify.characterize import DEG, DOFS, MASS_BAND_HZ, MASS_LEVELS
from sim.runs.files import save_figure_atomic, write_json_atomic, write_text_atomic
from sim.signals import estimation as E


def figures(results: list[dict], summary: dict, out: Path) -> list[str]:
    """Draw the programme's figures into ``out``; returns their file names."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pub = summary.get("published") or {}
    rnd = {(r["dof"], r["level"]): r for r in results if r["kind"] == "random" and not r.get("incomplete")}
    drawn = [
        _oil_column_figure(plt, rnd, pub, out),
        _effective_mass_figure(plt, rnd, pub, out),
        _friction_figure(plt, results, summary, out),
        _servovalve_figure(plt, results, summary, out),
        _harmonic_figure(plt, results, out),
    ]
    return [n for n in drawn if n is not None]


def _oil_column_figure(plt, rnd: dict, pub: dict, out: Path) -> str:
    """Spool position -> force FRF per DOF, with the model's peak and the published column."""
    oil_pub = pub.get("oil_column_hz") or {}
    lab = pub.get("labels") or {}
    fig, ax = plt.subplots(2, 6, figsize=(20, 6.5), sharex=True)
    for k, d in enumerate(DOFS):
        lv = "R1" if d in ("x", "y", "z") else "R2"
        r = rnd.get((d, lv))
        if r is None:
            continue
        f, H = r["oil"]["f"], r["oil"]["H"]
        sel = (f >= 1) & (f <= 50)
        ax[0, k].semilogy(f[sel], np.abs(H[sel]))
        ax[1, k].plot(f[sel], np.angle(H[sel], deg=True))
        for a in ax[:, k]:
            if d in oil_pub:
                a.axvline(oil_pub[d], color="r", ls="--", lw=1, label=f"published ({lab.get('oil_column_hz', '')})")
            a.axvline(r["peak"]["f_hz"], color="k", ls=":", lw=1, label="model peak")
            a.grid(True, which="both", alpha=0.3)
        unit = "N" if k < 3 else "N m"
        ax[0, k].set_title(
            f"{d}: {r['peak']['f_hz']:.2f} Hz" + (f" (published {oil_pub[d]:g})" if d in oil_pub else "")
        )
        ax[0, k].set_ylabel(f"|F/spool| ({unit} per unit opening)")
        ax[1, k].set_ylabel("phase (deg)")
        ax[1, k].set_xlabel("frequency (Hz)")
    ax[0, 0].legend(fontsize=7)
    fig.suptitle("Spool position -> force feedback FRF (DOF space), random acceleration control")
    fig.tight_layout()
    save_figure_atomic(fig, out / "oil_column_frf.png", dpi=90)
    plt.close(fig)
    return "oil_column_frf.png"


def _effective_mass_figure(plt, rnd: dict, pub: dict, out: Path) -> str:
    """Acceleration -> force FRF per DOF and level, with the averaging band and published mass."""
    mass_pub = pub.get("effective_mass") or {}
    lab = pub.get("labels") or {}
    fig, ax = plt.subplots(1, 6, figsize=(20, 3.8))
    for k, d in enumerate(DOFS):
        for lv, c in zip(MASS_LEVELS, ("C0", "C1")):
            r = rnd.get((d, lv))
            if r is None:
                continue
            f, H = r["mass"]["f"], r["mass"]["H"]
            sel = (f >= 0.5) & (f <= 50)
            ax[k].plot(f[sel], np.abs(H[sel]) / 1e3, c, lw=1, label=f"{lv}: {r['effective_mass'] / 1e3:.1f}")
        if d in mass_pub:
            ax[k].axhline(
                mass_pub[d] / 1e3, color="r", ls="--", lw=1, label=f"published ({lab.get('effective_mass', '')})"
            )
        ax[k].axvspan(*MASS_BAND_HZ, color="0.9", zorder=-1)
        if d in mass_pub:
            ax[k].set_ylim(0.7 * mass_pub[d] / 1e3, 1.4 * mass_pub[d] / 1e3)
        ax[k].set_title(d)
        ax[k].set_xlabel("frequency (Hz)")
        ax[k].set_ylabel("|F/a| (t)" if k < 3 else "|M/alpha| (t m^2)")
        ax[k].legend(fontsize=7)
        ax[k].grid(True, alpha=0.3)
    fig.suptitle("Acceleration -> force FRF (effective mass; grey: averaging band)")
    fig.tight_layout()
    save_figure_atomic(fig, out / "effective_mass.png", dpi=90)
    plt.close(fig)
    return "effective_mass.png"


def _friction_figure(plt, results: list[dict], summary: dict, out: Path) -> str | None:
    """Force-displacement loops of the friction tests (None: no friction test completed)."""
    fr = {r["dof"]: r for r in results if r["kind"] == "friction" and not r.get("incomplete")}
    if not fr:
        return None
    fig, ax = plt.subplots(1, 6, figsize=(20, 3.8))
    for k, d in enumerate(DOFS):
        r = fr.get(d)
        if r is None:
            ax[k].set_visible(False)
            continue
        sc = 1e3 if k < 3 else 1 / DEG
        ax[k].plot(r["trace"]["d"] * sc, r["trace"]["F"] / 1e3, lw=0.8)
        ax[k].set_xlabel("displacement (mm)" if k < 3 else "rotation (deg)")
        ax[k].set_ylabel("force (kN)" if k < 3 else "moment (kN m)")
        ax[k].set_title(f"{d}: Fc {r['fit']['coulomb'] / 1e3:.1f} k, {100 * summary['friction_fraction'][d]:.2f} %")
        ax[k].grid(True, alpha=0.3)
    fig.suptitle("Friction tests, 0.05 Hz tapered sine: actuator wrench (mean removed) vs displacement")
    fig.tight_layout()
    save_figure_atomic(fig, out / "friction_loops.png", dpi=90)
    plt.close(fig)
    return "friction_loops.png"


def _servovalve_figure(plt, results: list[dict], summary: dict, out: Path) -> str | None:
    """Spool/command FRF per axis with the fitted and the published orders."""
    vr = {r["dof"]: r for r in results if r["kind"] == "valve" and not r.get("incomplete")}
    if not vr:
        return None
    fig, ax = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    ff = np.geomspace(0.5, 125, 300)
    for d, r in vr.items():
        f, H = r["frf"]["f"], r["frf"]["H"]
        sel = (f >= 0.5) & (f <= 125)
        ax[0].semilogx(f[sel], 20 * np.log10(np.abs(H[sel])), lw=1, label=f"model {d}")
        ax[1].semilogx(f[sel], np.angle(H[sel], deg=True), lw=1)
    sv = summary["servovalve"]
    for lab, Hm, st in (
        (f"1st order fit tau {sv['tau_s'] * 1e3:.2f} ms", E.first_order(ff, sv["K_first"], sv["tau_s"]), "--"),
        (
            f"2nd order fit {sv['wn_hz']:.1f} Hz / {sv['zeta']:.2f}",
            E.second_order(ff, sv["K_second"], sv["wn_hz"], sv["zeta"]),
            "-.",
        ),
        ("paper 2nd order 41.5 Hz / 0.75", E.second_order(ff, 1.0, 41.5, 0.75), ":"),
    ):
        ax[0].semilogx(ff, 20 * np.log10(np.abs(Hm)), st, color="k" if st != ":" else "r", label=lab)
        ax[1].semilogx(ff, np.angle(Hm, deg=True), st, color="k" if st != ":" else "r")
    ax[0].set_ylabel("|spool/command| (dB)")
    ax[1].set_ylabel("phase (deg)")
    ax[1].set_xlabel("frequency (Hz)")
    ax[0].legend(fontsize=8)
    for a in ax:
        a.grid(True, which="both", alpha=0.3)
    fig.suptitle("Servovalve FRF (random displacement control, 0.01 m RMS, 0.5-125 Hz)")
    fig.tight_layout()
    save_figure_atomic(fig, out / "servovalve.png", dpi=90)
    plt.close(fig)
    return "servovalve.png"


def _harmonic_figure(plt, results: list[dict], out: Path) -> str | None:
    """Reference, closed-loop and replayed displacement of the harmonic test."""
    hr = [r for r in results if r["kind"] == "harmonic" and not r.get("incomplete")]
    if not hr:
        return None
    tr = hr[0]["trace"]
    fig, ax = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    for k, d in enumerate(("x", "y", "z")):
        ax[k].plot(tr["t"], tr["ref"][:, k] * 1e3, "k--", lw=1, label="reference")
        ax[k].plot(tr["t"], tr["closed"][:, k] * 1e3, lw=1, label="closed loop")
        if tr["replay"] is not None:
            ax[k].plot(tr["t"], tr["replay"][:, k] * 1e3, ":", lw=1.5, label="plant on recorded commands")
        ax[k].set_ylabel(f"{d} (mm)")
        ax[k].grid(True, alpha=0.3)
    ax[0].legend(fontsize=8)
    ax[-1].set_xlabel("time (s)")
    fig.suptitle("Harmonic validation test, 0.25 Hz, 100/100/50 mm, 90 deg lags")
    fig.tight_layout()
    save_figure_atomic(fig, out / "harmonic.png", dpi=90)
    plt.close(fig)
    return "harmonic.png"


def write_report(out: Path, summary: dict, rows: list[dict], figures: list[str]) -> None:
    L = [
        f"# Characterisation of `{summary['table']}`"
        + (f" with payload `{summary['payload']}`" if summary["payload"] else " (bare table)"),
        "",
    ]
    L.append(
        f"Programme of [Airouche 2014] run on the model ({summary.get('mode', 'full')} records), "
        f"{summary.get('wall_s', float('nan')):.0f} s wall time, {summary.get('sim_s', float('nan')):.0f} s "
        "simulated."
    )
    L.append("")
    if summary["failed_tests"]:
        L += ["**Tests that did not complete:**", ""] + [f"- {x}" for x in summary["failed_tests"]] + [""]
    L += [
        "## Paper vs model",
        "",
        "| quantity | DOF | paper | model | unit | error | within tolerance |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        w = "" if r["within"] is None else ("yes" if r["within"] else f"**no** (tol {100 * r['tolerance']:.0f} %)")
        L.append(
            f"| {r['quantity']} | {r['dof']} | {r['paper']:.4g} | {r['model']:.4g} | {r['unit']} | "
            f"{100 * r['error']:+.2f} % | {w} |"
        )
    L.append("")
    if summary.get("payload"):
        L += ["With a payload the paper values are the bare table's: the oil-column column shows the drop.", ""]
    if summary.get("oil_column_damping_ratio"):
        L += ["## Oil-column damping (half-power)", "", "| DOF | peak (Hz) | damping ratio |", "|---|---|---|"]
        for d, z in summary["oil_column_damping_ratio"].items():
            L.append(f"| {d} | {summary['oil_column_hz'][d]:.2f} | {100 * z:.1f} % |")
        L.append("")
    if summary.get("linear_oil_column_hz"):
        L += [
            "Linearised oil columns (locked valves, mid-stroke volumes): "
            + ", ".join(f"{d} {v:.2f}" for d, v in summary["linear_oil_column_hz"].items())
            + " Hz.",
            "",
        ]
    if summary.get("friction_fraction"):
        L += _friction_lines(summary)
    if summary.get("servovalve"):
        L += _servovalve_lines(summary)
    if summary.get("harmonic"):
        L += _harmonic_lines(summary)
    if summary.get("random_tracking_rms"):
        L += _random_lines(summary)
    L += ["## Figures", ""] + [f"![{n}]({n})" for n in figures] + [""]
    write_text_atomic(out / "report.md", "\n".join(L))


def _friction_lines(summary: dict) -> list[str]:
    """Friction per DOF: the fitted Coulomb level against the capability, and the loop shape."""
    L = [
        "## Friction",
        "",
        "Capability per DOF = supply pressure x sum_i A_i |J_ik| (every actuator at full pressure).",
        "",
        "Fraction: the least-squares Coulomb term (F = m a + k d + c v + F0 + Fc sign(v)); mid-stroke: "
        "the loop's half-height where |d| < 0.4 of the amplitude, for comparison.",
        "",
        "| DOF | friction | capability | fraction | mid-stroke half-height | outer/inner loop half-width |",
        "|---|---|---|---|---|---|",
    ]
    for d, v in summary["friction_fraction"].items():
        u = "kN" if d in ("x", "y", "z") else "kN m"
        L.append(
            f"| {d} | {summary['friction_force'][d] / 1e3:.2f} {u} | {summary['capability'][d] / 1e3:.0f} {u} "
            f"| {100 * v:.2f} % | {100 * summary['friction_midstroke_fraction'][d]:.2f} % "
            f"| {summary['friction_outer_over_inner'][d]:.3f} |"
        )
    L.append("")
    return L


def _servovalve_lines(summary: dict) -> list[str]:
    """The servovalve's first- and second-order fits per axis."""
    sv = summary["servovalve"]
    L = [
        "## Servovalve fits per axis",
        "",
        "tau: complex first-order fit over 0.5-20 Hz (the graded figure); tau, magnitude fit: the same model fitted to the "
        "magnitude alone over the whole 0.5-125 Hz test band, another reading of the paper's unstated fit.",
        "",
        "| axis | tau (ms) | tau, magnitude fit (ms) | K (1st) | w (Hz) | xi | K (2nd) |",
        "|---|---|---|---|---|---|---|",
    ]
    for d, p in sv["per_axis"].items():
        L.append(
            f"| {d} | {1e3 * p['tau_s']:.3f} | {1e3 * p['tau_s_magnitude_fit']:.3f} "
            f"| {p['K_first']:.3f} | {p['wn_hz']:.2f} | {p['zeta']:.3f} | {p['K_second']:.3f} |"
        )
    L.append("")
    return L


def _harmonic_lines(summary: dict) -> list[str]:
    """Peak and NRMSE of the harmonic test, closed loop and replayed."""
    h = summary["harmonic"]
    L = [
        "## Harmonic validation (0.25 Hz)",
        "",
        "| axis | peak (mm) | NRMSE closed loop | NRMSE replay vs closed loop |",
        "|---|---|---|---|",
    ]
    for d in ("x", "y", "z"):
        rp = h["nrmse_replay_vs_closed_loop"][d] if h["nrmse_replay_vs_closed_loop"] else float("nan")
        L.append(f"| {d} | {h['peak_mm'][d]:.1f} | {h['nrmse_closed_loop'][d]:.4f} | {rp:.2e} |")
    L.append("")
    return L


def _random_lines(summary: dict) -> list[str]:
    """Reference and achieved RMS acceleration of each random test."""
    L = [
        "## Random tests: RMS acceleration, reference vs achieved",
        "",
        "| test | reference | achieved |",
        "|---|---|---|",
    ]
    for k, v in summary["random_tracking_rms"].items():
        L.append(f"| {k} | {v['reference']:.4g} | {v['achieved']:.4g} |")
    L.append("")
    return L


def write_characterization(out, summary: dict, *, draw: bool = True) -> list[str]:
    """Write ``characterization.json`` (the summary without the raw results), ``report.md``
    and, with ``draw``, the figures into folder ``out``; returns the figure names."""
    from sim.runs.files import out_dir

    outp = out_dir(out)
    results = summary.get("_results", [])
    names = figures(results, summary, outp) if draw and results else []
    write_report(outp, summary, summary.get("comparison", []), names)
    write_json_atomic(outp / "characterization.json", {k: v for k, v in summary.items() if not k.startswith("_")})
    return names

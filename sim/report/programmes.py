"""``characterize`` for every table: run the programme its description declares and
write ``characterization.json``, ``report.md`` and the figures.

The programme is the table file's ``[published] programme`` (see
:mod:`sim.papers.programmes`): the 6-DOF identification programme
(:func:`sim.identify.characterize.characterize`, the default) or one of the papers'
programmes (:data:`sim.papers.programmes.PROGRAMMES`). Nothing here names a table.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from sim.runs.files import out_dir, write_json_atomic, write_text_atomic


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def frf_figures(results: list[dict], out: Path) -> list[str]:
    """One figure per paper figure: |T| of the model FRF and of the analytical T(s)."""
    plt = _plt()
    groups: dict[str, list[dict]] = {}
    for r in results:
        key = r["case"].figure.split(" ")[0:2]
        groups.setdefault(" ".join(key) or "cases", []).append(r)
    names = []
    for title, rs in groups.items():
        fig, ax = plt.subplots(figsize=(8, 4.5))
        for k, r in enumerate(rs):
            f = np.asarray(r["f"])
            sel = (f > 0) & (f <= 100)
            c = f"C{k % 10}"
            ax.semilogy(f[sel], np.abs(r["model"][sel]), color=c, lw=1, label=f"{r['case'].name} (model)")
            ax.semilogy(f[sel], np.abs(r["analytical"][sel]), color=c, lw=1, ls="--", label="analytical")
        ax.set_xlabel("frequency (Hz)")
        ax.set_ylabel("|commanded -> achieved acceleration|")
        ax.set_title(f"{title}: model FRF (solid) vs analytical T(s) (dashed)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=6, ncol=2)
        fig.tight_layout()
        name = "frf_" + (re.sub(r"[^a-z0-9]+", "_", title.lower()).strip("_") or "cases") + ".png"
        fig.savefig(out / name, dpi=90)
        plt.close(fig)
        names.append(name)
    return names


def identification_figures(results: list[dict], summary: dict, out: Path) -> list[str]:
    """Measured force against displacement for every test, and the identified
    parameters per test set against the paper's."""
    plt = _plt()
    n = len(results)
    cols = min(5, n) or 1
    rows = -(-n // cols)
    fig, ax = plt.subplots(rows, cols, figsize=(3.2 * cols, 2.8 * rows), squeeze=False)
    for a, r in zip(ax.flat, results):
        m = r["measured"]
        a.plot(np.asarray(m["disp"]) * 100, np.asarray(m["force"]) / 1e3, lw=0.6)
        a.set_title(r["name"], fontsize=9)
        a.grid(True, alpha=0.3)
    for a in ax[-1]:
        a.set_xlabel("displacement (cm)")
    for a in ax[:, 0]:
        a.set_ylabel("force (kN)")
    for a in list(ax.flat)[n:]:
        a.axis("off")
    fig.suptitle("Measured actuator force vs table displacement (DAQ model)")
    fig.tight_layout()
    fig.savefig(out / "force_displacement.png", dpi=90)
    plt.close(fig)
    names = ["force_displacement.png"]
    sets = summary.get("identification_sets") or {}
    paper = summary.get("paper") or {}
    if sets:
        keys = [
            ("M_e_kg", 1e3, "M_e (t)"),
            ("K_e_N_per_m", 1e6, "K_e (MN/m)"),
            ("C_e", 1e3, "C_e (kN (s/m)^a)"),
            ("F_mu_N", 1e3, "F_mu (kN)"),
        ]
        fig, ax = plt.subplots(1, 4, figsize=(16, 3.6))
        x = np.arange(len(sets))
        for a, (k, scale, label) in zip(ax, keys):
            a.bar(x, [v["unconstrained"][k] / scale for v in sets.values()], color="C0", label="identified")
            if k in paper:
                a.axhline(paper[k] / scale, color="r", ls="--", lw=1, label="paper")
            a.set_xticks(x, list(sets), rotation=30, fontsize=8)
            a.set_title(label)
            a.grid(True, axis="y", alpha=0.3)
        ax[0].legend(fontsize=7)
        fig.suptitle("Least-squares identification per test set (unconstrained)")
        fig.tight_layout()
        fig.savefig(out / "identification.png", dpi=90)
        plt.close(fig)
        names.append("identification.png")
    return names


#: what draws each paper programme's figures
FIGURES = {
    "frf_random": lambda s, out: frf_figures(s["_results"], out),
    "ls_identification": lambda s, out: identification_figures(s["_results"], s, out),
}


def characterize_table(
    table: str,
    payload: str | None = None,
    *,
    out,
    quick: bool = False,
    workers: int | None = None,
    progress=None,
    stage=None,
) -> dict:
    """Run the programme ``table`` declares and write its outputs into folder ``out``:
    ``characterization.json``, ``report.md`` and the figures. Returns the summary as
    written to the JSON (with ``figures`` and ``programme``). ``progress(done, total)``
    after each test; ``stage(text)`` once the inputs are checked and the tests start."""
    from sim.identify import characterize as C
    from sim.papers.programmes import DEFAULT_PROGRAMME, PROGRAMMES, declared_programme

    desc, _ = C.load_inputs(table, payload)
    prog = declared_programme(desc)
    if prog != DEFAULT_PROGRAMME and prog not in PROGRAMMES:
        raise C.CharacterizeError(
            f"{desc.source}: [published] programme '{prog}' is unknown; use one of "
            f"{', '.join([DEFAULT_PROGRAMME, *PROGRAMMES])}"
        )
    if payload and prog != DEFAULT_PROGRAMME:
        raise C.CharacterizeError(
            f"{desc.source} declares the '{prog}' programme, which runs on the bare table; leave out --payload"
        )
    outp = out_dir(out)  # checked before the work starts
    if stage:
        stage(f"characterising {desc.name} with the {prog} programme" + (" (quick)" if quick else ""))
    if prog == DEFAULT_PROGRAMME:
        from sim.report.characterization import write_characterization

        s = C.characterize(table, payload, quick=quick, workers=workers, progress=progress)
        s["programme"] = prog
        s["figures"] = write_characterization(outp, s)
        s.pop("_results", None)
        write_json_atomic(outp / "characterization.json", s)
        return s
    s = PROGRAMMES[prog](desc, quick=quick, workers=workers, progress=progress, runs_dir=outp / "runs")
    names = FIGURES[prog](s, outp)
    s["figures"] = names
    lines = list(s.pop("_report")) + ["", "## Figures", ""] + [f"![{n}]({n})" for n in names]
    write_text_atomic(outp / "report.md", "\n".join(lines) + "\n")
    s.pop("_results")
    write_json_atomic(outp / "characterization.json", s)
    return s


__all__ = ["characterize_table", "frf_figures", "identification_figures"]

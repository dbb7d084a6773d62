"""``shaketable calibrate`` presented: figures and ``report.md`` from a
:class:`sim.calibrate.search.CalibrationResult`."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sim.runs.files import write_text_atomic


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def figures(res, out: Path) -> list[str]:
    """Draw the calibration's figures into ``out``; returns their file names."""
    from sim.calibrate.residuals import spectra

    if res.series.get("kind") == "path":
        return path_figures(res, out)
    plt = _plt()
    names = []
    ho, before, after = res.series["holdout"], res.series["before"], res.series["after"]
    # 1. held-out error per run and DOF
    keys = list(res.per_channel)
    fig, ax = plt.subplots(figsize=(max(5, 1.2 * len(keys) + 2), 3.6))
    x = _error_bars(ax, res, keys)
    ax.set_xticks(x, keys, rotation=30, ha="right", fontsize=8)
    ax.set_ylabel("held-out force NRMSE (%)")
    ax.set_title(_title(res))
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "holdout_error.png", dpi=110)
    plt.close(fig)
    names.append("holdout_error.png")
    # 2. residual time series and 3. spectra, before/after (each held-out run, each DOF)
    k = len(ho[0].dofs)
    fig, ax = plt.subplots(len(ho) * k, 1, figsize=(10, 2.2 * len(ho) * k), squeeze=False)
    nc = min(k, 3)
    nr = -(-k // nc)
    fig2, ax2s = plt.subplots(nr, nc, figsize=(6 * nc, 3.8 * nr), squeeze=False)
    ax2 = ax2s.reshape(1, -1)
    for i, (mr, e0, e1) in enumerate(zip(ho, before, after)):
        t = np.arange(len(e0)) * mr.dt
        for j, d in enumerate(mr.dofs):
            a = ax[i * k + j, 0]
            a.plot(t, e0[:, j] / 1e3, lw=0.6, label="declared model")
            a.plot(t, e1[:, j] / 1e3, lw=0.6, label="calibrated")
            a.set_title(f"{Path(mr.name).name} {d}: residual force", fontsize=9)
            a.set_ylabel("kN (kN m)")
            if i == 0:
                s0 = spectra(e0[:, j], 1.0 / mr.dt)
                s1 = spectra(e1[:, j], 1.0 / mr.dt)
                ax2[0, j].semilogy(s0["f"][1:], s0["psd"][1:], lw=0.8, label="declared model")
                ax2[0, j].semilogy(s1["f"][1:], s1["psd"][1:], lw=0.8, label="calibrated")
                ax2[0, j].set_xlabel("Hz")
                ax2[0, j].set_ylabel("residual PSD (N^2/Hz)")
                ax2[0, j].set_title(f"{Path(mr.name).name} {d}")
                if res.unexplained and res.unexplained["where"].endswith(d):
                    ax2[0, j].axvline(res.unexplained["peak_hz"], color="k", ls=":", label="unexplained")
                ax2[0, j].legend(fontsize=8)
        ax[i * k, 0].legend(fontsize=7)
    ax[-1, 0].set_xlabel("s")
    for f_, nm in ((fig, "residual_time.png"), (fig2, "residual_spectra.png")):
        f_.tight_layout()
        f_.savefig(out / nm, dpi=110)
        plt.close(f_)
        names.append(nm)
    # 4. residual force vs displacement and velocity (fit runs, before/after)
    fit = res.series["fit"]
    fig, ax = plt.subplots(k, 4, figsize=(16, 3.2 * k), squeeze=False)
    for c0, (lab, E) in enumerate(
        (("declared model", res.series["fit_before"]), ("calibrated", res.series["fit_after"]))
    ):
        for j in range(k):
            a_d, a_v = ax[j, 2 * c0], ax[j, 2 * c0 + 1]
            for mr, e in zip(fit, E):
                a_d.plot(mr.u[mr.rows, j] * 1e3, e[mr.rows, j] / 1e3, ",", alpha=0.5)
                a_v.plot(mr.v[mr.rows, j], e[mr.rows, j] / 1e3, ",", alpha=0.5)
            a_d.set_title(f"{lab}: residual vs displacement ({fit[0].dofs[j]})", fontsize=9)
            a_v.set_title(f"{lab}: residual vs velocity ({fit[0].dofs[j]})", fontsize=9)
            a_d.set_xlabel("mm (mrad)")
            a_v.set_xlabel("m/s (rad/s)")
            a_d.set_ylabel("kN (kN m)")
    fig.tight_layout()
    fig.savefig(out / "residual_vs_state.png", dpi=110)
    plt.close(fig)
    names.append("residual_vs_state.png")
    # 5. accepted effects: value and 95 % interval, relative
    if res.effects_added:
        names.append(_effects_figure(plt, res, out))
    return names


def _title(res) -> str:
    b = getattr(res, "baseline", None)
    tail = f" (linear ARX baseline {100 * b['holdout_error']:.2f} %)" if b else ""
    return f"held-out error {100 * res.error_before:.2f} % -> {100 * res.error_after:.2f} %{tail}"


def _error_bars(ax, res, keys) -> np.ndarray:
    """Held-out error per run and column: declared model, calibrated, and the linear ARX
    baseline when there is one; returns the bar groups' positions."""
    x = np.arange(len(keys))
    base = (getattr(res, "baseline", None) or {}).get("per_channel")
    w = 0.27 if base else 0.4
    ax.bar(x - w / (1 if base else 2), [100 * res.per_channel[k]["before"] for k in keys], w, label="declared model")
    ax.bar(x + (0 if base else w / 2), [100 * res.per_channel[k]["after"] for k in keys], w, label="calibrated")
    if base:
        ax.bar(x + w, [100 * base.get(k, np.nan) for k in keys], w, label="linear ARX baseline")
    return x


def _bars(plt, res, out, ylabel) -> str:
    keys = list(res.per_channel)
    fig, ax = plt.subplots(figsize=(min(max(5, 0.5 * len(keys) + 2), 24), 3.8))
    x = _error_bars(ax, res, keys)
    ax.set_xticks(x, keys, rotation=60, ha="right", fontsize=6)
    ax.set_ylabel(ylabel)
    ax.set_title(_title(res))
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "holdout_error.png", dpi=110)
    plt.close(fig)
    return "holdout_error.png"


def path_figures(res, out: Path, n_columns: int = 6) -> list[str]:
    """The figures of the replay / closed-loop paths: held-out error per channel column,
    residual time series and spectra before/after for the columns with the largest
    residual, residual against the recorded signal, accepted effects."""
    from sim.calibrate.paths import residual_columns
    from sim.calibrate.residuals import spectra

    plt = _plt()
    names = [_bars(plt, res, out, "held-out NRMSE per channel column (%)")]
    pr, m0, m1 = res.series["holdout"][0], res.series["before"][0], res.series["after"][0]
    c0, c1 = residual_columns(pr, m0), residual_columns(pr, m1)
    order = sorted(
        range(len(c0)),
        key=lambda i: (
            -float(np.sum(c0[i][2] ** 2)) / max(float(np.sum(pr.recorded[c0[i][0]][pr.rows][:, c0[i][1]] ** 2)), 1e-300)
        ),
    )[:n_columns]
    t = pr.t[pr.rows]
    fig, ax = plt.subplots(len(order), 1, figsize=(10, 2.0 * len(order)), squeeze=False)
    fig2, ax2 = plt.subplots(len(order), 1, figsize=(7, 2.4 * len(order)), squeeze=False)
    fig3, ax3 = plt.subplots(len(order), 2, figsize=(10, 2.6 * len(order)), squeeze=False)
    for r, i in enumerate(order):
        ch, j, e0 = c0[i]
        e1 = c1[i][2]
        lab = f"{Path(pr.name).name} {ch}[{j}]"
        ax[r, 0].plot(t, e0, lw=0.6, label="declared model")
        ax[r, 0].plot(t, e1, lw=0.6, label="calibrated")
        ax[r, 0].set_title(lab + ": recorded - model", fontsize=9)
        s0, s1 = spectra(e0, 1.0 / pr.dt), spectra(e1, 1.0 / pr.dt)
        ax2[r, 0].semilogy(s0["f"][1:], s0["psd"][1:], lw=0.8, label="declared model")
        ax2[r, 0].semilogy(s1["f"][1:], s1["psd"][1:], lw=0.8, label="calibrated")
        ax2[r, 0].set_title(lab, fontsize=9)
        ax2[r, 0].set_ylabel("PSD (unit^2/Hz)")
        x = pr.recorded[ch][pr.rows][:, j]
        for k, (nm, e) in enumerate((("declared model", e0), ("calibrated", e1))):
            ax3[r, k].plot(x, e, ",", alpha=0.5)
            ax3[r, k].set_title(f"{nm}: residual vs recorded, {ch}[{j}]", fontsize=8)
    ax[0, 0].legend(fontsize=7)
    ax2[0, 0].legend(fontsize=7)
    ax[-1, 0].set_xlabel("s")
    ax2[-1, 0].set_xlabel("Hz")
    for f_, nm in ((fig, "residual_time.png"), (fig2, "residual_spectra.png"), (fig3, "residual_vs_state.png")):
        f_.tight_layout()
        f_.savefig(out / nm, dpi=110)
        plt.close(f_)
        names.append(nm)
    if res.effects_added:
        names.append(_effects_figure(plt, res, out))
    return names


def _effects_figure(plt, res, out) -> str:
    labels, rel, err = [], [], []
    for e in res.effects_added:
        for p, v in e["parameters"].items():
            if e["uncertainty"].get(p) is None:  # held at the description's value (no interval)
                continue
            labels.append(f"{e['name']} {e['where']}\n{p}")
            rel.append(1.0)
            err.append(abs(e["uncertainty"][p] / v) if v else np.inf)
    fig, ax = plt.subplots(figsize=(max(5, 1.6 * len(labels)), 3.6))
    ax.errorbar(np.arange(len(labels)), rel, yerr=err, fmt="o", capsize=4)
    ax.set_xticks(np.arange(len(labels)), labels, fontsize=8)
    ax.set_ylabel("value / fitted value (95 % interval)")
    ax.set_title("accepted effects")
    fig.tight_layout()
    fig.savefig(out / "effects.png", dpi=110)
    plt.close(fig)
    return "effects.png"


def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.2f} %"


def _where_error_sits(res) -> list[str]:
    """The held-out error per run and per channel / DOF, before and after, and the
    channels / DOFs left out as not excited (noise over nothing)."""
    L = ["## Where the error sits", ""]
    per_run = getattr(res, "per_run", {}) or {}
    if per_run:
        L += ["| held-out run | before | after |", "|---|---|---|"]
        L += [f"| `{k}` | {_pct(v['before'])} | {_pct(v['after'])} |" for k, v in per_run.items()]
        L.append("")
    if res.per_channel:
        L += _per_channel_table(res.per_channel, "run: channel or DOF")
    if _has_floor(res.per_channel):
        L += [
            "Noise floor: the error a perfect model would still leave there. On the mechanical path, "
            "the recorded acceleration's white noise (its level in the top of the band) times the "
            "declared moving mass, over the DOF's recorded force; on the replay and closed-loop "
            "paths, the channel's own white noise over its RMS. An error near its floor is the "
            "sensors', not the model's.",
            "",
        ]
    quiet = getattr(res, "not_excited", []) or []
    if quiet:
        from sim.calibrate.windows import QUIET_COLUMN

        L += [
            f"Not excited (RMS below {100 * QUIET_COLUMN:g} % of the run's largest, DOFs in actuator units; "
            "left out of every error above): " + ", ".join(f"`{q}`" for q in quiet) + ".",
            "",
        ]
    return L


def _paths_md(res) -> list[str]:
    """Each residual path's held-out error when the search ran on several
    (:mod:`sim.calibrate.stages`): what each found, and the paths' pooled verdict."""
    if len(res.paths) < 2:
        return []
    L = [
        "## Residual paths",
        "",
        "The runs support several paths; each effect was looked for where it shows "
        "(docs/calibration.md). Held-out NRMSE per path:",
        "",
        "| path | declared model | calibrated | linear ARX baseline | effects added here |",
        "|---|---|---|---|---|",
    ]
    for name, p in res.paths.items():
        if "skipped" in p:
            L.append(f"| {name} | - | - | - | left out: {p['skipped']} |")
            continue
        before = p.get("error_before_declared", p["error_before"])
        found = ", ".join(p["effects_added"]) or "none"
        refused = f" ({p['refused']})" if p.get("refused") else ""
        L.append(
            f"| {name} | {_pct(before)} | {_pct(p['error_after'])} | {_pct(p.get('baseline_error'))} | {found}{refused} |"
        )
    per_ch = {f"{name}: {k}": v for name, p in res.paths.items() for k, v in p.get("per_channel", {}).items()}
    return L + [""] + _per_channel_table(per_ch, "path: run: channel or DOF")


def _has_floor(per: dict) -> bool:
    """Whether any column of ``per`` carries a noise floor (the mechanical path's
    accelerometers' and load cells', the replay and closed-loop paths' channel noise)."""
    return any(v.get("floor") is not None for v in per.values())


def _per_channel_table(per: dict, head: str) -> list[str]:
    """The held-out error per column before and after, with the noise floor where a column
    has one (:func:`sim.calibrate.mechnoise.dof_floor`,
    :func:`sim.calibrate.paths.column_floors`) and the column's weight in the pooled error
    (:func:`sim.calibrate.mechnoise.dof_noise_weights`,
    :func:`sim.calibrate.paths.noise_weights`)."""
    floor = _has_floor(per)
    weight = any("weight" in v for v in per.values())
    L = [
        f"| {head} | before | after |" + (" noise floor |" if floor else "") + (" weight |" if weight else ""),
        "|---|---|---|" + ("---|" if floor else "") + ("---|" if weight else ""),
    ]
    for k, v in per.items():
        row = f"| `{k}` | {_pct(v['before'])} | {_pct(v['after'])} |"
        row += f" {_pct(v.get('floor'))} |" if floor else ""
        L.append(row + (f" {v['weight']:.2f} |" if "weight" in v else " |" if weight else ""))
    return L + [""]


def _unknowns_md(rep: dict | None) -> list[str]:
    """The section on the description's ``[unknown]`` values (sim/calibrate/unknowns.py)."""
    if not rep:
        return []
    L = ["## Values the lab did not know (identified first)", "", rep["note"] + "."]
    if rep.get("values"):
        L += [
            "",
            f"Held-out NRMSE with the nominals {_pct(rep['holdout_error_nominal'])}, with these values "
            f"{_pct(rep['holdout_error_identified'])} ({rep['path']} path).",
            "",
            "| key | range | nominal | identified | 95 % interval |",
            "|---|---|---|---|---|",
        ]
        for k, d in rep["values"].items():
            lo, hi = d["interval_95"]
            L.append(
                f"| `{k}` | {d['range'][0]:.4g}-{d['range'][1]:.4g} | {d['nominal']:.4g} | {d['value']:.4g}"
                + (" (at its bound)" if d["at_bound"] else "")
                + f" | {lo:.4g}-{hi:.4g} |"
            )
    return L + [""]


def _candidates_md(rows: list) -> list[str]:
    """The candidates table; with the path of each row where several paths were searched."""
    paths = any("path" in c for c in rows)
    head = (
        "| round | "
        + ("path | " if paths else "")
        + "effect | where | explains | held-out NRMSE | accepted | why not |"
    )
    L = [head, "|" + "---|" * (head.count("|") - 1)]
    for c in rows:
        L.append(
            f"| {c['round']} | "
            + (f"{c.get('path', '')} | " if paths else "")
            + f"{c['name']} | {c['where']} | {100 * c['explained_fraction']:.2f} % | "
            f"{_pct(c['holdout_error'])} | {'yes' if c['accepted'] else 'no'} | {c['reason']} |"
        )
    return L


def _compensation(res) -> list[str]:
    """The candidates refused as compensation: effects the table cannot have (a force
    above its actuators', a mass several times its moving mass, a valve flow or bandwidth
    no servovalve has) that the fit reached for to stand in for something else."""
    rows = [c for c in res.candidates if c.get("compensation")]
    L = ["", "## Refused as compensation", ""]
    if not rows:
        return L + ["No candidate was refused as physically implausible."]
    L += [
        "These fitted the records but are not physically there: each stands in for something "
        "the model lacks (docs/calibration.md, acceptance).",
        "",
        "| round | effect | where | parameters | why |",
        "|---|---|---|---|---|",
    ]
    for c in rows:
        pars = ", ".join(f"{k} = {v:.4g}" for k, v in c["parameters"].items())
        L.append(f"| {c['round']} | {c['name']} | {c['where']} | {pars} | {c['reason']} |")
    return L


def report_md(res, figs: list[str], toml_name: str) -> str:
    L = [f"# Calibration of `{res.table}`", ""]
    L.append(
        f"Residual path: **{res.residual_path}**. Fit runs: "
        + ", ".join(f"`{Path(r).name}`" for r in res.runs if r not in res.holdout)
        + ". "
        + f"Held-out: {res.holdout_note}."
    )
    L += [
        "",
        f"Held-out NRMSE{' (pooled over the paths: the RMS of theirs)' if len(res.searched_paths()) > 1 else ''}: "
        f"**{100 * res.error_before:.2f} %** (declared model) -> "
        f"**{100 * res.error_after:.2f} %** (calibrated).",
        "",
    ]
    L += _paths_md(res)
    L += _where_error_sits(res)
    L += baseline_md(res)
    L += _unknowns_md(getattr(res, "unknowns_identified", None))
    L += ["## Effects added", ""]
    if res.effects_added:
        L += ["| effect | where | parameter | value | 95 % interval |", "|---|---|---|---|---|"]
        for e in res.effects_added:
            for p, v in e["parameters"].items():
                u = e["uncertainty"].get(p)
                iv = (
                    f"+/-{u:.3g}"
                    if u is not None
                    else "fixed at its bound (the nested law)"
                    if p in e.get("fixed", {})
                    else "held at the description's value"
                )
                L.append(f"| {e['name']} | {e['where']} | {p} | {v:.6g} {e['units'][p]} | {iv} |")
        L += _later_path_notes(res) + _places_untold(res)
    else:
        L.append("None: no candidate passed the acceptance tests.")
    L += [
        "",
        f"Written to `{toml_name}` (the original description, comments kept).",
        "",
        "## Candidates",
        "",
    ]
    L += _candidates_md(res.candidates)
    L += _compensation(res)
    L += ["", "## Unexplained", ""]
    u = res.unexplained
    if u:
        L.append(
            f"A spectral line at **{u['peak_hz']:.2f} Hz** in `{u['channel']}` ({u['where']}) holds "
            f"{100 * u['fraction_of_residual']:.1f} % of the residual left (coherence with the "
            + (
                f"motion {u['coherence_with_motion']:.2f}"
                if "coherence_with_motion" in u
                else f"drive {u['coherence_with_drive']:.2f}"
            )
            + "); no effect of the library explains it."
        )
    else:
        L.append("No spectral line holds a notable share of the residual left.")
    L += ["", "## Figures", ""] + [f"![{f}]({f})" for f in figs]
    if len(res.searched_paths()) > 1:
        L += ["", f"Time: {res.timing['total_s']:.1f} s in all."]
        for name in res.searched_paths():
            L += _time_md(res.timing.get(name, {}), f"{name} path: ")
    else:
        L += _time_md(res.timing, "Time: ")
    return "\n".join(L)


def _later_path_notes(res) -> list[str]:
    """A line for each effect the later path refitted (``refined_on``), placed
    (``placed_on``) or could not place either (``tied_on_later``), and for each that a
    description number says the same as (``reads_as``, :mod:`sim.calibrate.readings`)."""
    out = [
        f"\n`{e['name']}` at {e['where']}: found on the {e.get('path', 'mechanical')} path, its values "
        f"refitted on the {e['refined_on'].replace('_', '-')} path, where its columns pin it (the intervals there)."
        for e in res.effects_added
        if e.get("refined_on")
    ]
    out += [
        f"\n`{e['name']}` at {e['where']}: on the mechanical path other places explained it as "
        f"well (the test moved them alike); the {e['placed_on'].replace('_', '-')} path's held-out "
        "error chose this one."
        for e in res.effects_added
        if e.get("placed_on")
    ]
    out += [
        f"\n`{e['name']}` at {e['where']}: {', '.join(e['tied_on_later'])} held out within the margin of it on "
        "the later path too: the records do not tell these places apart (a test that moves them differently would)."
        for e in res.effects_added
        if e.get("tied_on_later")
    ]
    return out + [
        f"\n`{e['name']}` at {e['where']} reads as {e['reads_as']}." for e in res.effects_added if e.get("reads_as")
    ]


def _places_untold(res) -> list[str]:
    """A line for each effect whose place tied with others on the mechanical path and that
    no later path placed (``--path mechanical``, or records without valve commands or a
    reference): the place is the tie-break's choice, not what the records show."""
    from sim.calibrate.placement import tied_places

    out = []
    for e in res.effects_added:
        alts = [] if e.get("placed_on") else tied_places(res.candidates, e)
        if alts:
            out.append(
                f"\n`{e['name']}` at {e['where']}: {', '.join(alts)} explained it as well on the mechanical "
                "path (the test moved them alike) and no later path told them apart: the place is the "
                "tie-break's choice, not a finding."
            )
    return out


def _time_md(tm: dict, head: str) -> list[str]:
    """Where one path's search spent its time."""
    if not tm:
        return []
    if "least_squares_fits" in tm:
        return [
            "",
            f"{head}{tm['total_s']:.1f} s (reading {tm['read_s']:.1f} s, residuals {tm['residuals_s']:.1f} s, "
            f"search {tm['search_s']:.1f} s, {tm['least_squares_fits']} candidate fits).",
            "",
        ]
    L = [
        "",
        f"{head}{tm['total_s']:.1f} s (reading {tm['read_s']:.1f} s; simulations of the current model "
        f"{tm['simulate_s']:.1f} s, screening {tm['screen_s']:.1f} s, refinement {tm['refine_s']:.1f} s, "
        f"whole-run acceptance {tm['accept_s']:.1f} s; {tm['replays']} replays).",
        "",
    ]
    if "screen_window_replay_s" in tm:
        L += [
            f"Windows (chosen by excitation): each screening replay {tm['screen_window_replay_s']:.2f} s "
            f"(the first {tm['screen_window_replay_s_first_seconds']:.2f} s would be the fixed window), "
            f"each refinement evaluation {tm['refine_windows_replay_s']:.2f} s over all fit runs "
            f"(fixed: {tm['refine_windows_replay_s_first_seconds']:.2f} s); "
            + "; ".join(
                f"{w['stage']} `{w['run']}` scored {w['scored_from_s']:.2f}-{w['to_s']:.2f} s "
                f"(replayed from {w['replayed_from_s']:.2f} s)"
                for w in tm.get("windows", [])
            )
            + ".",
            "",
        ]
    return L


def baseline_md(res) -> list[str]:
    """The held-out errors before / after / of the linear ARX baseline, pooled and per run
    and column, and the flag when the calibrated model does not beat the baseline."""
    from sim.calibrate.baseline import flag

    b = getattr(res, "baseline", None)
    if not b:
        return []
    L = ["## Against a linear baseline", ""]
    line = flag(res.error_after, b)
    if line:
        L += [f"**FLAG: {line}.**", ""]
    L += [
        f"Baseline: {b['model']} (inputs: {b['inputs']}; orders chosen per column on the fit runs, "
        f"{b['skipped_unstable']} unstable candidates skipped). Same fit runs, same held-out runs, same NRMSE.",
        "",
        "| held out | declared model | calibrated | linear ARX baseline |",
        "|---|---|---|---|",
        f"| pooled NRMSE | {_pct(res.error_before)} | {_pct(res.error_after)} | {_pct(b['holdout_error'])} |",
    ]
    band = b.get("band")
    if band:
        lo, hi = band["band_hz"]
        L.append(
            f"| {band['channel']} {lo:g}-{hi:g} Hz | {_pct(band['before'])} | {_pct(band['after'])} | "
            f"{_pct(band['baseline'])} |"
        )
    for k, v in res.per_channel.items():
        L.append(f"| {k} | {_pct(v['before'])} | {_pct(v['after'])} | {_pct(b['per_channel'].get(k))} |")
    return L + [""]


def write_report(res, out, toml_name: str) -> list[str]:
    """Figures and ``report.md`` into ``out``; returns the files written."""
    out = Path(out)
    figs = figures(res, out)
    write_text_atomic(out / "report.md", report_md(res, figs, toml_name))
    return figs + ["report.md"]


__all__ = ["baseline_md", "figures", "path_figures", "report_md", "write_report"]

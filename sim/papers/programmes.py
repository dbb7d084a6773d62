"""The uni-axial papers' programmes as ``characterize`` programmes.

A table file declares which identification programme characterises it in
``[published] programme = "..."`` (default :data:`DEFAULT_PROGRAMME`, the 6-DOF
programme of :mod:`sim.identify.characterize`). The two papers' programmes live here:

* ``"frf_random"`` [Trombetti 2002]: the random-test FRFs of every operating condition the
  paper plots (:func:`sim.papers.uniaxial.rice_cases`), model vs the analytical
  transfer function; the oil column is the peak of the model's FRF with the optimal
  gains, Hz;
* ``"ls_identification"`` [Ozcelik 2008]: the test programme measured with the LHPOST DAQ
  model and identified by least squares (M_e, K_e, C_e, F_mu).

Each returns a JSON-ready summary (``characterization.json``), the report's markdown
lines under ``_report`` and what the figures need under ``_results``; nothing is
written here except the UCSD programme's run files (under ``runs_dir``), which are
outputs in their own right (``shaketable identify`` reads them).
"""

from __future__ import annotations

import time

DEFAULT_PROGRAMME = "six_dof"


def _peak(p) -> dict:
    f, m = p
    return {"f_hz": f, "magnitude": m}


def frf_random(desc, *, quick: bool = False, workers: int | None = None, progress=None, runs_dir=None) -> dict:
    """The random-test programme of [Trombetti 2002] on the model (``desc`` must be that table)."""
    from sim.papers import uniaxial as U

    t0 = time.perf_counter()
    res = U.run_rice_programme(workers=workers or 2, n_segments=3 if quick else U.RICE_SEGMENTS, progress=progress)
    cases = []
    for r in res:
        c = r["case"]
        mm, am = r["model_metrics"], r["analytical_metrics"]
        cases.append(
            {
                "case": c.name,
                "figure": c.figure,
                "parameter_set": c.parameter_set,
                "delay": c.delay,
                "payload": c.payload,
                "max_error_0_100": r["max_error_0_100"],
                "f_max_error_hz": r["f_max_error"],
                "rms_error_0_100": r["rms_error_0_100"],
                "oil_peak_model": _peak(mm["oil_peak"]),
                "oil_peak_analytical": _peak(am["oil_peak"]),
                "low_peak_model": _peak(mm["low_peak"]),
                "low_peak_analytical": _peak(am["low_peak"]),
                "wall_s": r["wall_s"],
            }
        )
    opt = next(r for r in res if r["case"].name == "optimal")
    return {
        "table": desc.name,
        "payload": None,
        "programme": "frf_random",
        "mode": "quick" if quick else "full",
        "oil_column_hz": {"x": opt["model_metrics"]["oil_peak"][0]},
        "oil_column_analytical_hz": {"x": opt["analytical_metrics"]["oil_peak"][0]},
        "cases": cases,
        "wall_s": time.perf_counter() - t0,
        "sim_s": len(res) * ((3 if quick else U.RICE_SEGMENTS) * U.RICE_NPERSEG / U.RICE_FS_HZ + 2.0),  # + lead-in
        "_report": U.rice_report(res),
        "_results": res,
    }


def ls_identification(desc, *, quick: bool = False, workers: int | None = None, progress=None, runs_dir=None) -> dict:
    """The programme of [Ozcelik 2008] on the model: measured run files and the least squares."""
    from sim.papers import uniaxial as U

    t0 = time.perf_counter()
    names = U.ucsd_tests("triangular") + U.ucsd_tests("sinusoidal") if quick else None
    res = U.ucsd_programme(names, workers=workers or 2, out_dir=runs_dir, progress=progress)
    ident = U.ucsd_identification(res)
    sets = {
        k: {"unconstrained": v["unconstrained"].as_dict(), "constrained": v["constrained"].as_dict()}
        for k, v in ident.items()
        if k != "alpha_scan"
    }
    head = ident["periodic"]["unconstrained"]
    return {
        "table": desc.name,
        "payload": None,
        "programme": "ls_identification",
        "mode": "quick" if quick else "full",
        "identification": {k: head.as_dict()[k] for k in ("M_e_kg", "K_e_N_per_m", "C_e", "F_mu_N", "alpha", "error")}
        | {"test_set": "periodic"},
        "identification_sets": sets,
        "alpha_scan": [{"alpha": a.alpha, "error": a.error} for a in ident.get("alpha_scan", [])],
        "paper": dict(U.PAPER_PARAMS),
        "tests": [
            {
                "name": r["name"],
                "peak_velocity_m_s": r["peak_velocity"],
                "peak_force_n": r["peak_force"],
                "run_file": r.get("path"),
                "wall_s": r["wall_s"],
            }
            for r in res
        ],
        "wall_s": time.perf_counter() - t0,
        "_report": U.ucsd_report(res, ident),
        "_results": res,
    }


#: the papers' programmes by the name a table file declares in ``[published] programme``
PROGRAMMES = {"frf_random": frf_random, "ls_identification": ls_identification}


def declared_programme(desc) -> str:
    """The programme a table description declares (``[published] programme``)."""
    pub = desc.raw.get("published") or {}
    return str(pub.get("programme", DEFAULT_PROGRAMME))


__all__ = ["DEFAULT_PROGRAMME", "PROGRAMMES", "declared_programme", "frf_random", "ls_identification"]

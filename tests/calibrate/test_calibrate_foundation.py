"""The foundation mode on the replay path (issue #13): runs made on the CGS table with its
reaction mass (6400 t, Sec. 2 of [Airouche 2014]) on a spring, calibrated against the stock description (a
fixed foundation), name ``foundation_mode`` at the table, recover its frequency within
10 % and bring the held-out error down; clean runs with the candidate add nothing.

The candidate is fitted in the compliance s = (f_ref / f)^2 (0: the rigid, declared
foundation) and the damping ratio (from the declared value), the mass held at the
description's ``[foundation]`` value (sim.calibrate.sensitivity.foundation_candidate). Its nearest confusers on these
runs, measured with valve_flow_gain, bulk_modulus, spring and added_mass offered too
(docs/calibration.md): added_mass at the longitudinal actuators (2.6 % of the residual,
linearised) and bulk_modulus (2.2 %), both below the 5 % needed to be refined. The
planted tests offer added_mass (the nearest) to keep them short; the clean runs are
calibrated with all five types."""

from __future__ import annotations

import copy
import json
import tomllib

import numpy as np
import pytest
from test_calibrate_paths import _cgs_measured, _check, clean_paths, floor  # noqa: F401

from sim.calibrate import search as S

#: candidate types of the planted tests: the foundation mode and its nearest confuser (measured, above)
EFFECTS = ["foundation_mode", "added_mass"]
#: of the clean runs: the foundation mode and every confuser tried
CLEAN_EFFECTS = ["foundation_mode", "added_mass", "bulk_modulus", "valve_flow_gain", "spring"]
CGS_MASS_KG = 6.4e6  # Sec. 2 of [Airouche 2014]: the 6400 t reaction mass (scenarios/tables/cgs.toml)


def _foundation(f_hz, zeta=0.05):
    return {
        "type": "foundation_mode",
        "where": "table",
        "frequency_hz": f_hz,
        "mass_kg": CGS_MASS_KG,
        "damping_ratio": zeta,
    }


def _found_and_written(res, floor, f_hz, tmp_path):  # noqa: F811
    # measured (12 Hz): 11.9989 +/- 0.0147 Hz, held out 6.77 % -> 4.53 % (the floor 4.51 %)
    _check(res, floor, "foundation_mode", "table", "frequency_hz", f_hz, rel=0.001)
    e = res.effects_added[0]
    assert e["parameters"]["mass_kg"] == CGS_MASS_KG  # held at the description's [foundation] mass
    assert set(e["uncertainty"]) == {"frequency_hz", "damping_ratio"}  # the fitted parameters
    z, u = e["parameters"]["damping_ratio"], e["uncertainty"]["damping_ratio"]
    # measured (12 Hz): 0.05004 +/- 0.00122, the truth inside its interval
    assert z == pytest.approx(0.05, rel=0.005) and abs(z - 0.05) <= u and 0 < u < 0.005, (z, u)
    # the calibrated description holds a foundation_mode entry that builds into the same model
    import mjcf
    from mjcf.description import parse_table
    from sim.effects import build_model

    (tmp_path / "out").mkdir()
    js = S.write_outputs(res, tmp_path / "out", ["a.run.npz"])
    with open(js["calibrated_table_file"], "rb") as fh:
        raw = tomllib.load(fh)
    (ent,) = [x for x in raw["effect"] if x["type"] == "foundation_mode"]
    assert ent["frequency_hz"] == float(f"{e['parameters']['frequency_hz']:.6g}")  # written to 6 digits
    tm = build_model(parse_table(raw, src=mjcf.load_table("cgs").source))
    assert tm.model.body("foundation").mass[0] == pytest.approx(CGS_MASS_KG)


@pytest.mark.slow
def test_foundation_mode_in_the_band_found(floor, tmp_path):  # noqa: F811
    """A 12 Hz foundation, inside the runs' 1-30 Hz band: the linearisation at the rigid
    foundation points the wrong way; the frequency grid of the line search finds it."""
    paths = _cgs_measured(tmp_path, [_foundation(12.0)])
    res = S.calibrate(paths, path="replay", effects=EFFECTS, workers=2)
    _found_and_written(res, floor, 12.0, tmp_path)


@pytest.mark.slow
def test_foundation_mode_above_the_band_found_from_the_cli(floor, tmp_path, capsys):  # noqa: F811
    """A 20 Hz foundation damped 10 % (the description's assumed 5 % is only the start),
    through ``shaketable calibrate``: the damping ratio found, the held mass printed,
    reported and written as held (no interval)."""
    from types import SimpleNamespace

    from sim.cli import main

    paths = _cgs_measured(tmp_path, [_foundation(20.0, 0.10)])
    out = tmp_path / "cli"
    rc = main(
        ["calibrate", *paths, "--path", "replay", "--effects", ",".join(EFFECTS), "--workers", "2", "--out", str(out)]
    )
    assert rc == 0
    printed = capsys.readouterr().out
    assert "added foundation_mode at table: frequency_hz = 20" in printed
    assert "mass_kg = 6.4e+06 kg (held at the description's value)" in printed
    js = json.loads((out / "calibration.json").read_text())
    # measured: 20.0035 +/- 0.0164 Hz; held out 8.93 % -> 4.55 % (the floor 4.51 %)
    _check(SimpleNamespace(**js), floor, "foundation_mode", "table", "frequency_hz", 20.0, rel=0.001)
    assert (
        "| foundation_mode | table | mass_kg | 6.4e+06 kg | held at the description's value |"
        in (out / "report.md").read_text()
    )
    (e,) = js["effects_added"]
    z, u = e["parameters"]["damping_ratio"], e["uncertainty"]["damping_ratio"]
    # measured: 0.10037 +/- 0.00074, the truth inside its interval
    assert z == pytest.approx(0.10, rel=0.01) and abs(z - 0.10) <= u and 0 < u < 0.01, (z, u)
    (ent,) = [x for x in tomllib.loads((out / "cgs_calibrated.toml").read_text())["effect"]]
    assert ent["type"] == "foundation_mode" and ent["frequency_hz"] == pytest.approx(20.0, rel=0.001)
    assert ent["damping_ratio"] == pytest.approx(0.10, rel=0.01) and ent["mass_kg"] == CGS_MASS_KG


@pytest.mark.slow
def test_clean_runs_add_no_foundation(clean_paths):  # noqa: F811
    res = S.calibrate(clean_paths, path="replay", effects=CLEAN_EFFECTS, workers=2)
    assert res.effects_added == []
    assert res.error_after == res.error_before


# ------------------------------------------------------------------ the candidate itself
def _cgs():
    import mjcf

    return mjcf.load_table("cgs")


def test_foundation_candidate_is_neutral_at_the_rigid_foundation_and_maps_back():
    from sim.calibrate.sensitivity import FOUNDATION_MIN_HZ, foundation_candidate

    dt = 1.0 / 2048
    c = foundation_candidate(_cgs(), dt)
    assert list(c.names) == ["frequency_hz", "damping_ratio"] and list(c.neutral) == [0.0, 0.05]
    assert c.values(c.neutral)["frequency_hz"] == np.inf  # rigid: the declared model
    f_max = c.values(c.lower)["frequency_hz"]
    assert f_max == pytest.approx(1.0 / (2 * np.pi * dt))  # 326 Hz: half the explicit spring's limit
    assert c.values(c.upper)["frequency_hz"] == pytest.approx(FOUNDATION_MIN_HZ)
    s = (30.0 / 20.0) ** 2  # f_ref: CGS's declared (assumed) 30 Hz
    v = c.values(np.array([s, 0.07]))
    assert v == pytest.approx({"frequency_hz": 20.0, "mass_kg": CGS_MASS_KG, "damping_ratio": 0.07})
    held = foundation_candidate(_cgs(), dt, fit_damping=False)  # the damping held at the declared 5 %
    assert held.names == ("frequency_hz",)
    assert held.values(np.array([s])) == pytest.approx(
        {"frequency_hz": 20.0, "mass_kg": CGS_MASS_KG, "damping_ratio": 0.05}
    )
    # the interval mapped back: df = f_ref / (2 s^1.5) ds, checked against a finite difference
    ds = 1e-6
    fd = (held.values(np.array([s - ds]))["frequency_hz"] - held.values(np.array([s + ds]))["frequency_hz"]) / (2 * ds)
    sig = c.sigmas(np.array([s, 0.05]), np.array([0.01, 0.002]))
    assert sig == pytest.approx({"frequency_hz": 0.01 * fd, "damping_ratio": 0.002}, rel=1e-6)
    # the line search's grid: from twice f_ref (60 Hz) down to the softest, a quarter octave apart
    grid = [c.values(np.array([x]))["frequency_hz"] for x in c.line]
    assert grid[0] == pytest.approx(60.0) and FOUNDATION_MIN_HZ <= grid[-1] < FOUNDATION_MIN_HZ * 2**0.25
    assert np.allclose(np.array(grid[:-1]) / np.array(grid[1:]), 2**0.25)


def test_a_declared_spring_foundation_is_the_neutral_value():
    """On a table that declares a spring foundation, the candidate at its neutral value
    (s = 1) builds the declared foundation: same mass, stiffness and damping."""
    import mjcf
    from mjcf.description import parse_table
    from sim.calibrate.sensitivity import foundation_candidate
    from sim.effects import build_model

    desc = _cgs()
    raw = copy.deepcopy(desc.raw)
    raw["foundation"] = dict(
        raw["foundation"], mode="spring", frequency_hz=[27.0, 27.0, 18.0], damping_ratio=[0.04] * 3
    )
    spring = parse_table(raw, src=desc.source)
    c = foundation_candidate(spring, 1.0 / 2048)
    assert c.neutral[0] == 1.0
    v = c.values(c.neutral)
    assert (v["frequency_hz"], v["frequency_z_hz"], v["damping_ratio"]) == (27.0, 18.0, 0.04)
    m0 = build_model(spring).model
    m1 = build_model(parse_table(dict(raw, effect=[c.entry(c.neutral)]), src=desc.source)).model
    for j in ("foundation_x", "foundation_y", "foundation_z"):
        assert m1.jnt_stiffness[m1.joint(j).id] == pytest.approx(m0.jnt_stiffness[m0.joint(j).id], rel=1e-12)
        assert m1.dof_damping[m1.joint(j).dofadr[0]] == pytest.approx(m0.dof_damping[m0.joint(j).dofadr[0]], rel=1e-12)
    assert m1.body("foundation").mass[0] == m0.body("foundation").mass[0]
    assert mjcf.load_table("cgs").foundation.mode == "fixed"


def test_foundation_candidate_builds_before_a_dof_spring_and_runs_on_the_batch_route(clean_paths):  # noqa: F811
    """A foundation candidate added after an accepted DOF spring (a tendon on the free
    platen) is built first; the stiffest foundation the search reaches replays stably; the
    batch route (3 more DOFs: its own batch key) gives the single runs' answers."""
    from sim.calibrate import paths as P
    from sim.calibrate.description import TomlText
    from sim.calibrate.sensitivity import candidates, foundation_candidate
    from sim.runs.runfile import read_run

    desc = _cgs()
    (pr,) = P.path_runs([read_run(clean_paths[0])], desc, "replay")
    pr = pr.window(1.0)
    spring = {"type": "spring", "where": "dof:x", "stiffness_n_m": 1e6}
    c = foundation_candidate(desc, 1.0 / 2048)
    stiff, soft = c.entry(c.lower), c.entry(np.array([(30.0 / 20.0) ** 2, 0.05]))  # the stiffest: undamped
    raw, src = desc.raw, str(desc.source)
    jobs = [pr.job(raw, src, None, [spring]), pr.job(raw, src, None, [spring, stiff]), pr.job(raw, src, None, [soft])]
    counts: dict = {}
    many = P.simulate_jobs(jobs, counts=counts)
    assert counts == {"batch": 3, "fallback": 0}
    for j, m in zip(jobs, many):
        assert m is not None
        one = P.simulate_job(j)
        assert all(np.array_equal(m[k], one[k]) for k in m)
    e_rigid, e_stiff = P.nrmse([pr], [many[0]]), P.nrmse([pr], [many[1]])
    assert e_stiff == pytest.approx(e_rigid, rel=1e-3)  # 326 Hz: as good as rigid on these runs
    assert P.nrmse([pr], [many[2]]) > 1.2 * e_rigid  # a 20 Hz foundation the clean runs do not have
    # candidates() builds the current model with the accepted entries in build order
    mot = {"dof:x": (1e-3, 1e-2, 1.0)}
    offered = candidates(desc, None, [pr], [spring], mot, effects=["foundation_mode"])
    assert [x.key for x in offered] == [("foundation_mode", "table")]
    got = candidates(desc, None, [pr], [spring, stiff], mot, effects=["foundation_mode", "viscous_damping"])
    assert [x.key for x in got] == [("viscous_damping", "dof:x")]  # the foundation accepted already
    # the written description lists the foundation before the spring, and builds
    doc = TomlText.read(desc.source)
    doc.set_effect(dict(spring))
    doc.set_effect(dict(stiff))
    written = tomllib.loads(doc.text)
    assert [e["type"] for e in written["effect"]] == ["foundation_mode", "spring"]

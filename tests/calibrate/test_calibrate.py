"""`shaketable calibrate`: runs made with effects the description lacks are traced back to
those effects, their parameters recovered, the held-out error brought down; clean runs
add nothing; what no effect explains is reported with its frequency and channel."""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from sim.calibrate import search as S
from sim.calibrate.description import DescriptionWriteError, TomlText
from sim.cli import main
from sim.effects.base import EFFECTS, Effect, register
from sim.runs.runfile import read_run, write_run

UCSD_TOML = Path(__file__).resolve().parents[2] / "scenarios" / "tables" / "ucsd.toml"
#: the NEES-UCSD periodic tests simulated (sim.papers.uniaxial): 3 triangular, 4 sinusoidal
UCSD_SET = ["T5", "T7", "T9", "S4", "S6", "S8", "S10"]
#: the truth in ucsd.toml: F_mu = 4.1 kN + 0.39 % x 5.783 MN [Ozcelik 2008], C_e, alpha, K_e [Ozcelik 2008]
F_MU, C_E, ALPHA, K_E = 4.1e3 + 0.0039 * 5.783e6, 45.9e3, 0.5, 1.263e6


@pytest.fixture(scope="module")
def ucsd_runs(tmp_path_factory):
    """The seven periodic tests on the full ucsd model (spring, friction, power damping),
    measured with the LHPOST DAQ model (512 Hz, 100 Hz accelerometer conditioners, noise)."""
    from sim.papers.uniaxial import ucsd_programme

    out = tmp_path_factory.mktemp("ucsd_runs")
    res = ucsd_programme(UCSD_SET, workers=2, out_dir=out)
    return [r["path"] for r in res]


def declared(tmp_path, drop=(), edit=None) -> str:
    """ucsd.toml without the ``[[effect]]`` entries of types ``drop`` (and with ``edit``
    applied to its text), written to ``tmp_path``: a description that lacks them."""
    doc = TomlText.read(UCSD_TOML)
    for i, end, entry in reversed(doc.effect_blocks()):
        if entry["type"] in drop:
            del doc.lines[i:end]
    if edit:
        edit(doc)
    p = tmp_path / "ucsd_declared.toml"
    doc.save(p)
    return str(p)


def _effect(res, name):
    hits = [e for e in res.effects_added if e["name"] == name]
    assert len(hits) == 1, res.effects_added
    return hits[0]


# ------------------------------------------------------------------ plant and recover (UCSD)
def test_nees_ucsd_friction_and_power_damping_found(ucsd_runs, tmp_path):
    """The NEES-UCSD case, two effects at once: from mass and hold-down stiffness only,
    the periodic tests add Coulomb friction and power-law damping at the paper's values."""
    res = S.calibrate(
        ucsd_runs, table=declared(tmp_path, ("platen_coulomb", "platen_power_damping")), path="mechanical"
    )
    assert res.residual_path == "mechanical"
    assert {(e["name"], e["where"]) for e in res.effects_added} == {
        ("coulomb_friction", "dof:x"),
        ("power_damping", "dof:x"),
    }
    fr, ufr = _effect(res, "coulomb_friction")["parameters"], _effect(res, "coulomb_friction")["uncertainty"]
    pd, upd = _effect(res, "power_damping")["parameters"], _effect(res, "power_damping")["uncertainty"]
    # measured: friction 26.89 +/- 0.58 kN (truth 26.65 kN, 0.9 % high, inside its interval)
    assert fr["force_n"] == pytest.approx(F_MU, rel=0.02) and abs(fr["force_n"] - F_MU) <= ufr["force_n"]
    # measured: exponent 0.5033 +/- 0.016 (0.5, inside its interval)
    assert pd["exponent"] == pytest.approx(ALPHA, abs=0.01) and abs(pd["exponent"] - ALPHA) <= upd["exponent"]
    # measured: coefficient 45.26e3 +/- 0.51e3 (45.9e3): 1.4 % low, OUTSIDE its interval by
    # 1.27 x its half width (a bias the residual's colour does not show; docs/calibration-validation.md)
    assert pd["coefficient"] == pytest.approx(C_E, rel=0.03)
    # measured: held out 57.7 % -> 2.58 %, the clean runs' floor 2.58 %
    assert res.error_after < 0.1 * res.error_before, (res.error_before, res.error_after)
    assert res.error_after <= 1.1 * _clean_floor(ucsd_runs), (res.error_after, _clean_floor(ucsd_runs))
    for e in res.effects_added:  # finite, non-trivial 95 % intervals: 1.1-3.2 % of the value measured
        for k, v in e["parameters"].items():
            assert 0 < e["uncertainty"][k] < 0.05 * abs(v)
    assert res.unexplained is None


def test_missing_hold_down_spring_found(ucsd_runs, tmp_path):
    res = S.calibrate(ucsd_runs, table=declared(tmp_path, ("platen_spring",)), path="mechanical")
    (e,) = res.effects_added
    assert (e["name"], e["where"]) == ("spring", "dof:x")
    k, u = e["parameters"]["stiffness_n_m"], e["uncertainty"]["stiffness_n_m"]
    # measured: 1.263255e6 +/- 967 N/m (1.263e6, inside its interval); held out 126 % -> 2.58 %
    assert k == pytest.approx(K_E, rel=0.002) and abs(k - K_E) <= u and 0 < u < 0.005 * k
    assert res.error_after < 0.05 * res.error_before, (res.error_before, res.error_after)
    assert res.error_after <= 1.1 * _clean_floor(ucsd_runs), (res.error_after, _clean_floor(ucsd_runs))


def test_missing_mass_found(ucsd_runs, tmp_path):
    """A platen described 10 t too light: added_mass of ~10 t at x."""

    def lighter(doc):
        doc.set_value("platen", "mass_kg", 130000.0, "test: 10 t less than the truth")

    res = S.calibrate(ucsd_runs, table=declared(tmp_path, edit=lighter), path="mechanical")
    (e,) = res.effects_added
    assert (e["name"], e["where"]) == ("added_mass", "dof:x")
    m, u = e["parameters"]["mass_kg"], e["uncertainty"]["mass_kg"]
    # measured: 9986 +/- 77 kg (10 t, inside its interval); held out 6.54 % -> 2.58 %, the clean floor
    assert m == pytest.approx(10000.0, rel=0.005) and abs(m - 10000.0) <= u and 0 < u < 0.02 * m
    assert res.error_after < res.error_before, (res.error_before, res.error_after)
    assert res.error_after <= 1.1 * _clean_floor(ucsd_runs), (res.error_after, _clean_floor(ucsd_runs))


#: effects planted in the full ucsd model (absent from ucsd.toml), calibrated against ucsd.toml:
#: case -> (entries, {parameter checked: its relative tolerance, about 2-3 x the error
#: measured}, the --payload given). Values
#: assumed, of the order of the table's own terms (F_mu 26.7 kN, C_e 45.9 kN (s/m)^0.5):
#: a linear damper (issue #13: `identify` folded one into the Coulomb and power-law terms),
#: friction growing with the stroke, a specimen's mode. (Friction growing with an
#: actuator's force is not tried here: these runs record the total force, not each
#: actuator's; test_load_law_needs_each_actuators_force)
UCSD_PLANTED = {
    # measured 39.30 +/- 0.41 kN s/m: 1.75 % low, OUTSIDE its interval (UCSD_OUTSIDE)
    "viscous": ([{"type": "viscous_damping", "where": "dof:x", "damping_n_s_m": 40e3}], {"damping_n_s_m": 0.04}, None),
    "coulomb_grows_displacement": (
        [
            {
                "type": "coulomb_friction",
                "where": "dof:x",
                "force_n": 3000.0,
                "grows_with": "displacement",
                "coefficient": 5e4,
            }
        ],
        # measured: 3006 +/- 124 N, 49.33e3 +/- 0.78e3 N/m (both inside their intervals)
        {"force_n": 0.01, "coefficient": 0.03},
        None,
    ),
    "payload_mode": (
        [{"type": "payload_mode", "where": "dof:x", "mass_kg": 10e3, "frequency_hz": 6.0, "damping_ratio": 0.05}],
        # measured: 10043 +/- 61 kg, 6.0048 +/- 0.0043 Hz, 0.0507 +/- 0.0008 (the frequency
        # 0.08 % high, OUTSIDE its interval: UCSD_OUTSIDE)
        {"mass_kg": 0.01, "frequency_hz": 0.001, "damping_ratio": 0.03},
        "none",
    ),
}
#: (case, parameter) whose truth falls outside the 95 % interval found (measured above):
#: a bias of a few per cent the residual's colour does not show (docs/calibration.md, Limits);
#: and the mode's frequency, 0.08 % high from the simulator's step: the same runs stepped at
#: 1/8192 s give 5.99979 +/- 0.0047 Hz (measured 2026-11-28). The stepped mode has the
#: declared poles (mjcf.stepping); what is left is likely the semi-implicit step's spring
#: force, read at each step's start, half a step behind a continuous mode's.
UCSD_OUTSIDE = {("viscous", "damping_n_s_m"), ("payload_mode", "frequency_hz")}


@pytest.mark.parametrize("case", UCSD_PLANTED)
def test_ucsd_planted_effect_found(case, ucsd_runs, tmp_path):
    """Each effect planted in the truth: named at its place, its parameters within a few
    times the error measured and the truth inside their 95 % intervals (but UCSD_OUTSIDE),
    the held-out error to below half of before and within 10 % of the clean floor; nothing else."""
    from sim.papers.uniaxial import ucsd_programme

    planted, keys, payload = UCSD_PLANTED[case]
    runs = [r["path"] for r in ucsd_programme(UCSD_SET, workers=2, out_dir=tmp_path, effects=planted)]
    res = S.calibrate(runs, table=str(UCSD_TOML), payload=payload, path="mechanical")
    (e,) = res.effects_added
    p = planted[0]
    assert (e["name"], e["where"]) == (p["type"], p["where"]), res.effects_added
    assert e.get("options", {}) == ({"grows_with": p["grows_with"]} if "grows_with" in p else {})
    for k, rel in keys.items():
        v, u = e["parameters"][k], e["uncertainty"][k]
        assert v == pytest.approx(p[k], rel=rel), (k, e["parameters"], e["uncertainty"])
        assert 0 < u < 0.05 * abs(v), (k, u)  # 0.07-4.1 % of the value measured
        assert (case, k) in UCSD_OUTSIDE or abs(v - p[k]) <= u, (k, v, u, p[k])
    # measured: held out 6.8-8.5 % -> 2.37-2.59 %, the clean floor 2.58 %
    assert res.error_after < 0.5 * res.error_before, (res.error_before, res.error_after)
    assert res.error_after <= 1.1 * _clean_floor(ucsd_runs), (res.error_after, _clean_floor(ucsd_runs))


def test_load_law_needs_each_actuators_force(ucsd_runs):
    """The NEES-UCSD runs hold the measured total force in column E (W zero): a friction
    growing with an actuator's own force is not a candidate on them (planted at E, it was
    found at 0.0027 for 0.01: the law read the total, the model E's own force)."""
    res = S.calibrate(ucsd_runs, table=str(UCSD_TOML), path="mechanical")
    assert res.candidates and not any(c.get("options") == {"grows_with": "load"} for c in res.candidates)
    assert any(c.get("options") == {"grows_with": "displacement"} for c in res.candidates)


_FLOOR = {}


def _clean_floor(runs):
    if "e" not in _FLOOR:
        _FLOOR["e"] = S.calibrate(runs, table=str(UCSD_TOML), path="mechanical").error_before
    return _FLOOR["e"]


def test_clean_runs_add_nothing(ucsd_runs):
    res = S.calibrate(ucsd_runs, table=str(UCSD_TOML), path="mechanical")
    assert res.effects_added == []
    assert res.error_after == res.error_before
    assert res.candidates and not any(c["accepted"] for c in res.candidates)
    assert res.unexplained is None
    assert res.error_before < 0.06  # the DAQ noise floor of these runs (3.7 % measured)


# ------------------------------------------------------------------ outside the library
@register
class _LinePickup(Effect):
    """A 60 Hz mains pickup on the force channel: registered only here, with no force law."""

    type = "test_line_pickup"
    places = ("channel",)
    SPEC = {"amplitude_n": ("N", 0.0, math.inf, None), "frequency_hz": ("Hz", 0.0, math.inf, 60.0)}

    def measure(self, t, channels, rng):
        out = dict(channels)
        f = np.array(out["actuator_force"], float)
        f[:, 0] += self.values["amplitude_n"] * np.sin(2 * np.pi * self.values["frequency_hz"] * t + 0.3)
        out["actuator_force"] = f
        return out


@pytest.fixture
def pickup_runs(ucsd_runs, tmp_path):
    eff = EFFECTS["test_line_pickup"]({"where": "channel:actuator_force", "amplitude_n": 3e3})
    out = []
    for p in ucsd_runs:
        r = read_run(p)
        r.actuator_force = eff.measure(r.t, {"actuator_force": r.actuator_force}, None)["actuator_force"]
        out.append(str(write_run(tmp_path / Path(p).name, r)))
    return out


def test_line_pickup_reported_unexplained_not_papered_over(pickup_runs):
    res = S.calibrate(pickup_runs, table=str(UCSD_TOML), path="mechanical")
    assert res.effects_added == []
    u = res.unexplained
    assert u is not None and u["peak_hz"] == pytest.approx(60.0, abs=1.0)
    assert u["channel"] == "actuator_force" and u["where"] == "channel:actuator_force"
    assert u["fraction_of_residual"] > 0.3


def teardown_module(module):
    EFFECTS.pop("test_line_pickup", None)


# ------------------------------------------------------------------ the command
def test_cli_writes_json_report_and_commented_table(ucsd_runs, tmp_path):
    decl = declared(tmp_path, ("platen_coulomb", "platen_power_damping"))
    out = tmp_path / "out"
    fit, ho = ucsd_runs[:5], ucsd_runs[5:]
    rc = main(
        ["calibrate", *fit, "--table", decl, "--holdout", *ho, "--out", str(out), "--json", "--path", "mechanical"]
    )
    assert rc == 0
    js = json.loads((out / "calibration.json").read_text(), parse_constant=lambda c: pytest.fail(c))
    for k in ("error_before", "error_after", "residual_path", "effects_added", "candidates", "unexplained"):
        assert k in js
    assert js["holdout"] == [str(Path(h)) for h in ho]
    assert js["error_after"] < 0.2 * js["error_before"]
    assert {e["name"] for e in js["effects_added"]} == {"coulomb_friction", "power_damping"}
    for e in js["effects_added"]:
        assert set(e) >= {"name", "where", "parameters", "uncertainty"}
    text = (out / "ucsd_calibrated.toml").read_text()
    src = Path(decl).read_text()
    assert all(line in text for line in src.splitlines() if line.lstrip().startswith("#"))
    raw = tomllib.loads(text)
    new = [e for e in raw["effect"] if e["type"] in ("coulomb_friction", "power_damping")]
    assert len(new) == 2 and all(e["source"].startswith("calibrated: shaketable calibrate ucsd_T5") for e in new)
    md = (out / "report.md").read_text()
    for fig in (
        "holdout_error.png",
        "residual_time.png",
        "residual_spectra.png",
        "residual_vs_state.png",
        "effects.png",
    ):
        assert (out / fig).stat().st_size > 1000 and fig in md


def _bad_inputs(ucsd_runs, tmp_path):
    cases = {}
    t = read_run(ucsd_runs[0])
    t.meta = dict(t.meta, table="cgs")
    cases["tables"] = ([str(write_run(tmp_path / "cgs_meta.run.npz", t)), ucsd_runs[1]], "different tables")
    m = read_run(ucsd_runs[0])
    m.actuator_force = m.table_displacement = m.table_velocity = m.table_acceleration = None
    cases["channels"] = ([str(write_run(tmp_path / "noforce.run.npz", m))], "lacks actuator_force")
    n = read_run(ucsd_runs[0])
    n.table_velocity[100, 0] = np.nan
    cases["nan"] = ([str(write_run(tmp_path / "nan.run.npz", n))], "NaN")
    d = read_run(ucsd_runs[1])
    d2 = type(d)(
        t=d.t[::2] * 1.0,
        meta=dict(d.meta, sample_rate_hz=256.0),
        **{
            c: getattr(d, c)[::2]
            for c in ("actuator_force", "table_displacement", "table_velocity", "table_acceleration", "reference")
        },
    )
    d2.t = np.arange(len(d2.t)) / 256.0
    cases["rates"] = ([ucsd_runs[0], str(write_run(tmp_path / "half.run.npz", d2))], "sample rates differ")
    cases["holdout"] = ([ucsd_runs[0], ucsd_runs[1], "--holdout", ucsd_runs[1]], "both a fit run and a --holdout")
    cases["effect"] = ([ucsd_runs[0], "--effects", "coulomb_fricton"], "unknown effect 'coulomb_fricton'")
    bad = tmp_path / "bad_effects.py"
    bad.write_text("import not_a_module_anywhere\n")
    cases["effect_file"] = ([ucsd_runs[0], "--effect-file", str(bad)], "does not load")
    return cases


@pytest.mark.parametrize("case", ["tables", "channels", "nan", "rates", "holdout", "effect", "effect_file"])
def test_bad_input_one_line_exit_2_nothing_written(case, ucsd_runs, tmp_path, capsys):
    argv, msg = _bad_inputs(ucsd_runs, tmp_path)[case]
    out = tmp_path / "out"
    rc = main(["calibrate", *argv, "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and err.startswith("error: ") and "\n" not in err, err
    assert msg in err, err
    assert not out.exists()


def test_masses_mode_still_reachable(capsys):
    """`shaketable calibrate cgs` (a table, not runs) is the effective-mass calibration."""
    assert main(["calibrate", "cgs", "--json"]) == 0
    js = json.loads(capsys.readouterr().out)
    assert set(js) == {"values", "before", "after", "target"}
    for k in js["target"]:
        assert js["after"][k] == pytest.approx(js["target"][k], rel=1e-3)


# ------------------------------------------------------------------ the one writer
def test_writer_keeps_comments_rewrites_in_place_and_replaces_effects(tmp_path):
    doc = TomlText.read(UCSD_TOML)
    n_comments = sum(1 for x in doc.lines if x.lstrip().startswith("#"))
    doc.set_value("platen", "mass_kg", 141000.0, "calibrated: test", keep_comment=True)
    assert doc.set_effect({"type": "spring", "where": "dof:x", "stiffness_n_m": 1.0e6}) == "added"
    assert (
        doc.set_effect(
            {"type": "spring", "where": "dof:x", "stiffness_n_m": 2.0e6},
            comments={"stiffness_n_m": "calibrated: again"},
        )
        == "replaced"
    )
    p = doc.save(tmp_path / "t.toml")
    raw = tomllib.loads(p.read_text())
    assert raw["platen"]["mass_kg"] == 141000.0
    assert [e["stiffness_n_m"] for e in raw["effect"] if e["type"] == "spring"] == [2.0e6]
    line = next(x for x in p.read_text().splitlines() if x.startswith("mass_kg"))
    assert "calibrated: test" in line and "derived: M_e 144 t" in line  # new source, old kept
    assert sum(1 for x in p.read_text().splitlines() if x.lstrip().startswith("#")) == n_comments
    with pytest.raises(DescriptionWriteError):
        doc.set_value("platen", "no_such_key", 1.0)


# ------------------------------------------------------------------ CGS (6-DOF, 1024 Hz)
def _cgs_runs(out, raw, seeds=(3, 4, 5), seconds=4.0):
    """6-DOF band-limited white noise (0.5-30 Hz) on the CGS model described by ``raw``,
    measured through the built-in recorder model (seeded): the table's 300 Hz
    accelerometer conditioner, anti-alias filter, noise and quantisation, and only the
    meta a recorder writes (the table's name, not the truth's description)."""
    from mjcf.description import parse_table
    from sim.effects import build_model
    from sim.loop.simulation import Simulation
    from sim.runs.build import build_runfile
    from sim.runs.measure import load_sensors, measure_run
    from sim.scenario import motions as M
    from sim.scenario.reference import reference_from_motions

    tm = build_model(parse_table(raw, src="<truth>"))
    rms = {"x": 1.0, "y": 1.0, "z": 0.8, "rx": 0.5, "ry": 0.5, "rz": 0.5}
    paths = []
    for seed in seeds:
        mo = {
            d: M.white_noise(
                duration_s=seconds, sample_rate_hz=1024.0, band_hz=(0.5, 30.0), seed=(seed, k), rms_acceleration=rms[d]
            )
            for k, d in enumerate(rms)
        }
        ref = reference_from_motions(mo, 1024.0, seconds)
        res = Simulation(tm).run(reference=ref)
        assert res.incomplete_reason is None
        run = build_runfile(res, tm, source="simulated", reference=ref)
        run.meta.pop("table_description", None)  # a recorder writes the table's name
        run.meta.pop("table_sha256", None)
        paths.append(str(write_run(out / f"cgs_{seed}.run.npz", measure_run(run, load_sensors(), seed=seed))))
    return paths


@pytest.mark.slow
def test_cgs_lateral_seal_friction_found_and_clean_runs_add_nothing(tmp_path):
    """CGS at 1024 Hz, runs through the recorder model, calibrated with defaults: the
    lateral actuators' seal friction doubled (a per-class dry friction the description
    lacks) is found at class:lateral with the truth inside its interval (measured:
    5388.7 +/- 25.7 N), the held-out error falls by the margin (measured: 8.96 % -> 3.72 %,
    the clean runs' 3.74 %); the clean runs add nothing."""
    import copy

    import mjcf

    raw = copy.deepcopy(mjcf.load_table("cgs").raw)
    seal = raw["actuator_class"]["lateral"]["seal_friction_n"]
    (tmp_path / "clean").mkdir()
    (tmp_path / "lat").mkdir()
    clean = S.calibrate(_cgs_runs(tmp_path / "clean", raw), path="mechanical")
    assert clean.effects_added == []
    raw["actuator_class"]["lateral"]["seal_friction_n"] = 2 * seal
    res = S.calibrate(_cgs_runs(tmp_path / "lat", raw), path="mechanical")
    (e,) = res.effects_added
    assert (e["name"], e["where"]) == ("coulomb_friction", "class:lateral")
    assert abs(e["parameters"]["force_n"] - seal) <= e["uncertainty"]["force_n"], e
    assert res.error_after < (1 - S.HOLDOUT_MARGIN) * res.error_before

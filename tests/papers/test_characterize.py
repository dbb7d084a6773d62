"""The virtual identification programme (``shaketable characterize --quick``) against the
CGS paper [Airouche 2014]. One quick programme (~2 min on 2 cores) serves every assertion.

Two kinds of test, named for what they are:

* ``test_regression_*``: the figures ``cgs.toml`` was calibrated to (its ``calibrated:``
  lines: dead volumes to Table 1's oil columns, masses and inertias to Table 2, the
  translational seal friction to the 1.25 %). Measured again by the same programme, they
  show the calibration still holds and the programme still reads it; they cannot show
  that the model is right.
* ``test_validation_*``: published figures the calibration did not use: the servovalve's
  first-order time constant (Sec. 4: the table's valve is the paper's second-order fit,
  the 5.6 ms first-order fit of the same measurement is not an input) and the rotational
  friction (Sec. 6: 1.25 % on all six DOFs; only x, y, z were calibrated).

What the model does not meet is asserted as measured and reported in
docs/characterization.md.
"""

import dataclasses
import json

import numpy as np
import pytest

import mjcf
from mjcf.description import TABLES_DIR
from sim.calibrate import programme as P
from sim.cli import main
from sim.effects import build_model
from sim.identify import characterize as C
from sim.report.characterization import write_characterization

PUB = C.published(mjcf.load_table("cgs"))  # the paper's Tables 1-2 ([published] in cgs.toml)


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("char")
    s = C.characterize("cgs", None, quick=True)
    write_characterization(out, s)
    return s, out


def test_outputs_written(quick):
    s, out = quick
    js = json.loads((out / "characterization.json").read_text())
    for key in ("oil_column_hz", "effective_mass", "servovalve", "friction_fraction"):
        assert key in js
    assert set(js["oil_column_hz"]) == set(C.DOFS)
    assert set(js["effective_mass"]) == set(C.DOFS)
    assert {"tau_s", "wn_hz", "zeta"} <= set(js["servovalve"])
    rep = (out / "report.md").read_text()
    assert "| quantity | DOF | paper | model |" in rep
    for png in ("oil_column_frf.png", "effective_mass.png", "friction_loops.png", "servovalve.png"):
        assert (out / png).stat().st_size > 10_000
    assert not s["failed_tests"]


@pytest.mark.parametrize("dof", ["x", "y", "z", "rx", "ry", "rz"])
def test_regression_oil_column_still_meets_table_1_it_was_calibrated_to(quick, dof):
    """Table 1 within 3 % (the dead volumes were chosen for it)."""
    s, _ = quick
    assert s["oil_column_hz"][dof] == pytest.approx(PUB.oil_column_hz[dof], rel=0.03)


def test_oil_column_peaks_are_damped(quick):
    """Half-power damping of the oil-column peaks: a few per cent, as on a real table."""
    s, _ = quick
    z = np.array([s["oil_column_damping_ratio"][d] for d in C.DOFS])
    assert np.all(np.isfinite(z))
    assert np.all((z > 0.01) & (z < 0.15))


@pytest.mark.parametrize("dof", list(C.DOFS))
@pytest.mark.parametrize("level", ["R1", "R2"])
def test_regression_effective_mass_still_meets_table_2_it_was_calibrated_to(quick, dof, level):
    """Table 2 from the virtual tests at both levels, within 2 % (the masses are calibrated
    against the tests' mean; the R1/R2 difference is the model's own)."""
    s, _ = quick
    assert s["effective_mass_levels"][level][dof] == pytest.approx(PUB.effective_mass[dof], rel=0.02)


def test_regression_servovalve_fit_recovers_the_tables_own_valve(quick):
    """The table's valve is the paper's second-order fit (41.5 Hz, 0.75, gain 1): the
    virtual test and its fit read back the model's input, within 3 %."""
    s, _ = quick
    sv = s["servovalve"]
    assert sv["wn_hz"] == pytest.approx(41.5, rel=0.03)
    assert sv["zeta"] == pytest.approx(0.75, rel=0.03)
    assert sv["K_low"] == pytest.approx(1.0, rel=0.03)


def test_validation_servovalve_first_order_tau_is_the_papers_5_6_ms(quick):
    """Sec. 4 fits the same measured valve FRF twice: second order (the table's valve) and
    first order, tau = 5.6 ms, which the model never received. The programme's magnitude
    fit of the virtual FRF (0.5-125 Hz) gives it back within 0.05 ms (measured 5.59 ms);
    the complex fit over 0.5-20 Hz, where the phase holds, reads 4 % more (5.84 ms)."""
    s, _ = quick
    sv = s["servovalve"]
    assert sv["tau_s_magnitude_fit"] == pytest.approx(PUB.servovalve["tau_s"], abs=5e-5)
    assert sv["tau_s"] == pytest.approx(PUB.servovalve["tau_s"], rel=0.06)


@pytest.mark.parametrize("dof", ["x", "y", "z"])
def test_regression_translational_friction_still_meets_the_1_25_percent_it_was_calibrated_to(quick, dof):
    s, _ = quick
    assert s["friction_fraction"][dof] == pytest.approx(0.0125, abs=0.0015)


@pytest.mark.parametrize("dof", ["rx", "ry", "rz"])
def test_validation_rotational_friction_falls_short_of_the_papers_1_25_percent(quick, dof):
    """Sec. 6: 1.25 % of capability on all six DOFs. The seal friction was calibrated on
    x, y, z only; on the rotations the least-squares Coulomb term of the model's loops
    reads less (measured 0.83-0.91 % in the quick records; docs/characterization.md
    gives the reasons found and the loops' half-height reading). Not met; held at what it
    is: 60-80 % of the paper's figure."""
    s, _ = quick
    assert 0.60 * 0.0125 < s["friction_fraction"][dof] < 0.80 * 0.0125


@pytest.mark.parametrize("d", ["y", "z", "rx", "ry", "rz"])
def test_friction_loops_are_rectangular(quick, d):
    """Coulomb loops: the half-width is nearly constant along the stroke (x may grow)."""
    s, _ = quick
    assert 0.85 < s["friction_outer_over_inner"][d] < 1.2


def test_vertical_loop_is_shaped_by_the_support_air_chambers(quick):
    """The z friction loop is tilted by the air chambers' compression/suction: the fitted
    loop stiffness is the supports' air-spring stiffness sum n p0 A^2 / V (closed form, at
    the preload that carries the dead weight); the horizontal loops are not tilted."""

    s, _ = quick
    desc, _ = C.load_inputs("cgs", None)
    sp = desc.supports
    loads = build_model(desc).info.support_loads_n
    k_air = float(
        sum(
            sp.polytropic_exponent * (f / sp.piston_area_m2) * sp.piston_area_m2**2 / sp.chamber_volume_m3
            for f in loads
        )
    )
    k = s["friction_loop_stiffness"]
    assert k["z"] == pytest.approx(k_air, rel=0.10), (k["z"], k_air)
    assert abs(k["x"]) < 0.05 * k_air and abs(k["y"]) < 0.05 * k_air


def test_linear_estimate_is_close_to_the_virtual_test(quick):
    s, _ = quick
    for d in ("x", "y", "z"):
        assert s["oil_column_hz"][d] == pytest.approx(s["linear_oil_column_hz"][d], rel=0.03)


@pytest.mark.parametrize(
    "argv,msg",
    [
        (["characterize", "no_such_table"], "no table named"),
        (["characterize", "cgs", "--payload", "no_such_payload"], "no payload named"),
        (["characterize", "cgs", "--out", "/proc/forbidden/dir"], "cannot write to output folder"),
    ],
)
def test_bad_input_one_line_exit_2(argv, msg, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert msg in err and "\n" not in err


def test_calibrate_command_restores_perturbed_unknowns(tmp_path):
    """`characterize --calibrate` is a command, not a hand edit: on a copy of cgs.toml
    with three unknowns knocked off (vertical dead volume x3, roll inertia x0.85, lateral
    seal friction x0.6), one quick pass of virtual tests brings each back near the
    committed value and rewrites the file in place with its sources kept."""
    import tomllib

    from mjcf.description import parse_table

    src = TABLES_DIR / "cgs.toml"
    ref = parse_table(tomllib.loads(src.read_text()), src=str(src))
    raw = tomllib.loads(src.read_text())
    dv0 = raw["actuator_class"]["vertical"]["dead_volume_a_m3"]
    seal0 = raw["actuator_class"]["lateral"]["seal_friction_n"]
    I0 = raw["platen"]["inertia_kg_m2"]
    lines = []
    for line in src.read_text().split("\n"):
        if line.startswith("dead_volume_") and f"{dv0:.4e}" in line:
            line = line.replace(f"{dv0:.4e}", f"{3 * dv0:.4e}")
        if line.startswith("seal_friction_n") and f"{seal0:.1f}" in line:
            line = line.replace(f"{seal0:.1f}", f"{0.6 * seal0:.1f}")
        if line.startswith("inertia_kg_m2") and f"{I0[0]:.1f}" in line:
            line = line.replace(f"{I0[0]:.1f}", f"{0.85 * I0[0]:.1f}")
        lines.append(line)
    path = tmp_path / "cgs_perturbed.toml"
    path.write_text("\n".join(lines))
    pert = tomllib.loads(path.read_text())
    assert pert["actuator_class"]["vertical"]["dead_volume_a_m3"] == pytest.approx(3 * dv0, rel=1e-3)
    assert pert["actuator_class"]["lateral"]["seal_friction_n"] == pytest.approx(0.6 * seal0, rel=1e-3)
    assert pert["platen"]["inertia_kg_m2"][0] == pytest.approx(0.85 * I0[0], rel=1e-3)

    cal = P.calibrate(str(path), quick=True)
    P.write_calibration(path, cal)
    new = tomllib.loads(path.read_text())
    assert not list(tmp_path.glob("*.tmp"))
    assert new["actuator_class"]["vertical"]["dead_volume_a_m3"] == pytest.approx(dv0, rel=0.25)
    assert new["actuator_class"]["lateral"]["seal_friction_n"] == pytest.approx(seal0, rel=0.10)
    rx_ref = build_model(ref).effective_mass()["rx"]
    rx_new = build_model(parse_table(new, src=str(path))).effective_mass()["rx"]
    assert rx_new == pytest.approx(rx_ref, rel=0.03)
    text = path.read_text()
    assert text.count("calibrated: matches Table 1 (shaketable characterize --calibrate)") == 6
    assert "calibrated: matches Table 2 in the virtual R1/R2 tests" in text
    assert text.count("\n#") == src.read_text().count("\n#")  # comment lines kept


def test_payload_comparison_is_not_graded_against_the_bare_table():
    """With a payload the paper's numbers are the bare table's: the rows say so and carry no
    pass/fail (the drop is the payload's effect); bare-table rows are graded."""
    fake = {
        "oil_column_hz": {d: 0.8 * v for d, v in PUB.oil_column_hz.items()},
        "effective_mass_levels": {"R1": {d: 1.5 * v for d, v in PUB.effective_mass.items()}},
    }
    fake["published"] = dataclasses.asdict(PUB)
    rows = C.compare(dict(fake, payload="rigid_20t"))
    assert rows and all(r["within"] is None and "bare table" in r["quantity"] for r in rows)
    rows = C.compare(dict(fake, payload=None))
    assert all(r["within"] is False for r in rows)


def _z_loop_curvature(raw: dict) -> float:
    job = C.programme_jobs(C.load_inputs("cgs", None)[0], None, C.QUICK, parts=("friction",), friction_dofs=("z",))[0]
    r = C.run_test(dict(job, raw=raw))
    d = np.asarray(r["loop"]["d"])
    mid = 0.5 * (np.asarray(r["loop"]["upper"]) + np.asarray(r["loop"]["lower"]))
    ok = np.isfinite(d) & np.isfinite(mid)
    return float(np.polyfit(d[ok], mid[ok], 2)[0])


def test_vertical_loop_is_curved_by_the_air_law():
    """Compression stiffens and suction softens the supports: the vertical loop's midline
    (tilt removed) bends by -sum F0 n (n + 1) / 2 (A / V)^2 (second-order term of
    F0 (1 + A q / V)^-n), and does not with the linearised law."""
    import copy

    desc, _ = C.load_inputs("cgs", None)
    sp = desc.supports
    assert sp.air_law == "polytropic"
    loads = build_model(desc).info.support_loads_n
    c, n = sp.piston_area_m2 / sp.chamber_volume_m3, sp.polytropic_exponent
    closed = -float(np.sum(loads)) * n * (n + 1) / 2 * c * c
    assert _z_loop_curvature(desc.raw) == pytest.approx(closed, rel=0.15)
    raw = copy.deepcopy(desc.raw)
    raw["supports"]["air_law"] = "linear"
    assert abs(_z_loop_curvature(raw)) < 0.25 * abs(closed)

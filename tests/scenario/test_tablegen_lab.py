"""``shaketable table new``: the controller a lab runs, numbers it does not know, and a
specimen rating it did not give (issue #24 items 2, 3, 7; contract item 4)."""

from __future__ import annotations

import math
import tomllib

import numpy as np
import pytest

import mjcf
from sim.cli import main

BASE = """[lab]
moving_mass_kg = 840.0
piston_area_m2 = 3.0e-3
half_stroke_m = 0.1
supply_pressure_pa = 20.7e6
valve_rated_flow_m3_s = 1.0e-3
valve_bandwidth_hz = 60.0
"""


def _new(tmp_path, extra: str, name="td"):
    lab = tmp_path / "lab.toml"
    lab.write_text(BASE + extra)
    out = tmp_path / f"{name}.toml"
    rc = main(["table", "new", name, "--from", str(lab), "--out", str(out)])
    return rc, out


def _line(text: str, section: str, key: str) -> str:
    sec = None
    for line in text.splitlines():
        if line.startswith("["):
            sec = line.strip("[] ").split("]")[0]
        elif sec == section and line.split("=")[0].strip() == key:
            return line
    raise AssertionError(f"no {section}.{key}")


def test_the_labs_controller_and_recorder_are_written_with_their_origin(tmp_path):
    from sim.control.base import controller_settings

    extra = (
        "kp_per_s = 40.0\nkff_velocity = 0.9\nkff_acceleration_s = 0.0\nkdp = 0\ndp_highpass_hz = 0.5\n"
        "controller_rate_hz = 512\nrecorder_rate_hz = 204.8\n"
        "accelerometer_lowpass_hz = 100.0\naccelerometer_lowpass_order = 2\n"
    )
    rc, out = _new(tmp_path, extra)
    assert rc == 0
    text = out.read_text()
    desc = mjcf.load_table(out)
    g = controller_settings(desc)
    assert g.kdp == 0.0 and g.kp_per_s[0] == 40.0 and g.kff_velocity[0] == 0.9 and g.kff_acceleration_s[0] == 0.0
    assert g.dp_highpass_hz == 0.5 and g.rate_hz == 512.0
    assert desc.recorder_rate_hz == 204.8
    assert desc.accelerometer_bandwidth_hz == 100.0 and desc.accelerometer_filter_order == 2
    for sec, key in (("controller", "kdp"), ("controller", "kff_velocity"), ("sensors", "recorder_rate_hz")):
        assert "# lab: " in _line(text, sec, key)
    assert "# assumed:" in _line(text, "controller", "kff_jerk_s2")


def test_negative_gain_is_one_line(tmp_path, capsys):
    rc, out = _new(tmp_path, "kdp = -0.1\n")
    assert rc == 2 and not out.exists()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'kdp'" in err[0] and ">= 0" in err[0]


def test_unknown_values_get_their_nominal_their_mark_and_the_unknown_table(tmp_path):
    extra = 'bulk_modulus_pa = "unknown"\ndead_volume_m3 = { unknown = [5e-5, 4e-4] }\n'
    text = BASE.replace("valve_bandwidth_hz = 60.0", "valve_bandwidth_hz = { unknown = [30.0, 120.0], guess = 50.0 }")
    lab = tmp_path / "lab.toml"
    lab.write_text(text + extra)
    out = tmp_path / "td.toml"
    assert main(["table", "new", "td", "--from", str(lab), "--out", str(out)]) == 0
    written = out.read_text()
    desc = mjcf.load_table(out)
    u = desc.unknowns
    assert u["fluid.bulk_modulus_pa"] == (0.5e9, 1.8e9)  # the default range
    assert desc.raw["fluid"]["bulk_modulus_pa"] == pytest.approx(math.sqrt(0.5e9 * 1.8e9), rel=1e-5)
    assert u["actuator_class.main.dead_volume_a_m3"] == (5e-5, 4e-4) == u["actuator_class.main.dead_volume_b_m3"]
    assert desc.raw["actuator_class"]["main"]["dead_volume_a_m3"] == pytest.approx(math.sqrt(5e-5 * 4e-4), rel=1e-5)
    lo, hi = u["servovalve.tau_s"]  # a bandwidth is the valve's time constant in the description
    assert (lo, hi) == pytest.approx((1 / (2 * math.pi * 120), 1 / (2 * math.pi * 30)), rel=1e-5)
    assert desc.raw["servovalve"]["tau_s"] == pytest.approx(1 / (2 * math.pi * 50), rel=1e-5)  # the guess
    assert "# unknown: between 5e+08 and 1.8e+09 (default range: mineral oil" in _line(
        written, "fluid", "bulk_modulus_pa"
    )
    assert "# unknown: between" in _line(written, "servovalve", "tau_s")
    assert "# lab: " in _line(written, "servovalve", "rated_flow_m3_s")  # a known value keeps its origin
    assert "unknown" not in tomllib.loads(written)["servovalve"].get("model", "")


def test_required_numbers_may_be_unknown_with_a_default_range(tmp_path):
    text = BASE.replace("supply_pressure_pa = 20.7e6", 'supply_pressure_pa = "unknown"')
    text = text.replace("valve_rated_flow_m3_s = 1.0e-3", 'valve_rated_flow_m3_s = "unknown"')
    lab = tmp_path / "lab.toml"
    lab.write_text(text + 'leakage_m3_s_pa = "unknown"\n')
    out = tmp_path / "td.toml"
    assert main(["table", "new", "td", "--from", str(lab), "--out", str(out)]) == 0
    u = mjcf.load_table(out).unknowns
    assert u["supply.pressure_pa"] == (7e6, 35e6)
    assert u["servovalve.rated_flow_m3_s"] == pytest.approx((0.1 * 3e-3, 2.0 * 3e-3))  # 0.1-2 m/s of the piston
    lo, hi = u["actuator_class.main.leakage_cross_m3_s_pa"]
    assert lo == 0.0 and hi > 0


LAB_BAD = {
    "unknown range reversed": ("bulk_modulus_pa = { unknown = [1.8e9, 0.5e9] }\n", ["'bulk_modulus_pa'", "LO < HI"]),
    "guess outside": ("bulk_modulus_pa = { unknown = [0.5e9, 1.8e9], guess = 2e9 }\n", ["guess", "outside"]),
    "not unknowable": ("half_stroke_m_x = 1\n", ["unknown key 'half_stroke_m_x'"]),
    "stroke unknown": (None, ["'half_stroke_m' cannot be unknown"]),
    "unknown as a word": ('bulk_modulus_pa = "unknwon"\n', ["'bulk_modulus_pa'", "number"]),
}


@pytest.mark.parametrize("case", sorted(LAB_BAD))
def test_bad_lab_file_is_one_line(case, tmp_path, capsys):
    extra, fragments = LAB_BAD[case]
    lab = tmp_path / "lab.toml"
    lab.write_text(BASE.replace("half_stroke_m = 0.1", 'half_stroke_m = "unknown"') if extra is None else BASE + extra)
    out = tmp_path / "td.toml"
    assert main(["table", "new", "td", "--from", str(lab), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    for frag in fragments:
        assert frag in err[0], (frag, err[0])
    assert not out.exists()


def test_specimen_rating_is_unknown_unless_given_and_feasibility_says_so(tmp_path):
    from mjcf.description import RigidPayload
    from sim.assess.feasibility import specimen_checks, verdict

    rc, out = _new(tmp_path, "")
    assert rc == 0
    desc = mjcf.load_table(out)
    assert desc.limits.max_specimen_kg is None and desc.limits.overturning_moment_n_m is None
    heavy = RigidPayload(
        name="heavy",
        mass_kg=2000.0,  # more than the 840 kg platen: no reason to refuse without a rating
        com_m=[0.0, 0.0, 0.5],
        inertia_kg_m2=[100.0, 100.0, 100.0],
        footprint_m=[1.0, 1.0],
        height_m=1.0,
    )
    checks = specimen_checks(desc, heavy)
    v = verdict(checks)
    assert v["feasible"] and any("rating is unknown" in w for w in v["warnings"])
    from sim.assess.feasibility import check

    c = check("overturning_moment", 2000 * 9.81 * 0.5, desc.limits.overturning_moment_n_m, "N m")
    assert c["pass"] and "rating is unknown" in c["note"]
    rc, out2 = _new(tmp_path, "max_specimen_kg = 1500.0\n", name="td2")
    v2 = verdict(specimen_checks(mjcf.load_table(out2), heavy))
    assert not v2["feasible"] and v2["failed"] == ["specimen_mass"]


def test_a_heavy_specimen_on_a_guided_uniaxial_table_gets_its_oil_column():
    """Feasibility's specimen interaction on a platen on bearings: the model's mass matrix
    is over its one DOF (it raised a shape error on the uni-axial lab table before)."""
    from mjcf.description import RigidPayload
    from sim.assess.specimen import interaction

    desc = mjcf.load_table("lab")
    heavy = RigidPayload(
        name="heavy",
        mass_kg=2000.0,
        com_m=np.array([0.0, 0.0, 0.5]),
        inertia_kg_m2=np.array([400.0, 400.0, 300.0]),
        footprint_m=np.array([1.0, 1.0]),
        height_m=1.0,
    )
    oil = interaction(desc, heavy)["oil_columns_hz"]
    assert list(oil) == ["x"]
    # k / (m + 2000 kg) against k / m with m = 1200 kg: the column drops by sqrt(1200 / 3200)
    assert oil["x"] == pytest.approx(36.04 * math.sqrt(1200 / 3200), rel=0.03), oil


def test_kdp_zero_from_the_command_line(tmp_path):
    out = tmp_path / "t.toml"
    args = ["table", "new", "t", "--moving-mass", "840", "--piston-area", "3e-3", "--half-stroke", "0.1"]
    args += ["--supply-pressure", "20.7e6", "--valve-flow", "1e-3", "--valve-bandwidth", "60", "--kdp", "0"]
    assert main([*args, "--recorder-rate", "204.8", "--out", str(out)]) == 0
    desc = mjcf.load_table(out)
    assert desc.raw["controller"]["kdp"] == 0.0 and desc.recorder_rate_hz == 204.8
    assert "# lab: the command line" in _line(out.read_text(), "controller", "kdp")

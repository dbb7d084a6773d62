"""`table new --kind 6dof` (issue #14): a generic 6-DOF table from a lab's numbers loads,
builds, stands still with closed valves and tracks a short sine on each DOF, with no
code of its own."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

import mjcf
from sim.cli import main

ROOT = Path(__file__).resolve().parents[2]
EX = ROOT / "scenarios" / "lab_example"


def _generate(tmp_path, src, name, extra=None):
    inp = tmp_path / f"{name}_in.toml"
    text = (EX / src).read_text()
    if extra:
        text += "\n" + extra + "\n"
    inp.write_text(text)
    out = tmp_path / f"{name}.toml"
    assert main(["table", "new", name, "--kind", "6dof", "--from", str(inp), "--out", str(out)]) == 0
    return out


def _sine(rate, k, amp, f=2.0, T=1.0):
    from sim.scenario.reference import Reference

    t = np.arange(int(T * rate) + 1) / rate
    D, V, A = (np.zeros((len(t), 6)) for _ in range(3))
    w = 2 * np.pi * f
    D[:, k], V[:, k], A[:, k] = amp * np.sin(w * t), amp * w * np.cos(w * t), -amp * w * w * np.sin(w * t)
    return Reference(t=t, d=D, v=V, a=A)


@pytest.mark.parametrize(
    "src, name, supports",
    [("lab6_table.toml", "lab6", True), ("hexapod_table.toml", "hex6", False)],
)
def test_generated_6dof_table_stands_still_and_tracks_each_dof(tmp_path, src, name, supports):
    from sim.effects import build_model
    from sim.loop.simulation import Simulation

    out = _generate(tmp_path, src, name)
    desc = mjcf.load_table(out)
    assert desc.dofs == ("x", "y", "z", "rx", "ry", "rz")
    assert (desc.supports is not None) == supports
    # every numeric line says where its number comes from
    for line in out.read_text().splitlines():
        rhs = line.split("=", 1)[1].split("#")[0] if "=" in line and not line.startswith("#") else ""
        if any(c.isdigit() for c in rhs) and line.split("=")[0].strip() not in ("gravity_m_s2", "name", "title"):
            assert "#" in line, line
    sim = Simulation(build_model(desc, None))
    F = sim.static_forces()  # zero with supports; the legs carry the weight without
    if supports:
        assert np.abs(F).max() < 1e-6 * desc.platen.mass_kg * 9.81
    else:
        assert F.sum() > 0.5 * desc.platen.mass_kg * 9.81  # the legs hold it up
    # closed valves: it stands still (gravity on the supports or the oil columns)
    sim.reset(forces=F)
    res = sim.run(valve_command=np.zeros((512, len(desc.actuators))))
    assert res.incomplete_reason is None
    assert np.abs(res.channels["table_displacement"]).max() < 1e-4
    # a 2 Hz sine of 10 % of the rated motion on each DOF in turn, closed loop
    lim = np.r_[desc.limits.stroke_m, desc.limits.rotation_rad]
    rate = sim.gains.rate_hz
    i0 = int(0.5 * rate)  # after the start transient
    for k in range(6):
        ref = _sine(rate, k, 0.1 * lim[k])
        sim.reset(forces=F)
        r = sim.run(reference=ref)
        assert r.incomplete_reason is None, k
        d = r.channels["table_displacement"][i0:]
        e = d[:, k] - ref.d[i0:, k]
        assert np.sqrt(np.mean(e**2)) < 0.08 * np.sqrt(np.mean(ref.d[i0:, k] ** 2)), k
        cross = np.abs(np.delete(d, k, axis=1) / np.delete(lim, k)).max()
        assert cross < 0.005, (k, cross)  # the other DOFs stay put (< 0.5 % of their rating)


def test_explicit_layout_and_the_limits_fit_the_stroke(tmp_path):
    """Explicit attachment points (the 4h4v points rotated by 45 deg about z) give the
    same table; the derived limits are reachable (the description's own check) and use
    most of the stroke."""
    gen = tomllib.loads(_generate(tmp_path, "lab6_table.toml", "lab6").read_text())
    c, s = np.cos(np.pi / 4), np.sin(np.pi / 4)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    rows = []
    for a in gen["actuator"]:
        rows += [
            "[[lab.actuator]]",
            f'name = "{a["name"]}"',
            f'class = "{a["class"]}"',
            f"base_m = {[float(x) for x in R @ np.array(a['base_m'])]}",
            f"platen_m = {[float(x) for x in R @ np.array(a['platen_m'])]}",
        ]
    text = (EX / "lab6_table.toml").read_text().replace('layout = "4h4v"', 'layout = "explicit"')
    text = text.replace("[lab]", "[lab]\nstatic_supports = true", 1) + "\n" + "\n".join(rows) + "\n"
    inp = tmp_path / "ex_in.toml"
    inp.write_text(text)
    out = tmp_path / "ex.toml"
    assert main(["table", "new", "ex6", "--kind", "6dof", "--from", str(inp), "--out", str(out)]) == 0
    desc = mjcf.load_table(out)
    assert [a.name for a in desc.actuators] == [a["name"] for a in gen["actuator"]]
    # rotated layout: x and y swap roles at 45 deg, z and rz limits as the 4h4v table's
    ex = tomllib.loads(out.read_text())
    assert ex["limits"]["stroke_m"][2] == pytest.approx(gen["limits"]["stroke_m"][2], rel=0.2)
    from mjcf.description import actuator_strokes, envelope_corners

    need = np.abs(actuator_strokes(desc, envelope_corners(desc))).max(axis=0)
    assert need.max() > 0.8 * desc.actuators[0].cls.half_stroke_m  # not needlessly small


@pytest.mark.parametrize(
    "extra, needle",
    [
        ('layout = "tripod"', "'layout' must be"),
        ("pair_angle_deg = 150.0", "'pair_angle_deg' must be between"),
        ("nonsense_m = 1.0", "unknown key 'nonsense_m'"),
    ],
)
def test_6dof_bad_input_is_one_line_and_writes_nothing(tmp_path, capsys, extra, needle):
    text = (EX / "hexapod_table.toml").read_text()
    if extra.startswith("layout"):
        text = text.replace('layout = "hexapod"', extra)
    else:
        text = text.replace("[lab]", "[lab]\n" + extra, 1)
    inp = tmp_path / "in.toml"
    inp.write_text(text)
    out = tmp_path / "t.toml"
    assert main(["table", "new", "t6", "--kind", "6dof", "--from", str(inp), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "\n" not in err and needle in err, err
    assert not out.exists()


def test_a_layout_that_misses_a_dof_is_refused(tmp_path, capsys):
    """Six actuators all horizontal cannot lift or tilt the platen: rank < 6, refused."""
    rows = []
    for i, (b, p) in enumerate(
        [
            ([-3, 0.5, 0], [-1, 0.5, 0]),
            ([-3, -0.5, 0], [-1, -0.5, 0]),
            ([0.5, -3, 0], [0.5, -1, 0]),
            ([-0.5, -3, 0], [-0.5, -1, 0]),
            ([3, 0.5, 0], [1, 0.5, 0]),
            ([0.5, 3, 0], [0.5, 1, 0]),
        ]
    ):
        rows += ["[[lab.actuator]]", f'name = "H{i}"', 'class = "horizontal"', f"base_m = {b}", f"platen_m = {p}"]
    text = (EX / "lab6_table.toml").read_text().replace('layout = "4h4v"', 'layout = "explicit"')
    inp = tmp_path / "in.toml"
    inp.write_text(text + "\n" + "\n".join(rows) + "\n")
    out = tmp_path / "t.toml"
    assert main(["table", "new", "flat", "--kind", "6dof", "--from", str(inp), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "rank < 6" in err and "\n" not in err and not out.exists()

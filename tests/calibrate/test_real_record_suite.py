"""NEES-UCSD records made like real ones (docs/calibration-validation-blind.md), calibrated
with defaults: one planted effect a case, motion and force channels only, every run
through ``scenarios/sensors/real_record_1024hz.toml`` (a 5 s quiet lead-in, the
accelerometer's declared 100 Hz conditioner and lag, the displacement 0.3 sample early
and undeclared, zeros that change from record to record, drift, noise, 16 bits)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sim.calibrate import search as S

ROOT = Path(__file__).resolve().parents[2]
SENSORS = ROOT / "scenarios" / "sensors" / "real_record_1024hz.toml"
UCSD = ROOT / "scenarios" / "tables" / "ucsd.toml"
#: (name, motion, seconds): three fit runs, two held out
MOTIONS = [
    (
        "wn1",
        '[motion.x]\ntype = "white_noise"\nband_hz = [0.3, 15.0]\nseed = 11\nrms_acceleration = 2.0\ntaper_s = 1.0\n',
        12.0,
    ),
    ("ec100", '[motion]\ntype = "el_centro_1940"\namplitude_factor = 1.0\nmapping = { x = "180" }\n', 12.0),
    (
        "wn2",
        '[motion.x]\ntype = "white_noise"\nband_hz = [0.5, 20.0]\nseed = 12\nrms_acceleration = 3.0\ntaper_s = 1.0\n',
        10.0,
    ),
    ("ec200", '[motion]\ntype = "el_centro_1940"\namplitude_factor = 2.0\nmapping = { x = "180" }\n', 12.0),
    (
        "wn3",
        '[motion.x]\ntype = "white_noise"\nband_hz = [0.3, 10.0]\nseed = 13\nrms_acceleration = 1.5\ntaper_s = 1.0\n',
        10.0,
    ),
]
#: what a recorder of motion and force does not hold
DROPPED = ("valve_command", "spool_position", "pressure_a", "pressure_b")


def _sensors(folder: Path, channel: dict) -> Path:
    """The real-record sensor file with ``channel``'s keys added at the end of each
    channel's section (a TOML key may be given once: these are not in the file)."""
    text = SENSORS.read_text()
    for ch, keys in channel.items():
        head = f"[channel.{ch}]\n"
        lines = "".join(f"{k} = {json.dumps(v)}\n" for k, v in keys.items())
        text = text.replace(head, head + lines)
    p = folder / "sensors.toml"
    p.write_text(text)
    return p


def _motion_skewed(sensors: Path, samples: float) -> None:
    """``sensors`` with the displacement and the velocity ``samples`` early (the file's
    0.3 sample replaced)."""
    text = sensors.read_text()
    for ch in ("table_displacement", "table_velocity"):
        head = f"[channel.{ch}]\nskew_s = 0.00029297 "
        assert text.count(head) == 1, ch
        text = text.replace(head, f"[channel.{ch}]\nskew_s = {samples / 1024.0!r} ")
    sensors.write_text(text)


def _runs(folder: Path, effects=(), channel=None, motion_early=None, sensors_ready=False) -> list[str]:
    from sim.cli import main
    from sim.runs.runfile import read_run, write_run

    sensors = folder / "sensors.toml" if sensors_ready else _sensors(folder, channel or {})
    if motion_early is not None:
        _motion_skewed(sensors, motion_early)
    out = []
    for i, (name, motion, seconds) in enumerate(MOTIONS):
        text = f'[scenario]\nname = "{name}"\ntable = "ucsd"\nduration_s = {seconds}\n' + motion
        for e in effects:
            text += "[[effect]]\n" + "".join(f"{k} = {json.dumps(v)}\n" for k, v in e.items())
        (folder / f"{name}.toml").write_text(text)
        argv = ["run", str(folder / f"{name}.toml"), "--out", str(folder / "sim"), "--duration", str(seconds)]
        assert main(argv + ["--measure", str(sensors), "--measure-seed", str(100 + i)]) == 0
        run = as_recorded(read_run(folder / "sim" / f"{name}.measured.run.npz"), DROPPED)
        out.append(str(write_run(folder / f"{name}.run.npz", run)))
    return out


def as_recorded(run, dropped):
    """``run`` as its recorder writes it: the channels ``dropped`` gone, no extras, no
    table description (a real record carries none)."""
    for c in dropped:
        setattr(run, c, None)
    run.extras = {}
    for k in ("table_description", "table_sha256"):
        run.meta.pop(k, None)
    return run


def _calibrate(paths):
    return S.calibrate(paths[:3], holdout=paths[3:], table=str(UCSD), workers=2, log=lambda *a: None)


def test_a_load_cell_early_is_the_load_cells_alone(tmp_path):
    """The load cell 4 ms early (its sample 4 ms after its time stamp), the displacement
    0.3 sample early as in every case: the force's delay alone, -4.000 +/- 0.003 ms
    measured (it was -3.68 ms beside +0.32 ms on the accelerometer, the displacement's
    own skew read as the accelerometer's); held out 13.6 % -> 1.53 %, the clean floor."""
    res = _calibrate(_runs(tmp_path, channel={"actuator_force": {"skew_s": 0.004}}))
    assert [(e["name"], e["where"]) for e in res.effects_added] == [("sensor_delay", "channel:actuator_force")]
    d, u = (res.effects_added[0][k]["delay_s"] for k in ("parameters", "uncertainty"))
    assert abs(d + 0.004) <= u < 1e-5, (d, u)
    assert res.error_after < 0.2 * res.error_before, (res.error_before, res.error_after)
    # the mechanical path's held-out error per DOF is at the accelerometers' floor (the
    # error a perfect model would leave: their noise times the moving mass)
    for k, v in res.paths["mechanical"]["per_channel"].items():
        assert v["after"] <= 1.1 * v["floor"], (k, v)


@pytest.mark.parametrize("gain", [1.05, 0.9])
def test_a_load_cell_gain_is_its_gain_not_a_heavier_stiffer_rougher_table(gain, tmp_path):
    """The load cells read 5 % high (or 10 % low: a piston area or a unit nobody wrote
    down): their gain on the mechanical path, 1.04934 +/- 0.00037 (0.89942 +/- 0.00032)
    measured, and nothing else; pooled held out 4.38 % -> 1.50 % (9.76 % -> 1.54 %), the
    clean floor. The clean records read 0.99936 (refused: within a transducer's
    tolerance), the declared model's own scale against the simulated truth: every gain
    reads 0.9994 of itself. Before the candidate a 5 % gain was an added mass of 7.1 t, a
    Coulomb friction of 1.7 kN, a spring of 61.6 kN/m and a bulk modulus, 2.95 % held out."""
    res = _calibrate(_runs(tmp_path, channel={"actuator_force": {"gain": gain}}))
    assert [(e["name"], e["where"], e["path"]) for e in res.effects_added] == [
        ("sensor_gain", "channel:actuator_force", "mechanical")
    ]
    g, u = (res.effects_added[0][k]["gain"] for k in ("parameters", "uncertainty"))
    # the truth 1.8 of its 95 % intervals out: the model's 0.064 % is not in the interval
    assert abs(g - gain) <= 2 * u < 2e-3, (g, u)
    assert g == pytest.approx(gain, rel=1e-3), g
    assert res.error_after < 0.4 * res.error_before, (res.error_before, res.error_after)
    assert res.error_after < 0.016, res.error_after


def test_a_load_cell_gain_beside_an_added_mass_is_both(tmp_path):
    """The load cells 5 % high and 8 t nobody declared: each alone takes the other's force
    in (the gain alone read 1.106; a 69 Hz mode of 15 t won the first round, then a 0.16 Hz
    one of 49 t for the gain's share of the friction, and a bulk modulus on the closed
    loop: pooled held out 9.18 % -> 2.86 %). Read beside the law it goes with
    (sim/calibrate/gainpair.py) and the mode above the band demoted to a mass: measured
    1.04688 +/- 0.00429 and 8 028 +/- 37 kg (refitted on the closed loop; the mechanical
    path's 8 358 +/- 578 beside the gain), nothing else; pooled 9.18 % -> 1.49 %."""
    eff = [{"type": "added_mass", "where": "dof:x", "mass_kg": 8000.0}]
    res = _calibrate(_runs(tmp_path, effects=eff, channel={"actuator_force": {"gain": 1.05}}))
    found = {(e["name"], e["where"]): e for e in res.effects_added}
    assert sorted(found) == [("added_mass", "dof:x"), ("sensor_gain", "channel:actuator_force")], found
    g, u = (found[("sensor_gain", "channel:actuator_force")][k]["gain"] for k in ("parameters", "uncertainty"))
    assert abs(g - 1.05) <= u < 0.006, (g, u)
    m, um = (found[("added_mass", "dof:x")][k]["mass_kg"] for k in ("parameters", "uncertainty"))
    assert abs(m - 8000.0) <= um < 0.01 * 8000.0, (m, um)
    assert res.error_after < 0.2 * res.error_before, (res.error_before, res.error_after)
    assert res.error_after < 0.016, res.error_after


def test_an_added_mass_takes_no_compensating_mode(tmp_path):
    """8 t added at dof:x: the added mass alone, 7 927 +/- 43 kg measured (0.9 % low,
    outside its interval); a 91 Hz, 38 % mode of 87.8 t that took the mass to -80.7 t
    is refused as compensation. Held out 5.93 % -> 1.51 %."""
    res = _calibrate(_runs(tmp_path, effects=[{"type": "added_mass", "where": "dof:x", "mass_kg": 8000.0}]))
    assert [(e["name"], e["where"]) for e in res.effects_added] == [("added_mass", "dof:x")]
    m = res.effects_added[0]["parameters"]["mass_kg"]
    assert m == pytest.approx(8000.0, rel=0.015), m
    assert res.error_after < 0.3 * res.error_before, (res.error_before, res.error_after)


@pytest.mark.slow
def test_a_displacement_two_samples_early_is_its_own_delay_not_less_mass(tmp_path):
    """8 t added, the displacement and the velocity 2 samples early (undeclared): the
    acceleration times the motion at -1.989 +/- 0.061 ms (-1.953), and the added mass is
    7 981 +/- 50 kg (measured, eighteenth session); with 0 skew it is 7 975.5 +/- 18.4.
    Without the delay the mass read 7 691 +/- 55 kg (3.9 % low) while the held-out error
    fell by only 1.7 % with the delay: below the search's margin, so a motion off by more
    than half a sample is taken without one."""
    effects = [{"type": "added_mass", "where": "dof:x", "mass_kg": 8000.0}]
    res = _calibrate(_runs(tmp_path, effects=effects, motion_early=2.0))
    found = {(e["name"], e["where"]): e for e in res.effects_added}
    assert sorted(found) == [("added_mass", "dof:x"), ("sensor_delay", "channel:table_displacement")], found
    e = found[("sensor_delay", "channel:table_displacement")]
    d, u = e["parameters"]["delay_s"], e["uncertainty"]["delay_s"]
    assert abs(d + 2.0 / 1024.0) <= u < 2e-4, (d, u)
    m, um = (found[("added_mass", "dof:x")][k]["mass_kg"] for k in ("parameters", "uncertainty"))
    assert abs(m - 8000.0) <= um < 100.0, (m, um)


@pytest.mark.slow
def test_a_velocity_two_samples_early_is_its_own_delay(tmp_path):
    """8 t added, the velocity alone 2 samples early (undeclared; the displacement 0.3
    sample early as in every case): the velocity's delay against the displacement,
    -1.395 +/- 0.036 ms measured, for -1.953 + 0.293 ms and the simulator's own half
    physics step (its velocity is 0.244 ms behind its position), -1.416 ms. The added mass
    is 7 886 +/- 50 kg (1.4 % low), where without the velocity's delay it read 7 692 +/- 53
    kg (3.8 % low): the friction's switching and the damping read the velocity."""
    text = _sensors(tmp_path, {}).read_text()
    head = "[channel.table_velocity]\nskew_s = 0.00029297 "
    assert text.count(head) == 1
    (tmp_path / "sensors.toml").write_text(text.replace(head, f"[channel.table_velocity]\nskew_s = {2 / 1024!r} "))
    effects = [{"type": "added_mass", "where": "dof:x", "mass_kg": 8000.0}]
    res = _calibrate(_runs(tmp_path, effects=effects, sensors_ready=True))
    found = {(e["name"], e["where"]): e for e in res.effects_added}
    assert sorted(found) == [("added_mass", "dof:x"), ("sensor_delay", "channel:table_velocity")], found
    d, u = (found[("sensor_delay", "channel:table_velocity")][k]["delay_s"] for k in ("parameters", "uncertainty"))
    assert abs(d - (-2 / 1024 + 0.3 / 1024 + 0.5 / 2048)) <= u < 1e-4, (d, u)
    assert found[("added_mass", "dof:x")]["parameters"]["mass_kg"] == pytest.approx(8000.0, rel=0.02)


def test_three_sensor_faults_at_once_each_on_its_own_channel(tmp_path):
    """A 30 Hz, 4-pole load-cell conditioner nobody declared, the load cells 5 % high and
    the velocity alone 2 samples early, nothing else (measured: the force's delay 14.284
    +/- 0.026 ms, the conditioner's delay in the test's band; the gain 1.04846 +/- 0.00104,
    1.5 intervals low, the conditioner's shape not a delay's; the velocity -1.3957 +/-
    0.0353 ms for -1.416; pooled held out 45.4 % -> 1.80 %, the ARX baseline 14.7 %). The
    gain passed beside a 2.5 t, 17.9 Hz mode that explained 0.35 % more of the fit runs and
    predicted the held-out runs 17 % worse: the gain goes in (the mode, then a second gain
    and a bulk modulus on the closed loop, before)."""
    force = {"actuator_force": {"lowpass_hz": 30.0, "lowpass_order": 4, "gain": 1.05}}
    text = _sensors(tmp_path, force).read_text()
    head = "[channel.table_velocity]\nskew_s = 0.00029297 "
    assert text.count(head) == 1
    (tmp_path / "sensors.toml").write_text(text.replace(head, f"[channel.table_velocity]\nskew_s = {2 / 1024!r} "))
    res = _calibrate(_runs(tmp_path, sensors_ready=True))
    found = {(e["name"], e["where"]): e["parameters"] for e in res.effects_added}
    assert sorted(found) == [
        ("sensor_delay", "channel:actuator_force"),
        ("sensor_delay", "channel:table_velocity"),
        ("sensor_gain", "channel:actuator_force"),
    ], found
    assert 0.013 < found[("sensor_delay", "channel:actuator_force")]["delay_s"] < 0.0155, found
    assert found[("sensor_gain", "channel:actuator_force")]["gain"] == pytest.approx(1.05, abs=0.003), found
    assert found[("sensor_delay", "channel:table_velocity")]["delay_s"] == pytest.approx(-1.416e-3, abs=1e-4), found
    assert res.error_after < 0.05 * res.error_before and res.error_after < 0.2 * res.baseline["holdout_error"]


def test_an_accelerometer_reading_high_is_its_gain(tmp_path):
    """The accelerometer reads 4 % high: its gain on the closed loop, 1.03949 +/- 0.00040
    measured (the truth 1.3 intervals out); the velocity reads it so. No offset is taken
    from the records' own zeros (0.022 m/s^2 was, before each record's zero was its own)."""
    res = _calibrate(_runs(tmp_path, channel={"table_acceleration": {"gain": 1.04}}))
    assert [(e["name"], e["where"], e["path"]) for e in res.effects_added] == [
        ("sensor_gain", "channel:table_acceleration", "closed_loop")
    ]
    g = res.effects_added[0]["parameters"]["gain"]
    assert g == pytest.approx(1.04, abs=0.002), g
    assert res.error_after < res.error_before, (res.error_before, res.error_after)


@pytest.mark.slow
def test_a_declared_load_cell_conditioner_adds_nothing(tmp_path):
    """The load cells behind a 50 Hz, 4-pole conditioner the records declare, nothing
    planted: nothing added, pooled held out 1.02 % (measured, seventeenth session). Before
    the mechanical path put the model's forces through the declared conditioner it took a
    force delay of 8.40 ms (the conditioner's low-frequency delay) and the pooled error
    stayed at 22.8 %, the closed loop then comparing through both."""
    force = {"actuator_force": {"lowpass_hz": 50.0, "lowpass_order": 4, "declared": True}}
    res = _calibrate(_runs(tmp_path, channel=force))
    assert res.effects_added == [], res.effects_added
    assert res.error_after < 0.02, res.error_after

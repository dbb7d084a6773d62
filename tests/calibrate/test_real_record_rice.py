"""The Rice uni-axial table (Trombetti and Conte 2002) on records made like real ones,
calibrated with defaults: 4000 Hz records of its analog controller (which acts every
1/8000 s), through ``scenarios/sensors/real_record_1024hz.toml`` at the table's 4000 Hz
(a 5 s quiet lead-in, the accelerometer's declared conditioner and lag, the displacement
early and undeclared, zeros, drift, noise), pressures and spool dropped. The paper
identifies the valve's pure delay per test series (12.0-14.0 ms, its Table 1); the
description declares set d18's 13.5 ms."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sim.calibrate import search as S

ROOT = Path(__file__).resolve().parents[2]
SENSORS = ROOT / "scenarios" / "sensors" / "real_record_1024hz.toml"
RICE = ROOT / "scenarios" / "tables" / "rice.toml"

#: (seed, band top Hz, RMS m/s^2): three fit runs, one held out (8 s white noise, 22-41 % of the stroke)
MOTIONS = [(91, 20.0, 2.0), (92, 25.0, 3.0), (93, 30.0, 4.0), (94, 35.0, 5.0)]
DROPPED = ("spool_position", "pressure_a", "pressure_b")


def _sensors_4000(folder: Path) -> Path:
    """The real-record sensor file at the Rice recorder's 4000 Hz (Sec. 4 of Trombetti and
    Conte 2002), its anti-alias at a quarter of that as in the file."""
    text = SENSORS.read_text()
    text = text.replace("rate_hz = 1024.0 ", "rate_hz = 4000.0 ").replace(
        "anti_alias_hz = 256.0 ", "anti_alias_hz = 1000.0"
    )
    assert "rate_hz = 4000.0" in text and "anti_alias_hz = 1000.0" in text
    p = folder / "sensors_4000.toml"
    p.write_text(text)
    return p


def _runs(folder: Path, effects=(), table: Path = RICE) -> list[str]:
    from test_real_record_suite import as_recorded

    from sim.cli import main
    from sim.runs.runfile import read_run, write_run

    sensors = _sensors_4000(folder)
    out = []
    for i, (seed, top, rms) in enumerate(MOTIONS):
        name = f"wn{i + 1}"
        text = (
            f'[scenario]\nname = "{name}"\ntable = "{table}"\nduration_s = 8.0\n'
            f'[motion.x]\ntype = "white_noise"\nband_hz = [1.0, {top}]\nseed = {seed}\n'
            f"rms_acceleration = {rms}\ntaper_s = 1.0\n[output]\nsample_rate_hz = 4000.0\n"
        )
        for e in effects:
            text += "[[effect]]\n" + "".join(f"{k} = {json.dumps(v)}\n" for k, v in e.items())
        (folder / f"{name}.toml").write_text(text)
        argv = ["run", str(folder / f"{name}.toml"), "--out", str(folder / "sim")]
        assert main(argv + ["--measure", str(sensors), "--measure-seed", str(901 + i)]) == 0
        run = as_recorded(read_run(folder / "sim" / f"{name}.measured.run.npz"), DROPPED)
        out.append(str(write_run(folder / f"{name}.run.npz", run)))
    return out


def _calibrate(paths):
    return S.calibrate(paths[:3], holdout=paths[3:], table=str(RICE), workers=2, log=lambda *a: None)


@pytest.mark.slow
def test_a_shorter_valve_delay_is_found_on_the_rice_table(tmp_path):
    """The valve's delay 12.0 ms (the paper's set d0) where 13.5 ms is declared: the
    replay path finds 12.000 +/- 0.004 ms (2026-11-27, measure seeds 901-904, the command
    interpolated linearly; before the model stepped as the table's controller does, this
    path stopped with an error; with the command held, it read 11.875 ms). Held out
    11.7 % -> 5.9 %, the linear baseline 10.1 % (each column weighted by its noise: the
    1 kN load-cell noise on this table's 3 kN forces held it at 18.5 % -> 14.9 % before)."""
    res = _calibrate(_runs(tmp_path, effects=[{"type": "valve_delay", "where": "actuators", "delay_s": 0.012}]))
    assert [e["name"] for e in res.effects_added] == ["valve_delay"], res.effects_added
    d, u = (res.effects_added[0][k]["delay_s"] for k in ("parameters", "uncertainty"))
    assert abs(d - 0.012) <= 3 * u + 1e-9 and u < 2e-5, (d, u)
    assert res.error_after < 0.9 * res.error_before, (res.error_before, res.error_after)
    assert res.error_after < res.baseline["holdout_error"], (res.error_after, res.baseline)


@pytest.mark.slow
def test_clean_rice_records_add_nothing(tmp_path):
    """The same records with the declared delay: nothing added (2026-11-27, columns
    weighted by their noise: the replay path's best, a valve bandwidth of 2873 Hz,
    lowered the held-out error 3.72 % -> 3.71 %, under the margin)."""
    res = _calibrate(_runs(tmp_path))
    assert res.effects_added == [], res.effects_added


@pytest.mark.slow
def test_a_softer_reaction_mass_is_the_foundation_mode(tmp_path):
    """The reaction mass on its springs at 22 Hz where the description derives 27.46 Hz
    from the paper's f_b = 27.1 Hz (Sec. 5.1 of Trombetti and Conte 2002): the replay path
    names `foundation_mode`, 21.9970 +/- 0.0078 Hz and 5.560 +/- 0.032 % for 22 Hz and
    5.574 % (2026-11-27, measure seeds 901-904, linear interpolation), nothing else; held
    out 7.8 % -> 5.9 % (columns weighted by their noise), the linear baseline 10.8 %."""
    import tomllib

    text = RICE.read_text().replace("frequency_hz = [27.464, 27.464, 27.464]", "frequency_hz = [22.0, 22.0, 22.0]")
    assert tomllib.loads(text)["foundation"]["frequency_hz"] == [22.0, 22.0, 22.0]
    truth = tmp_path / "rice_truth.toml"
    truth.write_text(text)
    res = _calibrate(_runs(tmp_path, table=truth))
    assert [e["name"] for e in res.effects_added] == ["foundation_mode"], res.effects_added
    p, u = (res.effects_added[0][k] for k in ("parameters", "uncertainty"))
    assert abs(p["frequency_hz"] - 22.0) <= 3 * u["frequency_hz"] and u["frequency_hz"] < 0.05, (p, u)
    assert abs(p["damping_ratio"] - 0.05574) <= 3 * u["damping_ratio"], (p, u)
    assert res.error_after < res.error_before and res.error_after < res.baseline["holdout_error"]


@pytest.mark.slow
def test_a_softer_oil_is_found_under_a_noisy_load_cell(tmp_path):
    """The oil's bulk modulus 400 MPa where set d18 declares 503.3 MPa. The held-out run's
    force is 3 kN RMS under the sensor file's 1 kN of load-cell noise (a floor of 31 %):
    counted alike with the acceleration, it held the pooled held-out error at 19 % and the
    bulk modulus (400.45 MPa) lowered it by 3.3 %, under the margin; an accelerometer gain
    of 1.020 was taken in its place. Each column weighted by its noise floor
    (:func:`sim.calibrate.paths.noise_weights`): the replay path names `bulk_modulus`,
    400.59 +/- 0.52 MPa (2026-11-27, measure seeds 901-904), nothing else."""
    planted = {"type": "bulk_modulus", "where": "actuators", "bulk_modulus_pa": 4.0e8}
    res = _calibrate(_runs(tmp_path, effects=[planted]))
    assert [e["name"] for e in res.effects_added] == ["bulk_modulus"], res.effects_added
    b, u = (res.effects_added[0][k]["bulk_modulus_pa"] for k in ("parameters", "uncertainty"))
    assert abs(b - 4.0e8) <= 3 * u and u < 2e6, (b, u)
    assert res.error_after < 0.95 * res.error_before and res.error_after < res.baseline["holdout_error"]

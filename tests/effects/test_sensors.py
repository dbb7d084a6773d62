"""Sensor effects (sim/effects/sensors.py) and synthetic measurements (sim/runs/measure.py):
known signals in, the computed change out."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import numpy as np
import pytest

from sim.effects.base import create
from sim.effects.sensors import CHANNEL_NAMES
from sim.errors import ScenarioError
from sim.runs import measure as M
from sim.runs.runfile import CHANNELS, FORMAT, RunFile, read_run, write_run
from sim.signals import sensing

#: the papers' keys (docs/references.md)
CITATION_KEYS = ("[Airouche 2014]", "[Trombetti 2002]", "[Ozcelik 2008]")

ROOT = Path(__file__).resolve().parents[2]
FS = 1024.0
DOFS = ["x", "y", "z", "rx", "ry", "rz"]


def butterworth_gain(f, fc, order, fs):
    """|H| of the bilinear-transform Butterworth low-pass (cutoff pre-warped)."""
    r = math.tan(math.pi * f / fs) / math.tan(math.pi * fc / fs)
    return 1.0 / math.sqrt(1.0 + r ** (2 * order))


def sine_phasor(x, t, f):
    e = np.exp(-2j * np.pi * f * t)
    return 2.0 * np.sum(x * e) / len(t)


def make_run(n=4096, fs=FS):
    t = np.arange(n) / fs
    ramp = 0.5 * t
    sine = np.sin(2 * np.pi * 16.0 * t)
    return RunFile(
        t=t,
        meta={
            "format": FORMAT,
            "table": "test",
            "sample_rate_hz": fs,
            "actuators": ["A", "B"],
            "dofs": DOFS,
            "source": "simulated",
        },
        valve_command=np.column_stack([0.1 * sine, -0.1 * sine]),
        reference=np.column_stack([ramp] + [np.zeros(n)] * 5),
        actuator_force=np.column_stack([1e5 * sine, np.zeros(n)]),
        actuator_displacement=np.column_stack([ramp, -ramp]),
        table_acceleration=np.zeros((n, 6)),
        extras={"supply_pressure": np.full(n, 20e6)},
    )


# ---------------------------------------------------------------- sensor effects
def test_channel_names_are_the_run_file_channels():
    assert CHANNEL_NAMES == CHANNELS


def test_sensor_gain_and_offset_one_column_or_all():
    t = np.arange(100) / FS
    x = np.random.default_rng(0).normal(size=(100, 3))
    ch = {"actuator_force": x}
    g = create({"type": "sensor_gain", "where": "channel:actuator_force[2]", "gain": 1.25}).measure(t, ch, None)
    np.testing.assert_array_equal(g["actuator_force"][:, 2], 1.25 * x[:, 2])
    np.testing.assert_array_equal(g["actuator_force"][:, :2], x[:, :2])
    assert ch["actuator_force"] is x and np.all(x == ch["actuator_force"])  # the input is not changed
    o = create({"type": "sensor_offset", "where": "channel:actuator_force", "offset": -3.5}).measure(t, ch, None)
    np.testing.assert_array_equal(o["actuator_force"], x - 3.5)


def test_sensor_gain_on_several_columns():
    """One actuator class's load cells (``[1,3]``): those columns scaled, the others not;
    a column past the channel's is one line naming it."""
    t = np.arange(100) / FS
    x = np.random.default_rng(1).normal(size=(100, 4))
    e = create({"type": "sensor_gain", "where": "channel:actuator_force[1,3]", "gain": 1.05})
    y = e.measure(t, {"actuator_force": x}, None)["actuator_force"]
    np.testing.assert_array_equal(y[:, [1, 3]], 1.05 * x[:, [1, 3]])
    np.testing.assert_array_equal(y[:, [0, 2]], x[:, [0, 2]])
    bad = create(
        {"type": "sensor_gain", "where": "channel:actuator_force[1,4]", "gain": 1.05}, source="t.toml effect[0]"
    )
    with pytest.raises(ScenarioError, match="has 4 column"):
        bad.measure(t, {"actuator_force": x}, None)


def test_sensor_delay_is_a_fractional_delay():
    """A ramp delayed by 2.3 samples is the ramp 2.3 samples later, exactly (linear
    interpolation is exact on a line); a sine delayed by tau has its phase lowered by
    2 pi f tau."""
    n = 2048
    t = np.arange(n) / FS
    tau = 2.3 / FS
    ramp = 3.0 * t + 1.0
    d = create({"type": "sensor_delay", "where": "channel:table_displacement[0]", "delay_s": tau})
    y = d.measure(t, {"table_displacement": np.column_stack([ramp, ramp])}, None)["table_displacement"]
    np.testing.assert_allclose(y[3:, 0], 3.0 * (t[3:] - tau) + 1.0, rtol=0, atol=1e-12)
    assert y[0, 0] == 1.0 and np.all(y[:, 1] == ramp)
    f = 8.0
    s = np.sin(2 * np.pi * f * t)
    ys = d.measure(t, {"table_displacement": np.column_stack([s, s])}, None)["table_displacement"][:, 0]
    dphi = np.angle(sine_phasor(ys[64:], t[64:], f) / sine_phasor(s[64:], t[64:], f))
    assert dphi == pytest.approx(-2 * np.pi * f * tau, abs=1e-3)


@pytest.mark.parametrize("order", [1, 2, 4])
def test_sensor_lowpass_is_a_causal_butterworth(order):
    """Steady-state sine through the low-pass: the Butterworth gain at that frequency
    (closed form); a constant passes unchanged (started in steady state); causal: an
    impulse moves nothing before it."""
    fc, f = 50.0, 40.0
    n = 8192
    t = np.arange(n) / FS
    x = np.sin(2 * np.pi * f * t)
    lp = create({"type": "sensor_lowpass", "where": "channel:accelerometers", "cutoff_hz": fc, "order": order})
    y = lp.measure(t, {"accelerometers": x[:, None]}, None)["accelerometers"][:, 0]
    k = t >= 2.0
    gain = abs(sine_phasor(y[k], t[k], f)) / abs(sine_phasor(x[k], t[k], f))
    assert gain == pytest.approx(butterworth_gain(f, fc, order, FS), rel=1e-3)
    c = lp.measure(t, {"accelerometers": np.full((n, 1), 7.0)}, None)["accelerometers"]
    np.testing.assert_allclose(c, 7.0, rtol=1e-12)
    imp = np.zeros((n, 1))
    imp[500] = 1.0
    yi = lp.measure(t, {"accelerometers": imp}, None)["accelerometers"]
    assert np.all(yi[:500] == 0.0) and yi[500, 0] > 0


def test_sensor_noise_rms_and_seed():
    n = 20000
    t = np.arange(n) / FS
    z = {"pressure_a": np.zeros((n, 2))}
    e = create({"type": "sensor_noise", "where": "channel:pressure_a[1]", "rms": 5e3, "seed": 4})
    y = e.measure(t, z, None)["pressure_a"]
    assert np.std(y[:, 1]) == pytest.approx(5e3, rel=0.03) and np.all(y[:, 0] == 0.0)
    np.testing.assert_array_equal(y, e.measure(t, z, None)["pressure_a"])
    other = create({"type": "sensor_noise", "where": "channel:pressure_a[1]", "rms": 5e3, "seed": 5})
    assert not np.allclose(y, other.measure(t, z, None)["pressure_a"])


@pytest.mark.parametrize(
    "entry, match",
    [
        ({"type": "sensor_gain", "where": "channel:force", "gain": 2.0}, "is not a channel"),
        ({"type": "sensor_gain", "where": "actuator:E", "gain": 2.0}, "acts at channel"),
        ({"type": "sensor_gain", "where": "channel:actuator_force[2", "gain": 2.0}, "is not a channel"),
        ({"type": "sensor_gain", "where": "channel:actuator_force", "gian": 2.0}, "did you mean 'gain'"),
    ],
)
def test_bad_sensor_entries(entry, match):
    with pytest.raises(ScenarioError, match=match) as ei:
        create(entry, source="t.toml effect[0]")
    assert "\n" not in str(ei.value)


def test_sensor_column_out_of_range():
    e = create({"type": "sensor_gain", "where": "channel:actuator_force[5]", "gain": 2.0}, source="t.toml effect[0]")
    with pytest.raises(ScenarioError, match="has 2 column"):
        e.measure(np.arange(10) / FS, {"actuator_force": np.zeros((10, 2))}, None)


def test_sensor_effects_act_when_the_run_file_is_built():
    """A table with sensor effects: its run file's channels are the loop's through them."""
    import mjcf
    from mjcf.description import parse_table
    from sim.effects import build_model
    from sim.loop.simulation import Simulation
    from sim.runs.build import build_runfile

    desc = mjcf.load_table(ROOT / "scenarios" / "tables" / "ucsd.toml")
    raw = copy.deepcopy(desc.raw)
    raw["effect"] = [
        {"type": "sensor_gain", "where": "channel:actuator_force[1]", "gain": 1.5},
        {"type": "sensor_offset", "where": "channel:actuator_force[1]", "offset": 100.0},
        {"type": "sensor_delay", "where": "channel:table_acceleration", "delay_s": 0.5 / 1024},
    ]
    tm = build_model(parse_table(raw, "test"))
    sim = Simulation(tm)
    res = sim.run(valve_command=np.full((128, 2), 0.002))
    run = build_runfile(res, tm)
    f = res.channels["actuator_force"]
    np.testing.assert_array_equal(run.actuator_force[:, 0], f[:, 0])
    np.testing.assert_allclose(run.actuator_force[:, 1], 1.5 * f[:, 1] + 100.0, rtol=1e-15)
    a = res.channels["table_acceleration"][:, 0]
    np.testing.assert_allclose(run.table_acceleration[1:, 0], 0.5 * (a[1:] + a[:-1]), rtol=1e-12)


# ---------------------------------------------------------------- measure_run
def test_measured_run_noise_rms_and_quantisation_step():
    run = make_run(n=16384)
    R, bits = 10.0, 10
    sensors = {
        "channel": {
            "table_acceleration": {"noise_rms": [0.05, 0.0, 0.2, 0, 0, 0]},
            "actuator_force": {"range": 2e5, "bits": bits},
        }
    }
    m = M.measure_run(run, sensors, seed=1)
    acc = m.table_acceleration
    assert np.std(acc[:, 0]) == pytest.approx(0.05, rel=0.03)
    assert np.std(acc[:, 2]) == pytest.approx(0.2, rel=0.03)
    assert np.all(acc[:, 1] == 0.0)
    step = 2 * 2e5 / 2**bits
    q = m.actuator_force[:, 0] / step
    np.testing.assert_allclose(q, np.round(q), atol=1e-9)  # on the ADC's grid
    assert np.abs(m.actuator_force[:, 0] - run.actuator_force[:, 0]).max() <= step / 2 + 1e-9
    # noise then the ADC: within half a step of the noisy signal, and every step used
    noisy = {"noise_rms": 3e4}
    m0 = M.measure_run(run, {"channel": {"actuator_force": noisy}}, seed=2).actuator_force[:, 0]
    m1 = M.measure_run(run, {"channel": {"actuator_force": dict(noisy, range=3e5, bits=bits)}}, seed=2)
    f1 = m1.actuator_force[:, 0]
    step = 2 * 3e5 / 2**bits
    assert np.abs(f1 - m0).max() <= step / 2 + 1e-9 and np.abs(f1 - m0).max() > 0.45 * step
    assert len(np.unique(f1)) > 0.5 * 2 * 2e5 / step
    # clipping at the ends of the range
    clip = M.measure_run(run, {"channel": {"actuator_force": {"range": 5e4, "bits": bits}}}, 0).actuator_force[:, 0]
    assert clip.max() == pytest.approx(5e4 - 2 * 5e4 / 2**bits) and clip.min() == -5e4
    assert sensing.quantisation_step(16, R) == 2 * R / 65536


def test_measured_run_gain_offset_skew_and_meta():
    run = make_run()
    sensors = {
        "channel": {"actuator_displacement": {"gain": [2.0, 1.0], "offset": [0.0, 0.01], "skew_s": [0.0, 1.5 / FS]}}
    }
    m = M.measure_run(run, sensors, seed=0)
    x = run.actuator_displacement
    np.testing.assert_allclose(m.actuator_displacement[:, 0], 2.0 * x[:, 0], rtol=1e-15)
    # column B: sampled 1.5 samples late, on a ramp of slope -0.5 m/s: -0.5 (t + skew) + 0.01
    np.testing.assert_allclose(m.actuator_displacement[:-2, 1], -0.5 * (run.t[:-2] + 1.5 / FS) + 0.01, atol=1e-12)
    assert m.source == "measured" and run.source == "simulated"
    assert "measurement" not in m.meta  # a real record carries nothing about its sensor chain
    rec = M.chain_record(run.meta, sensors, 0)
    assert rec["seed"] == 0 and rec["of"] == "simulated" and rec["model"] == sensors
    np.testing.assert_array_equal(m.valve_command, run.valve_command)  # no model for it: unchanged


def test_recorder_rate_and_anti_alias():
    """512 Hz recorder of a 1024 Hz run behind a 100 Hz 4-pole anti-alias filter:
    every second sample, the sine's amplitude times the Butterworth gain, the digital
    channels (reference) and the extras just sampled."""
    run = make_run(n=8192)
    sensors = {
        "recorder": {
            "rate_hz": 512.0,
            "anti_alias_hz": 100.0,
            "anti_alias_order": 4,
            "digital": ["reference", "valve_command"],
        }
    }
    m = M.measure_run(run, sensors, seed=0)
    assert m.sample_rate_hz == 512.0 and m.n_samples == 4096
    np.testing.assert_array_equal(m.t, run.t[::2])
    np.testing.assert_array_equal(m.reference, run.reference[::2])
    np.testing.assert_array_equal(m.valve_command, run.valve_command[::2])
    np.testing.assert_array_equal(m.extras["supply_pressure"], run.extras["supply_pressure"][::2])
    k = m.t >= 2.0
    gain = abs(sine_phasor(m.actuator_force[k, 0], m.t[k], 16.0)) / 1e5
    assert gain == pytest.approx(butterworth_gain(16.0, 100.0, 4, FS), rel=1e-3)


def test_same_seed_same_run_other_seed_other_run(tmp_path):
    run = make_run()
    sensors = M.load_sensors()  # the built-in model
    a = M.measure_run(run, sensors, seed=3)
    b = M.measure_run(run, sensors, seed=3)
    c = M.measure_run(run, sensors, seed=4)
    for ch in ("actuator_force", "actuator_displacement", "table_acceleration"):
        np.testing.assert_array_equal(getattr(a, ch), getattr(b, ch))
        assert not np.array_equal(getattr(a, ch), getattr(c, ch))
    p = write_run(tmp_path / "m.run.npz", a)
    back = read_run(p)
    np.testing.assert_array_equal(back.actuator_force, a.actuator_force)
    assert back.source == "measured" and "measurement" not in back.meta
    assert back.meta["recorder"]["anti_alias_hz"] == sensors["recorder"]["anti_alias_hz"]


@pytest.mark.parametrize("model", [M.DEFAULT_SENSORS, M.DEFAULT_SENSORS.parent / "real_record_1024hz.toml"])
def test_builtin_model_has_a_source_beside_every_number(model):
    M.load_sensors(model, sample_rate_hz=FS)  # it loads
    for line in model.read_text().splitlines():
        code = line.split("#")[0]
        if "=" in code and any(ch.isdigit() for ch in code.split("=", 1)[1]):
            assert "#" in line and any(w in line for w in ("assumed:", "calibrated:", *CITATION_KEYS)), line


@pytest.mark.parametrize(
    "sensors, match",
    [
        ({"recorder": {"rate": 512.0}}, "did you mean 'rate_hz'"),
        ({"recorder": {"rate_hz": 1000.0}}, "does not divide the run's 1024 Hz"),
        ({"recorder": {"anti_alias_hz": 600.0}}, "Nyquist"),
        ({"channel": {"force": {"noise_rms": 1.0}}}, "is not a run-file channel"),
        ({"channel": {"actuator_force": {"noise": 1.0}}}, "did you mean 'noise_rms'"),
        ({"channel": {"actuator_force": {"noise_rms": -1.0}}}, ">= 0"),
        ({"channel": {"actuator_force": {"offset": [1.0, 2.0, 3.0]}}}, "has 3 values but the channel has 2 columns"),
        ({"channel": {"actuator_force": {"range": 0.0}}}, "> 0"),
        ({"sensor": {}}, "unknown section"),
    ],
)
def test_bad_sensor_models_are_one_line_errors(sensors, match):
    with pytest.raises(M.SensorsError, match=match) as ei:
        M.measure_run(make_run(n=64), sensors, seed=0)
    assert "\n" not in str(ei.value)


def test_cli_run_measure(tmp_path):
    """``shaketable run SCENARIO --measure``: the simulated run and its measured twin;
    a bad sensor model is exit 2 with nothing written."""
    from sim.cli import main

    rc = main(["run", "ucsd_t8", "--duration", "0.25", "--out", str(tmp_path), "--measure", "--json"])
    assert rc == 0
    sim_run = read_run(tmp_path / "ucsd_t8.run.npz")
    meas = read_run(tmp_path / "ucsd_t8.measured.run.npz")
    assert meas.source == "measured" and meas.n_samples == sim_run.n_samples
    assert json.loads((tmp_path / "summary.json").read_text())["measured_run_file"].endswith(".measured.run.npz")
    chain = json.loads((tmp_path / f"ucsd_t8.measured{M.CHAIN_SUFFIX}").read_text())  # the chain, beside the run
    assert chain["model_file"] == str(M.DEFAULT_SENSORS) and "measurement" not in meas.meta
    noise = meas.pressure_a - sim_run.pressure_a
    assert 1e3 < np.std(noise) < 2e4  # 5 kPa RMS noise (through nothing else of size)
    bad = tmp_path / "bad.toml"
    bad.write_text("[recorder]\nrate_hz = 1000.0\n")
    rc = main(["run", "ucsd_t8", "--duration", "0.25", "--out", str(tmp_path / "o2"), "--measure", str(bad)])
    assert rc == 2 and not (tmp_path / "o2").exists()

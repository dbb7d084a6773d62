"""A synthetic lab export for the worked example (docs/lab-example-noise.md).

The project plays the lab: the example table (``scenarios/tables/lab.toml``, written by
``shaketable table new`` from ``lab_table.toml``) with the 2-storey frame runs the white
noise test closed loop, with two things the lab's description does not declare:

* bearing friction on the platen (a ``platen_coulomb`` effect, ``FRICTION_N``), and
* a servovalve null bias of ``BIAS`` of the rated opening (the real valve passes flow at
  zero drive; the controller's recorded drive settles at ``-BIAS`` to hold the table).

Its recorder samples at ``rate_hz`` (204.8 Hz by default: every fifth controller tick;
at any other rate every channel is interpolated between the ticks, the drive as the
smooth output of the DAC's reconstruction filter) and writes a CSV in
lab units through ``lab_map.toml`` (volts, mm, mm/s^2, bar; timestamps rounded to
1e-5 s; a seeded accelerometer noise). Run from the repository root:

    python scenarios/lab_example/make_export.py --out out/lab_example [--duration 20] [--rate 204.8]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tomllib
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
if str(ROOT) not in sys.path:  # run as a script from anywhere
    sys.path.insert(0, str(ROOT))

FRICTION_N = 400.0  #: the undeclared bearing friction, N (example's choice: ~5 % of the peak actuator force)
BIAS = 0.01  #: the planted valve null bias, fraction of rated opening (1 %)
ACC_NOISE_M_S2 = 0.005  #: accelerometer noise RMS, m/s^2 (example's choice)
SEED = 14  #: seed of the accelerometer noise
#: The model's recorder takes the actuator force at t_k but the acceleration of the physics
#: step leaving t_k, which the force at t_k + h produced; the run file says by how much in
#: ``meta.force_lag_s`` (docs/run-file.md). A lab's recorder samples force and motion at one
#: instant, so the export reads the force that much later. Measured on the bare-table test
#: (docs/lab-example-noise.md, "The 9 % friction gap"): the model's own 1024 Hz force regressed on
#: [sign v, v, a] gives 388 N, 557 N s/m, 1198 kg as recorded and 393 N, 51 N s/m, 1200 kg
#: shifted by the lag: 0.49 ms reads as a drag M w^2 dt on this white noise, which sign(v)
#: partly absorbs (+36 N).


def truth_table(folder: Path) -> Path:
    """The lab table as it really is: its description plus the undeclared friction."""
    text = (ROOT / "scenarios" / "tables" / "lab.toml").read_text()
    text += (
        "\n# The worked example's truth: bearing friction the lab's description does not declare.\n"
        '[[effect]]\ntype = "platen_coulomb"\ndof = "x"\n'
        f"force_n = {FRICTION_N!r}   # assumed: the example's undeclared effect\n"
    )
    tomllib.loads(text)
    p = folder / "lab_truth.toml"
    p.write_text(text)
    return p


SECOND_SEED = 8  #: the noise seed of the second specimen test (held out by the calibration)


def simulate(folder: Path, duration_s: float, *, bare: bool = False, noise_seed: int | None = None):
    """Closed-loop run of the example test on the truth table (1024 Hz RunFile, model);
    ``bare``: the same test without the specimen (a lab's shake-down of the bare table);
    ``noise_seed``: another white noise than the scenario's (a second test)."""
    from sim.assess.run import plan_scenario
    from sim.scenario.files import load_scenario

    src = HERE / "lab_noise.toml"
    if noise_seed is not None:
        text = src.read_text()
        assert "\nseed = 7 " in text
        src = folder / f"lab_noise_seed{noise_seed}.toml"
        src.write_text(text.replace("\nseed = 7 ", f"\nseed = {int(noise_seed)} "))
    sc = load_scenario(src)
    sc = dataclasses.replace(sc, table=str(truth_table(folder)), **({"payload": None} if bare else {}))
    out = plan_scenario(sc, duration_s=duration_s).run()
    return out.run, out.tm


def lab_record(run, *, rate_hz: float = 204.8, bias: float = BIAS, seed: int = SEED, bare: bool = False):
    """What the lab's recorder holds: a uni-axial RunFile at ``rate_hz`` (DOF x, actuator
    A, floor accelerometers F1/F2, force from the differential pressure), the drive
    biased by ``-bias``."""
    from sim.runs.runfile import FORMAT, RunFile
    from sim.signals.resample import interpolate

    t = np.asarray(run.t, float)
    fs0 = run.sample_rate_hz
    x = run.dofs.index("x")
    acc_t = run.table_acceleration[:, x]
    # floor drifts relative to the platen (none on the bare table: the floor channels read the platen)
    drift = np.zeros((len(t), 2)) if bare else np.asarray(run.extras["payload_qpos"], float)
    floors = acc_t[:, None] + np.gradient(np.gradient(drift, 1 / fs0, axis=0), 1 / fs0, axis=0)
    n = int(np.floor(t[-1] * rate_hz + 1e-9)) + 1
    tr = np.arange(n) / rate_hz
    rng = np.random.default_rng(seed)
    meas = lambda a: interpolate(t, a, tr)
    meta = {
        "format": FORMAT,
        "table": "lab",
        "sample_rate_hz": rate_hz,
        "actuators": ["A"],
        "dofs": ["x"],
        "source": "measured",
        "description": "synthetic lab export (worked example)",
        "payload": None if bare else "lab_2storey",
        "accelerometers": [
            {"name": "F1", "position": [0.0, 0.0, 0.8], "direction": [1.0, 0.0, 0.0]},
            {"name": "F2", "position": [0.0, 0.0, 1.6], "direction": [1.0, 0.0, 0.0]},
        ],
    }
    return RunFile(
        t=tr,
        meta=meta,
        # the drive the controller put out, as the recorder's input saw it: the DAC's staircase
        # after its reconstruction filter (assumed smooth: interpolated between the ticks; at
        # 204.8 Hz every sample is a tick's own value)
        valve_command=interpolate(t, run.valve_command, tr) - bias,
        reference=interpolate(t, run.reference[:, [x]], tr),
        table_displacement=meas(run.table_displacement[:, [x]]),
        table_acceleration=meas(acc_t[:, None]) + ACC_NOISE_M_S2 * rng.standard_normal((n, 1)),
        accelerometers=meas(floors) + ACC_NOISE_M_S2 * rng.standard_normal((n, 2)),
        # the force at the motion's instant (meta.force_lag_s: see above)
        actuator_force=interpolate(t, run.actuator_force, tr + float(run.meta.get("force_lag_s") or 0.0)),
    )


def make_export(
    out, *, duration_s: float = 20.0, rates=(204.8,), bias: float = BIAS, bare: bool = True, second: bool = True
) -> dict:
    """Simulate once, write ``export_<rate>hz.csv`` per rate into ``out`` (with ``bare``,
    ``bare_<rate>hz.csv``: the same test on the bare table; with ``second``,
    ``second_<rate>hz.csv``: a second specimen test, another noise seed, that calibration
    holds out) and ``truth.json`` (what was planted); returns {name: csv path}."""
    import json

    from sim.runs.files import out_dir
    from sim.runs.importer import export_csv

    folder = out_dir(out)
    paths = {}
    kinds = ("export",) + (("bare",) if bare else ()) + (("second",) if second else ())
    for kind in kinds:
        run, _ = simulate(folder, duration_s, bare=kind == "bare", noise_seed=SECOND_SEED if kind == "second" else None)
        for r in rates:
            rec = lab_record(run, rate_hz=r, bias=bias, bare=kind == "bare")
            name = f"{kind}_{r:g}hz".replace(".", "p")  # export_204p8hz
            mp = HERE / ("lab_map_bare.toml" if kind == "bare" else "lab_map.toml")
            paths[name] = export_csv(rec, mp, folder / f"{name}.csv")
    (folder / "truth.json").write_text(
        json.dumps(
            {
                "valve_null_bias": bias,
                "bearing_friction_n": FRICTION_N,
                "accelerometer_noise_m_s2": ACC_NOISE_M_S2,
                "seed": SEED,
                "second_test_noise_seed": SECOND_SEED if second else None,
                "duration_s": duration_s,
            },
            indent=2,
        )
    )
    return paths


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--out", default="out/lab_example")
    p.add_argument("--duration", type=float, default=20.0)
    p.add_argument("--rate", type=float, action="append", help="recorder rate(s) in Hz (default 204.8)")
    p.add_argument("--no-bare", action="store_true", help="skip the bare-table test")
    p.add_argument("--no-second", action="store_true", help="skip the second specimen test (the held-out one)")
    a = p.parse_args(argv)
    for name, path in make_export(
        a.out, duration_s=a.duration, rates=tuple(a.rate or (204.8,)), bare=not a.no_bare, second=not a.no_second
    ).items():
        print(f"{name} -> {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

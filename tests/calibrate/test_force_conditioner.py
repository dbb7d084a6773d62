"""A load cell's declared analog conditioner on the mechanical path (issue #23 item 4).

The recorded force went through the load cells' conditioner; a record declares it
(``meta.channel_conditioning.actuator_force``: a map's ``lowpass_hz`` on the force column,
a sensor file's ``declared = true``). The force balance puts every force of the model
through it too (:func:`sim.calibrate.conditioning.force_chain_of`). Until the seventeenth
session it was left out: a NEES-UCSD record with a declared 50 Hz, 4-pole load-cell
conditioner read as a force 8.4 ms late (the conditioner's low-frequency delay), and the
pooled held-out error of a clean calibration stayed at 22.8 % (1.02 % with it)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sim.calibrate.residuals import mechanical_runs, nrmse_runs

ROOT = Path(__file__).resolve().parents[2]
UCSD = ROOT / "scenarios" / "tables" / "ucsd.toml"
#: the built-in recorder's rate and a load cell behind a 50 Hz, 4-pole conditioner the lab
#: states (no noise: what is compared is the balance's timing alone)
SENSORS = """[recorder]
rate_hz = 1024.0
[channel.actuator_force]
lowpass_hz = 50.0
lowpass_order = 4
declared = true
"""


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A 6 s NEES-UCSD white-noise run (1-15 Hz) measured through the conditioned load cell."""
    from sim.cli import main
    from sim.runs.runfile import read_run

    folder = tmp_path_factory.mktemp("force_conditioner")
    (folder / "sensors.toml").write_text(SENSORS)
    (folder / "wn.toml").write_text(
        '[scenario]\nname = "wn"\ntable = "ucsd"\nduration_s = 6.0\n'
        '[motion.x]\ntype = "white_noise"\nband_hz = [1.0, 15.0]\nseed = 11\nrms_acceleration = 2.0\ntaper_s = 1.0\n'
    )
    argv = ["run", str(folder / "wn.toml"), "--out", str(folder), "--measure", str(folder / "sensors.toml")]
    assert main(argv + ["--measure-seed", "1"]) == 0
    return read_run(folder / "wn.measured.run.npz")


def _declared_error(run) -> float:
    import mjcf

    mruns = mechanical_runs([run], mjcf.load_table(str(UCSD)))
    return nrmse_runs(mruns, [mr.residual for mr in mruns])


def test_the_record_declares_its_load_cells_conditioner(recorded):
    cond = recorded.meta["channel_conditioning"]["actuator_force"]
    assert cond["lowpass_hz"] == 50.0 and cond["lowpass_order"] == 4


def test_the_declared_model_balances_a_force_through_its_declared_conditioner(recorded):
    """The declared (true) model's force balance: measured 0.16 % with the conditioner
    applied to the model's forces, 50.2 % with the record's declaration removed."""
    import copy

    on = _declared_error(recorded)
    bare = copy.deepcopy(recorded)
    del bare.meta["channel_conditioning"]["actuator_force"]
    off = _declared_error(bare)
    assert on < 0.01, on
    assert off > 10 * on, (on, off)


def test_a_declared_load_cell_conditioner_is_its_butterworth():
    """The chain is the declared cut-off and order at the record's rate; none without a
    low-pass, and a cut-off too near the Nyquist frequency to filter counts as its delay."""
    from types import SimpleNamespace

    from sim.calibrate.conditioning import declared_state, force_chain_of

    def run(spec, dt=1 / 1024):
        return SimpleNamespace(name="r", meta={"channel_conditioning": {"actuator_force": spec}}, dt=dt)

    ch = force_chain_of(run({"delay_s": 0.0, "lowpass_hz": 50.0, "lowpass_order": 4}))
    x = np.zeros((2048, 1))
    x[100:] = 1.0
    y = ch(x)[:, 0]
    assert abs(y[-1] - 1.0) < 1e-6 and y[100] < 0.01  # unit gain at DC, causal and smooth
    assert force_chain_of(run({"delay_s": 0.002, "lowpass_hz": None, "lowpass_order": 0})) is None
    near = run({"delay_s": 0.0, "lowpass_hz": 100.0, "lowpass_order": 4}, dt=1 / 204.8)
    assert force_chain_of(near) is None
    assert declared_state(near, None)["force_delay_s"] == pytest.approx(2.6131 / (2 * np.pi * 100.0), rel=1e-4)

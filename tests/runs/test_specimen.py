"""The specimen sensors computed twice on purpose: the loop records each floor's
accelerometer exactly from the frame's springs and dampers (``sim.loop.specimen``,
a = -(K q + C qdot) / m), and ``sim.runs.specimen`` places a record's sensors (any
height, any direction) on the floors after a run from the recorded platen acceleration
and floor drifts (second central differences). Both place the floors with the same
``floor_heights`` (``sim.loop.specimen``); here they must agree within the
differentiation's truncation error."""

from __future__ import annotations

import numpy as np

FS = 1024.0


def test_the_record_side_floor_readings_match_the_loops_exact_ones():
    """On the lab table with its 2-storey frame under 0.5-20 Hz white noise the readings
    of ``specimen_accelerations`` at the floors' heights along the frame equal the loop's
    ``specimen_acceleration`` within 1 % RMS: np.gradient twice is the central second
    difference over 2h, error (2 omega h)^2 / 12 of the signal at omega, 0.5 % at 20 Hz
    and 1024 Hz; the lab frame's modes (below 20 Hz) carry most of it."""
    from mjcf import load_payload, load_table
    from sim.effects import build_model
    from sim.loop.simulation import Simulation
    from sim.loop.specimen import floor_heights, specimen_sensors
    from sim.runs.specimen import specimen_accelerations
    from sim.scenario import motions as MO
    from sim.scenario.reference import reference_from_motions

    pay = load_payload("lab_2storey")
    tm = build_model(load_table("lab"), pay)
    mo = MO.white_noise(duration_s=4.0, sample_rate_hz=FS, band_hz=(0.5, 20.0), seed=(2, 0), rms_acceleration=1.0)
    res = Simulation(tm).run(reference=reference_from_motions({"x": mo}, FS, 4.0))
    sensors = specimen_sensors(tm).meta
    assert [s["height_m"] for s in sensors] == floor_heights(pay) == [0.8, 1.6]
    exact = res.channels["specimen_acceleration"]
    placed, notes = specimen_accelerations(
        res.t, res.channels["table_acceleration"], res.extras["payload_qpos"], pay, sensors
    )
    assert notes == []
    keep = slice(4, -4)  # np.gradient is one-sided (first order) at the ends
    rms = np.sqrt(np.mean(exact[keep] ** 2, axis=0))
    err = np.sqrt(np.mean((placed[keep] - exact[keep]) ** 2, axis=0))
    assert np.all(rms > 0.5)  # the floors move
    assert np.all(err < 0.01 * rms), err / rms

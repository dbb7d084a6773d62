"""Records the calibration tests make: band-limited white noise along x, closed loop on a
model, as a run file (the tests then measure it through a recorder model of their own)."""

from __future__ import annotations


def noise_run(tm, seed, seconds: float, *, fs: float = 1024.0, band_hz=(1.0, 30.0), rms: float = 1.5):
    """The closed-loop run of white noise (``band_hz``, ``rms`` m/s^2, ``seed``) along x on
    ``tm``: ``(loop result, run file)``."""
    from sim.loop.simulation import Simulation
    from sim.runs.build import build_runfile
    from sim.scenario import motions as M
    from sim.scenario.reference import reference_from_motions

    mo = M.white_noise(duration_s=seconds, sample_rate_hz=fs, band_hz=band_hz, seed=seed, rms_acceleration=rms)
    ref = reference_from_motions({"x": mo}, fs, seconds)
    res = Simulation(tm).run(reference=ref)
    assert res.incomplete_reason is None
    return res, build_runfile(res, tm, reference=ref)

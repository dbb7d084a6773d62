"""The CGS static supports' air springs (issue #23): the true table a copy of ``cgs`` with
its air chambers half as large (``[supports] chamber_volume_m3 = 0.2``, declared 0.4:
each support twice as stiff, n F0 A / V), a changed description number, not an
``[[effect]]``. Runs closed loop through the recorder model (the table's 300 Hz
conditioner, noise, quantisation), the records carrying the table's name only.

What the change does to the force balance: the four supports stand under the platen at
(+/-1.5, +/-1.5) m, pinned to it by shoes that slide in x and y, so each adds
``dk q_i`` along its vertical stroke and nothing horizontally; the preloads that carry the
dead weight are solved from the static balance and do not depend on the chamber volume.
In DOF space that is a spring of 4 dk in z and 4 dk (1.5 m)^2 about x and y. Under the
3-axis 1-30 Hz noise of the other CGS tests the controller holds the rotations to
~2e-5 rad: the change is a z force of ~1 % of the recorded one and nothing else
(:func:`test_the_change_on_three_axis_noise_is_a_vertical_force_below_the_margin`). A
vertical 0.5-10 Hz test (8-12 mm RMS of stroke) makes it 8-12 % of the z force, and the existing ``spring`` candidate at a vertical place finds it
(:func:`test_stiffer_supports_found_as_a_vertical_spring_on_a_low_frequency_test`).
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

from mjcf.description import DOFS6
from sim.calibrate import search as S

DECLARED_M3 = 0.4  #: scenarios/tables/cgs.toml [supports] chamber_volume_m3
TRUE_M3 = 0.2  #: half as large: twice as stiff
#: a vertical test that moves the platen 8-12 mm RMS: band-limited noise, m/s^2 RMS
VERTICAL = {"axes": {"z": 0.8}, "band_hz": (0.5, 10.0), "seconds": 4.0}
THREE_AXIS = {"axes": {"x": 1.0, "y": 1.0, "z": 0.8}, "band_hz": (1.0, 30.0), "seconds": 3.0}


def _cgs_with_chambers(volume_m3: float):
    """The cgs description with its supports' chamber volume set (re-parsed and checked)."""
    import mjcf
    from mjcf.description import parse_table

    base = mjcf.load_table("cgs")
    raw = copy.deepcopy(base.raw)
    raw["supports"]["chamber_volume_m3"] = volume_m3
    return parse_table(raw, src=base.source)


def _runs(out, volume_m3, test, seeds=(3, 4, 5)):
    """Closed-loop noise runs of ``test`` on cgs with ``volume_m3`` chambers, through the
    recorder model (seeded), as run files in ``out``; their paths."""
    from sim.effects import build_model
    from sim.loop.simulation import Simulation
    from sim.runs.build import build_runfile
    from sim.runs.measure import load_sensors, measure_run
    from sim.runs.runfile import write_run
    from sim.scenario import motions as M
    from sim.scenario.reference import reference_from_motions

    tm = build_model(_cgs_with_chambers(volume_m3))
    secs, sensors, paths = test["seconds"], load_sensors(), []
    for seed in seeds:
        mo = {
            d: M.white_noise(
                duration_s=secs,
                sample_rate_hz=1024.0,
                band_hz=test["band_hz"],
                seed=(seed, DOFS6.index(d)),  # each axis its own signal, as in the other CGS tests
                rms_acceleration=a,
            )
            for d, a in test["axes"].items()
        }
        ref = reference_from_motions(mo, 1024.0, secs)
        res = Simulation(tm).run(reference=ref)
        assert res.incomplete_reason is None
        run = build_runfile(res, tm, source="simulated", reference=ref)
        # a recorder writes the table's name, not the true description
        run.meta.pop("table_description", None)
        run.meta.pop("table_sha256", None)
        paths.append(str(write_run(out / f"cgs_{seed}.run.npz", measure_run(run, sensors, seed=seed))))
    return paths


def _support_stiffness_change(declared, true):
    """(6,) N/m, N m/rad: the supports' added stiffness along x, y, z, rx, ry, rz (the
    joint springs projected on the platen's DOFs, as the mechanical path sees them)."""
    from sim.calibrate.residuals import joint_terms
    from sim.effects import build_model

    j0, j1 = (joint_terms(build_model(d), list(range(6))) for d in (declared, true))
    return ((j1.K - j0.K)[:, None] * j0.T**2).sum(axis=0)


def test_the_change_on_three_axis_noise_is_a_vertical_force_below_the_margin(tmp_path):
    """One 3 s run of the 3-axis noise: the supports' added force is ~1 % of the recorded
    z force and nothing about x and y (rotations held still); the negative inertia about
    x and y the mechanical path offers is the recorder's (it explains the same share of
    the residual under the TRUE model: the rotations' accelerations, from accelerometers
    5.6 m apart, are noise several times their signal); and replaying the record with the
    true description lowers its error by less than the acceptance margin, so no candidate
    for the change can be accepted on these records."""
    from sim.calibrate import paths as P
    from sim.calibrate.acceptance import HOLDOUT_MARGIN
    from sim.calibrate.residuals import joint_terms, mechanical_runs
    from sim.effects import build_model
    from sim.runs.runfile import read_run

    declared, true = _cgs_with_chambers(DECLARED_M3), _cgs_with_chambers(TRUE_M3)
    dk = _support_stiffness_change(declared, true)
    assert dk[3] == pytest.approx(dk[4]) and dk[3] == pytest.approx(1.5**2 * dk[2], rel=1e-3), dk
    assert np.all(np.abs(dk[[0, 1, 5]]) < 1e-6 * dk[2]), dk
    (path,) = _runs(tmp_path, TRUE_M3, THREE_AXIS, seeds=(3,))
    run = read_run(path)
    (mr,) = mechanical_runs([run], declared)
    rows = mr.rows
    j0, j1 = (joint_terms(build_model(d), list(range(6))) for d in (declared, true))
    added = mr.demean(mr.filt(j1.force(mr.u, mr.v, mr.dt) - j0.force(mr.u, mr.v, mr.dt)))[rows]
    force = mr.demean(mr.force)[rows]
    share = np.sqrt(np.mean(added**2, axis=0) / np.mean(force**2, axis=0))
    assert 0.005 < share[2] < 0.02, share  # measured 1.1 % in z
    assert np.all(share[3:5] < 1e-3), share  # 16 N m of 33 kN m about x and y
    (mt,) = mechanical_runs([run], true)
    res, acc = mr.demean(mt.force - mt.model)[rows], mr.demean(mt.a)[rows]
    for k in (3, 4):
        inertia = acc[:, k] @ res[:, k] / (acc[:, k] @ acc[:, k])
        explained = 1 - np.sum((res[:, k] - inertia * acc[:, k]) ** 2) / np.sum(res[:, k] ** 2)
        assert inertia < 0 and explained > 0.5, (k, inertia, explained)  # measured -2.3e5 kg m^2, 79-81 %
    err = {}
    for name, d in (("declared", declared), ("true", true)):
        (pr,) = P.path_runs([run], d, "replay")
        err[name] = P.nrmse([pr], [P.simulate_job(pr.job(d.raw, str(d.source), None, []))])
    assert 0 < err["declared"] - err["true"] < HOLDOUT_MARGIN * err["declared"], err  # measured 0.6 %


def _equivalent(where: str, dk_z: float, declared) -> float:
    """The stiffness a vertical spring at ``where`` needs to carry the supports' added
    ``dk_z`` (the rotations held still: every vertical stroke is the platen's z)."""
    if where.startswith("class:"):
        return dk_z / sum(a.cls.name == where[6:] for a in declared.actuators)
    return dk_z


@pytest.mark.slow
def test_stiffer_supports_found_as_a_vertical_spring_on_a_low_frequency_test(tmp_path):
    """3 x 4 s of vertical 0.5-10 Hz noise (8-12 mm RMS of stroke), the whole library, no path
    named: the mechanical path adds one ``spring`` with the supports' added z stiffness
    (4 dk = 5.54e5 N/m) inside its interval, and its held-out error falls by the margin.
    Which vertical place is not told by the mechanical path (the rotations stay still:
    dof:z, one vertical actuator or the class explain 82.72 % each); the replay tells them
    apart (a spring at one corner tilts the platen there) and places it along z or at the
    class; then the replay adds nothing (measured: 0.0968 declared, 0.0522 with the spring
    at dof:z, at its load cells' noise; 0.127 at actuator:Z1, where the ninth session's
    code left it, and two horizontal valve nulls taken as compensations). The library has
    no candidate placed at the supports (docs/calibration.md, Limits)."""
    declared = _cgs_with_chambers(DECLARED_M3)
    dk_z = _support_stiffness_change(declared, _cgs_with_chambers(TRUE_M3))[2]
    res = S.calibrate(_runs(tmp_path, TRUE_M3, VERTICAL), workers=2)
    assert [e["name"] for e in res.effects_added] == ["spring"], res.effects_added
    e = res.effects_added[0]
    assert e["path"] == "mechanical" and e["where"] in ("dof:z", "class:vertical"), e
    assert e["placed_on"] == "replay", e
    k, u95 = e["parameters"]["stiffness_n_m"], e["uncertainty"]["stiffness_n_m"]
    assert abs(k - _equivalent(e["where"], dk_z, declared)) <= u95, (k, u95, dk_z)  # inside its 95 %: 0.57 of it
    mech, replay = res.paths["mechanical"], res.paths["replay"]
    assert mech["error_after"] < (1 - S.HOLDOUT_MARGIN) * mech["error_before"], mech
    assert replay["error_after"] < 0.6 * replay["error_before_declared"], replay  # measured 0.0522 / 0.0968


@pytest.mark.slow
def test_clean_vertical_runs_add_nothing(tmp_path):
    """The same vertical test on the declared chambers: nothing added on either path (the
    polytropic law's departure from its linear spring, which the mechanical path leaves
    out, is F0 n (n + 1) / 2 (A q / V)^2: 8-17 N per
    support of 140 kN at 8-12 mm RMS)."""
    res = S.calibrate(_runs(tmp_path, DECLARED_M3, VERTICAL), workers=2)
    assert res.effects_added == []
    assert res.error_after == res.error_before

"""The replay path's valve null estimate on an over-actuated table (issue #13).

CGS has 12 actuators for 6 DOF: the actuators cannot move apart, so the stroke-velocity
directions outside the kinematic Jacobian's range carry no motion, only the actuator
transducers' noise. That noise (the differentiated displacement's end-point noise over the
record) entered each actuator's null estimate and, replayed open loop, drove an internal
force of up to ~1.3 kN on clean runs. Projected onto the table's motions, the estimate's
internal part is what the recorded commands held there, and the clean replay's mean force
residual is at the load cells' noise."""

from __future__ import annotations

import numpy as np
import pytest

from tests.calibrate.test_calibrate_paths import _cgs_measured


@pytest.fixture(scope="module")
def clean_run(tmp_path_factory):
    from sim.runs.runfile import read_run

    (p,) = _cgs_measured(tmp_path_factory.mktemp("vnull"), seeds=(5,))
    return read_run(p)


def test_internal_basis_of_cgs_and_of_a_single_actuator():
    import mjcf
    from sim.calibrate.valve_null import internal_basis
    from sim.control.tvc import dof_jacobian

    desc = mjcf.load_table("cgs")
    N, J = internal_basis(desc), dof_jacobian(desc)
    assert N.shape == (12, 6)
    assert np.allclose(N.T @ N, np.eye(6), atol=1e-9)
    assert np.abs(N.T @ J).max() < 1e-6 * np.abs(J).max()  # J^T f = 0: an internal force moves nothing
    assert internal_basis(mjcf.load_table("lab")).shape[1] == 0


def test_the_null_estimate_sees_no_transducer_noise_in_the_internal_directions(clean_run):
    """The estimate's internal part (as stroke velocity) is minus the recorded command's
    (the closed loop held the internal force still): before the projection the transducer
    noise put 1-18 um/s there on this run."""
    import mjcf
    from sim.calibrate.valve_null import estimate, internal_basis, stroke_velocity

    desc = mjcf.load_table("cgs")
    N = internal_basis(desc)
    v, what = stroke_velocity(clean_run, desc)
    assert "projected" in what and np.abs(v @ N).max() < 1e-12
    est = estimate(clean_run, desc, drift=False)
    held = N.T @ (est.gain * -np.mean(clean_run.valve_command, axis=0))
    assert np.abs(N.T @ (est.gain * est.offset) - held).max() < 0.5e-6  # m/s


def test_clean_replay_holds_no_internal_force(clean_run):
    """Every load cell's mean replay residual within 0.1 kN (X1 and X3 were -1.32 and
    -1.22 kN on this run before the projection; the cells' noise is 1 kN RMS, 18 N on the
    mean of 3 s)."""
    import mjcf
    from sim.calibrate import paths as P

    desc = mjcf.load_table("cgs")
    (pr,) = P.path_runs([clean_run], desc, "replay")
    m = P.simulate_job(pr.job(desc.raw, str(desc.source), None, []))
    mean = np.mean(pr.recorded["actuator_force"] - m["actuator_force"], axis=0)
    assert np.abs(mean).max() < 100.0, mean
    assert P.nrmse([pr], [m]) < 0.05  # 0.0560 before, 0.0477 after (the noise floor of this run)


def test_the_internal_part_of_a_load_cell_offset():
    """sensitivity.internal_force_part: a projector of rank 6 on CGS whose forces exert no
    wrench on the platen; a horizontal cell's offset is 62.5 % internal (of its square), a
    vertical one's 25 %; nothing on a table without redundancy."""
    import mjcf
    from sim.calibrate.sensitivity import internal_force_part
    from sim.control.tvc import dof_jacobian

    desc = mjcf.load_table("cgs")
    P, J = internal_force_part(desc), dof_jacobian(desc)
    assert np.allclose(P @ P, P, atol=1e-12) and np.allclose(P, P.T)
    assert np.trace(P) == pytest.approx(6.0)
    assert np.abs(J.T @ P).max() < 1e-6 * np.abs(J).max()
    assert np.diag(P)[:8] == pytest.approx([0.625] * 8, abs=1e-9)
    assert np.diag(P)[8:] == pytest.approx([0.25] * 4, abs=1e-9)
    assert not internal_force_part(mjcf.load_table("lab")).any()


def test_a_valve_the_test_left_still_is_divided_by_its_declared_gain(tmp_path):
    """A vertical test (4 s of 0.5-10 Hz noise, z only) leaves the eight horizontal valves
    at commands of ~2e-4: their gain read off the record was noise (0.005 +/- 1.2 m/s for
    1.7), and the null it gave (up to 9.4e-3 of rated opening), replayed open loop, pushed
    an internal force into the vertical load cells (their replay error 0.15-0.33 against a
    0.07 floor). Those valves now take the declared gain; the vertical ones, which the test
    moved, keep theirs (1.078 under the dead weight, 1.086 declared)."""
    import mjcf
    from sim.calibrate import paths as P
    from sim.calibrate.valve_null import declared_velocity_gain, estimate
    from sim.runs.runfile import read_run
    from tests.calibrate.test_cgs_supports import DECLARED_M3, VERTICAL, _runs

    desc = mjcf.load_table("cgs")
    (path,) = _runs(tmp_path, DECLARED_M3, VERTICAL, seeds=(4,))
    run = read_run(path)
    est, k0 = estimate(run, desc, drift=False), declared_velocity_gain(desc)
    still = [i for i, a in enumerate(run.actuators) if not a.startswith("Z")]
    assert np.array_equal(est.gain[still], k0[still])
    assert np.abs(est.offset[still]).max() < 1e-4, est.offset  # measured 9.4e-3 before
    moved = [i for i, a in enumerate(run.actuators) if a.startswith("Z")]
    assert np.all(np.abs(est.gain[moved] / k0[moved] - 1) < 0.02), est.gain
    assert np.all(est.gain[moved] != k0[moved])  # read off the record
    (pr,) = P.path_runs([run], desc, "replay")
    model = P.simulate_job(pr.job(desc.raw, str(desc.source), None, []))
    err, floor = P.column_errors(pr, model), P.column_floors(pr)
    forces = [k for k in err if k.startswith("actuator_force")]
    assert len(forces) == 4, err
    assert all(err[k] < 1.1 * floor[k] for k in forces), (err, floor)  # measured 1.02 (0.0735 / 0.0723)

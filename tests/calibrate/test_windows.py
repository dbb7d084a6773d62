"""Windows chosen by the excitation they hold, and columns left out when a test does not
excite them (sim.calibrate.windows): a record's first seconds may be its quiet lead-in
(a real earthquake record sits still for seconds), and a DOF a test does not drive holds
noise over nothing."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from sim.calibrate.windows import SETTLE_S, Window, choose, dof_weights, excited, quiet_lead

FS = 256.0


def _burst(t, t_on, t_off, f_hz, rng, noise=0.01):
    """(n, 2) drive and (n, 3) motion: sensor noise, and from ``t_on`` to ``t_off`` a sine
    burst (0.3 s ramp) on the drive and the first motion column (the others stay still)."""
    env = np.clip((t - t_on) / 0.3, 0, 1) * np.clip((t_off - t) / 0.3, 0, 1)
    s = np.sin(2 * np.pi * f_hz * t) * env
    drive = noise * rng.standard_normal((len(t), 2)) + s[:, None] * np.array([1.0, 0.4])
    motion = noise * rng.standard_normal((len(t), 3))
    motion[:, 0] += 3.0 * s
    return drive, motion


def _mean_square(x, a, b):
    return float(np.mean(x[a:b] ** 2))


def test_window_lands_in_the_strong_motion_after_a_quiet_lead_in():
    """3 s of sensor noise, then 4 s of motion: the fixed first second holds nothing, the
    chosen window the motion; it replays from SETTLE_S before the lead-in's end (the model's
    rest state is the record's there) and costs about its own length, not the lead-in."""
    t = np.arange(int(8 * FS)) / FS
    drive, motion = _burst(t, 3.0, 7.0, 2.3, np.random.default_rng(1))
    (w,) = choose([drive, motion], FS, 1.0)
    q = quiet_lead([drive, motion], FS)
    assert q / FS == pytest.approx(3.0, abs=0.1)
    assert 2.9 <= w.score_from / FS <= 3.4, w  # past the burst's 0.3 s ramp at most
    assert w.stop - w.score_from == int(round(FS)) + 1
    assert w.start == q - int(round(SETTLE_S * FS))
    assert w.replay_s <= 1.0 + SETTLE_S + 0.4
    # what the fixed first second held: sensor noise only (< 0.1 % of the chosen window's)
    fixed, chosen = _mean_square(motion[:, 0], 0, int(FS)), _mean_square(motion[:, 0], w.score_from, w.stop)
    assert fixed < 1e-3 * chosen, (fixed, chosen)


def test_a_record_moving_from_its_start_keeps_its_first_window():
    """Stationary motion from the first sample: the earliest strong window is the first
    (the cheapest: nothing replayed before it), as the fixed window was."""
    t = np.arange(int(6 * FS)) / FS
    drive, motion = _burst(t, -1.0, 7.0, 3.1, np.random.default_rng(2))
    (w,) = choose([drive, motion], FS, 1.0)
    assert (w.start, w.score_from) == (0, 0)
    assert choose([drive, motion], FS, None) == [Window(0, 0, len(t), FS)]


def test_a_long_record_is_sampled_by_segments():
    """Two bursts far apart after a quiet lead-in: two segments, one in each, each in its
    burst's strong part, both replayed from the lead-in's end."""
    t = np.arange(int(40 * FS)) / FS
    rng = np.random.default_rng(3)
    d1, m1 = _burst(t, 5.0, 12.0, 2.0, rng)
    d2, m2 = _burst(t, 25.0, 35.0, 6.0, rng, noise=0.0)
    drive, motion = d1 + d2, m1 + m2
    ws = choose([drive, motion], FS, 2.0, segments=2)
    assert len(ws) == 2
    assert 5.0 <= ws[0].score_from / FS <= 11.0 and 24.5 <= ws[1].score_from / FS <= 34.0, ws
    assert all(w.start / FS == pytest.approx(5.0 - SETTLE_S, abs=0.15) for w in ws)
    for w in ws:  # each segment scored over its half of the budget, in strong motion
        assert w.stop - w.score_from == int(round(FS)) + 1
        assert _mean_square(motion[:, 0], w.score_from, w.stop) > 1.0


def test_moments_and_rotations_compared_in_actuator_units():
    """On CGS a moment is weighed as the actuator forces that make it (the lever arms
    shrink it) and a rotation as the strokes it takes (they grow it); a column below
    QUIET_COLUMN of the largest in those units is not excited."""
    import mjcf
    from sim.control.tvc import dof_jacobian

    desc = mjcf.load_table("cgs")
    J6 = dof_jacobian(desc)
    wf, wm = dof_weights(J6, desc.dofs, "force"), dof_weights(J6, desc.dofs, "motion")
    assert np.all(wf[3:] < 0.5 * wf[:3].min()) and np.all(wm[3:] > 2 * wm[:3].max())
    # 70 kN on x, 15 kN m about z: in N it would pass, as actuator forces (lever arms) it does not
    assert list(excited([70e3, 0, 0, 0, 0, 15e3], wf)) == [True] + [False] * 5
    assert list(excited([70e3, 0, 0, 0, 0, 15e3])) == [True, False, False, False, False, True]


# ------------------------------------------------------------------ the mechanical path
@pytest.fixture(scope="module")
def translational_cgs(tmp_path_factory):
    """Two clean 2 s CGS runs, 3-axis translational random (1-30 Hz), closed loop,
    measured through the built-in recorder model (seeded): the controller holds the
    rotations, the moment about the vertical is cross-talk."""
    import mjcf
    from sim.effects import build_model
    from sim.loop.simulation import Simulation
    from sim.runs.build import build_runfile
    from sim.runs.measure import load_sensors, measure_run
    from sim.runs.runfile import read_run, write_run
    from sim.scenario import motions as M
    from sim.scenario.reference import reference_from_motions

    desc = mjcf.load_table("cgs")
    tm = build_model(desc)
    out = tmp_path_factory.mktemp("translational")
    runs, paths = [], []
    for seed in (7, 8):
        mo = {
            d: M.white_noise(
                duration_s=2.0, sample_rate_hz=1024.0, band_hz=(1.0, 30.0), seed=(seed, k), rms_acceleration=r
            )
            for k, (d, r) in enumerate({"x": 1.0, "y": 1.0, "z": 0.8}.items())
        }
        ref = reference_from_motions(mo, 1024.0, 2.0)
        res = Simulation(tm).run(reference=ref)
        assert res.incomplete_reason is None
        run = build_runfile(res, tm, source="simulated", reference=ref)
        paths.append(str(write_run(out / f"cgs_{seed}.run.npz", measure_run(run, load_sensors(), seed=seed))))
        runs.append(read_run(paths[-1]))
    return desc, runs, paths


def test_unexcited_rotation_left_out_of_the_pooled_mechanical_error(translational_cgs):
    """A clean translational CGS case: rz (moment 2 % of the largest force in actuator
    units) is reported as not excited and left out; the pooled error is that of the
    excited DOFs, each weighted by its noise (sim.calibrate.mechnoise). Measured: the
    translations 2.5-3.2 %, the moments about x and y 18-21 %, each within 1.03 of the
    floor its accelerometers' and load cells' noise sets (the floors 2.6-3.1 % and
    18-21 %); weights 1.54-1.66 and 0.11-0.15; pooled 5.2 % (12.8 % with every excited DOF
    alike), where pooling rz in, every DOF alike, gave 90 % (rz: 220 %)."""
    from sim.calibrate import residuals as R
    from sim.calibrate.search import mechanical_errors

    desc, runs, _paths = translational_cgs
    mrs = R.mechanical_runs(runs, desc)  # through the table's 300 Hz conditioner, which the runs declare
    assert all(mr.prefilter is not None and mr.prefilter.cutoff_hz == 300.0 for mr in mrs)
    res = [mr.residual for mr in mrs]
    per, per_run, quiet = mechanical_errors(mrs, res, res)
    assert quiet == [f"cgs_{s}.run.npz:rz" for s in (7, 8)]
    assert not any(k.endswith(":rz") for k in per)
    pooled = R.nrmse_runs(mrs, res)
    excited_errors = [v["before"] for v in per.values()]
    weights = [v["weight"] for v in per.values()]
    assert pooled == pytest.approx(math.sqrt(np.average(np.square(excited_errors), weights=weights)), rel=1e-9)
    assert max(v["before"] for k, v in per.items() if k.split(":")[1] in "xyz") < 0.05
    assert all(v["before"] < 1.1 * v["floor"] for v in per.values()), per  # a clean run sits at its noise
    rot = [w for k, w in zip(per, weights) if k.split(":")[1].startswith("r")]
    assert max(rot) < 0.2 * min(w for k, w in zip(per, weights) if k.split(":")[1] in "xyz")
    assert pooled < 0.06, pooled
    for mr in mrs:
        mr.excited = None  # rz pooled in: its noise weight (0.0007) keeps it out all the same
    assert R.nrmse_runs(mrs, res) < 1.25 * pooled  # measured 6.2 % (1.17 times)
    for mr in mrs:
        mr.extra["noise_weight"] = np.ones(len(mr.dofs))  # the old normalisation: every DOF alike
    assert R.nrmse_runs(mrs, res) > 4 * pooled


def test_clean_cgs_records_need_no_accelerometer_timing(translational_cgs):
    """The measured runs went through the CGS table's declared accelerometer conditioner
    (``[sensors] accelerometer_bandwidth_hz`` = 300 Hz, 4 poles) and declare it in
    ``meta.channel_conditioning``, as an imported record does: calibrated with the
    defaults on the mechanical path (its sensor-timing candidates only, to keep it short),
    nothing is added.

    Before ``run --measure`` applied the table's conditioner, the mechanical path put the
    model's acceleration through it (the table's, no declaration in the run) and the record
    had none: it "found" the acceleration -1.398 +/- 0.020 ms late (the conditioner's lag,
    1 / (2 pi 300 Hz sin(pi / 8)) = 1.386 ms) and accepted it (held-out 0.248 -> 0.120,
    measured on these runs). Measured with every excited DOF alike: -0.014 +/- 0.019 ms,
    refused; held-out 0.121. Each DOF weighted by its noise (sim.calibrate.mechnoise), the
    moments about x and y at their accelerometers' floor count less and the interval
    shrinks to a third: +6.60 +/- 6.59 us (1.002 of its 95 % half-width), refused; held-out
    0.052. The bound is 1.5 half-widths (3 standard deviations): under 10 us, where the
    old one was 19 us. Not measured here is which of the model's own timing approximations
    leaves a few microseconds (the conditioner discretised by the bilinear transform at
    the record's rate, the force's lag read by a spline). The conditioner's cutoff shows
    the same lag: 297.19 +/- 1.37 Hz, 0.94 % low (296.7 +/- 3.9 alike)."""
    from sim.calibrate import search as S
    from sim.calibrate.timing import TIMING_EFFECTS

    _desc, runs, paths = translational_cgs
    for r in runs:
        assert r.meta["channel_conditioning"]["table_acceleration"] == {
            "delay_s": 0.0,
            "lowpass_hz": 300.0,
            "lowpass_order": 4,
        }
    res = S.calibrate(paths, path="mechanical", effects=list(TIMING_EFFECTS))
    assert res.effects_added == [], res.effects_added
    rows = {(c["name"], c["where"]): c for c in res.candidates}
    acc = rows[("sensor_delay", "channel:table_acceleration")]
    d, u = acc["parameters"]["delay_s"], acc["uncertainty"]["delay_s"]
    assert abs(d) <= 1.5 * u and u < 1e-5, (d, u)  # 0 within 3 standard deviations
    assert abs(d) < 0.01 * 1.386e-3, d  # not the conditioner's lag (0.5 % of it measured)
    lp = rows[("sensor_lowpass", "channel:table_acceleration")]
    # 297.19 +/- 1.37 Hz (296.7 +/- 3.9 alike): 0.94 % low, 2.05 half-widths, the few
    # microseconds of lag the delay shows too; bound at 1 %, 3 Hz, where the old was 3.9
    assert abs(lp["parameters"]["cutoff_hz"] - 300.0) < 0.01 * 300.0, lp
    assert res.error_before < 0.06, res.error_before  # 0.052 measured (0.248 with the conditioner unmatched, alike)


# ------------------------------------------------------------------ the replay path
LEAD_S, STRONG_S = 3.0, 2.0


def _lab_with_quiet_lead(out, seed, effects):
    """A `lab` run (uni-axial) closed loop: LEAD_S s at rest, then STRONG_S s of 1-20 Hz
    random motion, with ``effects`` planted, measured through the built-in recorder model."""
    import mjcf
    from mjcf.description import parse_table
    from sim.effects import build_model
    from sim.loop.simulation import Simulation
    from sim.runs.build import build_runfile
    from sim.runs.measure import load_sensors, measure_run
    from sim.runs.runfile import write_run
    from sim.scenario import motions as M
    from sim.scenario.reference import Reference

    fs = 1024.0
    mo = M.white_noise(
        duration_s=STRONG_S, sample_rate_hz=fs, band_hz=(1.0, 20.0), seed=(seed, 0), rms_acceleration=1.0
    )
    n, k = int(round((LEAD_S + STRONG_S) * fs)) + 1, int(round(LEAD_S * fs))
    D, V, A = (np.zeros((n, 6)) for _ in range(3))
    m = min(n - k, len(mo.d))
    for X, x in ((D, mo.d), (V, mo.v), (A, mo.a)):
        X[k : k + m, 0] = x[:m]
    ref = Reference(t=np.arange(n) / fs, d=D, v=V, a=A)
    base = mjcf.load_table("lab")
    raw = copy.deepcopy(base.raw)
    raw["effect"] = list(raw.get("effect", [])) + [dict(e) for e in effects]
    tm = build_model(parse_table(raw, src=base.source))
    res = Simulation(tm).run(reference=ref)
    assert res.incomplete_reason is None
    run = build_runfile(res, tm, source="simulated", reference=ref)
    return str(write_run(out / f"lab_{seed}.run.npz", measure_run(run, load_sensors(), seed=seed)))


def test_replay_path_finds_a_flow_gain_behind_a_quiet_lead_in(tmp_path):
    """The lab table's valve flow 15 % short, on records that sit still for 3 s: on the
    fixed first second the screening explained nothing and put the flow gain at an absurd
    0.28; on the chosen window it explains 99 % and the search recovers 0.85."""
    import mjcf
    from sim.calibrate import paths as P
    from sim.calibrate import search as S
    from sim.calibrate import sensitivity as SE
    from sim.calibrate.pathsearch import MIN_SCORE, motion_rms
    from sim.runs.runfile import read_run

    plant = [{"type": "valve_flow_gain", "where": "actuator:A", "factor": 0.85}]
    paths = [_lab_with_quiet_lead(tmp_path, seed, plant) for seed in (3, 4)]
    desc = mjcf.load_table("lab")
    raw, src = desc.raw, str(desc.source)
    run = read_run(paths[0])
    (pr,) = P.path_runs([run], desc, "replay")
    fs = 1.0 / pr.dt
    scores = []
    for w in (pr.span(Window(0, 0, int(fs) + 1, fs)), pr.window(1.0)):
        cands = SE.candidates(desc, None, [w], [], motion_rms([run], desc), ["valve_flow_gain"])
        (sc,) = SE.screen(cands, [w], [P.simulate_job(w.job(raw, src, None, []))], (raw, src, None, []), workers=1)
        scores.append(sc.score)
    assert scores[0] < MIN_SCORE < 0.9 < scores[1], scores
    res = S.calibrate(paths, path="replay", effects=["valve_flow_gain", "bulk_modulus"], workers=1)
    assert [(e["name"], e["where"]) for e in res.effects_added] == [("valve_flow_gain", "class:main")]
    e = res.effects_added[0]
    assert abs(e["parameters"]["factor"] - 0.85) < max(e["uncertainty"]["factor"], 0.002), e
    assert res.error_after < 0.5 * res.error_before
    screen = [w for w in res.timing["windows"] if w["stage"] == "screen"]
    assert screen and all(w["scored_from_s"] >= LEAD_S - 0.1 for w in screen), res.timing["windows"]


def test_report_says_where_the_error_sits_and_what_was_not_excited():
    """report.md lists the held-out error per run and per channel / DOF, before and after,
    and the columns left out as not excited; calibration.json carries the same."""
    from sim.calibrate.search import CalibrationResult
    from sim.report.calibration import report_md

    res = CalibrationResult(
        table="cgs",
        table_source="cgs.toml",
        runs=["a.run.npz", "b.run.npz"],
        holdout=["b.run.npz"],
        holdout_note="held out: b.run.npz",
        residual_path="mechanical",
        error_before=0.031,
        error_after=0.022,
        effects_added=[],
        candidates=[],
        unexplained=None,
        per_channel={"b.run.npz:x": {"before": 0.031, "after": 0.022}},
        timing={"total_s": 1.0, "read_s": 0.1, "residuals_s": 0.2, "search_s": 0.7, "least_squares_fits": 3},
        per_run={"b.run.npz": {"before": 0.031, "after": 0.022}},
        not_excited=["b.run.npz:rz"],
    )
    md = report_md(res, [], "cgs_calibrated.toml")
    assert "## Where the error sits" in md
    assert "| `b.run.npz` | 3.10 % | 2.20 % |" in md and "| `b.run.npz:x` | 3.10 % | 2.20 % |" in md
    assert "Not excited" in md and "`b.run.npz:rz`" in md
    js = res.to_json()
    assert js["not_excited"] == ["b.run.npz:rz"] and js["per_run"]["b.run.npz"]["after"] == 0.022

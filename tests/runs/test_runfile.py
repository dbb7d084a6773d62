"""Run files (docs/run-file.md): round trip, every validation error, atomic write, NaN rule."""

import json
import os
import zipfile

import numpy as np
import pytest

from sim.errors import RunFileError, UserError
from sim.runs import runfile
from sim.runs.runfile import CHANNELS, RunFile, read_run, write_run

ACTS = [f"{a}{i}" for a in "XYZ" for i in range(1, 5)]
DOFS = ["x", "y", "z", "rx", "ry", "rz"]
FS = 1024.0


def make_run(n=256, **over):
    rng = np.random.default_rng(0)
    t = np.arange(n) / FS
    meta = {
        "format": "shaketable-run/1",
        "table": "cgs",
        "sample_rate_hz": FS,
        "actuators": list(ACTS),
        "dofs": list(DOFS),
        "source": "simulated",
        "description": "unit test",
        "accelerometers": [{"name": f"A{i}", "position": [0.0, 0.0, 0.0], "direction": "x"} for i in range(3)],
        "specimen_sensors": [{"name": f"F{i}", "height_m": 0.8 * i, "direction": [1.0, 0.0, 0.0]} for i in (1, 2)],
    }
    cols = {"accelerometers": 3, "specimen_acceleration": 2}
    chans = {}
    for c in CHANNELS:
        k = len(ACTS) if c in runfile.ACTUATOR_CHANNELS else cols.get(c, len(DOFS))
        chans[c] = rng.standard_normal((n, k))
    chans.update(over)
    return RunFile(t=t, meta=meta, **chans)


def one_line(exc):
    msg = str(exc.value)
    assert "\n" not in msg and msg
    assert isinstance(exc.value, UserError)
    return msg


def test_round_trip_every_channel(tmp_path):
    run = make_run()
    p = write_run(tmp_path / "a.run.npz", run)
    back = read_run(p, require=CHANNELS)
    np.testing.assert_array_equal(back.t, run.t)
    for c in CHANNELS:
        np.testing.assert_array_equal(back.channel(c), getattr(run, c))
    assert back.meta == run.meta
    assert back.n_samples == 256 and back.sample_rate_hz == FS
    assert back.actuators == ACTS and back.dofs == DOFS
    assert back.source == "simulated" and not back.incomplete
    np.testing.assert_array_equal(back.column("actuator_force", "Z3"), run.actuator_force[:, 10])
    np.testing.assert_array_equal(back.column("reference", "ry"), run.reference[:, 4])
    np.testing.assert_array_equal(back.column("accelerometers", "A2"), run.accelerometers[:, 2])
    np.testing.assert_array_equal(back.column("specimen_acceleration", "F2"), run.specimen_acceleration[:, 1])
    # no temp files left beside it
    assert sorted(os.listdir(tmp_path)) == ["a.run.npz"]


def test_minimal_run_and_missing_channel_message(tmp_path):
    run = make_run()
    for c in CHANNELS:
        if c != "reference":
            setattr(run, c, None)
    back = read_run(write_run(tmp_path / "m.run.npz", run))
    assert back.valve_command is None
    with pytest.raises(RunFileError) as e:
        back.channel("pressure_a")
    msg = one_line(e)
    assert "m.run.npz" in msg and "no channel 'pressure_a'" in msg and "reference" in msg
    with pytest.raises(RunFileError) as e:
        back.column("reference", "q")
    assert "no column 'q'" in one_line(e)
    with pytest.raises(RunFileError) as e:
        read_run(tmp_path / "m.run.npz", require=["table_acceleration"])
    assert "table_acceleration" in one_line(e)


def test_incomplete_flag(tmp_path):
    run = make_run()
    run.mark_incomplete("simulation diverged at t = 0.1 s: actuator X1 past its stroke")
    back = read_run(write_run(tmp_path / "i.run.npz", run))
    assert back.incomplete and "diverged" in back.incomplete_reason
    run.meta.pop("incomplete_reason")
    with pytest.raises(RunFileError) as e:
        write_run(tmp_path / "j.run.npz", run)
    assert "incomplete_reason" in one_line(e)


def test_nan_rule(tmp_path):
    run = make_run()
    run.pressure_a[100, 2] = np.nan  # missing samples are allowed...
    p = write_run(tmp_path / "n.run.npz", run)
    assert np.isnan(read_run(p).pressure_a[100, 2])
    read_run(p, require=["valve_command", "actuator_force"])
    with pytest.raises(RunFileError) as e:  # ...unless the reader needs the channel
        read_run(p, require=["pressure_a"])
    msg = one_line(e)
    assert "'pressure_a'" in msg and "sample 100" in msg and "X3" in msg
    assert f"t = {100 / FS:.6g} s" in msg


def test_atomic_write_failure_leaves_nothing(tmp_path, monkeypatch):
    target = tmp_path / "f.run.npz"

    def boom(*a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez_compressed", boom)
    with pytest.raises(RunFileError) as e:
        write_run(target, make_run())
    assert "No space left" in one_line(e)
    assert os.listdir(tmp_path) == []


def test_atomic_write_keeps_old_file_on_failure(tmp_path, monkeypatch):
    target = tmp_path / "g.run.npz"
    write_run(target, make_run())
    before = target.read_bytes()

    def boom(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(KeyboardInterrupt):
        write_run(target, make_run(n=100))
    assert target.read_bytes() == before
    assert os.listdir(tmp_path) == ["g.run.npz"]


def test_write_errors(tmp_path, monkeypatch):
    with pytest.raises(RunFileError) as e:
        write_run(tmp_path / "a.npz", make_run())
    assert ".run.npz" in one_line(e)
    with pytest.raises(RunFileError) as e:
        write_run(tmp_path / "nope" / "a.run.npz", make_run())
    assert "does not exist" in one_line(e)
    # A folder that refuses the finished file (read-only for this user): the refusal is
    # raised at the rename onto the final name, after the whole file was written beside it
    # (root, as in CI, would not feel a folder's permissions). One line; no file left, not
    # even the temporary one.
    from sim.runs import files

    def refused(src, dst):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(files.os, "replace", refused)
    ro = tmp_path / "ro"
    ro.mkdir()
    with pytest.raises(RunFileError) as e:
        write_run(ro / "a.run.npz", make_run())
    assert "cannot be written (Permission denied)" in one_line(e)
    assert list(ro.iterdir()) == []


def test_unwritable_folder_is_one_line(tmp_path, monkeypatch):
    import tempfile

    def denied(*a, **k):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(tempfile, "mkstemp", denied)
    with pytest.raises(RunFileError) as e:
        write_run(tmp_path / "a.run.npz", make_run())
    msg = one_line(e)
    assert "cannot be written (Permission denied)" in msg and "a.run.npz" in msg


def _save(path, **arrays):
    np.savez_compressed(path, **arrays)
    return path


def _arrays(run, **changes):
    arrays = {"t": run.t, "meta": np.array(json.dumps(run.meta))}
    arrays.update({c: getattr(run, c) for c in CHANNELS if getattr(run, c) is not None})
    arrays.update(changes)
    return {k: v for k, v in arrays.items() if v is not None}


def _meta(**changes):
    m = make_run().meta
    for k, v in changes.items():
        if v is None:
            m.pop(k)
        else:
            m[k] = v
    return np.array(json.dumps(m))


N = 256
BAD_CASES = {
    "no_t": (dict(t=None), "no 't' array"),
    "no_meta": (dict(meta=None), "no 'meta' array"),
    "meta_not_json": (dict(meta=np.array("{format: nope")), "not valid JSON"),
    "meta_not_object": (dict(meta=np.array("[1, 2]")), "not a JSON object"),
    "wrong_format": (dict(meta=_meta(format="shaketable-run/0")), "shaketable-run/0"),
    "missing_keys": (dict(meta=_meta(table=None, source=None)), "table, source"),
    "bad_source": (dict(meta=_meta(source="guessed")), "'guessed'"),
    "bad_rate": (dict(meta=_meta(sample_rate_hz=1000.0)), "sample_rate_hz 1000"),
    "nonuniform_t": (dict(t=np.r_[np.arange(100), np.arange(101, N + 1)] / FS), "non-uniform time step at sample 100"),
    "nonincreasing_t": (
        dict(t=np.r_[np.arange(50), 48, np.arange(51, N)] / FS),
        "not strictly increasing at sample 50",
    ),
    "short_channel": (dict(actuator_force=np.zeros((N - 1, 12))), "'actuator_force' has 255 samples"),
    "wrong_act_columns": (dict(pressure_b=np.zeros((N, 11))), "'pressure_b' has 11 columns but there are 12 actuators"),
    "wrong_dof_columns": (dict(table_velocity=np.zeros((N, 3))), "'table_velocity' has 3 columns but there are 6 DOFs"),
    "wrong_acc_columns": (dict(accelerometers=np.zeros((N, 5))), "'accelerometers' has 5 columns"),
    "wrong_specimen_columns": (
        dict(specimen_acceleration=np.zeros((N, 3))),
        "'specimen_acceleration' has 3 columns but there are 2 sensors in meta specimen_sensors",
    ),
    "one_d_channel": (dict(reference=np.zeros(N)), "'reference' has shape (256,)"),
    "no_input": (dict(reference=None, valve_command=None), "neither valve_command nor reference"),
    "unknown_key": (dict(pressureA=np.zeros((N, 12))), "unknown array(s) pressureA"),
    "dup_actuator": (dict(meta=_meta(actuators=ACTS[:-1] + ["X1"])), "repeats X1"),
}


@pytest.mark.parametrize("case", sorted(BAD_CASES))
def test_read_rejects(tmp_path, case):
    changes, expected = BAD_CASES[case]
    p = _save(tmp_path / f"{case}.run.npz", **_arrays(make_run(), **changes))
    with pytest.raises(RunFileError) as e:
        read_run(p)
    msg = one_line(e)
    assert f"{case}.run.npz" in msg
    assert expected in msg
    assert ";" in msg  # problem; fix


def test_read_rejects_non_archives(tmp_path):
    p = tmp_path / "text.run.npz"
    p.write_text("time,x\n0,0\n")
    with pytest.raises(RunFileError) as e:
        read_run(p)
    assert "not a NumPy .npz archive" in one_line(e)
    p = tmp_path / "arr.run.npz"
    with open(p, "wb") as fh:
        np.save(fh, np.zeros(3))
    with pytest.raises(RunFileError) as e:
        read_run(p)
    assert "not a NumPy .npz archive" in one_line(e)
    with pytest.raises(RunFileError) as e:
        read_run(tmp_path / "missing.run.npz")
    assert "does not exist" in one_line(e)
    p = tmp_path / "broken.run.npz"
    with zipfile.ZipFile(p, "w") as z:
        z.writestr("t.npy", b"garbage")
        z.writestr("meta.npy", b"garbage")
    with pytest.raises(RunFileError) as e:
        read_run(p)
    assert "damaged" in one_line(e)


def test_write_validates_too(tmp_path):
    run = make_run()
    run.table_displacement = run.table_displacement[:, :2]
    with pytest.raises(RunFileError) as e:
        write_run(tmp_path / "v.run.npz", run)
    assert "table_displacement" in one_line(e)
    assert os.listdir(tmp_path) == []


def test_uniaxial_table(tmp_path):
    n = 50
    t = 2.0 + np.arange(n) / 512.0
    meta = {
        "format": "shaketable-run/1",
        "table": "lhpost",
        "sample_rate_hz": 512,
        "actuators": ["E", "W"],
        "dofs": ["x"],
        "source": "measured",
    }
    run = RunFile(t=t, meta=meta, valve_command=np.zeros((n, 2)), table_acceleration=np.ones((n, 1)))
    back = read_run(write_run(tmp_path / "u.run.npz", run), require=["valve_command"])
    assert back.dofs == ["x"] and back.source == "measured"
    np.testing.assert_array_equal(back.column("table_acceleration", "x"), np.ones(n))

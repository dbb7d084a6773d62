"""Rerun recordings (sim/report/rerun.py, ``shaketable view``, ``shaketable run --rrd``).

Run files are made here with the project's own simulator (2 s of harmonic_bare).
"""

from __future__ import annotations

import math
import shutil
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest

from sim import cli
from sim.effects import build_model
from sim.runs.runfile import read_run, write_run

ACTS = [f"{a}{i}" for a in "XYZ" for i in range(1, 5)]
DOFS = ["x", "y", "z", "rx", "ry", "rz"]


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """A 2 s simulated run, recorded by ``shaketable run --rrd``."""
    d = tmp_path_factory.mktemp("rec")
    rc = cli.main(["run", "harmonic_bare", "--out", str(d), "--duration", "2", "--rrd", str(d / "h.rrd")])
    assert rc == 0
    return d, d / "harmonic_bare.run.npz", d / "h.rrd"


def _rerun_exe() -> str | None:
    exe = Path(sys.executable).with_name("rerun")
    return str(exe) if exe.exists() else shutil.which("rerun")


def _read(path):
    """{entity: rows on the time line}, {entity: set of components}, static entities, blueprint count."""
    import rerun as rr

    reader = rr.chunk.RrdReader(str(path))
    rows, comps, static, data = defaultdict(int), defaultdict(set), set(), defaultdict(list)
    for ch in reader.store().stream():
        rb = ch.to_record_batch()
        names = [n for n in rb.schema.names if ":" in n]
        if ch.is_static:
            static.add(ch.entity_path)
            comps[ch.entity_path] |= set(names)
            continue
        assert "time" in rb.schema.names
        rows[ch.entity_path] += ch.num_rows
        comps[ch.entity_path] |= set(names)
        data[ch.entity_path].append(rb)
    return rows, comps, static, data, len(reader.blueprints())


def _column(batches, name):
    """Rows of component ``name`` in time order: (rows,) for one value per row, (rows, k) for k."""
    out, times = [], []
    for rb in batches:
        col = rb.column(rb.schema.get_field_index(name)).to_pylist()
        t = rb.column(rb.schema.get_field_index("time")).to_pylist()
        for v, tt in zip(col, t):
            out.append(v[0] if isinstance(v, list) and len(v) == 1 else v)
            times.append(tt)
    order = np.argsort([x.total_seconds() if hasattr(x, "total_seconds") else x for x in times], kind="stable")
    return np.array(out, dtype=float)[order]


def _times(batches):
    t = [
        x.total_seconds() if hasattr(x, "total_seconds") else x * 1e-9
        for rb in batches
        for x in rb.column(rb.schema.get_field_index("time")).to_pylist()
    ]
    return np.sort(np.array(t))


def _names(path, ent):
    """The series names logged (static) on ``ent``."""
    import rerun as rr

    for ch in rr.chunk.RrdReader(str(path)).store().stream():
        if ch.is_static and ch.entity_path == ent:
            rb = ch.to_record_batch()
            i = rb.schema.get_field_index("SeriesLines:names")
            if i >= 0:
                return rb.column(i).to_pylist()[0]
    return None


def test_recording_verifies(made):
    _, _, rrd = made
    exe = _rerun_exe()
    # rerun-sdk is a dependency (pyproject.toml) and installs the CLI beside Python: a
    # missing CLI is a broken install, which this test reports rather than skips
    assert exe is not None, "the rerun CLI (installed by rerun-sdk) is missing"
    r = subprocess.run([exe, "rrd", "verify", str(rrd)], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr[-2000:]


def test_recording_contents(made):
    from sim.report import rerun as recording

    _, run_path, rrd = made
    run = read_run(run_path)
    n = run.n_samples
    rows, comps, static, data, n_bp = _read(rrd)
    assert n_bp == 1  # the blueprint travels with the recording
    step = round(run.sample_rate_hz / 50.0)
    frames = math.ceil(n / step)
    # the platen moves once per display frame (not per physics step), at the run's pose
    assert rows["/table/platen"] == frames
    assert "Transform3D:translation" in comps["/table/platen"]
    tr = np.array([_column(data["/table/platen"], "Transform3D:translation")]).reshape(frames, 3)
    np.testing.assert_allclose(tr, run.table_displacement[::step, :3], atol=1e-6)
    # all 12 linkages: cylinder and rod bodies move, their geoms carry static shapes and force colours
    for a in ACTS:
        for part in ("cylinder", "rod"):
            ent = f"/table/actuators/{a}/{part}"
            assert rows[ent] == frames, ent
            geom = f"{ent}/{a}_{part}"
            assert geom in static and "Cylinders3D:lengths" in comps[geom]
            assert rows[geom] == frames and "Cylinders3D:colors" in comps[geom]
    for s in ("S1", "S2", "S3", "S4"):
        assert rows[f"/table/supports/{s}/shoe"] == frames
    assert "/table/platen/accelerometers" in static
    assert any(e.startswith("/table/foundation/") for e in static)
    # time series: one entity per group, one value per channel and row, every 4th sample
    # of the 1024 Hz run by default (>= 250 Hz)
    ss = recording.series_stride(run.sample_rate_hz, recording.DEFAULT_SERIES_RATE_HZ)
    assert ss == 4
    ns = math.ceil(n / ss)
    for d in DOFS:
        for q in ("displacement", "acceleration"):
            ent = f"/plots/dof/{d}/{q}"
            assert rows[ent] == ns, ent
            assert _column(data[ent], "Scalars:scalars").shape == (ns, 2)
    assert [x.split(" [")[0] for x in _names(rrd, "/plots/dof/x/displacement")] == ["reference", "achieved"]
    for a in ACTS:
        for sub in ("valve", "pressure"):
            assert rows[f"/plots/actuators/{a}/{sub}"] == ns, (a, sub)
    for q in ("force", "stroke"):
        assert _column(data[f"/plots/actuators/{q}"], "Scalars:scalars").shape == (ns, 12)
        assert [x.split(" [")[0] for x in _names(rrd, f"/plots/actuators/{q}")] == ACTS
    for e in ("/plots/hydraulics/supply_pressure", "/plots/hydraulics/accumulator_gas_volume"):
        assert rows[e] == ns
    assert rows["/plots/model/loop_gap"] == int(np.isfinite(run.extras["loop_gap"][::ss]).sum())
    acc = _column(data["/plots/accelerometers"], "Scalars:scalars")
    assert acc.shape == (ns, len(run.accelerometer_names))
    np.testing.assert_allclose(acc, run.accelerometers[::ss])
    xd = _column(data["/plots/dof/x/displacement"], "Scalars:scalars")
    np.testing.assert_allclose(xd[:, 1], run.column("table_displacement", "x")[::ss])
    np.testing.assert_allclose(_times(data["/plots/dof/x/displacement"]), run.t[::ss], atol=1e-9)
    f = _column(data["/plots/actuators/force"], "Scalars:scalars")
    np.testing.assert_allclose(f, run.actuator_force[::ss])
    # no time series is sent one channel per entity any more
    assert not any(e.startswith("/plots/dof/x/displacement/") for e in rows)


def test_full_rate(made, tmp_path):
    """``--full-rate`` keeps every sample of every series."""
    _, run_path, _ = made
    run = read_run(run_path)
    out = tmp_path / "full.rrd"
    assert cli.main(["view", str(run_path), "--rrd", str(out), "--full-rate"]) == 0
    rows, _, _, data, _ = _read(out)
    n = run.n_samples
    assert rows["/plots/dof/x/acceleration"] == n and rows["/plots/actuators/Z4/pressure"] == n
    v = _column(data["/plots/actuators/X1/valve"], "Scalars:scalars")
    np.testing.assert_allclose(
        v, np.column_stack([run.column("valve_command", "X1"), run.column("spool_position", "X1")])
    )
    assert rows["/table/platen"] == math.ceil(n / round(run.sample_rate_hz / 50.0))  # 3-D scene unchanged
    assert out.stat().st_size > 2 * made[2].stat().st_size


def test_partial_nan_channel_splits_off(tmp_path):
    """A channel with drop-outs leaves its group for ``<group>/<name>`` (finite samples only);
    the rest of the group keeps every row, and no row carries a NaN."""
    import rerun as rr

    from sim.report import rerun as recording

    t = np.arange(40) / 100.0
    v = np.column_stack([np.sin(t), np.cos(t), t])
    v[5:9, 1] = np.nan
    v[:, 2] = np.nan
    out = tmp_path / "g.rrd"
    rec = rr.RecordingStream("test", recording_id="g")
    rec.save(str(out))
    recording.RrdTarget._send_group(rr, rec, t, "plots/g", ["p", "q r", "s"], "m", None, v)
    rec.flush()
    rec.disconnect()
    rows, _, _, data, _ = _read(out)
    assert rows["/plots/g"] == 40 and rows["/plots/g/q\\ r"] == 36 and "/plots/g/s" not in rows
    np.testing.assert_allclose(_column(data["/plots/g"], "Scalars:scalars"), v[:, 0])
    np.testing.assert_allclose(_column(data["/plots/g/q\\ r"], "Scalars:scalars"), v[np.isfinite(v[:, 1]), 1])


def test_view_compare_residuals(made, tmp_path):
    _, run_path, _ = made
    run = read_run(run_path)
    other = read_run(run_path)
    other.table_displacement = other.table_displacement * 1.1
    other.meta["source"] = "measured"
    other_path = write_run(tmp_path / "measured.run.npz", other)
    out = tmp_path / "cmp.rrd"
    rc = cli.main(["view", str(run_path), "--rrd", str(out), "--compare", str(other_path), "--rate", "25"])
    assert rc == 0
    rows, comps, static, data, _ = _read(out)
    n = run.n_samples
    frames = math.ceil(n / round(run.sample_rate_hz / 25))
    assert rows["/table/platen"] == frames and rows["/compare/platen"] == frames
    ss = 4  # 1024 Hz run, series at >= 250 Hz
    ns = math.ceil(n / ss)
    # the compare run's achieved displacement only (its reference is not repeated)
    cmp_x = _column(data["/plots/compare/dof/x/displacement"], "Scalars:scalars")
    np.testing.assert_allclose(cmp_x, 1.1 * run.column("table_displacement", "x")[::ss], atol=1e-12)
    res = _column(data["/plots/residual/dof/x/displacement"], "Scalars:scalars")
    np.testing.assert_allclose(res, -0.1 * run.column("table_displacement", "x")[::ss], atol=1e-12)
    f = _column(data["/plots/residual/actuators/force"], "Scalars:scalars")
    assert f.shape == (ns, 12) and not f.any()  # identical channels: zero residual, still there
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_fast_loop_closure_matches_set_platen_pose():
    import mjcf
    from sim.report import rerun as recording

    rng = np.random.default_rng(1)
    tm = build_model(mjcf.load_table("cgs"), mjcf.load_payload("frame_3storey_297"))
    assert recording._LoopSolver.build(tm) is not None
    poses = np.column_stack([rng.uniform(-0.15, 0.15, (5, 3)), rng.uniform(-0.02, 0.02, (5, 3))])
    pq = rng.uniform(-0.01, 0.01, (5, len(tm.info.payload_joints)))
    bodies = recording._scene(tm).bodies
    p1, q1 = recording._body_poses(tm, poses, pq, bodies)
    p2, q2 = recording._body_poses(tm, poses, pq, bodies, exact=True)
    np.testing.assert_allclose(p1, p2, atol=1e-9)
    np.testing.assert_allclose(np.abs(np.einsum("fbi,fbi->fb", q1, q2)), 1.0, atol=1e-9)
    # the payload is drawn deformed: floors follow their drift coordinates
    names = [e for _, e in bodies]
    fl = names.index("table/payload/floor3")
    p0, _ = recording._body_poses(tm, poses, None, bodies)
    assert np.abs(p1[:, fl] - p0[:, fl]).max() > 1e-3


@pytest.mark.parametrize(
    "target, why",
    [
        ("afile/x.rrd", "is a file, not a folder"),
        ("x.txt", "does not end with '.rrd'"),
    ],
)
def test_bad_recording_path(made, tmp_path, capsys, target, why):
    _, run_path, _ = made
    if target.startswith("afile/"):
        (tmp_path / "afile").write_text("")
    rc = cli.main(["view", str(run_path), "--rrd", str(tmp_path / target)])
    err = capsys.readouterr().err
    assert rc == 2 and why in err and err.count("\n") == 1 and err.startswith("error: ")
    assert [p.name for p in tmp_path.rglob("*")] == (["afile"] if target.startswith("afile/") else [])


def test_recording_folder_is_created(made, tmp_path, capsys):
    """``view --rrd DIR/FILE`` creates DIR, as ``run --out DIR`` does."""
    _, run_path, _ = made
    rc = cli.main(["view", str(run_path), "--rrd", str(tmp_path / "new" / "sub" / "x.rrd")])
    assert rc == 0 and (tmp_path / "new" / "sub" / "x.rrd").stat().st_size > 0


def test_unwritable_folder(made, tmp_path, capsys, monkeypatch):
    """A folder the user may not write to: one line, exit 2, nothing left in it. The
    refusal is raised where the recording probes the folder (root, as in CI, would not
    feel a folder's permissions)."""
    import tempfile

    from sim.report import rerun

    _, run_path, _ = made
    ro = tmp_path / "ro"
    ro.mkdir()
    real_mkstemp = tempfile.mkstemp

    def refused(*a, dir=None, **k):
        if dir is not None and Path(dir) == ro:
            raise PermissionError(13, "Permission denied")
        return real_mkstemp(*a, dir=dir, **k)

    monkeypatch.setattr(rerun.tempfile, "mkstemp", refused)
    rc = cli.main(["view", str(run_path), "--rrd", str(ro / "x.rrd")])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "cannot be written (Permission denied)" in err
    assert list(ro.iterdir()) == []


def test_not_a_run_file(tmp_path, capsys):
    bad = tmp_path / "bad.run.npz"
    bad.write_text("not a run")
    rc = cli.main(["view", str(bad), "--rrd", str(tmp_path / "x.rrd")])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "not a NumPy .npz archive" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.run.npz"]


def test_run_rrd_fails_early(tmp_path, capsys):
    (tmp_path / "nope").write_text("a file where the folder should be")
    rc = cli.main(
        [
            "run",
            "harmonic_bare",
            "--out",
            str(tmp_path / "o"),
            "--duration",
            "0.5",
            "--rrd",
            str(tmp_path / "nope" / "x.rrd"),
        ]
    )
    err = capsys.readouterr().err
    assert rc == 2 and "is a file, not a folder" in err and err.count("\n") == 1
    assert not (tmp_path / "o" / "harmonic_bare.run.npz").exists()  # failed before simulating


def test_failure_leaves_no_partial_file(made, tmp_path, monkeypatch):
    import mjcf
    from sim.report import rerun as recording

    _, run_path, _ = made
    run = read_run(run_path)
    tm = build_model(mjcf.load_table("cgs"), None)

    def boom(*a, **k):
        raise RuntimeError("disk gone")

    monkeypatch.setattr(recording.RrdTarget, "_log_series", boom)
    target = recording.RrdTarget.open(tmp_path / "x.rrd")
    with pytest.raises(RuntimeError):
        target.write_run(run, tm)
    assert list(tmp_path.iterdir()) == []


def test_blueprint_is_one_function(made):
    import rerun.blueprint as rrb

    from sim.report import rerun as recording

    run = read_run(made[1])
    bp = recording.blueprint(run)
    assert isinstance(bp, rrb.Blueprint)
    assert isinstance(recording.blueprint(run, run), rrb.Blueprint)


def test_force_colours():
    from sim.report.rerun import force_colors

    c = force_colors(np.array([0.0, 0.5, 1.0, 3.0, np.nan]))
    assert c.shape == (5, 4) and c.dtype == np.uint8
    assert c[2].tolist() == c[3].tolist()  # clipped at capacity
    assert c[0, 2] > c[0, 0] and c[2, 0] > c[2, 2]  # blue at rest, red at capacity
    assert c[4, :3].tolist() == [128, 128, 128]


def test_writer_process(made, tmp_path):
    """A file target imports rerun in a writer process started by ``open``; its failures come back
    here (an unwritable file as RecordingError), and no partial file is left."""
    import mjcf
    from sim.report import rerun as recording

    run = read_run(made[1])
    tm = build_model(mjcf.load_table("cgs"), None)
    target = recording.RrdTarget.open(tmp_path / "w.rrd")
    assert target._worker is not None and target._worker.poll() is None
    assert target.write_run(run, tm) == tmp_path / "w.rrd" and target._worker is None
    # the folder is replaced by a file between open and write_run
    sub = tmp_path / "gone"
    sub.mkdir()
    target = recording.RrdTarget.open(sub / "x.rrd")
    sub.rmdir()
    sub.write_text("")
    with pytest.raises(recording.RecordingError, match="cannot be written"):
        target.write_run(run, tm)
    # a target never written stops its writer
    target = recording.RrdTarget.open(tmp_path / "never.rrd")
    proc = target._worker
    target.close()
    assert proc.poll() is not None
    assert sorted(p.name for p in tmp_path.iterdir()) == ["gone", "w.rrd"] and sub.is_file()

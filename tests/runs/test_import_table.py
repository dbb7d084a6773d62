"""A lab's own table and specimen, end to end (issue 24, items 1, 5, 6): the map names its
table and payload files by paths beside it, the import is run from another folder, and
every command finds the table in the run file with no --table. The lab's table is the
example lab table renamed ``td3`` (so the stock folder cannot stand in for it), its
specimen the example's 2-storey frame renamed ``frame2``."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from mjcf import load_table
from sim.cli import main
from sim.runs.importer import import_file, load_map
from sim.runs.runfile import read_run

ROOT = Path(__file__).resolve().parents[2]
FS = 204.8  #: the recorder's rate (the issue's lab)

MAP = """[source]
table = "td3.toml"
payload = "specimen/frame2.toml"
time_column = "time"
derive_velocity = true
command_hold = "linear"

[[column]]
name = "drive"
channel = "valve_command"
actuator = "A"
unit = "V"
full_scale = 10.0

[[column]]
name = "disp"
channel = "table_displacement"
dof = "x"
unit = "mm"

[[column]]
name = "acc"
channel = "table_acceleration"
dof = "x"
unit = "m/s^2"
delay_s = 0.002
lowpass_hz = 100.0
lowpass_order = 4

[[column]]
name = "force"
channel = "actuator_force"
actuator = "A"
unit = "kN"

[[column]]
name = "Acc 2F"
channel = "specimen_acceleration"
sensor = "F2"
height_m = 1.6
direction = [1, 0, 0]
unit = "m/s^2"
"""


def lab_folder(folder: Path, duration_s: float = 3.0) -> Path:
    """``folder/lab``: td3.toml, specimen/frame2.toml, map.toml and export.csv (a 2 Hz sine
    of 5 mm; the header writes the floor sensor as ``" Acc 2F"``, after a comma and a space)."""
    lab = folder / "lab"
    (lab / "specimen").mkdir(parents=True)
    text = (ROOT / "scenarios/tables/lab.toml").read_text().replace('name = "lab"', 'name = "td3"', 1)
    (lab / "td3.toml").write_text(text)
    pay = (ROOT / "scenarios/payloads/lab_2storey.toml").read_text()
    (lab / "specimen/frame2.toml").write_text(pay.replace('name = "lab_2storey"', 'name = "frame2"', 1))
    (lab / "map.toml").write_text(MAP)
    n = int(duration_s * FS)
    t = np.arange(n) / FS
    x = 0.005 * np.sin(2 * np.pi * 2.0 * t) * np.minimum(1.0, t / 0.5)
    v = np.gradient(x, t)
    a = np.gradient(v, t)
    force = 1200.0 * a + 2000.0 * v + 300.0 * np.sign(v)  # N: mass, viscous, Coulomb
    rows = ["time, drive, disp, acc, force, Acc 2F"]
    rows += [
        f"{t[i]:.5f}, {10 * v[i] / 0.55:.6g}, {1e3 * x[i]:.6g}, {a[i]:.6g}, {force[i] / 1e3:.6g}, {1.3 * a[i]:.6g}"
        for i in range(n)
    ]
    (lab / "export.csv").write_text("\n".join(rows) + "\n")
    return lab


@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    """The lab folder and its export imported from ANOTHER working folder (the map's
    relative paths must resolve from the map's folder)."""
    import os

    root = tmp_path_factory.mktemp("lab24")
    lab = lab_folder(root)
    work = root / "work"
    work.mkdir()
    old = os.getcwd()
    os.chdir(work)
    try:
        rc = main(["import", "../lab/export.csv", "--map", "../lab/map.toml", "--out", "runs"])
    finally:
        os.chdir(old)
    assert rc == 0
    return {"lab": lab, "work": work, "run": work / "runs" / "export.run.npz"}


def test_the_run_carries_the_maps_table_and_payload(imported):
    run = read_run(imported["run"])
    lab = imported["lab"]
    m = run.meta
    assert m["table"] == "td3" and m["payload"] == "frame2"
    assert m["table_path"] == str((lab / "td3.toml").resolve())
    assert m["table_sha256"] == hashlib.sha256((lab / "td3.toml").read_bytes()).hexdigest()
    assert m["table_description"] == (lab / "td3.toml").read_text()
    assert m["payload_path"] == str((lab / "specimen/frame2.toml").resolve())
    assert m["payload_sha256"] == hashlib.sha256((lab / "specimen/frame2.toml").read_bytes()).hexdigest()
    # the floor sensor (header " Acc 2F", map "Acc 2F") and the declared conditioning
    assert m["specimen_sensors"] == [{"name": "F2", "height_m": 1.6, "direction": [1.0, 0.0, 0.0]}]
    np.testing.assert_allclose(run.specimen_acceleration[:, 0], 1.3 * run.table_acceleration[:, 0], rtol=1e-5)
    assert m["channel_conditioning"] == {
        "table_acceleration": {"delay_s": 0.002, "lowpass_hz": 100.0, "lowpass_order": 4}
    }


def test_replay_identify_calibrate_need_no_table(imported, tmp_path, capsys):
    """Each command rebuilds td3 + frame2 from the run (no stock table of that name exists)."""
    run = str(imported["run"])
    assert main(["replay", run, "--out", str(tmp_path / "rep")]) == 0
    replayed = read_run(tmp_path / "rep" / "export.replay.run.npz")
    assert replayed.meta["table"] == "td3" and replayed.meta["specimen_sensors"][0]["name"] == "F2"
    assert np.isfinite(replayed.specimen_acceleration).all()
    capsys.readouterr()
    assert main(["identify", run, "--model", "ucsd-ls", "--json"]) == 0
    ident = json.loads(capsys.readouterr().out)
    assert 1000.0 < ident["M_e_kg"] < 1500.0  # the export's 1200 kg (the sine barely moves a frame at 2 Hz)
    out = tmp_path / "cal"
    second = tmp_path / "export2.run.npz"
    second.write_bytes(Path(run).read_bytes())
    assert main(["calibrate", run, "--holdout", str(second), "--out", str(out), "--path", "mechanical"]) == 0
    calibrated = (out / "td3_calibrated.toml").read_text()
    assert calibrated.startswith((imported["lab"] / "td3.toml").read_text().splitlines()[0])  # the file, comments kept


def test_view_needs_no_table_and_draws_specimen_sensors_under_the_payload(imported, tmp_path):
    import rerun as rr

    assert main(["view", str(imported["run"]), "--rrd", str(tmp_path / "v.rrd")]) == 0
    reader = rr.chunk.RrdReader(str(tmp_path / "v.rrd"))
    paths = {c.entity_path for c in reader.store().stream()}
    assert "/payload/sensors/F2/acceleration" in paths  # the series
    assert "/table/payload/floor2/specimen_sensors" in paths  # the sensor, on the floor at 1.6 m


def test_replay_gives_the_floors_acceleration_by_height(imported):
    """The model's floor sensors obey the frame's equation of motion: the masses times
    their absolute accelerations sum to the first storey's shear (spring k1 u1 plus the
    little damping), and a sensor at height 0 reads the platen. A sensor between floors
    has no reading (NaN, with a note)."""
    from mjcf import load_payload
    from sim.calibrate.replay import replay
    from sim.signals.resample import interpolate

    run = read_run(imported["run"])
    run.meta["specimen_sensors"] = [
        {"name": "B", "height_m": 0.0, "direction": [1.0, 0.0, 0.0]},
        {"name": "F1", "height_m": 0.8, "direction": [1.0, 0.0, 0.0]},
        {"name": "F2", "height_m": 1.6, "direction": [1.0, 0.0, 0.0]},
        {"name": "F2y", "height_m": 1.6, "direction": [0.0, 1.0, 0.0]},
        {"name": "mid", "height_m": 1.2, "direction": [1.0, 0.0, 0.0]},
    ]
    run.specimen_acceleration = np.zeros((run.n_samples, 5))
    out = replay(run)
    a = out.run.specimen_acceleration
    np.testing.assert_allclose(a[:, 0], out.run.table_acceleration[:, 0], atol=1e-9)
    assert np.all(a[:, 3] == 0.0) and np.all(np.isnan(a[:, 4]))
    assert any("sensor mid at 1.2 m" in n and "no acceleration" in n for n in out.notes)
    pay = load_payload(imported["lab"] / "specimen/frame2.toml")
    u = interpolate(out.result.t, out.result.extras["payload_qpos"], out.run.t)  # floor drifts, m
    k1 = pay.stiffness_n_m[0][0] + pay.stiffness_n_m[0][1]  # first storey: K[0,0] + K[0,1] (N/m)
    shear = -(np.asarray(pay.mass_kg) * a[:, 1:3]).sum(axis=1)
    keep = out.run.t > 0.5  # past the ramp
    assert np.corrcoef(shear[keep], k1 * u[keep, 0])[0, 1] > 0.98
    assert np.std(shear[keep] - k1 * u[keep, 0]) < 0.25 * np.std(shear[keep])


def test_a_bare_name_is_still_the_stock_table(tmp_path):
    lab = lab_folder(tmp_path, duration_s=1.0)
    (lab / "map.toml").write_text(MAP.replace('table = "td3.toml"', 'table = "lab"'))
    run = import_file(lab / "export.csv", load_map(lab / "map.toml")).run
    assert run.meta["table"] == "lab"
    assert run.meta["table_path"] == str((ROOT / "scenarios/tables/lab.toml").resolve())


def test_a_map_that_does_not_say_its_hold_leaves_it_to_the_controller_rate(tmp_path):
    """No ``command_hold`` in the map: none in the run, and replay interpolates (the lab
    table's controller ticks at 1024 Hz, faster than this export's rate); the map's
    word wins where it gives one."""
    from sim.calibrate.replay import command_hold

    lab = lab_folder(tmp_path, duration_s=1.0)
    (lab / "map.toml").write_text(
        MAP.replace('table = "td3.toml"', 'table = "lab"').replace('command_hold = "linear"\n', "")
    )
    run = import_file(lab / "export.csv", load_map(lab / "map.toml")).run
    assert "command_hold" not in run.meta and run.sample_rate_hz < 1024.0
    assert command_hold(run, load_table("lab")) == "cubic"
    (lab / "zoh.toml").write_text(MAP.replace('table = "td3.toml"', 'table = "lab"').replace('"linear"', '"zoh"'))
    said = import_file(lab / "export.csv", load_map(lab / "zoh.toml")).run
    assert said.meta["command_hold"] == "zoh" and command_hold(said, load_table("lab")) == "zoh"


def test_map_names_are_compared_stripped_of_spaces(tmp_path):
    lab = lab_folder(tmp_path, duration_s=1.0)
    (lab / "map.toml").write_text(MAP.replace('name = "Acc 2F"', 'name = " Acc 2F "'))
    run = import_file(lab / "export.csv", load_map(lab / "map.toml")).run
    assert run.column_names("specimen_acceleration") == ["F2"]


def test_conditioning_of_one_channel_must_agree(tmp_path):
    from sim.errors import UserError

    lab = lab_folder(tmp_path, duration_s=1.0)
    text = MAP + "lowpass_hz = 50.0\nlowpass_order = 2\n"  # on the floor sensor, the map's last column
    text += '\n[[column]]\nname = "acc"\nchannel = "specimen_acceleration"\nsensor = "B"\nheight_m = 0.0\n'
    text += 'unit = "m/s^2"\nlowpass_hz = 60.0\nlowpass_order = 2\n'
    (lab / "map.toml").write_text(text)
    with pytest.raises(UserError, match="declare different conditioning for channel specimen_acceleration"):
        import_file(lab / "export.csv", load_map(lab / "map.toml"))


def test_the_carried_text_wins_over_an_edited_table_file(tmp_path):
    """The run keeps the table it was imported with: after the lab edits td3.toml, the
    run still rebuilds the old text (its source then the run itself), and a calibrated
    copy starts from that text, not from the edited file."""
    from sim.runs.runfile import source_text, table_of, write_run

    lab = lab_folder(tmp_path, duration_s=1.0)
    run = import_file(lab / "export.csv", load_map(lab / "map.toml")).run
    path = write_run(tmp_path / "r.run.npz", run)
    run = read_run(path)
    assert table_of(run).source == str((lab / "td3.toml").resolve())  # unchanged: the file itself
    old = (lab / "td3.toml").read_text()
    (lab / "td3.toml").write_text(old.replace("mass_kg = 1140.0", "mass_kg = 2000.0", 1))
    desc = table_of(run)
    assert desc.source == f"{path} [meta.table_description]"
    assert desc.raw["platen"]["mass_kg"] == 1140.0
    assert source_text(desc.source) == old

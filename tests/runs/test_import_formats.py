"""`shaketable import` of an NI TDMS file (npTDMS) through the same column map as a CSV
(issue #14): the channels come out as the map says, as from the CSV within its rounding."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sim.cli import main
from sim.runs.importer import import_file, load_map
from sim.runs.runfile import read_run

nptdms = pytest.importorskip("nptdms")  # the test extra has it (pyproject.toml)

ROOT = Path(__file__).resolve().parents[2]
MAP = ROOT / "scenarios" / "lab_example" / "lab_map.toml"
RATE = 204.8
N = 400


def _columns(seed=3):
    """Lab-unit columns of the example map: seeded noise of the recorder's sizes."""
    rng = np.random.default_rng(seed)
    t = np.round(np.arange(N) / RATE, 5)  # the recorder's timestamps, rounded to 1e-5 s
    return {
        "time": t,
        "drive": -0.1 + 2.0 * rng.standard_normal(N),  # V
        "disp_cmd": 10.0 * rng.standard_normal(N),  # mm
        "disp": 0.5 + 10.0 * rng.standard_normal(N),  # mm, LVDT 0.5 mm off
        "acc_table": 3000.0 * rng.standard_normal(N),  # mm/s^2
        "acc_floor1": 5000.0 * rng.standard_normal(N),
        "acc_floor2": 8000.0 * rng.standard_normal(N),
        "dp": 40.0 * rng.standard_normal(N),  # bar
    }


def _write_tdms(path, cols, groups=("Recorder",)):
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    objs = [RootObject(properties={"name": "shaketable test"})]
    for g in groups:
        objs.append(GroupObject(g))
        objs += [ChannelObject(g, k, np.asarray(v, dtype=np.float64)) for k, v in cols.items()]
    with TdmsWriter(str(path)) as w:
        w.write_segment(objs)
    return path


def test_tdms_import_matches_the_map_and_the_csv(tmp_path):
    cols = _columns()
    tdms = _write_tdms(tmp_path / "rec.tdms", cols)
    csv = tmp_path / "rec.csv"
    names = list(cols)
    rows = [",".join(names)] + [",".join(f"{cols[k][i]:.7g}" for k in names) for i in range(N)]
    csv.write_text("\n".join(rows) + "\n")
    mp = load_map(MAP)
    a = import_file(tdms, mp).run
    b = import_file(csv, mp).run
    assert a.sample_rate_hz == RATE and a.n_samples == N
    # exactly the map's arithmetic on the TDMS values: SI = sign * (raw - offset) * unit
    np.testing.assert_allclose(a.table_displacement[:, 0], (cols["disp"] - 0.5) * 1e-3, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(a.valve_command[:, 0], cols["drive"] / 10.0, rtol=1e-12)
    np.testing.assert_allclose(a.accelerometers[:, 0], -cols["acc_floor1"] * 1e-3, rtol=1e-12)
    area = 5.0e-3  # scenarios/tables/lab.toml: piston area
    np.testing.assert_allclose(a.actuator_force[:, 0], cols["dp"] * 1e5 * area, rtol=1e-12)
    # and the CSV of the same numbers (7 significant digits) within that rounding
    for ch in ("valve_command", "reference", "table_displacement", "table_acceleration", "accelerometers"):
        x, y = getattr(a, ch), getattr(b, ch)
        assert np.abs(x - y).max() <= 1e-6 * np.abs(x).max() + 1e-9, ch


def test_tdms_through_the_cli_and_group_names(tmp_path, capsys):
    cols = _columns()
    # the same channel names in two groups: a bare name is ambiguous, "group/channel" is not
    tdms = _write_tdms(tmp_path / "two.tdms", cols, groups=("Raw", "Scaled"))
    out = tmp_path / "runs"
    assert main(["import", str(tdms), "--map", str(MAP), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "has 2 channels named" in err and "group/channel" in err and "\n" not in err
    assert not out.exists()
    text = MAP.read_text()
    for k in cols:
        text = text.replace(f'name = "{k}"', f'name = "Scaled/{k}"').replace(
            f'time_column = "{k}"', f'time_column = "Scaled/{k}"'
        )
    mp = tmp_path / "map.toml"
    mp.write_text(text)
    assert main(["import", str(tdms), "--map", str(mp), "--out", str(out)]) == 0
    run = read_run(out / "two.run.npz")
    np.testing.assert_allclose(run.reference[:, 0], cols["disp_cmd"] * 1e-3, rtol=1e-12)


def test_tdms_missing_channel_and_damaged_file_are_one_line(tmp_path, capsys):
    cols = _columns()
    del cols["dp"]
    tdms = _write_tdms(tmp_path / "short.tdms", cols)
    bad = tmp_path / "bad.tdms"
    bad.write_bytes(b"TDSm not really a tdms file")
    for f, needle in ((tdms, "has no channel 'dp'"), (bad, "cannot be read as a TDMS file")):
        out = tmp_path / "runs"
        assert main(["import", str(f), "--map", str(MAP), "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("error: ") and needle in err and "\n" not in err, err
        assert not out.exists()

"""What `shaketable calibrate` is and is no longer: ``--strategy scale`` and ``shaketable
fit`` (global scale factors on the replay, which added 12.5 t to a 0.84 t table, issue #23)
were removed and say so in one line; the characterisation calibration (``characterize
--calibrate``) writes calibration.json in the shape of the search's."""

from __future__ import annotations

import json

import pytest

from sim.cli import main


@pytest.mark.parametrize(
    "argv, what",
    [
        (["fit", "x.run.npz", "--table", "lab", "--out", "OUT"], "shaketable fit was removed"),
        (["fit", "-h"], "shaketable fit was removed"),
        (["calibrate", "x.run.npz", "--strategy", "scale", "--out", "OUT"], "calibrate --strategy scale was removed"),
    ],
)
def test_removed_scale_strategy_and_fit_say_so_in_one_line(argv, what, tmp_path, capsys):
    out = tmp_path / "out"
    rc = main([str(out) if a == "OUT" else a for a in argv])
    err = capsys.readouterr().err
    assert rc == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert what in err and "use `shaketable calibrate RUN... --out DIR`" in err
    assert not out.exists()


def test_removed_commands_are_not_listed(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    text = capsys.readouterr().out
    assert "calibrate" in text and "fit" not in text.replace("fitted", "")


def test_characterisation_calibration_in_the_report_shape():
    """`characterize --calibrate` writes calibration.json in the same shape: the values
    it rewrites as effects per class, the oil-column error before and after."""
    import mjcf
    from sim.calibrate.programme import calibration_report

    desc = mjcf.load_table("cgs")
    tgt = {d: 20.0 for d in ("x", "y", "z", "rx", "ry", "rz")}
    cal = {
        "dead_volume_m3": {"lateral": 2e-3},
        "seal_friction_n": {"lateral": 5000.0},
        "linear_targets": tgt,
        "linear_before": {d: 22.0 for d in tgt},
        "linear_after": {d: 20.2 for d in tgt},
        "masses": None,
    }
    js = calibration_report(cal, desc, "x.toml")
    assert js["error_before"] == pytest.approx(0.10) and js["error_after"] == pytest.approx(0.01)
    assert {(e["name"], e["where"]) for e in js["effects_added"]} == {
        ("dead_volume", "class:lateral"),
        ("seal_friction", "class:lateral"),
    }
    for k in ("residual_path", "candidates", "unexplained", "calibrated_table_file"):
        assert k in js
    json.dumps(js, allow_nan=False)

"""Table/payload descriptions: bad input is refused with one line naming the field."""

import json
import re
import subprocess
import sys

import pytest

from mjcf.description import TABLES_DIR
from sim.cli import main

CGS = (TABLES_DIR / "cgs.toml").read_text()


def _run(tmp_path, text, capsys, name="bad.toml"):
    p = tmp_path / name
    p.write_text(text)
    rc = main(["model", str(p)])
    err = capsys.readouterr().err.strip()
    return rc, err


def _set(text, section, key, value):
    """Replace key's value in [section] of a TOML text."""
    lines = text.split("\n")
    cur = None
    for i, line in enumerate(lines):
        h = re.match(r"^\[+([^\]]+)\]+", line)
        if h:
            cur = h.group(1)
        elif cur == section and re.match(rf"^{key}\s*=", line):
            lines[i] = f"{key} = {value}"
            return "\n".join(lines)
    raise KeyError(key)


def _drop(text, section, key):
    lines = text.split("\n")
    cur = None
    for i, line in enumerate(lines):
        h = re.match(r"^\[+([^\]]+)\]+", line)
        if h:
            cur = h.group(1)
        elif cur == section and re.match(rf"^{key}\s*=", line):
            del lines[i]
            return "\n".join(lines)
    raise KeyError(key)


@pytest.mark.parametrize(
    "mutate,expect",
    [
        (lambda t: _drop(t, "platen", "mass_kg"), "missing field 'platen.mass_kg'"),
        (lambda t: t.replace("[platen]\n", "[platen]\ncolour = 3\n"), "unknown key 'colour'"),
        (lambda t: _set(t, "platen", "mass_kg", "-5.0"), "'platen.mass_kg' must be > 0"),
        (lambda t: _set(t, "actuator_class.vertical", "rod_mass_kg", "-1.0"), "rod_mass_kg' must be > 0"),
        (lambda t: _set(t, "actuator_class.lateral", "half_stroke_m", "0.16"), "actuator 'Y1' needs"),
        (lambda t: t.replace('name = "X2"', 'name = "X1"'), "two actuators are named 'X1'"),
        (lambda t: t.replace('class = "vertical"', 'class = "verticle"', 1), "known classes"),
        (lambda t: _set(t, "foundation", "mode", '"floating"'), "'foundation.mode' must be one of fixed, spring"),
        (lambda t: t + "\n[[[", "not valid TOML"),
    ],
)
def test_bad_table_is_refused_in_one_line(tmp_path, capsys, mutate, expect):
    rc, err = _run(tmp_path, mutate(CGS), capsys)
    assert rc == 2
    assert expect in err, err
    assert len(err.splitlines()) == 1 and "Traceback" not in err


def test_bad_payload_is_refused(tmp_path, capsys):
    p = tmp_path / "heavy.toml"
    p.write_text(
        '[payload]\ntype = "rigid"\nname = "heavy"\nmass_kg = 400000.0\ncom_m = [0, 0, 1]\n'
        "inertia_kg_m2 = [1e5, 1e5, 1e5]\nfootprint_m = [3, 3]\nheight_m = 2.0\n"
    )
    rc = main(["model", "cgs", "--payload", str(p)])
    err = capsys.readouterr().err
    assert rc == 2 and "capacity" in err
    p.write_text(
        '[payload]\ntype = "shear_frame"\nname = "f"\ndirection = "x"\nmass_kg = [1.0, 1.0]\n'
        "stiffness_n_m = [[1.0, 2.0], [2.0, 1.0]]\ndamping_ratio = 0.02\nstorey_height_m = 1.0\n"
    )
    rc = main(["model", "cgs", "--payload", str(p)])
    err = capsys.readouterr().err
    assert rc == 2 and "positive definite" in err


def test_model_json(capsys, tmp_path):
    rc = main(["model", "cgs", "--json", "--xml", str(tmp_path)])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0
    assert set(out["effective_mass"]) == {"x", "y", "z", "rx", "ry", "rz"}
    assert [a["name"] for a in out["actuators"]] == [f"{g}{i}" for g in "XYZ" for i in range(1, 5)]
    for a in out["actuators"]:
        assert len(a["base"]) == 3 and len(a["platen"]) == 3 and a["stroke"] > 0
    assert (tmp_path / "scene.xml").exists() and (tmp_path / "table.xml").exists()


def test_cli_user_error_has_no_traceback(tmp_path):
    bad = tmp_path / "x.toml"
    bad.write_text(_set(CGS, "platen", "mass_kg", "-1.0"))
    r = subprocess.run([sys.executable, "-m", "sim", "model", str(bad)], capture_output=True, text=True)
    assert r.returncode == 2
    assert "Traceback" not in r.stderr and r.stderr.count("\n") == 1

"""What stands on the platen on its own joints is flexible on the mechanical path too
(sim.calibrate.flexible): a declared shear frame, a description's ``payload_mode``
entries. Before, the mechanical path held them rigidly to the platen (the effective mass
at home) while the replay modelled them flexible, and the paths disagreed."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from sim.calibrate import search as S

ROOT = Path(__file__).resolve().parents[2]
FRAME = ROOT / "scenarios/payloads/lab_2storey.toml"


def _declared_modes(payload):
    """The frame's modes from its description (floor masses, storey stiffness matrix,
    modal damping): frequencies (Hz) and effective modal masses (m^T phi)^2 / phi^T M phi."""
    from scipy.linalg import eigh

    M, K = np.diag(payload.mass_kg), np.asarray(payload.stiffness_n_m, float)
    w2, phi = eigh(K, M)
    meff = (phi.T @ M @ np.ones(len(M))) ** 2 / np.einsum("in,ij,jn->n", phi, M, phi)
    return np.sqrt(w2) / (2 * math.pi), meff


def test_the_compiled_frames_modes_are_the_declared_ones():
    """The modes read from the compiled model (mass, tendon stiffness and damping by finite
    differences, each mode as the model's step has it: mjcf.stepping) are the description's:
    frequencies, modal masses and damping."""
    import mjcf
    from mjcf.description import load_payload
    from sim.calibrate.flexible import flexible_parts
    from sim.effects import build_model

    pay = load_payload(str(FRAME))
    parts = flexible_parts(build_model(mjcf.load_table("lab"), pay), [0])
    f, meff = _declared_modes(pay)
    assert parts.frequency_hz == pytest.approx(f, rel=1e-6)
    assert parts.L[:, 0] ** 2 == pytest.approx(meff, rel=1e-6)
    assert parts.damping_ratio == pytest.approx([pay.damping_ratio] * 2, rel=1e-4)
    assert flexible_parts(build_model(mjcf.load_table("lab"), None), [0]) is None


@pytest.fixture(scope="module")
def frame_runs(tmp_path_factory):
    """Three 3 s random runs of the lab table carrying the 2-storey frame (4.0 and 10.5 Hz),
    measured through the recorder model."""
    from tests.calibrate.test_payload_mode_paths import _runs

    return _runs(tmp_path_factory.mktemp("frame"), FRAME.read_text())


def _explained(res, name: str) -> float:
    """The largest share of the residual a candidate of type ``name`` explained."""
    return max(c["explained_fraction"] for c in res.candidates if c["name"] == name)


def test_a_declared_frame_needs_no_mode_on_the_mechanical_path(frame_runs):
    """The frame declared: the mechanical path, offered modes and added mass, adds neither,
    and neither explains anything (measured: a mode 0.12 %, an added mass 8.8 +/- 12.2 kg.
    Held rigid, a mode explained 47.5 % and an added mass of -314 kg 16.8 %; below 40 Hz
    the frame's first mode was 1412 N of the force's 2894 N RMS, now 281 N, the table's
    own floor under a rigid block on the same seeds)."""
    res = S.calibrate(
        frame_runs, table="lab", payload=str(FRAME), path="mechanical", effects=["payload_mode", "added_mass"]
    )
    assert res.effects_added == [], res.effects_added
    assert _explained(res, "payload_mode") < 0.01 and _explained(res, "added_mass") < 0.01, res.candidates


def test_a_calibrated_descriptions_modes_are_not_counted_twice(frame_runs, tmp_path):
    """The frame's modes written as a calibrated description writes them (``payload_mode``
    entries, ``--payload none``): calibrated again on the frame's records, the mechanical
    path adds no mode, a mode explains nothing, and its error is the declared frame's;
    without the entries a mode explains much of the residual. (Held rigid, the entries
    left the mode's (H - 1) share in the residual, as the declared frame did.)"""
    import tomllib

    from mjcf.description import load_payload

    pay = load_payload(str(FRAME))
    f, meff = _declared_modes(pay)
    text = (ROOT / "scenarios/tables/lab.toml").read_text()
    for fi, mi in zip(f, meff):
        text += (
            f'\n[[effect]]\ntype = "payload_mode"\nwhere = "dof:x"\nmass_kg = {float(mi)!r}\nfrequency_hz = {float(fi)!r}\n'
            f'damping_ratio = {float(pay.damping_ratio)!r}\nsource = "the frame\'s modes (test)"\n'
        )
    tomllib.loads(text)
    (tmp_path / "lab_modes.toml").write_text(text)
    kw = {"payload": "none", "path": "mechanical", "effects": ["payload_mode", "added_mass"]}
    res = S.calibrate(frame_runs, table=str(tmp_path / "lab_modes.toml"), **kw)
    framed = S.calibrate(frame_runs, table="lab", payload=str(FRAME), path="mechanical", effects=["added_mass"])
    assert res.effects_added == [], res.effects_added
    assert _explained(res, "payload_mode") < 0.01, res.candidates
    assert res.error_before == pytest.approx(framed.error_before, rel=1e-3)
    bare = S.calibrate(frame_runs, table="lab", **kw)
    assert _explained(bare, "payload_mode") > 0.3, bare.candidates

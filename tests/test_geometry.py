"""Geometric nonlinearity study against closed form."""

import json
import math

import numpy as np

from mjcf.description import actuator_strokes, envelope_corners
from sim.assess.geometry import forward_kinematics, study
from sim.cli import main


def test_second_order_stroke_matches_closed_form(cgs_desc):
    r = study(cgs_desc)
    z1 = cgs_desc.actuator("Z1")
    L = z1.length0_m
    x = cgs_desc.limits.stroke_m[0]
    expect = math.sqrt(L * L + x * x) - L  # a vertical linkage tilted by a horizontal shift
    assert abs(r["second_order_stroke_m"]["x"]["Z1"] - expect) < 1e-9


def test_forward_kinematics_inverts_the_exact_geometry(cgs_desc):
    rng = np.random.default_rng(1)
    for p in list(envelope_corners(cgs_desc)[::7]) + list(rng.uniform(-1, 1, (10, 6)) * 0.1):
        q = forward_kinematics(cgs_desc, actuator_strokes(cgs_desc, p))
        assert np.abs(q - p).max() < 1e-9


def test_geometry_cli_json(capsys, cgs_desc):
    assert main(["geometry", "cgs", "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    # a 250 mm longitudinal stroke through a linear DOF map drops the platen by the
    # vertical linkages' tilt: 16 mm on the CGS layout
    assert r["parasitic_motion_linear_map"]["x+"]["z"] < -0.015
    assert 0.0 < r["oil_column_max_relative_change"] < 0.5
    assert len(r["oil_column_hz"]["centre"]) == 6

"""The replay and closed-loop paths refuse a candidate that is an effect the model holds
already at its place (sim.calibrate.pathjudge): a specimen's mode whose frequency's 95 %
interval holds a mode there, a power-law damper whose exponent's interval holds 0 beside
a Coulomb friction (or 1 beside a viscous damper). The numbers are the ones measured on
the worked example's replay-only records (docs/lab-example-validation.md)."""

from __future__ import annotations

import types

from sim.calibrate.pathjudge import same_law, same_mode


def _refined(type_, where, values):
    cand = types.SimpleNamespace(type=type_, where=where, values=lambda theta: dict(values))
    return types.SimpleNamespace(cand=cand, theta=None)


FIRST_MODE = {
    "type": "payload_mode",
    "where": "dof:x",
    "mass_kg": 754.0,
    "frequency_hz": 7.464,
    "damping_ratio": 0.0125,
}


def test_a_second_mode_inside_the_first_ones_interval_is_the_same_mode():
    rf = _refined("payload_mode", "dof:x", {"mass_kg": 66.0, "frequency_hz": 7.714, "damping_ratio": 0.157})
    why = same_mode(rf, {"frequency_hz": 1.0}, [FIRST_MODE])
    assert "7.464 Hz already in the model" in why
    assert same_mode(rf, {"frequency_hz": 0.2}, [FIRST_MODE]) == ""  # told apart: a mode of its own
    assert same_mode(rf, {"frequency_hz": 1.0}, [{**FIRST_MODE, "where": "dof:y"}]) == ""  # another DOF


def test_the_second_mode_of_a_frame_is_not_the_first():
    rf = _refined("payload_mode", "dof:x", {"mass_kg": 27.9, "frequency_hz": 19.69, "damping_ratio": 0.03})
    assert same_mode(rf, {"frequency_hz": 0.58}, [FIRST_MODE]) == ""


def test_a_power_law_with_an_exponent_near_zero_beside_a_coulomb_friction_is_that_friction():
    coulomb = {"type": "coulomb_friction", "where": "dof:x", "force_n": 882.0}
    rf = _refined("power_damping", "dof:x", {"coefficient": 203.8, "exponent": 0.0278})
    assert "coulomb_friction already at dof:x" in same_law(rf, {"exponent": 0.069}, [coulomb])
    assert same_law(rf, {"exponent": 0.01}, [coulomb]) == ""  # an exponent told apart from 0
    grows = {**coulomb, "grows_with": "displacement", "coefficient": 5e4}
    assert same_law(rf, {"exponent": 0.069}, [grows]) == ""  # not the plain friction
    assert same_law(rf, {"exponent": 0.069}, [{**coulomb, "where": "class:main"}]) == ""


def test_a_power_law_with_an_exponent_near_one_beside_a_viscous_damper_is_that_damper():
    viscous = {"type": "viscous_damping", "where": "dof:x", "damping_n_s_m": 4e4}
    rf = _refined("power_damping", "dof:x", {"coefficient": 1e3, "exponent": 0.97})
    assert "viscous_damping already at dof:x" in same_law(rf, {"exponent": 0.05}, [viscous])
    ucsd_like = _refined("power_damping", "dof:x", {"coefficient": 45.9e3, "exponent": 0.5})
    assert same_law(ucsd_like, {"exponent": 0.016}, [viscous]) == ""

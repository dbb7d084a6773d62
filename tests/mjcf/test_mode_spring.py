"""A mode's spring and damper as MuJoCo steps them (:mod:`mjcf.stepping`): one slide's
free vibration at the builder's step has the declared frequency and damping (closed
form), where k = m w^2, c = 2 z m w put it 0.045 % low at 6 Hz and 1.6 % at 60 Hz; and
:func:`mjcf.stepping.stepped_mode` says where a plain spring's mode lands."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from mjcf.builder import BuildOptions
from mjcf.stepping import mode_spring, stepped_mode

H = BuildOptions().timestep_s
CASES = [(6.0, 0.05), (20.0, 0.05), (7.5, 0.003), (60.0, 0.2), (60.0, 1.5)]


def _spec(integrator: str = "implicitfast") -> mujoco.MjSpec:
    spec = mujoco.MjSpec()
    spec.option.timestep = H
    spec.option.integrator = getattr(mujoco.mjtIntegrator, f"mjINT_{integrator.upper()}")
    spec.option.gravity = [0.0, 0.0, 0.0]
    return spec


def _stepped_mode(k: float, c: float, m: float, integrator: str = "implicitfast") -> tuple[float, float]:
    """(frequency Hz, damping ratio) of one slide of mass ``m`` on ``k``, ``c``, read off
    its free vibration as MuJoCo steps it: the poles of the exact second-order recursion
    its samples obey."""
    spec = _spec(integrator)
    b = spec.worldbody.add_body(name="mass")
    b.explicitinertial = True
    b.mass = m
    b.inertia = [1.0, 1.0, 1.0]
    j = b.add_joint(name="slide", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[1, 0, 0])
    j.stiffness = [k, 0, 0]
    j.damping = [c, 0, 0]
    model = spec.compile()
    data = mujoco.MjData(model)
    data.qpos[0] = 1e-3
    x = []
    for _ in range(400):
        mujoco.mj_step(model, data)
        x.append(float(data.qpos[0]))
    x = np.array(x)
    a1, a2 = np.linalg.lstsq(np.c_[x[1:-1], x[:-2]], x[2:], rcond=None)[0]
    s = np.log(np.roots([1.0, -a1, -a2]).astype(complex)) / H
    wn = math.sqrt(abs(s[0] * s[1]))  # |s1 s2| = w^2 also for two real poles
    return wn / (2 * math.pi), float(-(s[0] + s[1]).real / (2 * wn))


@pytest.mark.parametrize("f,z", CASES)
def test_a_stepped_mode_has_the_declared_frequency_and_damping(f, z):
    m = 1200.0
    fs, zs = _stepped_mode(*mode_spring(_spec(), m, f, z), m)
    assert fs == pytest.approx(f, rel=1e-6) and zs == pytest.approx(z, rel=1e-6), (fs, zs)


def test_the_plain_spring_is_what_the_step_biases():
    """The uncorrected values are measurably off (so the test above could fail)."""
    w = 2 * math.pi * 60.0
    fs, zs = _stepped_mode(w * w, 2 * 0.2 * w, 1.0)
    assert fs / 60.0 - 1 < -0.01 and zs / 0.2 - 1 < -0.01, (fs, zs)


def test_an_explicit_integrator_gets_the_continuous_values():
    k, c = mode_spring(_spec("rk4"), 2.0, 6.0, 0.05)
    w = 2 * math.pi * 6.0
    assert (k, c) == (pytest.approx(2.0 * w * w), pytest.approx(2 * 0.05 * 2.0 * w))


@pytest.mark.parametrize("f,z", CASES)
def test_stepped_mode_is_where_a_plain_spring_lands(f, z):
    w = 2 * math.pi * f
    fs, zs = _stepped_mode(w * w, 2 * z * w, 1.0)
    fp, zp = stepped_mode(f, z, H)
    assert fp == pytest.approx(fs, rel=1e-6) and zp == pytest.approx(zs, rel=1e-6), (fp, fs, zp, zs)


@pytest.mark.parametrize("f,z", CASES)
def test_a_matched_spring_read_back_is_the_declared_mode(f, z):
    """What a reader of the compiled model (k, c) gets back through :func:`stepped_mode`."""
    k, c = mode_spring(_spec(), 1.0, f, z)
    fc, zc = math.sqrt(k) / (2 * math.pi), c / (2 * math.sqrt(k))
    assert stepped_mode(fc, zc, H) == (pytest.approx(f, rel=1e-9), pytest.approx(z, rel=1e-9))

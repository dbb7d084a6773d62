"""Motions and records: requested peaks, seeds, AT2 reading, baseline, spectrum closed form."""

import numpy as np
import pytest

from sim.errors import MotionError, UserError
from sim.scenario.motions import (
    G,
    Motion,
    Peaks,
    check_limits,
    response_spectrum,
    sine,
    tapered_sine,
    triangle,
    white_noise,
)
from sim.scenario.records import (
    EL_CENTRO_MAPPING,
    el_centro_1940,
    el_centro_motions,
    integrate,
    process_record,
    read_at2,
    resample,
    scale_amplitude,
    time_scale,
)

FS = 1024.0


def _consistent(m: Motion, tol_v=2e-3, tol_a=2e-2):
    """v and a agree with finite differences of d and v (relative to their peaks)."""
    dv = np.gradient(m.d, m.t)
    da = np.gradient(m.v, m.t)
    assert np.max(np.abs(dv - m.v)[1:-1]) <= tol_v * m.peaks.velocity
    assert np.median(np.abs(da - m.a)[1:-1]) <= tol_a * m.peaks.acceleration


def test_sine_peaks():
    D, f = 0.04, 0.4  # NEES-UCSD S4: 4 cm, 10.05 cm/s, 0.0257 g at 0.40 Hz
    m = sine(amplitude=D, frequency_hz=f, duration_s=10, sample_rate_hz=FS)
    w = 2 * np.pi * f
    assert m.peaks.displacement == pytest.approx(D, rel=1e-5)
    assert m.peaks.velocity == pytest.approx(D * w, rel=1e-5)
    assert m.peaks.acceleration == pytest.approx(D * w * w, rel=1e-5)
    assert m.peaks.velocity == pytest.approx(0.1005, rel=1e-3)
    assert m.peaks.acceleration / G == pytest.approx(0.0257, rel=1e-2)
    _consistent(m)
    t, d, v, a = m
    assert t[1] == pytest.approx(1 / FS) and d.shape == v.shape == a.shape == t.shape


def test_tapered_sine_starts_and_ends_at_rest():
    m = tapered_sine(amplitude=0.2, frequency_hz=0.05, duration_s=120, sample_rate_hz=64, taper_cycles=1)
    assert m.peaks.displacement == pytest.approx(0.2, rel=1e-4)
    for x in (m.d, m.v, m.a):
        assert abs(x[0]) < 1e-12 and abs(x[-1]) < 1e-9
    _consistent(m)
    with pytest.raises(MotionError):
        tapered_sine(amplitude=0.1, frequency_hz=0.05, duration_s=30, sample_rate_hz=64, taper_cycles=1)


@pytest.mark.parametrize("D,V", [(0.05, 0.01), (0.50, 0.10), (0.625, 1.0), (0.675, 1.8)])
def test_triangle_peaks(D, V):  # NEES-UCSD T1, T4, T10, T12
    m = triangle(peak_displacement=D, peak_velocity=V, sample_rate_hz=FS, n_cycles=2)
    pk = m.peaks
    assert pk.displacement == pytest.approx(D, rel=1e-6)
    assert pk.velocity == pytest.approx(V, rel=1e-9)
    assert pk.acceleration == pytest.approx(m.info["peak_acceleration"], rel=1e-9)
    assert pk.acceleration <= 2 * G * (1 + 1e-9)
    Tr = m.info["rounding_s"]
    assert Tr >= 0.1 * m.info["period_s"] * (1 - 1e-9)
    assert pk.acceleration == pytest.approx(2 * V / Tr)
    assert abs(m.d[-1]) < 1e-9 and m.v[-1] == 0 and m.d[0] == 0 and m.v[0] == 0
    _consistent(m, tol_v=5e-3, tol_a=1e-9)  # central differences across the acceleration steps


def test_triangle_acceleration_limit_and_errors():
    m = triangle(peak_displacement=0.675, peak_velocity=1.8, sample_rate_hz=FS)
    assert m.info["acceleration_limited"]
    with pytest.raises(MotionError) as e:
        triangle(peak_displacement=0.01, peak_velocity=2.0, sample_rate_hz=FS)
    assert "peak_velocity" in str(e.value)


def test_white_noise_seed_and_rms():
    kw = dict(duration_s=30, sample_rate_hz=512, band_hz=(0.5, 50), rms_acceleration=0.1 * G)
    a = white_noise(seed=7, **kw)
    b = white_noise(seed=7, **kw)
    c = white_noise(seed=8, **kw)
    assert np.array_equal(a.a, b.a) and np.array_equal(a.d, b.d)
    assert not np.allclose(a.a, c.a)
    assert np.sqrt(np.mean(a.a**2)) == pytest.approx(0.1 * G, rel=1e-12)
    assert abs(np.mean(a.a)) < 1e-3 * 0.1 * G
    rms_d = np.sqrt(np.mean(a.d**2))
    assert abs(np.mean(a.d)) < 0.05 * rms_d
    for x in (a.d, a.v):  # drift-free, at rest at both ends
        assert abs(x[0]) < 1e-12 and abs(x[-1]) < 1e-12
    _consistent(a, tol_v=5e-3)
    d = white_noise(seed=(7, 1), duration_s=30, sample_rate_hz=512, band_hz=(1, 20), rms_displacement=0.01)
    assert np.sqrt(np.mean(d.d**2)) == pytest.approx(0.01, rel=1e-12)
    # band respected: spectrum of the untapered middle is empty outside the band
    spec = np.abs(np.fft.rfft(d.a))
    f = np.fft.rfftfreq(d.a.size, 1 / 512)
    assert spec[f > 25].max() < 0.05 * spec.max()
    with pytest.raises(MotionError):
        white_noise(
            seed=1, duration_s=30, sample_rate_hz=512, band_hz=(0.5, 50), rms_acceleration=1, rms_displacement=1
        )


def test_el_centro_at2():
    recs = el_centro_1940()
    assert set(recs) == set(EL_CENTRO_MAPPING) == {"x", "y", "z"}
    expect = {"x": ("180", 5372, 0.2808), "y": ("270", 5346, 0.2107), "z": ("UP", 5378, 0.1781)}
    for dof, (comp, npts, pga_g) in expect.items():
        dt, acc, header = recs[dof]
        assert header["component"] == comp and header["npts"] == npts == acc.size
        assert dt == 0.01 and header["units"] == "g"
        assert np.max(np.abs(acc)) / G == pytest.approx(pga_g, abs=5e-4)
    swapped = el_centro_1940({"x": "270", "y": "180"})
    assert swapped["x"].header["component"] == "270" and "z" not in swapped


AT2_OK = """PEER NGA STRONG MOTION DATABASE RECORD
Test event, 1/1/2000, Station, 090
ACCELERATION TIME SERIES IN UNITS OF G
NPTS= 6 DT= 0.02
 .1 -.2 .3E-01
 -.4E+00 .5 0.0
"""


@pytest.mark.parametrize("header", ["NPTS= 6 DT= 0.02", "NPTS=     6, DT=   .0200 SEC,", "     6    .0200    NPTS, DT"])
def test_at2_header_variants(tmp_path, header):
    p = tmp_path / "ok.AT2"
    p.write_text(AT2_OK.replace("NPTS= 6 DT= 0.02", header))
    dt, acc, h = read_at2(p)
    assert dt == 0.02 and h["npts"] == 6 and h["component"] == "090"
    np.testing.assert_allclose(acc, np.array([0.1, -0.2, 0.03, -0.4, 0.5, 0.0]) * G)


@pytest.mark.parametrize(
    "text,expected",
    [
        ("just some text\n", "not an AT2 file"),
        (AT2_OK.replace("NPTS= 6 DT= 0.02", "points and step follow"), "no NPTS/DT"),
        (AT2_OK.replace("NPTS= 6", "NPTS= 7"), "has 6 values but its header says NPTS=7"),
        (AT2_OK.replace(".5", "abc"), "non-number 'abc'"),
    ],
)
def test_malformed_at2(tmp_path, text, expected):
    p = tmp_path / "bad.AT2"
    p.write_text(text)
    with pytest.raises(MotionError) as e:
        read_at2(p)
    msg = str(e.value)
    assert isinstance(e.value, UserError) and "\n" not in msg and "bad.AT2" in msg and expected in msg
    with pytest.raises(MotionError):
        read_at2(tmp_path / "missing.AT2")


def test_el_centro_processing_drift_free():
    ms = el_centro_motions(sample_rate_hz=FS)
    ts = [m.t for m in ms.values()]
    assert all(np.array_equal(ts[0], t) for t in ts)
    for dof, m in ms.items():
        pk = m.peaks
        assert abs(m.d[-1]) < 1e-6 * pk.displacement and abs(m.v[-1]) < 1e-9
        assert m.d[0] == 0 and m.v[0] == 0
        # the end correction is a small fraction of the motion: the filter did the work
        assert m.info["end_correction_peak_m"] < 0.05 * pk.displacement
        v, d = integrate(m.a, m.dt)  # d, v, a consistent (same integration)
        np.testing.assert_allclose(d, m.d, atol=1e-9 * pk.displacement + 1e-12)
        assert pk.acceleration == pytest.approx(np.max(np.abs(el_centro_1940()[dof].acceleration)), rel=0.02)
    assert 0.10 < ms["y"].peaks.displacement < 0.20  # E-W, 0.1 Hz high-pass: 0.156 m
    m80 = el_centro_motions(sample_rate_hz=FS, amplitude_factor=0.8)
    assert m80["y"].peaks.displacement == pytest.approx(0.8 * ms["y"].peaks.displacement, rel=1e-9)


def test_record_scaling_and_resampling():
    dt = 0.01
    t = np.arange(2000) * dt
    acc = np.sin(2 * np.pi * 2.0 * t) * np.hanning(t.size)
    assert np.max(np.abs(scale_amplitude(acc, target_pga=3.0))) == pytest.approx(3.0)
    y = resample(acc, dt, 1024)
    assert y.size == pytest.approx(acc.size * 10.24, abs=2)
    tt = np.arange(y.size) / 1024
    ref = np.sin(2 * np.pi * 2.0 * tt) * np.interp(tt, t, np.hanning(t.size))
    assert np.max(np.abs(y - ref)[200:-200]) < 1e-2
    # similitude: time compressed by sqrt(4) -> 2x frequency, displacement / 4, same acceleration
    lam = 0.25
    full = process_record(acc, dt, sample_rate_hz=FS, pad_before_s=0, pad_after_s=0)
    small = process_record(
        acc, dt, sample_rate_hz=FS, time_factor=np.sqrt(lam), highpass_hz=0.2, pad_before_s=0, pad_after_s=0
    )
    assert time_scale(dt, np.sqrt(lam)) == pytest.approx(0.005)
    assert small.peaks.acceleration == pytest.approx(full.peaks.acceleration, rel=0.02)
    assert small.peaks.displacement == pytest.approx(lam * full.peaks.displacement, rel=0.03)
    with pytest.raises(MotionError):
        process_record(acc, dt, sample_rate_hz=FS, baseline="magic")


def test_check_limits_message():
    limits = {
        "stroke_m": {"x": 0.25, "y": 0.15, "z": 0.10},
        "velocity_m_s": 1.1,
        "acceleration_m_s2": 1.0 * G,
        "rotation_rad": 0.02,
    }
    warn = check_limits({"x": Peaks(0.31, 0.5, 3.0), "y": Peaks(0.1, 1.2, 3.0), "rx": Peaks(0.01, 1, 1)}, limits)
    assert warn[0] == "x peak displacement 0.31 m exceeds the +/-0.25 m stroke by 24 %"
    assert warn[1].startswith("y peak velocity 1.2 m/s exceeds the +/-1.1 m/s velocity limit by 9 %")
    assert len(warn) == 2
    assert check_limits({"x": sine(amplitude=0.1, frequency_hz=0.5, duration_s=4, sample_rate_hz=100)}, limits) == []


@pytest.mark.parametrize("zeta", [0.05, 0.02])
def test_response_spectrum_closed_form(zeta):
    """Harmonic ground acceleration A0 sin(W t): steady-state |u| = A0 / sqrt((w^2-W^2)^2 + (2 z w W)^2)."""
    A0, fW, fs = 1.0, 2.0, 200.0
    m = tapered_sine(
        amplitude=A0 / (2 * np.pi * fW) ** 2, frequency_hz=fW, duration_s=120, sample_rate_hz=fs, taper_cycles=60
    )
    freqs = np.array([0.5, 1.0, 2.0, 4.0, 10.0])
    psa = response_spectrum(m.a, 1 / fs, freqs=freqs, damping=zeta)
    w, W = 2 * np.pi * freqs, 2 * np.pi * fW
    expect = w**2 * A0 / np.sqrt((w**2 - W**2) ** 2 + (2 * zeta * w * W) ** 2)
    np.testing.assert_allclose(psa, expect, rtol=2e-3)
    assert psa[2] == pytest.approx(A0 / (2 * zeta), rel=2e-3)  # resonance
    # zero period gives PGA; periods and freqs agree
    p = response_spectrum(m.a, 1 / fs, periods=np.array([0.0, 0.5]), damping=zeta)
    assert p[0] == pytest.approx(np.max(np.abs(m.a))) and p[1] == pytest.approx(psa[2])


def test_response_spectrum_filters_are_remembered_and_bit_identical():
    """The oscillator filters are cached per (frequencies, damping, step): a second spectrum
    at the same periods reuses them (read-only) and equals the uncached computation."""
    from sim.scenario import motions as MO

    rng = np.random.default_rng(7)
    acc = rng.normal(0, 1, 2000)
    periods = np.linspace(0.05, 2.0, 17)
    MO._FOH_CACHE.clear()
    first = MO.response_spectrum(acc, 1 / 512, periods)
    assert len(MO._FOH_CACHE) == 1
    b, a = next(iter(MO._FOH_CACHE.values()))
    assert not b.flags.writeable and not a.flags.writeable
    again = MO.response_spectrum(acc, 1 / 512, periods)
    assert len(MO._FOH_CACHE) == 1
    assert np.array_equal(first, again)
    w = 2 * np.pi / periods
    b0, a0 = MO._foh_filters_uncached(w, 0.05, 1 / 512)
    assert np.array_equal(b, b0) and np.array_equal(a, a0)
    MO.response_spectrum(acc, 1 / 256, periods)  # another step: another entry
    assert len(MO._FOH_CACHE) == 2

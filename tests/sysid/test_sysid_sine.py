"""Tests for servoscope.sysid.sine.fit_sine (oracles: numpy formulas, python-control)."""

from __future__ import annotations

import json
import math

import control
import numpy as np
import pytest

from servoscope.errors import ServoscopeError
from servoscope.sysid.sine import SineFit, fit_sine

FPS = 100.0
T0 = 0.1234  # off the frame grid
PAPER_G = control.tf([0.23 * 37.0**2], [1.0, 2 * 0.65 * 37.0, 37.0**2])


def frames(duration_s: float = 3.0, offset_s: float = 0.0037) -> np.ndarray:
    return np.arange(int(round(duration_s * FPS))) / FPS + offset_s


def sine(t, amp, f, phase, offset=0.0, t0=T0):
    return offset + amp * np.sin(2 * np.pi * f * (t - t0) + phase)


def wrap(x):
    return (x + np.pi) % (2 * np.pi) - np.pi


def test_recovers_parameters_within_few_stderr():
    t = frames()
    rng = np.random.default_rng(42)
    amp, f, ph, off = 0.05, 3.0, -0.7, 0.01
    y = sine(t, amp, f, ph, off) + 1e-4 * rng.standard_normal(t.size)
    r = fit_sine(t, y, 3.0, t0_s=T0, settle_s=0.5)
    assert isinstance(r, SineFit)
    assert abs(r.amplitude - amp) < 4 * r.amplitude_stderr
    assert abs(r.frequency_hz - f) < 4 * r.frequency_stderr_hz
    assert abs(wrap(r.phase_rad - ph)) < 4 * r.phase_stderr_rad
    assert abs(r.offset - off) < 4 * r.offset_stderr
    # Stderrs are small but not absurdly small.
    assert 1e-6 < r.amplitude_stderr < 1e-4
    assert r.residual_rms == pytest.approx(1e-4, rel=0.2)
    assert r.commanded_frequency_hz == 3.0
    assert r.window_s[0] >= T0 + 0.5 and r.window_s[1] == pytest.approx(t[-1])
    assert r.n_samples == np.count_nonzero(t >= T0 + 0.5)
    assert r.warnings == ()


def test_refined_frequency_when_commanded_is_slightly_off():
    t = frames()
    rng = np.random.default_rng(1)
    y = sine(t, 0.04, 5.03, 0.3) + 1e-4 * rng.standard_normal(t.size)
    r = fit_sine(t, y, 5.0, t0_s=T0)
    assert abs(r.frequency_hz - 5.03) < 4 * r.frequency_stderr_hz
    # Phase relative to t0 uses the refined frequency.
    assert abs(wrap(r.phase_rad - 0.3)) < 4 * r.phase_stderr_rad
    # Without refinement the frequency is the commanded one.
    r2 = fit_sine(t, y, 5.0, t0_s=T0, refine_frequency=False)
    assert r2.frequency_hz == 5.0 and r2.frequency_stderr_hz is None


def test_stderr_is_honest_monte_carlo():
    t = frames()
    amp, f, ph = 0.05, 2.0, 0.9
    clean = sine(t, amp, f, ph, 0.02)
    est = {"a": [], "p": [], "f": []}
    rep = {"a": [], "p": [], "f": []}
    for seed in range(50):
        rng = np.random.default_rng(1000 + seed)
        r = fit_sine(t, clean + 1e-4 * rng.standard_normal(t.size), f, t0_s=T0, refine_frequency=True)
        est["a"].append(r.amplitude)
        est["p"].append(r.phase_rad)
        est["f"].append(r.frequency_hz)
        rep["a"].append(r.amplitude_stderr)
        rep["p"].append(r.phase_stderr_rad)
        rep["f"].append(r.frequency_stderr_hz)
    for k in est:
        emp = np.std(est[k], ddof=1)
        reported = np.mean(rep[k])
        assert 0.7 < emp / reported < 1.3, (k, emp, reported)
    # And unbiased at the level of the standard error of the mean.
    assert abs(np.mean(est["a"]) - amp) < 4 * np.mean(rep["a"]) / math.sqrt(50)
    assert abs(np.mean(est["p"]) - ph) < 4 * np.mean(rep["p"]) / math.sqrt(50)


@pytest.mark.parametrize("f_hz", [1.0, 4.0, 9.0])
def test_phase_matches_python_control_with_dead_time(f_hz):
    """Output of G(s)e^{-s tau} driven by A sin(2 pi f (t - t0)), t >= t0."""
    tau, a_in = 0.085, 0.1
    dt = 1e-4
    t_fine = np.arange(0.0, 3.2, dt)
    t0 = 0.1234  # on the fine grid, off the 100 fps frame grid
    u = np.where(t_fine >= t0, a_in * np.sin(2 * np.pi * f_hz * (t_fine - t0)), 0.0)
    y_fine = np.asarray(control.forced_response(PAPER_G, T=t_fine, U=u).outputs).ravel()
    t = frames(3.0)
    y = np.interp(t - tau, t_fine, y_fine, left=0.0)
    rng = np.random.default_rng(7)
    y = y + 1e-4 * rng.standard_normal(t.size)
    r = fit_sine(t, y, f_hz, t0_s=t0, settle_s=0.5)
    w = 2 * np.pi * f_hz
    g = complex(control.evalfr(PAPER_G, 1j * w)) * np.exp(-1j * w * tau)
    assert abs(r.amplitude / a_in - abs(g)) < 5 * r.amplitude_stderr / a_in + 1e-5
    assert abs(wrap(r.phase_rad - np.angle(g))) < 5 * r.phase_stderr_rad + 1e-4
    assert r.fidelity > 0.99


def test_no_t0_gives_no_phase_and_window_from_first_sample():
    t = frames() + 10.0
    y = sine(t, 0.05, 2.0, 0.4, t0=10.0)
    r = fit_sine(t, y, 2.0, settle_s=0.2)
    assert r.phase_rad is None and r.phase_stderr_rad is None and r.phase_deg is None
    assert r.t0_s is None
    assert r.window_s[0] >= t[0] + 0.2
    assert r.reference_time_s == r.window_s[0]
    assert r.amplitude == pytest.approx(0.05, rel=1e-9)
    np.testing.assert_allclose(r.model(t), y, atol=1e-10)


def test_noise_free_is_exact_and_model_matches():
    t = frames()
    y = sine(t, 0.03, 7.0, -2.5, -0.1)
    r = fit_sine(t, y, 7.0, t0_s=T0)
    assert r.amplitude == pytest.approx(0.03, rel=1e-9)
    assert r.frequency_hz == pytest.approx(7.0, rel=1e-10)
    assert wrap(r.phase_rad + 2.5) == pytest.approx(0.0, abs=1e-8)
    assert r.fidelity == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(r.y - r.model(r.time_s), r.residual, atol=1e-15)


def test_fidelity_with_third_harmonic():
    # Whole number of periods: fundamental power / total AC power is exact.
    t = np.arange(400) / FPS  # 4 s
    a1, a3 = 0.05, 0.01
    y = a1 * np.sin(2 * np.pi * 2.0 * t) + a3 * np.sin(2 * np.pi * 6.0 * t + 0.3)
    r = fit_sine(t, y, 2.0, t0_s=0.0, settle_s=0.0, refine_frequency=False)
    assert r.fidelity == pytest.approx(a1**2 / (a1**2 + a3**2), rel=1e-6)
    assert r.amplitude == pytest.approx(a1, rel=1e-9)


def test_valid_mask_and_nans_are_excluded():
    t = frames()
    rng = np.random.default_rng(3)
    y = sine(t, 0.05, 3.0, 0.2) + 1e-4 * rng.standard_normal(t.size)
    ref = fit_sine(t, y, 3.0, t0_s=T0)
    bad = y.copy()
    valid = np.ones(t.size, bool)
    valid[100:110] = False
    bad[100:110] = 5.0
    bad[200] = np.nan
    r = fit_sine(t, bad, 3.0, t0_s=T0, valid=valid)
    assert r.n_samples == ref.n_samples - 11
    assert abs(r.amplitude - ref.amplitude) < 3 * ref.amplitude_stderr


def test_warnings_short_window_and_few_samples():
    t = np.arange(12) / FPS + 0.6
    y = sine(t, 0.05, 3.0, 0.2)
    r = fit_sine(t, y, 3.0, t0_s=0.0, settle_s=0.5)
    text = " ".join(r.warnings)
    assert "periods" in text and "samples" in text


def test_warning_when_energy_is_not_at_commanded_frequency():
    t = frames()
    y = sine(t, 0.05, 3.0, 0.2) + 1e-4 * np.random.default_rng(0).standard_normal(t.size)
    r = fit_sine(t, y, 4.5, t0_s=T0)
    assert any("periodogram" in w for w in r.warnings)
    ok = fit_sine(t, y, 3.0, t0_s=T0)
    assert not any("periodogram" in w for w in ok.warnings)


def test_too_few_samples_raises():
    t = np.arange(4) / FPS
    with pytest.raises(ServoscopeError):
        fit_sine(t, np.sin(t), 1.0, settle_s=0.0)
    t = frames()
    with pytest.raises(ServoscopeError):
        fit_sine(t, np.sin(t), 1.0, t0_s=T0, settle_s=10.0)
    with pytest.raises(ServoscopeError):
        fit_sine(t, np.sin(t)[:-1], 1.0)
    with pytest.raises(ServoscopeError):
        fit_sine(t, np.sin(t), -1.0)
    with pytest.raises(ServoscopeError):
        fit_sine(t, np.sin(t), 1.0, valid=np.ones(3, bool))


def test_summary_is_json_serializable():
    t = frames()
    r = fit_sine(t, sine(t, 0.05, 2.0, 0.1), 2.0)  # no t0: phase None
    s = r.summary()
    json.dumps(s, allow_nan=False)
    assert s["phase_rad"] is None and s["amplitude"] == pytest.approx(0.05)
    assert isinstance(s["n_samples"], int) and isinstance(s["warnings"], list)


def test_to_pandas_is_the_window_with_its_fit():
    import pandas as pd  # a test dependency (the test extra): the real branch, not the ImportError one

    t = frames()
    r = fit_sine(t, sine(t, 0.05, 2.0, 0.1), 2.0, t0_s=T0)
    df = r.to_pandas()
    assert isinstance(df, pd.DataFrame)
    assert list(df.columns) == ["time_s", "y", "fitted", "residual"]
    assert len(df) == r.n_samples
    np.testing.assert_array_equal(df["time_s"].to_numpy(), r.time_s)
    np.testing.assert_array_equal(df["y"].to_numpy(), r.y)
    np.testing.assert_allclose(df["fitted"].to_numpy(), r.model(r.time_s))
    np.testing.assert_allclose(df["y"] - df["fitted"], df["residual"], atol=1e-12)


def test_auto_refinement_keeps_commanded_frequency_on_short_windows():
    """On half a period a free frequency costs phase accuracy; "auto" does not pay it."""
    t = np.arange(0.0, 1.2, 0.01)
    t0, f, ph = 0.2, 1.0, -0.4
    spread = {}
    for mode in ("auto", True):
        phases = []
        for seed in range(40):
            rng = np.random.default_rng(seed)
            y = np.where(t >= t0, 0.02 * np.sin(2 * np.pi * f * (t - t0) + ph), 0.0) + 2e-4 * rng.standard_normal(t.size)
            r = fit_sine(t, y, f, t0_s=t0, settle_s=0.5, refine_frequency=mode)
            phases.append(r.phase_rad)
            if mode == "auto":
                assert abs(r.phase_rad - ph) < 5 * r.phase_stderr_rad
        spread[mode] = np.std(phases)
    assert spread["auto"] < 0.5 * spread[True]


def test_t0_uncertainty_widens_the_phase_error():
    t = frames()
    y = sine(t, 0.05, 4.0, 0.2) + 1e-4 * np.random.default_rng(5).standard_normal(t.size)
    a = fit_sine(t, y, 4.0, t0_s=T0)
    b = fit_sine(t, y, 4.0, t0_s=T0, t0_stderr_s=1e-3)
    assert b.phase_stderr_rad == pytest.approx(math.hypot(a.phase_stderr_rad, 2 * math.pi * 4.0 * 1e-3), rel=1e-9)
    assert b.phase_rad == a.phase_rad


# ------------------------------------------------ steady state, harmonics, flags
def test_auto_window_starts_after_the_transient():
    """Twin output from rest (85 ms dead time, then the transient): auto settle finds its end."""
    from servoscope.simulate import PAPER_SERVO, InputSignal

    t = frames(3.5)
    f = 2.0
    y_clean = PAPER_SERVO.response(InputSignal("sine", 0.1, f, t0_s=T0), t)
    rng = np.random.default_rng(8)
    y = y_clean + 1e-4 * rng.standard_normal(t.size)
    r = fit_sine(t, y, f, t0_s=T0)
    # Transient: dead time + decay exp(-zeta*wn*t) = exp(-24 t) from ~0.01 rad
    # to the 3e-4 rad detection level takes ~0.15 s.
    assert 0.15 < r.settle_s < 0.45
    assert r.window_s[0] == pytest.approx(T0 + r.settle_s, abs=0.011)
    g = complex(control.evalfr(PAPER_G, 2j * np.pi * f)) * np.exp(-2j * np.pi * f * 0.085)
    assert abs(r.amplitude - 0.1 * abs(g)) < 4 * r.amplitude_stderr
    assert abs(wrap(r.phase_rad - np.angle(g))) < 4 * r.phase_stderr_rad
    assert "transient" not in r.flags
    # Too short a numeric settle_s: the remaining transient is reported.
    short = fit_sine(t, y, f, t0_s=T0, settle_s=0.02)
    assert "transient" in short.flags and any("settle_s='auto'" in w for w in short.warnings)
    assert short.settle_s == pytest.approx(0.02)


def test_harmonics_and_thd_are_exact_for_a_distorted_sine():
    t = np.arange(400) / FPS
    a1, a2, a3, a5 = 0.05, 0.004, 0.002, 0.001
    w = 2 * np.pi * 2.0
    y = a1 * np.sin(w * t) + a2 * np.cos(2 * w * t + 0.4) + a3 * np.sin(3 * w * t - 1.0) + a5 * np.sin(5 * w * t)
    r = fit_sine(t, y, 2.0, t0_s=0.0, settle_s=0.0, refine_frequency=False)
    np.testing.assert_allclose(r.harmonic_amplitudes, [a2, a3, 0.0, a5], atol=1e-12)
    assert r.thd == pytest.approx(math.sqrt(a2**2 + a3**2 + a5**2) / a1, rel=1e-9)
    assert r.harmonic_residual_rms < 1e-12
    assert "distorted" in r.flags  # 9 % THD, far above noise
    # Harmonics at or above 95 % of Nyquist are not fitted: 12 Hz at 100 fps -> only k = 2, 3.
    r12 = fit_sine(t, np.sin(2 * np.pi * 12.0 * t), 12.0, t0_s=0.0, settle_s=0.0)
    assert r12.harmonic_amplitudes[2:] == (None, None)
    assert r12.thd == pytest.approx(0.0, abs=1e-9) and r12.flags == ()
    json.dumps(r.summary(), allow_nan=False)
    assert r.summary()["flags"] == ["distorted"]


def test_pure_noisy_sine_is_not_flagged_distorted():
    t = frames(4.0)
    count = 0
    for seed in range(20):
        y = sine(t, 0.01, 3.0, 0.2) + 5e-4 * np.random.default_rng(seed).standard_normal(t.size)
        r = fit_sine(t, y, 3.0, t0_s=T0)
        count += "distorted" in r.flags
        assert r.thd < 0.05
    assert count <= 1


def test_flags_for_invalid_frames_aliasing_and_frequency_mismatch():
    t = frames()
    y = sine(t, 0.05, 3.0, 0.2) + 1e-4 * np.random.default_rng(0).standard_normal(t.size)
    valid = np.ones(t.size, bool)
    window = t >= T0 + 0.5
    idx = np.nonzero(window)[0]
    valid[idx[::3]] = False  # a third of the window's frames lost
    r = fit_sine(t, y, 3.0, t0_s=T0, settle_s=0.5, valid=valid)
    assert r.invalid_fraction == pytest.approx(idx[::3].size / idx.size)
    assert "invalid_frames" in r.flags
    ok = fit_sine(t, y, 3.0, t0_s=T0, settle_s=0.5)
    assert ok.invalid_fraction == 0.0 and ok.flags == ()
    # 44 Hz at 100 frames/s: 88 % of the Nyquist frequency.
    y44 = sine(t, 0.05, 44.0, 0.2)
    assert "aliasing" in fit_sine(t, y44, 44.0, t0_s=T0).flags
    # Energy at 3 Hz, commanded 4.5 Hz.
    assert "frequency_mismatch" in fit_sine(t, y, 4.5, t0_s=T0).flags
    with pytest.raises(ServoscopeError, match="settle_s"):
        fit_sine(t, y, 3.0, settle_s="soon")


# ------------------------------------------------- correlated noise (HAC)
def _newey_west_oracle(X, r, lag):
    """Newey–West by its textbook formula: Σ_l w_l Σ_t x_t r_t r_{t-l} x_{t-l}ᵀ."""
    n, p = X.shape
    S = np.zeros((p, p))
    for l in range(-lag, lag + 1):
        w = 1.0 - abs(l) / (lag + 1.0)
        for t in range(max(0, l), min(n, n + l)):
            S += w * np.outer(X[t] * r[t], X[t - l] * r[t - l])
    B = np.linalg.inv(X.T @ X)
    return B @ S @ B * n / (n - p)


def test_hac_covariance_is_the_newey_west_formula():
    from servoscope.sysid.sine import hac_covariance, newey_west_lag

    rng = np.random.default_rng(3)
    t = frames(1.2)
    X = np.column_stack([np.ones_like(t), np.cos(2 * np.pi * 2.0 * t), np.sin(2 * np.pi * 2.0 * t)])
    r = rng.standard_normal(t.size)
    for lag in (1, 4):
        np.testing.assert_allclose(hac_covariance(X, r, lag), _newey_west_oracle(X, r, lag), rtol=1e-10)
    assert newey_west_lag(100) == 4 and newey_west_lag(350) == 5 and newey_west_lag(3) == 1


def test_stderr_is_honest_for_correlated_noise():
    """AR(1) noise (φ = 0.8): the white-noise formula's stderr is too small; HAC's is not."""
    import servoscope.sysid.hac as hac_mod

    t = frames(4.0)
    clean = sine(t, 0.02, 0.7, 0.4)
    amps, se_hac, se_white = [], [], []
    for seed in range(60):
        rng = np.random.default_rng(500 + seed)
        e = np.empty(t.size)
        e[0] = rng.standard_normal()
        for i in range(1, t.size):
            e[i] = 0.8 * e[i - 1] + math.sqrt(1 - 0.64) * rng.standard_normal()
        y = clean + 1e-4 * e
        r = fit_sine(t, y, 0.7, t0_s=T0, settle_s=0.2, refine_frequency=False)
        amps.append(r.amplitude)
        se_hac.append(r.amplitude_stderr)
        try:
            hac_mod.USE_HAC = False
            se_white.append(fit_sine(t, y, 0.7, t0_s=T0, settle_s=0.2, refine_frequency=False).amplitude_stderr)
        finally:
            hac_mod.USE_HAC = True
    emp = np.std(amps, ddof=1)
    # Spectral density of AR(1) at low frequency is (1+φ)/(1-φ) = 9 times the white one's.
    assert emp / np.mean(se_white) > 2.0
    assert 0.7 < emp / np.mean(se_hac) < 1.4, (emp, np.mean(se_hac))


# ------------------------------------- distortion vs. tracking artefacts
def _two_markers(pose, rng, lock_px=0.03, noise_px=0.005):
    """Centroids of two stickers on a rigid blade turning by ``pose`` (rad) about a pivot,
    each pulled towards pixel centres (pixel locking: an error set by its sub-pixel position)."""
    centre = np.array([400.3, 290.7])
    out = []
    for radius in (450.0, -150.0):
        p = centre + radius * np.column_stack([np.cos(0.2 + pose), np.sin(0.2 + pose)])
        out.append(p - lock_px * np.sin(2 * np.pi * p) + noise_px * rng.standard_normal(p.shape))
    lead, trail = out
    return lead, trail, np.arctan2(lead[:, 1] - trail[:, 1], lead[:, 0] - trail[:, 0])


def test_rigid_motion_null_cancels_any_rigid_motion():
    from servoscope.sysid import rigid_motion_null

    t = frames(2.0)
    # A strongly non-sinusoidal pose: the null channel holds none of it.
    pose = 0.02 * np.sign(np.sin(2 * np.pi * 1.3 * t)) + 0.01 * np.sin(2 * np.pi * 4.1 * t)
    lead, trail, _ = _two_markers(pose, np.random.default_rng(0), lock_px=0.0, noise_px=0.0)
    null = rigid_motion_null(lead, trail)
    assert np.nanmax(np.abs(null)) < 1e-12
    # Invalid frames stay NaN; too few frames give all NaN.
    valid = np.ones(t.size, bool)
    valid[5] = False
    assert np.isnan(rigid_motion_null(lead, trail, valid)[5])
    assert np.all(np.isnan(rigid_motion_null(lead[:2], trail[:2])))


def test_tracking_artefacts_are_not_flagged_as_distortion_but_backlash_is():
    from servoscope.simulate.servo import _play_operator
    from servoscope.sysid import rigid_motion_null

    t = frames(4.0)
    rng = np.random.default_rng(1)
    # A linear response of 2 mrad at 12 Hz: the stickers move < 1 px, and
    # pixel locking puts 1.5 % of harmonics into the angle.
    lead, trail, angle = _two_markers(0.002 * np.sin(2 * np.pi * 12.0 * t), rng)
    plain = fit_sine(t, angle, 12.0, t0_s=0.0, settle_s=0.5)
    assert plain.thd > 0.01 and "distorted" in plain.flags  # the false flag without a null channel
    nulled = fit_sine(t, angle, 12.0, t0_s=0.0, settle_s=0.5, null_channel=rigid_motion_null(lead, trail))
    assert "distorted" not in nulled.flags and nulled.null_harmonic_amplitudes[0] > 0
    assert nulled.thd == pytest.approx(plain.thd)  # the measurement is the same; only the test changed
    json.dumps(nulled.summary(), allow_nan=False)
    # Backlash (a play of 1 mrad) on the same blade and tracking: flagged.
    fine = np.arange(0.0, 4.0, 1e-4) + t[0]
    pose = np.interp(t, fine, _play_operator(0.004 * np.sin(2 * np.pi * 5.0 * fine), 0.0005))
    lead, trail, angle = _two_markers(pose, rng)
    bl = fit_sine(t, angle, 5.0, t0_s=0.0, settle_s=0.5, null_channel=rigid_motion_null(lead, trail))
    assert "distorted" in bl.flags and bl.thd > 0.03
    with pytest.raises(ServoscopeError, match="null_channel"):
        fit_sine(t, angle, 5.0, t0_s=0.0, null_channel=angle[:-1])


# ------------------------------------------------------------ the codec check
def _codec_footage(f_hz, gop=15, shrink=0.97, lag_rad=0.01, seed=3):
    """A dwell as a codec records it: intra-coded frames (every ``gop``-th) show the true sine; the frames
    predicted from them show it shrunk and late (as the twin's MPEG-2 does to small motions)."""
    t = frames(3.0)
    rng = np.random.default_rng(seed)
    intra = np.arange(t.size) % gop == 0
    true = sine(t, 0.02, f_hz, -0.4)
    coded = np.where(intra, true, sine(t, 0.02 * shrink, f_hz, -0.4 - lag_rad))
    return t, coded + 2e-5 * rng.standard_normal(t.size), intra


def test_codec_check_takes_gain_and_phase_from_intra_frames():
    t, y, intra = _codec_footage(4.1)
    plain = fit_sine(t, y, 4.1, t0_s=T0, settle_s=0.3)
    checked = fit_sine(t, y, 4.1, t0_s=T0, settle_s=0.3, intra=intra)
    # Without the check the codec's 3 % is in the gain, far beyond its standard error.
    assert abs(plain.amplitude - 0.02) > 10 * plain.amplitude_stderr
    assert checked.estimator == "intra frames" and "codec" in checked.flags
    assert checked.n_intra == int(np.count_nonzero(intra & (t >= T0 + checked.settle_s)))
    # The truth, within the stated errors.
    assert abs(checked.amplitude - 0.02) < 3 * checked.amplitude_stderr
    assert abs(wrap(checked.phase_rad + 0.4)) < 3 * checked.phase_stderr_rad
    # The codec's effect, measured: the predicted frames (14 of 15) shrink by ~3 % and lag by ~0.01 rad.
    assert checked.codec_gain_bias == pytest.approx(plain.amplitude / checked.amplitude - 1.0)
    assert -0.03 < checked.codec_gain_bias < -0.024
    assert abs(checked.codec_gain_bias + 0.028) < 3 * checked.codec_gain_bias_stderr
    assert -0.011 < checked.codec_phase_bias_rad < -0.008
    assert checked.all_frames_amplitude == pytest.approx(plain.amplitude)
    summary = checked.summary()
    assert summary["estimator"] == "intra frames" and summary["codec_gain_bias"] == checked.codec_gain_bias


def test_codec_check_oracle_is_the_intra_frames_own_least_squares():
    t, y, intra = _codec_footage(2.3, shrink=0.99)
    fit = fit_sine(t, y, 2.3, t0_s=T0, settle_s=0.3, intra=intra, refine_frequency=False)
    sel = intra & (t >= T0 + fit.settle_s)
    X = np.column_stack([np.ones(sel.sum()), np.sin(2 * np.pi * 2.3 * (t[sel] - T0)),
                         np.cos(2 * np.pi * 2.3 * (t[sel] - T0))])
    c, *_ = np.linalg.lstsq(X, y[sel], rcond=None)
    assert fit.amplitude == pytest.approx(math.hypot(c[1], c[2]), rel=1e-9)
    assert fit.phase_rad == pytest.approx(math.atan2(c[2], c[1]), abs=1e-9)


def test_codec_check_skipped_or_inconclusive():
    t, y, intra = _codec_footage(4.1)
    # Every frame intra-coded (uncompressed footage): nothing to check.
    every = fit_sine(t, y, 4.1, t0_s=T0, settle_s=0.3, intra=np.ones(t.size, bool))
    assert every.estimator == "all frames" and every.codec_gain_bias is None and every.n_intra == 0
    # A GOP of seconds: too few intra frames in the window.
    sparse = fit_sine(t, y, 4.1, t0_s=T0, settle_s=0.3, intra=np.arange(t.size) % 150 == 0)
    assert sparse.estimator == "all frames" and sparse.codec_gain_bias is None and 0 < sparse.n_intra < 8
    # I-frames at the dwell's own frequency (100/15 Hz) sample one phase only: the check cannot decide.
    f = FPS / 15
    t, y, intra = _codec_footage(f)
    stuck = fit_sine(t, y, f, t0_s=T0, settle_s=0.3, intra=intra)
    assert stuck.estimator == "all frames"
    assert any("codec check impossible" in w for w in stuck.warnings)
    # Near it (the I-frames' phase drifts by a tenth of a period over the dwell): inconclusive.
    t, y, intra = _codec_footage(f * 1.012)
    near = fit_sine(t, y, f * 1.012, t0_s=T0, settle_s=0.3, intra=intra)
    assert near.estimator == "all frames"
    assert any("codec check inconclusive" in w for w in near.warnings), near.warnings
    with pytest.raises(ServoscopeError, match="intra"):
        fit_sine(t, y, f, t0_s=T0, intra=intra[:-1])

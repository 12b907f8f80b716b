"""A frequency sweep's response with coherence (CIFER's spectral method, issue 31).

The paper's servo ``0.23·37²/(s² + 2·0.65·37·s + 37²)·e^(−0.085 s)`` is simulated with
python-control's ``forced_response`` at 4000 samples/s (its input is interpolated linearly
between samples: 4 kHz keeps that error below 1e-4 at 15 Hz) and sampled at the camera's
rate. The dead time is exact: the input is the chirp evaluated at ``t − 0.085`` (python-control
has no pure delay in a continuous transfer function, and a Padé approximant would bend the
phase at the top of the band). The command: a 12 s logarithmic chirp 0.5–15 Hz, a sine from
zero (``phi = −90``) starting at t0 = 1 s, amplitude 0.1, with 1 s at rest before and after;
white measurement noise of 5e-5 rad (the tracker's ~3 mdeg) or 1e-3 rad (noisy).
"""

from __future__ import annotations

import dataclasses
import functools
import json

import numpy as np
import pytest
from scipy import signal

from servoscope.errors import ServoscopeError
from servoscope.sysid import fit_transfer_function
from servoscope.sysid.frequency_response import FrequencyResponse
from servoscope.sysid.sweep import SweepResponse, sweep_response, window_estimate

K, WN, ZETA, TAU = 0.23, 37.0, 0.65, 0.085
T0, T_SWEEP, F0, F1, AMP = 1.0, 12.0, 0.5, 15.0, 0.1
LOW, NOISY = 5e-5, 1e-3


def truth(f_hz):
    s = 2j * np.pi * np.asarray(f_hz)
    return K * WN**2 / (s**2 + 2 * ZETA * WN * s + WN**2) * np.exp(-s * TAU)


def chirp(t):
    tt = np.asarray(t) - T0
    u = AMP * signal.chirp(np.clip(tt, 0, T_SWEEP), F0, T_SWEEP, F1, method="logarithmic", phi=-90)
    return np.where((tt >= 0) & (tt <= T_SWEEP), u, 0.0)


@functools.lru_cache(maxsize=None)
def _clean(fps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    import control

    fine = 4000
    t_fine = np.arange(0, T0 + T_SWEEP + 1.0, 1 / fine)
    servo = control.tf([K * WN**2], [1, 2 * ZETA * WN, WN**2])
    y = control.forced_response(servo, t_fine, chirp(t_fine - TAU)).outputs
    step = fine // fps
    t = t_fine[::step]
    return t, chirp(t), y[::step]


def record(fps: int, noise: float, seed: int = 0):
    t, u, y = _clean(fps)
    return t, u, y + noise * np.random.default_rng(seed).standard_normal(t.size)


@functools.lru_cache(maxsize=None)
def _response(fps: int, noise: float) -> SweepResponse:
    t, u, y = record(fps, noise)
    return sweep_response(t, u, y, from_hz=F0, to_hz=F1)


# (a) ------------------------------------------------------------------ one window
def test_one_window_is_what_scipy_gives():
    t, u, y = record(100, NOISY)
    fs, nperseg = 100.0, 200
    est = window_estimate(u, y, fs, nperseg, overlap=0.5)
    kw = dict(fs=fs, window="hann", nperseg=nperseg, noverlap=100)
    f, gxy = signal.csd(u, y, **kw)
    _, gxx = signal.welch(u, **kw)
    _, coh = signal.coherence(u, y, **kw)
    np.testing.assert_allclose(est.frequency_hz, f)
    np.testing.assert_allclose(est.response[1:], (gxy / gxx)[1:], rtol=1e-12)
    np.testing.assert_allclose(est.coherence[1:], coh[1:], rtol=1e-10, atol=1e-14)
    assert est.n_averages == 1 + (u.size - nperseg) // 100
    # Welch's correction for 50 % overlapped Hann segments: about 0.95 of them independent.
    assert 0.9 * est.n_averages < est.effective_averages < est.n_averages
    g2 = coh[1:]
    np.testing.assert_allclose(est.random_error[1:], np.sqrt(1 - g2) / np.sqrt(g2 * 2 * est.effective_averages),
                               rtol=1e-9)
    # An alignment shift changes the estimate's bias, not what it estimates: the phase is put back.
    shifted = window_estimate(u, y, fs, nperseg, overlap=0.5, shift_samples=9)
    band = (f > 2) & (f < 8)
    assert np.all(np.abs(shifted.response[band] / truth(f[band]) - 1) < 4 * shifted.random_error[band])
    assert np.all(shifted.coherence[band] > est.coherence[band])


# (b) ---------------------------------------------------------------- the composite
@pytest.mark.parametrize("fps,noise", [(100, LOW), (1000, LOW), (100, NOISY)])
def test_composite_holds_the_true_response_within_two_random_errors(fps, noise):
    r = _response(fps, noise)
    h = truth(r.frequency_hz)
    k = r.kept
    assert k.sum() >= 15 and r.frequency_hz[0] == pytest.approx(F0) and r.frequency_hz[-1] <= F1
    gain_z = (r.gain / np.abs(h) - 1) / r.random_error
    phase_z = np.radians(r.phase_deg - np.degrees(np.unwrap(np.angle(h)))) / r.random_error
    assert np.mean(np.abs(gain_z[k]) < 2) >= 0.9
    assert np.mean(np.abs(phase_z[k]) < 2) >= 0.9
    # Continuous and lagging: −0.085 s·f·360° plus the servo's own lag, about −500° at 14 Hz.
    assert np.all(np.diff(r.phase_deg) < 0) and r.phase_deg[-1] < -450
    # Neighbouring points are at least two bins (2/T) of every contributing window apart.
    assert np.all(np.diff(r.frequency_hz) >= 2 / max(r.windows_s) * 0.98)
    assert len(r.windows_s) == 5 and all(p >= 1 for p in r.window_points)


def test_the_phase_is_exact_with_the_grid_spacing_and_no_noise():
    t, u, y = record(100, 0.0)
    r = sweep_response(t, u, y, from_hz=F0, to_hz=F1)
    h = truth(r.frequency_hz)
    np.testing.assert_allclose(r.gain, np.abs(h), rtol=0.012)
    np.testing.assert_allclose(r.phase_deg, np.degrees(np.unwrap(np.angle(h))), atol=1.0)


# (c) ------------------------------------------------------------- coherence falls
def test_coherence_falls_and_points_are_flagged_where_noise_dominates():
    t, u, y = record(100, LOW)
    sos = signal.butter(8, 10.0, "highpass", fs=100, output="sos")
    hf = signal.sosfilt(sos, np.random.default_rng(5).standard_normal(t.size))
    r = sweep_response(t, u, y + 0.005 * hf / hf.std(), from_hz=F0, to_hz=F1)
    low = r.frequency_hz < 8
    assert np.all(r.coherence[low] > 0.99) and np.all(r.kept[low])
    high = r.frequency_hz > 11
    assert np.all(r.coherence[high] < 0.6) and not np.any(r.kept[high])
    assert np.all(np.diff(r.coherence[r.frequency_hz > 8]) < 0)
    assert any("coherence below 0.6" in w for w in r.warnings)
    fr = r.to_frequency_response()
    assert len(fr) == r.kept.sum() and fr.frequency_hz.max() < 11
    # The random error grows as the coherence falls.
    assert np.all(r.random_error[high] > 5 * r.random_error[low].max())


# (d) ------------------------------------------------------------ the fitted servo
@pytest.mark.parametrize("fps", [100, 1000])
def test_the_transfer_function_fit_recovers_the_servo(fps):
    fr = _response(fps, LOW).to_frequency_response()
    assert isinstance(fr, FrequencyResponse) and fr.labels[0] == "sweep@0.5Hz"
    fit = fit_transfer_function(fr, mode="complex")
    p = fit.parameters
    assert p["gain"].value == pytest.approx(K, rel=0.005)
    assert p["natural_frequency_rad_s"].value == pytest.approx(WN, rel=0.005)
    assert p["damping_ratio"].value == pytest.approx(ZETA, rel=0.01)
    assert p["dead_time_s"].value == pytest.approx(TAU, abs=0.001)
    # The intervals hold the truth. Measured at 100 (1000) frames/s: K −0.03 % (+0.01 %), ωn +0.03 %
    # (+0.17 %), ζ +0.01 % (+0.11 %), τ −0.03 ms (+0.03 ms), against stated errors of 0.16 %, 0.2 %,
    # 0.3 %, 0.06 ms. At this noise the coherence (0.999) is limited by the estimator's own small
    # biases, not the noise: over 40 records the parameters scatter by 0.13–0.35 of their stated
    # errors, and ωn, ζ carry a bias of about +0.12 % that no record's interval is narrow enough
    # to exclude. With noise 1e-3 rad the 95 % intervals hold the truth in 96–97 % of 1000 records
    # (tests/sysid/test_sweep_coverage.py, docs/accuracy.md).
    for name, value in zip(p, (K, WN, ZETA, TAU)):
        assert p[name].holds(value), (name, p[name])


# ---------------------------------------------------------------- the samples
def test_short_gaps_are_filled_and_counted_long_ones_refused():
    t, u, y = record(100, LOW)
    y = y.copy()
    y[[200, 500, 501, 900]] = np.nan
    y[:3] = np.nan
    r = sweep_response(t, u, y, from_hz=F0, to_hz=F1)
    assert r.filled_samples == 4
    assert any("4 invalid frame(s) in 3 gap(s)" in w for w in r.warnings)
    assert any("3 invalid frame(s) at the record's ends" in w for w in r.warnings)
    np.testing.assert_allclose(r.gain, _response(100, LOW).gain, rtol=0.01)
    y[600:604] = np.nan
    with pytest.raises(ServoscopeError, match="gap of 4 invalid frame"):
        sweep_response(t, u, y, from_hz=F0, to_hz=F1)


def test_dropped_frames_and_jitter():
    t, u, y = record(100, LOW)
    keep = np.ones(t.size, bool)
    keep[[300, 700]] = False
    jitter = 1e-4 * np.random.default_rng(1).standard_normal(keep.sum())
    r = sweep_response(t[keep] + jitter, u[keep], y[keep], from_hz=F0, to_hz=F1)
    assert r.filled_samples == 2 and r.sample_rate_hz == pytest.approx(100, rel=1e-4)
    with pytest.raises(ServoscopeError, match="not nearly uniform"):
        sweep_response(t + 0.004 * (np.arange(t.size) % 2), u, y, from_hz=F0, to_hz=F1)


def test_a_record_without_rest_around_the_sweep_is_warned_about():
    t, u, y = record(100, LOW)
    assert not any("while the command moves" in w for w in _response(100, LOW).warnings)
    inside = (t >= T0) & (t <= T0 + T_SWEEP)
    r = sweep_response(t[inside], u[inside], y[inside], from_hz=F0, to_hz=F1)
    assert sum("ends while the command moves" in w for w in r.warnings) == 1


@pytest.mark.parametrize("kwargs,match", [
    (dict(from_hz=1.0, to_hz=60.0), "Nyquist"),
    (dict(from_hz=5.0, to_hz=1.0), "0 < from_hz < to_hz"),
    (dict(from_hz=1.0, to_hz=10.0, overlap=1.0), "overlap"),
    (dict(from_hz=1.0, to_hz=10.0, windows_s=[30.0]), "windows_s"),
])
def test_bad_options_are_refused(kwargs, match):
    t, u, y = record(100, LOW)
    with pytest.raises(ServoscopeError, match=match):
        sweep_response(t, u, y, **kwargs)


# ---------------------------------------------------------------- the result
def test_the_result_is_frozen_and_round_trips():
    r = _response(100, NOISY)
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.gain = r.gain
    with pytest.raises(ValueError):
        r.gain[0] = 1.0
    data = json.loads(json.dumps(r.summary()))
    back = SweepResponse.from_summary(data)
    assert back.summary() == r.summary()
    np.testing.assert_array_equal(back.kept, r.kept)
    np.testing.assert_allclose(r.gain_stderr, r.random_error * r.gain)
    np.testing.assert_allclose(r.phase_stderr_deg, np.degrees(r.random_error))
    df = r.to_pandas()
    assert len(df) == len(r) and {"gain_db", "coherence", "kept", "phase_stderr_deg"} <= set(df.columns)


def test_plot_draws_cifers_three_panels():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    r = _response(100, NOISY)
    artists = r.plot()
    gain, phase, coh, threshold = artists
    np.testing.assert_allclose(gain.get_xdata(), r.frequency_hz)
    np.testing.assert_allclose(gain.get_ydata(), r.gain_db)
    np.testing.assert_allclose(phase.get_ydata(), r.phase_deg)
    np.testing.assert_allclose(coh.get_ydata(), r.coherence)
    assert gain.axes.get_xscale() == "log" and threshold.get_ydata()[0] == pytest.approx(0.6)
    plt.close("all")

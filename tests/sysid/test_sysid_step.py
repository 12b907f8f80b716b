"""Tests for servoscope.sysid.step (oracle: python-control step responses / step_info)."""

from __future__ import annotations

import json

import control
import numpy as np
import pytest

from servoscope.errors import ServoscopeError
from servoscope.sysid import analyse_step, model_step_metrics

K, WN, ZETA = 0.23, 37.0, 0.65
PAPER_G = control.tf([K * WN**2], [1.0, 2 * ZETA * WN, WN**2])
TAU = 0.085
T0 = 0.30370  # off the 100 fps frame grid
STEP = 0.5
BASE = 0.02
FPS = 100.0

_FINE = np.arange(0.0, 2.0, 1e-5)
_FINE_Y = np.asarray(control.step_response(PAPER_G, T=_FINE).outputs).ravel()
# Independent oracle for the metrics: step_info on a 10 us grid.
INFO = control.step_info(PAPER_G, T=_FINE, SettlingTimeThreshold=0.02, RiseTimeLimits=(0.1, 0.9))


def truth(t, tau=TAU, step=STEP):
    """Noise-free response of G(s)e^{-s tau} to a step of `step` at T0."""
    return BASE + step * np.interp(t - T0 - tau, _FINE, _FINE_Y, left=0.0)


def record(seed, n=150, sigma=1e-4, step=STEP):
    t = np.arange(n) / FPS
    y = truth(t, step=step) + sigma * np.random.default_rng(seed).standard_normal(n)
    return t, y


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_step_metrics_and_dead_time(seed):
    t, y = record(seed)
    r = analyse_step(t, y, t0_s=T0, step_size=STEP, model=PAPER_G)
    assert abs(r.dead_time_s - TAU) < 1e-3
    assert abs(r.dead_time_s - TAU) < 5 * r.dead_time_stderr_s
    assert r.dead_time_stderr_s < 2e-4
    assert r.rise_time_s == pytest.approx(INFO["RiseTime"], abs=5e-4)
    assert r.overshoot_pct == pytest.approx(INFO["Overshoot"], abs=0.25)
    assert r.settling_time_s == pytest.approx(INFO["SettlingTime"] + TAU, abs=5e-3)
    assert r.peak_time_s == pytest.approx(INFO["PeakTime"] + TAU, abs=0.01)
    assert r.initial_value == pytest.approx(BASE, abs=1e-4)
    assert r.final_value == pytest.approx(BASE + K * STEP, abs=5e-4)
    assert r.gain == pytest.approx(K, rel=0.005)
    assert r.fitted_gain == pytest.approx(K, abs=4 * r.fitted_gain_stderr)
    assert r.noise_sigma == pytest.approx(1e-4, rel=0.5)
    # Frame counting is late by the time the response needs to reach 2 %,
    # plus at most one frame.
    t_reach = _FINE[np.nonzero(_FINE_Y > 0.02 * K)[0][0]]
    assert TAU + t_reach - 1e-3 <= r.dead_time_threshold_s <= TAU + t_reach + 1 / FPS + 1e-3
    # Prediction reproduces the noise-free truth.
    np.testing.assert_allclose(r.predicted(t), truth(t), atol=3e-4)
    assert np.std(r.residual) == pytest.approx(1e-4, rel=0.3)
    assert r.warnings == ()


def test_noise_free_dead_time_is_sub_frame_exact():
    t = np.arange(150) / FPS
    r = analyse_step(t, truth(t), t0_s=T0, step_size=STEP, model=PAPER_G)
    assert r.dead_time_s == pytest.approx(TAU, abs=2e-5)
    assert r.fitted_gain == pytest.approx(K, rel=1e-4)


def test_negative_step_and_valid_mask():
    t, y = record(5, step=-STEP)
    valid = np.ones(t.size, bool)
    valid[80:83] = False
    y[80:83] = 10.0  # garbage on invalid frames
    y[100] = np.nan
    r = analyse_step(t, y, t0_s=T0, step_size=-STEP, valid=valid, model=PAPER_G)
    assert r.gain == pytest.approx(K, rel=0.005)
    assert r.change < 0
    assert abs(r.dead_time_s - TAU) < 1e-3
    assert r.rise_time_s == pytest.approx(INFO["RiseTime"], abs=1e-3)
    assert r.overshoot_pct == pytest.approx(INFO["Overshoot"], abs=0.5)
    assert r.time_s.size == t.size - 4


def test_without_model():
    t, y = record(3)
    r = analyse_step(t, y, t0_s=T0, step_size=STEP)
    assert r.dead_time_s is None and r.dead_time_stderr_s is None and r.residual is None
    assert np.isfinite(r.dead_time_threshold_s)
    with pytest.raises(ServoscopeError):
        r.predicted(t)
    s = r.summary()
    json.dumps(s, allow_nan=False)
    assert s["dead_time_s"] is None
    for key in ("rise_time_s", "overshoot_pct", "settling_time_s", "dead_time_s", "dead_time_stderr_s",
                "dead_time_threshold_s", "final_value", "initial_value", "gain"):
        assert key in s


def test_unsettled_record_warns():
    t = np.arange(56) / FPS  # ends ~0.17 s after the delayed response starts
    y = truth(t)
    r = analyse_step(t, y, t0_s=T0, step_size=STEP)
    assert np.isnan(r.settling_time_s) or r.warnings


def test_model_step_metrics_matches_step_info():
    m = model_step_metrics(PAPER_G, dead_time_s=TAU)
    assert m["rise_time_s"] == pytest.approx(INFO["RiseTime"], abs=1e-4)
    assert m["overshoot_pct"] == pytest.approx(INFO["Overshoot"], abs=1e-3)
    assert m["settling_time_s"] == pytest.approx(INFO["SettlingTime"] + TAU, abs=1e-4)
    assert m["steady_state_value"] == pytest.approx(K)
    # Analytic overshoot of a 2nd-order system.
    assert m["overshoot_pct"] == pytest.approx(100 * np.exp(-np.pi * ZETA / np.sqrt(1 - ZETA**2)), abs=1e-3)


def test_bad_input_raises():
    t, y = record(0)
    with pytest.raises(ServoscopeError):  # no pre-roll
        analyse_step(t, y, t0_s=-1.0, step_size=STEP)
    with pytest.raises(ServoscopeError):  # too few samples after t0
        analyse_step(t, y, t0_s=t[-3], step_size=STEP)
    with pytest.raises(ServoscopeError):
        analyse_step(t, y, t0_s=T0, step_size=0.0)
    with pytest.raises(ServoscopeError):
        analyse_step(t, y[:-1], t0_s=T0, step_size=STEP)
    with pytest.raises(ServoscopeError):  # unstable model
        analyse_step(t, y, t0_s=T0, step_size=STEP, model=control.tf([1.0], [1.0, -1.0]))


def test_to_pandas_is_the_samples_and_the_prediction():
    t, y = record(0)
    r = analyse_step(t, y, t0_s=T0, step_size=STEP, model=PAPER_G)
    df = r.to_pandas()  # pandas is a test dependency: the real table
    assert list(df.columns) == ["time_s", "y", "predicted"]
    np.testing.assert_array_equal(df["time_s"].to_numpy(), r.time_s)
    np.testing.assert_array_equal(df["y"].to_numpy(), r.y)
    np.testing.assert_allclose(df["predicted"].to_numpy(), r.predicted(r.time_s))


def test_summary_predicted_metrics_are_the_models_step_info():
    t, y = record(0)
    r = analyse_step(t, y, t0_s=T0, step_size=STEP, model=PAPER_G)
    pred = r.summary()["predicted"]
    assert pred["rise_time_s"] == pytest.approx(INFO["RiseTime"], rel=0.01)
    assert pred["overshoot_pct"] == pytest.approx(INFO["Overshoot"], rel=0.01)
    assert pred["settling_time_s"] == pytest.approx(INFO["SettlingTime"] + r.dead_time_s, rel=0.01)
    assert pred["peak_time_s"] == pytest.approx(INFO["PeakTime"] + r.dead_time_s, rel=0.01)
    assert pred["final_change"] == pytest.approx(K * STEP, rel=1e-6)
    assert analyse_step(t, y, t0_s=T0, step_size=STEP).summary()["predicted"] is None


def test_t0_uncertainty_adds_to_the_dead_time_uncertainty():
    """The dead time is counted from t0: a t0 known to ±0.4 ms makes the dead time no better.

    Coverage with t0 itself drawn wrong by its stated σ: the stated dead-time σ must
    cover the error, which the fit's own σ (~0.03 ms) alone would not.
    """
    t, y = record(0)
    alone = analyse_step(t, y, t0_s=T0, step_size=STEP, model=PAPER_G)
    sigma_t0 = 4e-4
    with_t0 = analyse_step(t, y, t0_s=T0, step_size=STEP, model=PAPER_G, t0_stderr_s=sigma_t0)
    assert with_t0.dead_time_stderr_s == pytest.approx(np.hypot(alone.dead_time_stderr_s, sigma_t0), rel=1e-9)
    assert with_t0.dead_time_s == alone.dead_time_s
    rng = np.random.default_rng(3)
    z = []
    for _ in range(30):
        t0_measured = T0 + sigma_t0 * rng.standard_normal()
        r = analyse_step(t, y, t0_s=t0_measured, step_size=STEP, model=PAPER_G, t0_stderr_s=sigma_t0)
        z.append((r.dead_time_s - TAU) / r.dead_time_stderr_s)
    z = np.abs(z)
    assert np.max(z) < 3.5 and 0.3 < np.median(z) < 1.2


def test_output_moved_flags_a_step_lost_in_the_noise():
    # The flag identify decides on, and the warning it comes with (text unchanged).
    t, y = record(1)
    moved = analyse_step(t, y, t0_s=T0, step_size=STEP)
    assert moved.output_moved
    assert not any(w.startswith("no discernible step response") for w in moved.warnings)
    flat = np.random.default_rng(1).normal(0.0, 1e-3, t.size)  # the blade never moves
    still = analyse_step(t, flat, t0_s=T0, step_size=STEP)
    assert not still.output_moved
    assert "no discernible step response (change within 10 noise sigma)" in still.warnings


@pytest.mark.parametrize("num,den", [([0.23 * 37.0**2], [1.0, 2 * 0.65 * 37.0, 37.0**2]), ([1.0], [1.0, 1.0]),
                                     ([2.0, 3.0], [1.0, 5.0, 6.0, 4.0]), ([1.0, 0.5], [1.0, 0.2, 100.0]),
                                     ([0.5, 1.0, 2.0], [1.0, 3.0, 2.0])])
def test_step_response_on_grid_is_python_controls(num, den):
    # The oracle: python-control's own step response (its Python loop), on the grids the step analysis uses.
    import control

    from servoscope.sysid.step import step_response_on_grid

    model = control.tf(num, den)
    grid = np.linspace(0.0, 4.0, 8001)
    want = np.asarray(control.step_response(model, T=grid).outputs, dtype=float).ravel()
    got = step_response_on_grid(model, grid)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * max(1.0, float(np.abs(want).max())))
    np.testing.assert_allclose(step_response_on_grid(control.ss(model), grid), want, rtol=0, atol=1e-12 * max(
        1.0, float(np.abs(want).max())))

"""The flapping model fitted to the heave's whole traces (issue 32, build 1).

Oracle: python-control's ``forced_response`` of ``−κ·s²/(s² + 2ζω·s + ω²)`` driven by a known pitch
(sine dwells that start from rest, too short to settle near the mode, and a step), plus an axis
error's heave ``e·θ``, levels and correlated (AR(1)) tracker noise, seeded.
"""

from __future__ import annotations

import math

import control
import numpy as np
import pytest

from servoscope.sysid.hac import hac_covariance
from servoscope.sysid.heave import HeaveModel
from servoscope.sysid.heave_traces import HeaveTrace, fit_heave_traces, mode_response_px

FPS = 200.0
MODE = (9.3, 0.03, 40.0)  # Hz, damping ratio, κ px/rad: the blade


def _pitch(t, start, kind, f=0.0, amplitude=0.05):
    """A servo-like pitch: a sine from rest at ``start`` (smoothed on by the servo's own 2nd order), or a step."""
    servo = control.tf([37.0**2], [1.0, 2 * 0.65 * 37.0, 37.0**2])
    u = np.where(t >= start, np.sin(2 * math.pi * f * (t - start)) if kind == "sine" else 1.0, 0.0) * amplitude
    return np.asarray(control.forced_response(servo, t, u).outputs, float)


def _heave(t, pitch, mode=MODE):
    fm, z, k = mode
    w = 2 * math.pi * fm
    return np.asarray(control.forced_response(control.tf([-k, 0, 0], [1, 2 * z * w, w * w]), t, pitch).outputs, float)


def _traces(seed, axis_px_per_rad=3.0, noise_px=0.02, rho=0.8, dwell_s=2.0):
    rng = np.random.default_rng(seed)
    out = []
    plan = [("sine", f) for f in (1.0, 2.0, 4.5, 7.0, 8.5, 9.3)] + [("step", 0.0)]
    for k, (kind, f) in enumerate(plan):
        start = 0.3
        t = np.arange(0.0, start + (dwell_s if kind == "sine" else 3.0), 1.0 / FPS)
        # Fine grid for the oracle, read at the frames (a camera samples a continuous motion).
        fine = np.linspace(0.0, t[-1], 10 * t.size + 1)
        p_fine = _pitch(fine, start, kind, f)
        h = np.interp(t, fine, _heave(fine, p_fine))
        p = np.interp(t, fine, p_fine)
        e = np.zeros(t.size)
        for i in range(1, t.size):  # correlated tracking error, as sub-pixel errors are
            e[i] = rho * e[i - 1] + math.sqrt(1 - rho**2) * rng.normal(0.0, noise_px)
        measured = 50.0 + k + h + axis_px_per_rad * p + e
        out.append(HeaveTrace(f"{kind}{k}", t, p + rng.normal(0.0, 2e-5, t.size), measured, start))
    return out


def test_mode_response_is_python_controls():
    t = np.arange(0.0, 2.0, 1.0 / FPS)
    fine = np.linspace(0.0, t[-1], 10 * t.size + 1)
    p_fine = _pitch(fine, 0.3, "sine", 8.0)
    ours = mode_response_px(t, np.interp(t, fine, p_fine), 9.3, 0.03) * 40.0
    ref = np.interp(t, fine, _heave(fine, p_fine))
    assert np.max(np.abs(ours - ref)) < 0.01 * np.max(np.abs(ref))


def test_whole_traces_give_the_mode_the_axis_term_and_intervals_that_hold():
    zs = {"kappa": [], "f": [], "zeta": [], "axis": []}
    for seed in range(6):
        model = fit_heave_traces(_traces(seed), [(9.0, 0.05)], n_dwells=6)
        assert isinstance(model, HeaveModel) and model.method == "whole traces"
        m = model.mode
        # The targets: frequency within 0.5 %, damping within 10 %, κ within 3 %, from 2-second dwells.
        assert m.frequency_hz == pytest.approx(MODE[0], rel=0.005)
        assert m.damping_ratio == pytest.approx(MODE[1], rel=0.10)
        assert model.gain_px_per_rad == pytest.approx(MODE[2], rel=0.03)
        for name, value, se, true in (("kappa", model.gain_px_per_rad, model.gain_stderr_px_per_rad, MODE[2]),
                                      ("f", m.frequency_hz, m.frequency_stderr_hz, MODE[0]),
                                      ("zeta", m.damping_ratio, m.damping_ratio_stderr, MODE[1]),
                                      ("axis", model.axis_px_per_rad, model.axis_stderr_px_per_rad, 3.0)):
            zs[name].append((value - true) / se)
        p = model.parameters
        assert p["damping_ratio"].ci95[0] <= MODE[1] <= p["damping_ratio"].ci95[1]
        assert p["axis_px_per_rad"].ci95[0] <= 3.0 <= p["axis_px_per_rad"].ci95[1]
    for name, z in zs.items():
        # No stated error much too small: nothing past 3 σ, and (the modes' systematic part aside,
        # which is for codecs) the axis term's z-scores spread as they should.
        assert np.max(np.abs(z)) < 3.0, (name, z)
    assert 0.4 < np.sqrt(np.mean(np.square(zs["axis"]))) < 1.6, zs["axis"]


def test_without_a_mode_only_the_axis_term_and_the_model_round_trips():
    traces = [HeaveTrace(tr.label, tr.time_s, tr.pitch_rad, tr.heave_px - np.interp(tr.time_s, tr.time_s,
                         _heave(tr.time_s, tr.pitch_rad)), tr.start_s) for tr in _traces(1)]
    rigid = fit_heave_traces(traces, [])
    assert rigid.modes == () and rigid.axis_px_per_rad == pytest.approx(3.0, abs=4 * rigid.axis_stderr_px_per_rad)
    model = fit_heave_traces(_traces(2), [(9.0, 0.05)])
    back = HeaveModel.from_summary(model.summary())
    assert back.method == "whole traces" and back.axis_px_per_rad == model.axis_px_per_rad
    assert back.ratio_stderr(9.3) == pytest.approx(model.ratio_stderr(9.3))
    assert back.mode.source == "heave_traces"
    # The model's steady heave at the mode: its stated error holds the truth.
    w = 2 * math.pi * 9.3
    true = abs(40.0 * w**2 / ((2 * math.pi * 9.3) ** 2 - w**2 + 2j * 0.03 * 2 * math.pi * 9.3 * w))
    assert abs(abs(model.ratio(np.array([9.3]))[0]) - true) < 3 * model.ratio_stderr(9.3)
    assert "axis_px_per_rad" in model.fit_report() and "whole traces" in model.fit_report()


def test_hac_groups_leave_out_products_across_series():
    rng = np.random.default_rng(0)
    jac = rng.normal(size=(200, 2))
    r = rng.normal(size=200)
    one = hac_covariance(jac, r, lag=5)
    assert np.allclose(hac_covariance(jac, r, lag=5, groups=np.zeros(200, int)), one)
    # Two series: the same as the scores' long-run covariance summed over each alone.
    groups = np.repeat([0, 1], 100)
    two = hac_covariance(jac, r, lag=5, groups=groups)
    u = jac * r[:, None]
    S = np.zeros((2, 2))
    for g in (0, 1):
        v = u[groups == g]
        S += v.T @ v
        for lag in range(1, 6):
            c = v[lag:].T @ v[:-lag]
            S += (1 - lag / 6) * (c + c.T)
    B = np.linalg.inv(jac.T @ jac)
    assert np.allclose(two, B @ S @ B * 200 / 198)

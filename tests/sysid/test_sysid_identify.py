"""Tests for general-order transfer-function fitting, order selection and uncertainty.

Oracles: scipy.signal.freqs (model frequency responses), python-control
(frequency responses, bandwidth, step_info), scipy.stats.t (nlparci-style
intervals), numpy percentiles (bootstrap), the digital twin's exact
ServoModel responses (sine dwells, no rendering).
"""

from __future__ import annotations

import json
import math

import control
import numpy as np
import pytest
import scipy.signal
from scipy.stats import t as student_t

from servoscope.errors import ServoscopeError
from servoscope.simulate import PAPER_SERVO, InputSignal, ServoModel
from servoscope.sysid import (
    FrequencyResponse,
    OrderSelection,
    TransferFunctionFit,
    cifer_cost,
    fit_second_order,
    fit_sine,
    fit_transfer_function,
    model_step_metrics,
    select_order,
)
from servoscope.report import write_report

K, WN, ZETA, TAU = 0.23, 37.0, 0.65, 0.085
F_HZ = np.geomspace(0.5, 15.0, 14)
W = 2 * np.pi * F_HZ

FIRST = (np.array([0.5]), np.array([1 / 20.0, 1.0]))
THIRD = (np.array([0.3]), np.polymul([1 / 30.0, 1.0], [1 / 60.0**2, 2 * 0.4 / 60.0, 1.0]))
PAPER = (np.array([K]), np.array([1 / WN**2, 2 * ZETA / WN, 1.0]))


def noisy_fr(num, den, *, tau=TAU, seed=0, rel=0.005, deg=0.3, f_hz=F_HZ):
    """Frequency response of num/den*exp(-s tau) with Gaussian errors of the stated size."""
    w = 2 * np.pi * f_hz
    _, h = scipy.signal.freqs(num, den, w)
    h = h * np.exp(-1j * w * tau)
    rng = np.random.default_rng(seed)
    mag = np.abs(h) * (1 + rel * rng.standard_normal(w.size))
    ph = np.degrees(np.unwrap(np.angle(h))) + deg * rng.standard_normal(w.size)
    return FrequencyResponse(f_hz, mag, rel * mag, ph, np.full(w.size, deg), np.ones(w.size), None)


# ------------------------------------------------------------- the model
MODELS = {
    (0, 1): (FIRST[0], FIRST[1], 0.0),
    (1, 3): (0.3 * np.array([1 / 45.0, 1.0]), np.polymul([1 / 12.0, 1.0], [1 / 60.0**2, 0.8 / 60.0, 1.0]), 0.03),
    (2, 4): (
        0.8 * np.array([1 / 50.0**2, 2 * 0.5 / 50.0, 1.0]),
        np.polymul([1 / 20.0**2, 2 * 0.7 / 20.0, 1.0], [1 / 80.0**2, 2 * 0.3 / 80.0, 1.0]),
        0.02,
    ),
}


@pytest.mark.parametrize("order", list(MODELS))
@pytest.mark.parametrize("mode", ["magnitude", "complex"])
def test_exact_data_recovered_and_model_matches_scipy_freqs(order, mode):
    num, den, tau = MODELS[order]
    f_hz = np.geomspace(0.3, 20.0, 16)
    fr = noisy_fr(num, den, tau=tau, rel=0.0, deg=0.0, f_hz=f_hz)
    fr = FrequencyResponse(f_hz, fr.gain, None, fr.phase_deg, None, fr.fidelity, None)
    r = fit_transfer_function(fr, order=order, mode=mode)
    assert r.order == order and r.mode == mode and r.n_points == 16
    # The fitted polynomials are the true ones (normalized to D(0) = 1).
    np.testing.assert_allclose(r.den, np.asarray(den) / den[-1], rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(r.num, np.asarray(num) / den[-1], rtol=1e-6, atol=1e-12)
    assert r.gain == pytest.approx(num[-1] / den[-1], rel=1e-8)
    if mode == "complex":
        assert r.dead_time_s == pytest.approx(tau, abs=1e-9)
    else:
        assert r.dead_time_s is None
    # The model's own evaluation equals scipy.signal.freqs of num/den (x delay).
    wd = np.geomspace(0.1, 1000.0, 200)
    _, h = scipy.signal.freqs(r.num, r.den, wd)
    h = h * np.exp(-1j * wd * (r.dead_time_s or 0.0))
    np.testing.assert_allclose(r.frequency_response(wd), h, rtol=1e-9, atol=0)
    np.testing.assert_allclose(r.magnitude(wd), np.abs(h), rtol=1e-9)
    # Continuous phase: unwrapped angle of the freqs response.
    np.testing.assert_allclose(r.phase_rad(wd), np.unwrap(np.angle(h)), atol=1e-9)
    # Stable by construction; control.TransferFunction exposed.
    assert np.all(r.poles_rad_s.real < 0)
    assert isinstance(r.transfer_function, control.TransferFunction)
    assert r.J < 1e-10 and r.undetermined == ()


def test_free_zeros_find_a_right_half_plane_zero():
    # G = K (1 - s/25) / ((s/15 + 1)(s^2/60^2 + 0.8 s/60 + 1)): non-minimum phase.
    num = 0.4 * np.array([-1 / 25.0, 1.0])
    den = np.polymul([1 / 15.0, 1.0], [1 / 60.0**2, 0.8 / 60.0, 1.0])
    fr = noisy_fr(num, den, tau=0.01, rel=0.0, deg=0.0)
    r = fit_transfer_function(fr, order=(1, 3), mode="complex", zeros="free")
    np.testing.assert_allclose(r.zeros_rad_s.real, [25.0], rtol=1e-6)
    assert r.params["num_c1"] == pytest.approx(-1 / 25.0, rel=1e-6)
    assert r.dead_time_s == pytest.approx(0.01, abs=1e-8)
    # A minimum-phase fit cannot reproduce the phase.
    mp = fit_transfer_function(fr, order=(1, 3), mode="complex")
    assert mp.residual_rms_deg > 1.0
    with pytest.raises(ServoscopeError, match="zeros='free' needs mode='complex'"):
        fit_transfer_function(fr, order=(1, 3), zeros="free")


# ---------------------------------------------------- simulator campaign
def simulate_dwells(servo, *, seed, noise_rad=2e-4, fps=100.0, exposure_s=0.01, amplitude=0.1, f_hz=F_HZ):
    """Sine dwells of the paper preset's timing, exact twin outputs averaged over the exposure."""
    rng = np.random.default_rng(seed)
    offsets = ((np.arange(8) + 0.5) / 8 - 0.5) * exposure_s
    fits = []
    for f in f_hz:
        t0 = 0.5 + rng.uniform(0.0, 1.0 / fps)  # never on a frame boundary
        t = np.arange(0.0, t0 + 0.5 + max(3.0, 4.0 / f), 1.0 / fps)
        y = servo.response(InputSignal("sine", amplitude, float(f), t0_s=t0), (t[:, None] + offsets).ravel())
        y = y.reshape(t.size, -1).mean(axis=1) + noise_rad * rng.standard_normal(t.size)
        fits.append(fit_sine(t, y, float(f), t0_s=t0))
    return fits


@pytest.fixture(scope="module")
def paper_campaign():
    fits = simulate_dwells(PAPER_SERVO, seed=1)
    fr = FrequencyResponse.from_sine_fits(fits, 0.1, [f"dwell{i:02d}" for i in range(len(fits))])
    return fr.corrected_for_exposure(0.01)


@pytest.mark.parametrize("mode", ["magnitude", "complex"])
def test_paper_campaign_meets_targets_and_intervals_contain_truth(paper_campaign, mode):
    r = fit_second_order(paper_campaign, mode=mode, bootstrap=100, seed=7)
    truth = {"gain": K, "natural_frequency_rad_s": WN, "damping_ratio": ZETA}
    assert r.gain == pytest.approx(K, rel=0.01)
    assert r.natural_frequency_rad_s == pytest.approx(WN, rel=0.01)
    assert r.damping_ratio == pytest.approx(ZETA, rel=0.03)
    true_bw = float(control.bandwidth(PAPER_SERVO.transfer_function))
    assert r.bandwidth_rad_s == pytest.approx(true_bw, rel=0.01)
    if mode == "complex":
        truth["dead_time_s"] = TAU
        assert abs(r.dead_time_s - TAU) < 2e-3
    else:
        assert r.dead_time_s is None and "dead_time_s" not in r.ci95
    assert set(r.ci95) == set(truth) == set(r.ci95_bootstrap)
    for name, value in truth.items():
        lo, hi = r.ci95[name]
        assert lo <= value <= hi, (name, lo, value, hi)
        blo, bhi = r.ci95_bootstrap[name]
        assert blo <= value <= bhi, (name, blo, value, bhi)
    assert r.J <= 50 and r.J_rating == "near-perfect"
    assert r.warnings == ()
    s = r.summary()
    json.dumps(s, allow_nan=False)
    assert s["fit"]["mode"] == mode and s["fit"]["n_points"] == 14 and s["fit"]["n_params"] == len(truth)
    for key in ("J", "AIC", "BIC"):
        assert isinstance(s["fit"][key], float)
    assert s["ci95"]["gain"] == list(r.ci95["gain"])
    assert "<table>" in r._repr_html_()


def test_jacobian_intervals_are_nlparci_and_cover_95_percent():
    """Intervals are value +- t(0.975, dof) * stderr, and cover the truth ~95 % of the time."""
    truth = np.array([K, WN, ZETA, TAU])
    hits = np.zeros(4)
    n_rep = 80
    for seed in range(n_rep):
        r = fit_second_order(noisy_fr(*PAPER, seed=100 + seed), mode="complex")
        names = r.param_names
        assert names == ("gain", "natural_frequency_rad_s", "damping_ratio", "dead_time_s")
        tq = student_t.ppf(0.975, r.n_residuals - r.n_params)
        for j, name in enumerate(names):
            v, se = r.params[name], r.stderr[name]
            assert r.ci95[name] == pytest.approx((v - tq * se, v + tq * se), rel=1e-12)
            hits[j] += r.ci95[name][0] <= truth[j] <= r.ci95[name][1]
    coverage = hits / n_rep
    assert np.all((coverage >= 0.87) & (coverage <= 1.0)), coverage


def test_bootstrap_is_deterministic_and_percentile_based():
    fr = noisy_fr(*PAPER, seed=3)
    a = fit_second_order(fr, mode="complex", bootstrap=60, seed=11)
    b = fit_second_order(fr, mode="complex", bootstrap=60, seed=11)
    c = fit_second_order(fr, mode="complex", bootstrap=60, seed=12)
    np.testing.assert_array_equal(a.bootstrap_samples, b.bootstrap_samples)
    assert not np.array_equal(a.bootstrap_samples, c.bootstrap_samples)
    assert a.bootstrap_samples.shape == (60, 4)
    for j, name in enumerate(a.param_names):
        lo, hi = np.percentile(a.bootstrap_samples[:, j], [2.5, 97.5])
        assert a.ci95_bootstrap[name] == pytest.approx((lo, hi), rel=1e-12)
        # Same order of magnitude as the Jacobian interval.
        ratio = (hi - lo) / (a.ci95[name][1] - a.ci95[name][0])
        assert 0.3 < ratio < 3.0, (name, ratio)
    assert a.ci95_bootstrap is not None and fit_second_order(fr).ci95_bootstrap is None


# -------------------------------------------------------- order selection
@pytest.mark.parametrize(
    ("plant", "mode", "true_order"),
    [(FIRST, "magnitude", (0, 1)), (THIRD, "magnitude", (0, 3)), (FIRST, "complex", (0, 1)), (THIRD, "complex", (0, 3))],
)
def test_order_selection_picks_the_true_order(plant, mode, true_order):
    sel = select_order(noisy_fr(*plant, seed=4), mode=mode)
    assert isinstance(sel, OrderSelection)
    assert sel.order == true_order and sel.best.order == true_order
    rows = sel.table
    assert sum(r["chosen"] for r in rows) == 1
    chosen = next(r for r in rows if r["chosen"])
    assert tuple(chosen["order"]) == true_order
    assert {(0, 1), (0, 2), (0, 3), (0, 4)} <= {tuple(r["order"]) for r in rows}
    for r in rows:
        for key in ("n_params", "J", "AIC", "BIC", "residual_rms_db"):
            assert key in r
    # The measured slope is shallower than the asymptote: a lower bound.
    rel = true_order[1] - true_order[0]
    assert 1 <= sel.relative_degree_estimate <= rel
    assert -20 * rel - 3 < sel.slope_db_per_decade < -10
    json.dumps(sel.summary(), allow_nan=False)
    assert sel.summary()["chosen_order"] == list(true_order)
    assert "<table>" in sel._repr_html_()


def test_order_auto_on_the_paper_campaign(paper_campaign):
    r = fit_transfer_function(paper_campaign, order="auto", mode="complex")
    assert r.order == (0, 2) and isinstance(r.order_selection, OrderSelection)
    assert r.natural_frequency_rad_s == pytest.approx(WN, rel=0.01)
    # Other orders report their own parameters; the 2nd-order fields are None.
    third = r.order_selection.fits[(0, 3)]
    assert third.natural_frequency_rad_s is None and "pole_rad_s" in third.params
    assert set(third.summary()["ci95"]) == set(third.param_names)


def test_model_step_metrics_of_a_fitted_third_order_match_step_info():
    r = fit_transfer_function(noisy_fr(*THIRD, seed=5), order=(0, 3))
    got = model_step_metrics(r.transfer_function)
    t = np.linspace(0.0, 3.0, 60_001)
    info = control.step_info(r.transfer_function, T=t, SettlingTimeThreshold=0.02, RiseTimeLimits=(0.1, 0.9))
    assert got["rise_time_s"] == pytest.approx(info["RiseTime"], rel=0.01)
    assert got["settling_time_s"] == pytest.approx(info["SettlingTime"], rel=0.01)
    assert got["overshoot_pct"] == pytest.approx(info["Overshoot"], rel=0.01, abs=1e-3)


# ------------------------------------------------------------ nonlinearity
def test_rate_limit_and_backlash_are_flagged_not_silently_fitted():
    f_hz = np.array([1.0, 2.0, 4.0, 6.0])
    servos = {
        "linear": PAPER_SERVO,
        "rate": ServoModel(PAPER_SERVO.num, PAPER_SERVO.den, TAU, rate_limit_per_s=1.2),
        "backlash": ServoModel(PAPER_SERVO.num, PAPER_SERVO.den, TAU, backlash=0.006),
    }
    out = {}
    for name, servo in servos.items():
        fits = simulate_dwells(servo, seed=2, f_hz=f_hz, exposure_s=0.0)
        fr = FrequencyResponse.from_sine_fits(fits, 0.1)
        fit = fit_second_order(fr, mode="complex")
        out[name] = (fits, fr, fit)
    fits, fr, fit = out["linear"]
    assert all("distorted" not in fi.flags and "low_fidelity" not in fi.flags for fi in fits)
    assert not any("distortion" in w for w in fit.warnings)
    assert np.all(fr.thd < 0.01)
    for name in ("rate", "backlash"):
        fits, fr, fit = out[name]
        flagged = [fi.commanded_frequency_hz for fi in fits if "distorted" in fi.flags]
        assert flagged, name
        assert any("distorted" in fl for fl in fr.flags)
        assert any("harmonic distortion" in w for w in fit.warnings), (name, fit.warnings)
        assert np.nanmax(fr.thd) > 0.01


# --------------------------------------------------------------- bad input
def test_unusable_dwells_are_left_out_with_warnings():
    fits = simulate_dwells(PAPER_SERVO, seed=5, f_hz=F_HZ[::2], exposure_s=0.0)
    labels = [f"v{i}" for i in range(len(fits))]
    fr = FrequencyResponse.from_sine_fits([None] + fits[1:], 0.1, labels)
    assert len(fr) == len(fits) - 1 and any("v0" in w and "left out" in w for w in fr.warnings)
    r = fit_second_order(fr)
    assert r.n_points == len(fits) - 1
    # A point without a usable gain is left out by the fit, with a warning.
    gain = fr.gain.copy()
    gain[2] = np.nan
    bad = FrequencyResponse(fr.frequency_hz, gain, fr.gain_stderr, fr.phase_deg, fr.phase_stderr_deg, fr.fidelity, fr.labels)
    r2 = fit_second_order(bad, mode="complex")
    assert r2.n_points == len(fr) - 1
    assert any(fr.labels[2] in w and "left out" in w for w in r2.warnings)
    assert all(math.isfinite(v) for v in r2.params.values())
    # A dwell whose frames are all invalid cannot be fitted at all.
    t = np.arange(300) / 100.0
    with pytest.raises(ServoscopeError, match="no valid frames"):
        fit_sine(t, np.sin(t), 1.0, t0_s=0.1, valid=np.zeros(300, bool))
    with pytest.raises(ServoscopeError, match="no dwell"):
        FrequencyResponse.from_sine_fits([None, None], 0.1)


def test_data_that_cannot_determine_the_model_raise_clear_errors():
    fr = noisy_fr(*PAPER, seed=1)
    one_freq = FrequencyResponse(np.full(5, 2.0), fr.gain[:5], None, fr.phase_deg[:5], None, np.ones(5), None)
    with pytest.raises(ServoscopeError, match="one frequency"):
        fit_second_order(one_freq)
    with pytest.raises(ServoscopeError, match="one frequency"):
        fit_second_order(one_freq, mode="complex")
    few = FrequencyResponse(F_HZ[:3], fr.gain[:3], None, None, None, np.ones(3), None)
    with pytest.raises(ServoscopeError, match=r"4 parameters but only 3 dwell"):
        fit_transfer_function(few, order=(1, 2))
    dup = FrequencyResponse(np.repeat(F_HZ[:2], 3), np.repeat(fr.gain[:2], 3), None, None, None, np.ones(6), None)
    with pytest.raises(ServoscopeError, match="2 distinct frequencies"):
        fit_second_order(dup)
    with pytest.raises(ServoscopeError, match="0 <= nb < na <= 4"):
        fit_transfer_function(fr, order=(2, 2))
    with pytest.raises(ServoscopeError, match="0 <= nb < na <= 4"):
        fit_transfer_function(fr, order=(0, 5))
    with pytest.raises(ServoscopeError, match="no candidate order"):
        select_order(few, max_order=4, candidates=[(0, 3), (1, 3)])


def test_cifer_cost_formula():
    db = np.array([1.0, -2.0, 0.5])
    deg = np.array([10.0, np.nan, -4.0])
    gam2 = np.array([1.0, 0.5, np.nan])
    wg = (1.58 * (1 - np.exp(-np.array([1.0, 0.5, 1.0])))) ** 2
    expected = 20 / 3 * np.sum(wg * (db**2 + 0.01745 * np.array([100.0, 0.0, 16.0])))
    assert cifer_cost(db, deg, gam2) == pytest.approx(expected, rel=1e-12)
    assert cifer_cost(db) == pytest.approx(20 / 3 * np.sum((1.58 * (1 - math.exp(-1))) ** 2 * db**2), rel=1e-12)


def test_fit_result_types():
    r = fit_transfer_function(noisy_fr(*THIRD, seed=6), order=(0, 3), mode="complex")
    assert isinstance(r, TransferFunctionFit)
    assert r.natural_frequency_rad_s is None and r.damping_ratio is None
    assert r.param_names == ("gain", "pole_rad_s", "natural_frequency_rad_s", "damping_ratio", "dead_time_s")
    assert r.params["pole_rad_s"] == pytest.approx(30.0, rel=0.05)
    assert r.covariance.shape == (5, 5)
    np.testing.assert_allclose(np.sqrt(np.diag(r.covariance)), [r.stderr[n] for n in r.param_names])
    s = r.summary()
    json.dumps(s, allow_nan=False)
    assert s["order"] == [0, 3] and len(s["poles"]) == 3 and s["natural_frequency_rad_s"] is None


def test_tracked_footage_backlash_is_flagged_linear_servo_is_not(tmp_path, quick_result):
    """Through rendered H.264 footage and the tracker: the markers' null channel
    tells tracking artefacts (linear servo) from a servo's own distortion."""
    from servoscope.campaign import identify, load_campaign
    from servoscope.simulate import simulate_campaign

    assert not any("distorted" in fi.flags for fi in quick_result.sine_fits.values())
    assert not any("harmonic distortion" in w for w in quick_result.warnings)
    servo = ServoModel(PAPER_SERVO.num, PAPER_SERVO.den, TAU, backlash=0.006)
    result = identify(load_campaign(simulate_campaign(tmp_path, preset="quick", seed=2, servo=servo, include_step=False)))
    flagged = [fi.commanded_frequency_hz for fi in result.sine_fits.values() if "distorted" in fi.flags]
    assert len(flagged) >= 2, flagged
    assert any("harmonic distortion" in w for w in result.warnings)
    for fi in result.sine_fits.values():
        assert fi.null_harmonic_amplitudes is not None


# ------------------------------------------------- bad input, end to end
def _with(track, **changes):
    from dataclasses import replace

    return replace(track, **changes)  # a Track is frozen: a changed one is a new one


def test_dwell_without_valid_frames_and_motionless_step_are_left_out(tmp_path, quick_result):
    from servoscope.campaign import identify

    campaign, tracks = quick_result.campaign, dict(quick_result.tracks)
    dead = campaign.sine_tests[1].label
    n = tracks[dead].n_frames
    tracks[dead] = _with(tracks[dead], valid=np.zeros(n, bool), angle_rad=np.full(n, np.nan))
    step = campaign.step_tests[0].label
    st = tracks[step]
    # The step video's blade never moves: the angle stays at its pre-step level (plus noise).
    flat = np.nanmedian(st.angle_rad[: 10]) + 2e-5 * np.random.default_rng(0).standard_normal(st.n_frames)
    tracks[step] = _with(st, angle_rad=np.where(st.valid, flat, np.nan))
    result = identify(campaign, tracks=tracks)
    assert dead not in result.sine_fits and len(result.sine_fits) == len(campaign.sine_tests) - 1
    assert result.step is None
    summary = result.summary()
    json.dumps(summary, allow_nan=False)
    assert any(dead in w and "left out" in w for w in summary["warnings"])
    assert any(step in w and "left out" in w and "never moves" in w for w in summary["warnings"])
    assert summary["step"] is None
    assert all(math.isfinite(v) for v in result.model.params.values())
    paths = write_report(result, tmp_path / "out")
    html = paths["report"].read_text()
    assert "never moves" in html and f"{dead}: only 0 valid frames; dwell left out" in html
    written = json.loads((tmp_path / "out" / "result.json").read_text())
    assert any("never moves" in w for w in written["warnings"])


def test_too_few_dwells_is_a_clear_error_not_a_nan_model(quick_result):
    from servoscope.campaign import identify

    campaign, tracks = quick_result.campaign, dict(quick_result.tracks)
    for test in campaign.sine_tests[:2]:
        n = tracks[test.label].n_frames
        tracks[test.label] = _with(tracks[test.label], valid=np.zeros(n, bool), angle_rad=np.full(n, np.nan))
    with pytest.raises(ServoscopeError, match=r"only 2 sine dwell\(s\) could be fitted"):
        identify(campaign, tracks=tracks)


@pytest.mark.parametrize("case", ["two_dwells", "one_frequency"])
def test_cli_exit_2_when_the_dwells_cannot_determine_the_model(tmp_path, quick_campaign, case):
    import re
    import shutil

    from support import run_cli  # the command's entry point in this process, as a child ran it

    text = quick_campaign.read_text()
    base = quick_campaign.parent
    text = re.sub(r'(video|calibration) = "([^"]+)"', lambda m: f'{m.group(1)} = "{(base / m.group(2)).as_posix()}"', text)
    blocks = text.split("[[tests]]")
    sines = [b for b in blocks[1:] if 'kind = "sine"' in b]
    if case == "two_dwells":
        text = blocks[0] + "".join("[[tests]]" + b for b in sines[:2])
        expected = "only 2 sine dwell(s) could be fitted"
    else:
        # The same dwell recorded three times (copies of one video): every
        # point at one frequency, whatever the sine fit refines.
        for k in range(3):
            shutil.copy(base / re.search(r'video = "([^"]+)"', sines[1]).group(1).split("/")[-1], tmp_path / f"same{k}.mp4")
        same = [re.sub(r'video = "[^"]+"', f'video = "same{k}.mp4"', sines[1]) for k in range(3)]
        text = blocks[0] + "".join("[[tests]]" + b for b in same)
        expected = "at one frequency"
    manifest = tmp_path / "campaign.toml"
    manifest.write_text(text)
    out = tmp_path / "out"
    proc = run_cli("identify", str(manifest), "--out", str(out))
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("servoscope: error: ") and expected in lines[0], proc.stderr
    assert not (out / "result.json").exists()


def test_three_precise_phases_give_the_dead_time_not_an_alias():
    """A twin campaign's three dwells (monochrome 12-bit MRAW, seed 13): their phases known to 0.2–0.9°.

    The delay's basin is a millisecond wide there, and every quasi-random seed's rational part
    was tens of degrees off: the fit ended at 31.4 s (and, bounded, at 685 ms), cost 20050 where
    the renderer's 85 ms costs 3.2. Started from the magnitudes' own fit, it finds 85 ms.
    """
    fr = FrequencyResponse(np.array([1.5, 4.0, 10.0]), np.array([0.2317801329830731, 0.22225277418629988,
                                                               0.07908848547393754]),
                           np.array([0.0003868736749653076, 0.0001406288577689701, 6.650622962475589e-05]),
                           np.array([-65.37774708377498, -181.96443937056674, -76.02812574133416]),
                           np.array([0.28655546829918505, 0.914518959939884, 0.18924409021358815]),
                           np.ones(3), None)
    r = fit_second_order(fr, mode="complex")
    # The renderer's truth: K 0.23, ωn 37 rad/s, ζ 0.65, τ 85 ms.
    assert r.dead_time_s == pytest.approx(0.085, abs=0.5e-3)
    assert r.natural_frequency_rad_s == pytest.approx(37.0, rel=0.01)
    assert r.damping_ratio == pytest.approx(0.65, rel=0.01)
    # Its cost is the fit at the true delay's or lower (the global optimum, not a neighbour of it).
    held = fit_transfer_function(fr, order=(0, 2), mode="complex", fix={"dead_time_s": 0.085})
    assert r.cost <= held.cost


def test_settle_auto_in_the_manifest_is_fit_sines_auto(quick_result):
    """campaign.toml's ``settle_s = "auto"``: each dwell's window where fit_sine's own "auto" puts it."""
    from dataclasses import replace

    from servoscope.campaign import identify
    from servoscope.campaign.result import input_start

    campaign = replace(quick_result.campaign, settle_s="auto")
    result = identify(campaign, tracks=quick_result.tracks)
    assert set(result.sine_fits) == set(quick_result.sine_fits)
    for test in campaign.sine_tests:
        track = quick_result.tracks[test.label]
        own = fit_sine(track.angle_time_s, track.angle_rad, test.frequency_hz, t0_s=input_start(test, track),
                       valid=track.valid)
        got = result.sine_fits[test.label]
        assert got.settle_s == own.settle_s and got.n_samples == own.n_samples
        assert got.amplitude == pytest.approx(own.amplitude, rel=1e-9)
        assert quick_result.sine_fits[test.label].settle_s == pytest.approx(quick_result.campaign.settle_s)
    # The fixed 0.5 s and the dwells' own windows (0.31-0.5 s here) give the same model.
    for name, value in quick_result.model.params.items():
        assert result.model.params[name] == pytest.approx(value, rel=2e-3)

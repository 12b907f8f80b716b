"""Identification from a turning rotor's passes: a dwell's sine and the step from irregular pass samples.

The passes are computed here, not rendered: a rotor at Ω rev/s with a seeded slow drift of its
speed and a random start, N blades equally spaced, each read once a revolution (the blade at
ψ = 0); the pitch is the twin's servo (``PAPER_SERVO``, its dead time included) sampled at those
instants, plus each blade's offset and 0.01° of seeded noise. Oracles: the servo's own frequency
response (python-control), its step metrics, and :func:`fit_sine` on regular samples.
"""

from __future__ import annotations

import json
import math

import control
import numpy as np
import pytest
from scipy.interpolate import CubicSpline
from scipy.signal import lfilter

from servoscope.errors import ServoscopeError
from servoscope.rig.rotor_plan import plan_rotor_sweep
from servoscope.simulate import InputSignal
from servoscope.simulate.presets import PAPER_SERVO
from servoscope.sysid import FrequencyResponse, SineFit, fit_sine, fit_transfer_function
from servoscope.sysid.pass_sine import PassSineFit, fit_pass_sine, pass_nyquist_hz
from servoscope.sysid.pass_step import analyse_pass_step
from servoscope.sysid.step import model_step_metrics

NOISE_RAD = math.radians(0.01)
OFFSETS_RAD = np.array([0.0, math.radians(0.2), math.radians(-0.1)])
T0_S = 0.4
A_IN = 0.1


def pass_times(rev_per_s: float, n_blades: int, t_end_s: float, rng: np.random.Generator, drift: float = 0.005):
    """Each blade's passes: the rotor's turns reach ``k + i/N`` (blade i), its speed wobbling by `drift` at 0.3 Hz."""
    f_d, ph, start = 0.3, rng.uniform(0.0, 2 * np.pi), rng.uniform(0.0, 1.0)
    k = rev_per_s * drift / (2 * np.pi * f_d)

    def turns(t):  # the rotor's revolutions at t: its speed rev_per_s·(1 + drift·sin(2π f_d t + ph))
        return start + rev_per_s * t - k * (np.cos(2 * np.pi * f_d * t + ph) - np.cos(ph))

    u = np.arange(math.ceil(start * n_blades), math.floor(turns(t_end_s) * n_blades) + 1) / n_blades
    t = (u - start) / rev_per_s
    for _ in range(6):  # Newton: turns(t) = u
        t -= (turns(t) - u) / (rev_per_s * (1 + drift * np.sin(2 * np.pi * f_d * t + ph)))
    assert np.max(np.abs(turns(t) - u)) < 1e-12
    return t, np.rint((u * n_blades) % n_blades).astype(int)


def rotor_dwell(f_hz, rng, *, rev_per_s=20.0, n_blades=2, t_end_s=None):
    """Passes of one dwell: times, blades, pitches (servo + offsets + noise), stated errors."""
    t_end_s = t_end_s if t_end_s is not None else T0_S + max(3.0, 0.5 + 8 / f_hz)
    t, b = pass_times(rev_per_s, n_blades, t_end_s, rng)
    y = PAPER_SERVO.response(InputSignal("sine", A_IN, f_hz, t0_s=T0_S), t)
    return t, b, y + OFFSETS_RAD[b] + NOISE_RAD * rng.standard_normal(t.size), np.full(t.size, NOISE_RAD)


def truth(f_hz):
    """The servo's gain and phase at `f_hz`, its dead time included."""
    w = 2 * np.pi * f_hz
    g = complex(control.evalfr(PAPER_SERVO.transfer_function, 1j * w)) * np.exp(-1j * w * PAPER_SERVO.dead_time_s)
    return abs(g), np.angle(g)


def wrap(x):
    return (np.asarray(x) + np.pi) % (2 * np.pi) - np.pi


# ------------------------------------------------------------------ one dwell against fit_sine
@pytest.mark.parametrize("settle_s", [0.5, "auto"])
def test_regular_samples_of_one_blade_give_fit_sines_numbers(settle_s):
    rng = np.random.default_rng(3)
    t = np.arange(400) / 100.0 + 0.003
    y = PAPER_SERVO.response(InputSignal("sine", A_IN, 3.0, t0_s=0.21), t) + 0.01 + 1e-4 * rng.standard_normal(t.size)
    ref = fit_sine(t, y, 3.0, t0_s=0.21, settle_s=settle_s, refine_frequency=False)
    # No stated errors: the scatter (HAC) sets the errors, as in fit_sine.
    got = fit_pass_sine(t, np.zeros(t.size, int), y, None, 3.0, t0_s=0.21, settle_s=settle_s)
    assert isinstance(got, SineFit)
    for name in ("amplitude", "amplitude_stderr", "phase_rad", "phase_stderr_rad", "offset", "offset_stderr",
                 "fidelity", "thd", "residual_rms", "settle_s"):
        assert getattr(got, name) == pytest.approx(getattr(ref, name), rel=1e-9, abs=1e-15), name
    assert got.n_samples == ref.n_samples and got.window_s == ref.window_s and got.flags == ref.flags == ()
    np.testing.assert_allclose(got.model(t), ref.model(t), rtol=0, atol=1e-15)


# ------------------------------------------------------------------ many rotors: intervals hold
@pytest.fixture(scope="module")
def monte_carlo():
    """600 seeded rotors (2 blades, 20 rev/s, drifting) at 2 Hz and 11 Hz: the fits.

    The servo's exact response is computed once a frequency on a 0.2 ms grid and read at each
    rotor's passes through a cubic spline (checked here against the servo at the passes: 1e-13 rad).
    """
    rows = []
    for f_hz in (2.0, 11.0):
        t_end = T0_S + max(3.0, 0.5 + 8 / f_hz)
        grid = np.arange(T0_S, t_end + 1e-3, 2e-4)
        signal = InputSignal("sine", A_IN, f_hz, t0_s=T0_S)
        servo = CubicSpline(grid, PAPER_SERVO.response(signal, grid))
        for seed in range(300):
            rng = np.random.default_rng(1000 * int(f_hz) + seed)
            t, b = pass_times(20.0, 2, t_end, rng)
            t, b = t[t > T0_S], b[t > T0_S]
            if seed == 0:
                np.testing.assert_allclose(servo(t), PAPER_SERVO.response(signal, t), rtol=0, atol=1e-12)
            y = servo(t) + OFFSETS_RAD[b] + NOISE_RAD * rng.standard_normal(t.size)
            rows.append((f_hz, fit_pass_sine(t, b, y, np.full(t.size, NOISE_RAD), f_hz, t0_s=T0_S, settle_s=0.5)))
    return rows


def test_amplitude_and_phase_intervals_hold_the_servos_truth_95_percent(monte_carlo):
    z_amp, z_ph = [], []
    for f_hz, fit in monte_carlo:
        gain, phase = truth(f_hz)
        z_amp.append((fit.amplitude - A_IN * gain) / fit.amplitude_stderr)
        z_ph.append(wrap(fit.phase_rad - phase) / fit.phase_stderr_rad)
        assert fit.flags == (), fit.warnings
    for z in (np.array(z_amp), np.array(z_ph)):
        cover = np.mean(np.abs(z) < 1.96)
        assert 0.91 <= cover <= 0.985, cover   # 95 % within about 4 of its sampling errors (0.9 %)
        assert 0.85 < np.sqrt(np.mean(z**2)) < 1.15
        assert abs(np.mean(z)) < 0.2  # unbiased: the mean z of 600 within 5 of its own error


def test_blade_offset_recovered_to_003_deg_and_its_interval_holds(monte_carlo):
    true_diff = OFFSETS_RAD[1] - OFFSETS_RAD[0]
    inside = []
    for f_hz, fit in monte_carlo:
        (d,) = fit.blade_differences
        assert (d.blade, d.reference_blade) == (1, 0)
        assert abs(math.degrees(d.difference_rad - true_diff)) < 0.03
        inside.append(d.ci95_rad[0] <= true_diff <= d.ci95_rad[1])
        assert [o.blade for o in fit.blade_offsets] == [0, 1]
        assert fit.blade_offsets[1].offset_rad - fit.blade_offsets[0].offset_rad == pytest.approx(d.difference_rad)
        assert fit.rev_per_s == pytest.approx(20.0, rel=0.01) and fit.pass_nyquist_hz == pytest.approx(20.0, rel=0.01)
    assert 0.92 <= np.mean(inside) <= 0.98
    # The stated errors are honest here: the scatter agrees with them (χ² per degree of freedom about 1).
    assert np.mean([fit.chi2_reduced for _, fit in monte_carlo]) == pytest.approx(1.0, abs=0.05)


def test_transfer_function_from_pass_dwells_up_to_70_percent_of_nyquist():
    plan = plan_rotor_sweep(2000.0, 20.0, 2, points=10, step=False)
    freqs = [d.frequency_hz for d in plan.dwells]
    assert max(freqs) == pytest.approx(0.7 * pass_nyquist_hz(20.0, 2))
    fits = []
    for i, d in enumerate(plan.dwells):
        t, b, y, s = rotor_dwell(d.frequency_hz, np.random.default_rng(77 + i), t_end_s=T0_S + d.duration_s)
        fits.append(fit_pass_sine(t, b, y, s, d.frequency_hz, t0_s=T0_S, settle_s=plan.settle_s))
    assert not any(f.flags for f in fits), [f.warnings for f in fits]  # the plan's dwells stay clear of the Nyquist
    fr = FrequencyResponse.from_sine_fits(fits, A_IN)
    fit = fit_transfer_function(fr, order=(0, 2), mode="complex")
    true = {"gain": PAPER_SERVO.gain, "natural_frequency_rad_s": PAPER_SERVO.natural_frequency_rad_s,
            "damping_ratio": PAPER_SERVO.damping_ratio, "dead_time_s": PAPER_SERVO.dead_time_s}
    p = fit.parameters
    assert p["gain"].value == pytest.approx(true["gain"], rel=0.01)
    assert p["natural_frequency_rad_s"].value == pytest.approx(true["natural_frequency_rad_s"], rel=0.01)
    assert p["damping_ratio"].value == pytest.approx(true["damping_ratio"], rel=0.03)
    assert p["dead_time_s"].value == pytest.approx(true["dead_time_s"], abs=1e-3)
    for name, value in true.items():
        assert p[name].holds(value), (name, p[name])
    json.dumps([f.summary() for f in fits], allow_nan=False)


# ------------------------------------------------------------------ what passes cannot see
def test_dwells_at_or_near_the_pass_rate_nyquist_are_flagged():
    rng = np.random.default_rng(5)
    planned = fit_pass_sine(*rotor_dwell(14.0, rng), 14.0, t0_s=T0_S, settle_s=0.5)
    assert "aliasing" not in planned.flags
    near = fit_pass_sine(*rotor_dwell(17.0, rng), 17.0, t0_s=T0_S, settle_s=0.5)
    assert "aliasing" in near.flags and any("close to the pass-rate Nyquist" in w for w in near.warnings)
    above = fit_pass_sine(*rotor_dwell(23.0, rng), 23.0, t0_s=T0_S, settle_s=0.5, rev_per_s=20.0)
    assert "aliasing" in above.flags
    assert any("cannot tell it from 17 Hz" in w for w in above.warnings), above.warnings


def test_a_dwell_on_the_rotor_speed_with_three_blades_is_flagged():
    # With 3 blades Ω = 20 Hz is below the passes' Nyquist (30 Hz), but every blade sees the sine still.
    rng = np.random.default_rng(9)
    on = fit_pass_sine(*rotor_dwell(20.0, rng, n_blades=3), 20.0, t0_s=T0_S, settle_s=0.5)
    assert "rotor_harmonic" in on.flags and "aliasing" not in on.flags
    off = fit_pass_sine(*rotor_dwell(13.0, rng, n_blades=3), 13.0, t0_s=T0_S, settle_s=0.5)
    assert "rotor_harmonic" not in off.flags and len(off.blade_differences) == 2
    true = OFFSETS_RAD[1:3] - OFFSETS_RAD[0]
    got = [d.difference_rad for d in off.blade_differences]
    assert np.degrees(np.abs(np.subtract(got, true))).max() < 0.03


def test_auto_settle_takes_each_blades_offset_off_before_looking_for_the_transient():
    rng = np.random.default_rng(8)
    t, b, y, s = rotor_dwell(5.0, rng)
    auto = fit_pass_sine(t, b, y, s, 5.0, t0_s=T0_S)
    fixed = fit_pass_sine(t, b, y, s, 5.0, t0_s=T0_S, settle_s=0.5)
    # The servo's transient (dead time 85 ms, ζωn = 24/s) is over within a few tenths of a second;
    # a 0.2° offset left in would read as a transient that lasts half the record.
    assert 0.1 < auto.settle_s < 0.6 and "transient" not in auto.flags
    assert auto.amplitude == pytest.approx(fixed.amplitude, abs=2 * fixed.amplitude_stderr)


def test_stated_errors_are_a_floor_and_the_scatter_widens_them():
    rng = np.random.default_rng(21)
    t, b, y, s = rotor_dwell(4.0, rng)
    honest = fit_pass_sine(t, b, y, s, 4.0, t0_s=T0_S, settle_s=0.5)
    modest = fit_pass_sine(t, b, y, 10 * s, 4.0, t0_s=T0_S, settle_s=0.5)   # tracker says 10× the scatter
    bold = fit_pass_sine(t, b, y, 0.1 * s, 4.0, t0_s=T0_S, settle_s=0.5)    # tracker says a tenth
    assert modest.amplitude == pytest.approx(honest.amplitude, rel=1e-12)
    assert modest.amplitude_stderr == pytest.approx(10 * honest.amplitude_stderr, rel=0.3)
    assert bold.amplitude_stderr == pytest.approx(honest.amplitude_stderr, rel=0.3)
    assert bold.chi2_reduced == pytest.approx(100 * honest.chi2_reduced, rel=1e-9)


def test_passes_whose_errors_are_correlated_take_the_hac_covariance():
    # The tracker's error drifts from pass to pass (AR(1), 0.8 a pass), its stated error the
    # marginal one: weighted least squares alone would state the 2 Hz amplitude's error ~3 times too small.
    z, kinds = [], []
    f_hz = 2.0
    gain, _ = truth(f_hz)
    for seed in range(150):
        rng = np.random.default_rng(seed)
        t, b, y, s = rotor_dwell(f_hz, rng)
        e = lfilter([0.6], [1.0, -0.8], rng.standard_normal(t.size), zi=[0.8 * rng.standard_normal()])[0]
        fit = fit_pass_sine(t, b, y + 3 * NOISE_RAD * e, np.hypot(s, 3 * NOISE_RAD), f_hz, t0_s=T0_S, settle_s=0.5)
        z.append((fit.amplitude - A_IN * gain) / fit.amplitude_stderr)
        kinds.append(fit.covariance_kind)
    assert kinds.count("HAC") >= 140
    assert np.mean(np.abs(z) < 1.96) >= 0.88
    white = fit_pass_sine(*rotor_dwell(f_hz, np.random.default_rng(4)), f_hz, t0_s=T0_S, settle_s=0.5)
    assert white.covariance_kind == "stated errors"


def test_bad_inputs_are_one_clear_error():
    t, b, y, s = rotor_dwell(2.0, np.random.default_rng(0))
    with pytest.raises(ServoscopeError, match="blade has"):
        fit_pass_sine(t, b[:-1], y, s, 2.0, t0_s=T0_S)
    with pytest.raises(ServoscopeError, match="stated error"):
        fit_pass_sine(t, b, y, np.where(b == 1, 0.0, s), 2.0, t0_s=T0_S)
    with pytest.raises(ServoscopeError, match="whole numbers"):
        fit_pass_sine(t, b - 1, y, s, 2.0, t0_s=T0_S)
    with pytest.raises(ServoscopeError, match="usable passes"):
        fit_pass_sine(t[:4], b[:4], y[:4], s[:4], 2.0, t0_s=0.0, settle_s=0.0)


def test_a_pass_fit_round_trips_as_a_sine_fit():
    fit = fit_pass_sine(*rotor_dwell(6.0, np.random.default_rng(2)), 6.0, t0_s=T0_S, settle_s=0.5)
    data = fit.summary()
    assert data["rotor"]["n_blades"] == 2 and len(data["rotor"]["blade_differences"]) == 1
    back = SineFit.from_summary(data)
    assert back.amplitude == fit.amplitude and back.phase_rad == fit.phase_rad
    np.testing.assert_allclose(back.model(fit.time_s), fit.model(fit.time_s), atol=1e-12)
    again = PassSineFit.from_summary(json.loads(json.dumps(data)))
    assert isinstance(again, PassSineFit) and again.summary() == data
    assert again.blade_differences == fit.blade_differences
    np.testing.assert_allclose(fit.y - fit.model(fit.time_s), fit.residual, atol=1e-15)


# ------------------------------------------------------------------ the step from passes
def test_step_from_passes_removes_offsets_and_states_what_the_spacing_allows():
    true = model_step_metrics(PAPER_SERVO.transfer_function)
    rise_err, rise_se, thr, covered = [], [], [], []
    for seed in range(60):
        rng = np.random.default_rng(seed)
        t, b = pass_times(20.0, 2, 3.0, rng)
        y = (PAPER_SERVO.response(InputSignal("step", 0.5, t0_s=0.8), t) + OFFSETS_RAD[b]
             + NOISE_RAD * rng.standard_normal(t.size))
        sa = analyse_pass_step(t, b, y, t0_s=0.8, step_size=0.5)
        diff = sa.blade_offsets_rad[1] - sa.blade_offsets_rad[0]
        assert abs(math.degrees(diff - OFFSETS_RAD[1])) < 0.03
        assert sa.pass_spacing_s == pytest.approx(0.025, rel=0.01)
        assert sa.gain == pytest.approx(PAPER_SERVO.gain, rel=0.01)
        rise_err.append(sa.rise_time_s - true["rise_time_s"])
        rise_se.append(sa.rise_time_stderr_s)
        covered.append(abs(rise_err[-1]) < 1.96 * rise_se[-1])
        thr.append(sa.dead_time_threshold_s)
    assert np.mean(covered) >= 0.95
    assert np.sqrt(np.mean(np.square(rise_err))) < 0.004  # a few ms from passes 25 ms apart
    # The threshold dead time moves with where the passes fall: by h/√12, what it states.
    assert np.std(thr) == pytest.approx(sa.dead_time_threshold_stderr_s, rel=0.3)
    assert sa.dead_time_threshold_stderr_s == pytest.approx(0.025 / math.sqrt(12), rel=0.02)
    assert any("cannot be read to 1 ms by counting passes" in w and "dwells' phases and the LED" in w
               for w in sa.warnings)
    # With the model, its step fitted to the passes locates the dead time (a check beside the dwells').
    modelled = analyse_pass_step(t, b, y, t0_s=0.8, step_size=0.5, model=PAPER_SERVO.transfer_function)
    assert abs(modelled.dead_time_s - PAPER_SERVO.dead_time_s) < 4 * modelled.dead_time_stderr_s < 1e-3
    assert any("resting on the model's shape" in w for w in modelled.warnings)
    data = sa.summary()
    json.dumps(data, allow_nan=False)
    assert data["passes"]["pass_spacing_s"] == pytest.approx(sa.pass_spacing_s)

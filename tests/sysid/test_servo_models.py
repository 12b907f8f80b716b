"""One model for the sines and the step (issue 17, builds 2, 3 and 5): block-structured servo models.

Oracles: the digital twin's servo simulator (:mod:`servoscope.simulate.servo`, written
separately: its own grid, first-order hold and play operator), python-control's forced
response with numpy's clip (saturation, which the twin does not have), and the truth the
twin's servos were built with.
"""

from __future__ import annotations

import json
import math

import control
import numpy as np
import pytest

from servoscope.simulate.presets import get_preset
from servoscope.simulate.servo import InputSignal, ServoModel
from servoscope.sysid.servo_fit import (
    TRACE_SYSTEMATIC,
    dwell_cost,
    fit_percent,
    fit_servo_model,
)
from servoscope.sysid.servo_select import select_servo_model
from servoscope.sysid.servo_sim import ServoTrace, simulate_trace

PAPER = get_preset("quick").servo
K, WN, ZETA, TAU = PAPER.gain, PAPER.natural_frequency_rad_s, PAPER.damping_ratio, 0.085
LINEAR = {"gain": K, "natural_frequency_rad_s": WN, "damping_ratio": ZETA, "dead_time_s": TAU}
#: Each structure: the twin's option and the fitted parameter's true value (the rate limit in the
#: output's units: the twin limits the reference, in input units per second, so times K).
STRUCTURES = {"rate_limit": ({"rate_limit_per_s": 4.0}, "rate_limit_rad_s", 4.0 * K),
              "backlash": ({"backlash": 0.004}, "backlash_rad", 0.004),
              "quantization": ({"input_quantization": 0.02}, "quantization_step", 0.02)}


def _trace(kind, amplitude, frequency_hz, t, y, noise=3e-5, exposure_s=0.0, t0=0.3):
    window = (t0 + 0.3, float(t[-1])) if kind == "sine" else None
    return ServoTrace(f"{kind}_{frequency_hz}_{amplitude}", kind, amplitude, frequency_hz, t0, t, y, noise,
                      exposure_s, window)


def _campaign(servo: ServoModel, seed: int, fps: float = 100.0, noise: float = 3e-5):
    """The quick preset's tests (4 frequencies at 2 amplitudes and a step) simulated by the twin, with noise."""
    rng = np.random.default_rng(seed)
    traces, response = [], {}
    for f in (1.0, 2.29, 5.24, 12.0):
        for a in (0.05, 0.2):
            t = np.arange(0.0, 0.3 + 0.3 + max(1.0, 2.0 / f), 1.0 / fps) + rng.uniform(0, 1.0 / fps)
            y = servo.response(InputSignal("sine", a, f, 0.3), t) + noise * rng.standard_normal(t.size) + 0.02
            tr = _trace("sine", a, f, t, y, noise)
            traces.append(tr)
    t = np.arange(0.0, 1.0, 1.0 / fps)
    traces.append(_trace("step", 0.5, None, t, servo.response(InputSignal("step", 0.5, None, 0.3), t)
                         + noise * rng.standard_normal(t.size) - 0.01, noise))
    for tr in traces:
        if tr.kind == "sine":
            # The measured fundamental, by the same regression the model's goes through (a linear oracle).
            lo, hi = tr.window_s
            inside = (tr.time_s >= lo) & (tr.time_s <= hi)
            w = 2 * math.pi * tr.frequency_hz * (tr.time_s[inside] - tr.t0_s)
            a, b, _ = np.linalg.lstsq(np.column_stack([np.sin(w), np.cos(w), np.ones_like(w)]),
                                      tr.angle_rad[inside], rcond=None)[0]
            response[tr.label] = (math.hypot(a, b) / tr.amplitude, math.degrees(math.atan2(b, a)), 1.0)
    return traces, response


@pytest.mark.parametrize("kind", ["sine", "step"])
@pytest.mark.parametrize("structure", ["linear", *STRUCTURES])
def test_simulation_agrees_with_the_twins(structure, kind):
    option, name, value = STRUCTURES.get(structure, ({}, None, None))
    twin = ServoModel(PAPER.num, PAPER.den, dead_time_s=TAU, **option)
    t = np.arange(0.0, 1.5, 0.01) + 0.0037
    signal = InputSignal(kind, 0.2, 5.24 if kind == "sine" else None, 0.3)
    truth = twin.response(signal, t)
    ours = simulate_trace(_trace(kind, 0.2, signal.frequency_hz, t, truth), structure,
                          {**LINEAR, **({name: value} if name else {})})
    # Two discretisations of the same physics: exact for the linear model, within 0.1 % of the
    # swing where a rate limit's corners or a quantized command's steps fall between grid points.
    tol = 1e-7 if structure == "linear" else 1e-3 * np.ptp(truth)
    assert np.max(np.abs(ours - truth)) < tol
    assert np.max(np.abs(truth)) > 0.03  # the test moved


def test_exposure_averages_the_output_over_its_window():
    t = np.arange(0.0, 1.2, 0.01)
    twin = ServoModel(PAPER.num, PAPER.den, dead_time_s=TAU, backlash=0.004)
    signal = InputSignal("sine", 0.2, 12.0, 0.3)
    e = 0.008
    # The oracle: the twin's output averaged over 801 instants across each exposure.
    offsets = np.linspace(-e / 2, e / 2, 801)
    truth = np.mean([twin.response(signal, t + o) for o in offsets], axis=0)
    ours = simulate_trace(_trace("sine", 0.2, 12.0, t, truth, exposure_s=e), "backlash",
                          {**LINEAR, "backlash_rad": 0.004})
    assert np.max(np.abs(ours - truth)) < 2e-6
    assert np.max(np.abs(twin.response(signal, t) - truth)) > 3e-4  # the exposure mattered (100x the agreement)


def test_saturation_against_python_control():
    fine = np.arange(0.0, 1.0, 1e-5)
    u = np.where(fine >= 0.3 + TAU, 0.5, 0.0)  # the step, delayed
    linear = np.asarray(control.forced_response(control.tf(PAPER.num, PAPER.den), fine, u).outputs)[::100]
    truth = np.clip(linear, -0.11, 0.11)
    t = fine[::100]
    ours = simulate_trace(_trace("step", 0.5, None, t, truth), "saturation", {**LINEAR, "saturation_rad": 0.11})
    assert np.max(linear) > 0.12  # the travel clipped the overshoot
    # python-control interpolates its input linearly: its step lands within half its 10 µs grid.
    assert np.max(np.abs(ours - truth)) < 5e-5


def test_fit_percent_is_matlab_compare():
    y = np.array([0.0, 1.0, 2.0, 3.0])
    assert fit_percent(y, y) == 100.0
    assert fit_percent(y, np.full(4, y.mean())) == pytest.approx(0.0)
    assert fit_percent(y, y + 0.1) == pytest.approx(100 * (1 - 0.2 / math.sqrt(5.0)))


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("structure", ["linear", *STRUCTURES])
def test_the_true_structure_is_selected_and_measured(structure, seed):
    option, name, value = STRUCTURES.get(structure, ({}, None, None))
    traces, response = _campaign(ServoModel(PAPER.num, PAPER.den, dead_time_s=TAU, **option), seed)
    sel = select_servo_model(traces, list(STRUCTURES), response=response)
    fit = sel.selected
    assert fit.structure == structure, [(c.structure, c.bic) for c in sel.candidates]
    truth = {**LINEAR, **({name: value} if name else {})}
    for k in ("gain", "natural_frequency_rad_s"):
        assert fit.params[k] == pytest.approx(truth[k], rel=0.02)
    if name:
        assert fit.params[name] == pytest.approx(value, rel=0.05 if structure == "rate_limit" else 0.1)
    for k, v in truth.items():
        lo, hi = fit.ci95[k]
        assert lo <= v <= hi, (k, v, lo, hi)
    assert fit.J < 50 and fit.step_fit_percent > 99
    # The linear model, fitted to the same traces, explains them worse by far when the servo is not linear.
    linear = sel.candidates[0]
    assert linear.structure == "linear"
    if name:
        assert linear.bic - fit.bic > 100
    assert sel.cross_validation["dwells_to_step"]["fit_percent"] > 95


def test_holding_a_parameter_at_its_truth_narrows_the_others():
    traces, response = _campaign(ServoModel(PAPER.num, PAPER.den, dead_time_s=TAU), 3)
    free = fit_servo_model(traces, "linear", response=response)
    held = fit_servo_model(traces, "linear", fix={"damping_ratio": ZETA}, response=response)
    assert held.params["damping_ratio"] == ZETA and held.stderr["damping_ratio"] == 0 and held.fixed == ("damping_ratio",)
    assert held.n_free == free.n_free - 1
    # The stated errors include a systematic floor (TRACE_SYSTEMATIC): compare the statistical parts.
    def statistical(fit, k):
        return math.sqrt(max(fit.stderr[k] ** 2 - (TRACE_SYSTEMATIC[k] * fit.params[k]) ** 2, 0.0))
    assert statistical(held, "natural_frequency_rad_s") < statistical(free, "natural_frequency_rad_s")
    for fit in (free, held):
        for k, v in LINEAR.items():
            assert fit.ci95[k][0] <= v <= fit.ci95[k][1], (k, fit.ci95[k], v)
    bounded = fit_servo_model(traces, "linear", bounds={"natural_frequency_rad_s": (20.0, 30.0)})
    assert bounded.params["natural_frequency_rad_s"] == pytest.approx(30.0)
    assert any("ended at its limit" in w for w in bounded.warnings)


def test_paper_nonlinear_preset_is_the_papers_puzzle_and_backlash_explains_it():
    preset = get_preset("paper-nonlinear")
    servo = preset.servo
    rng = np.random.default_rng(0)
    traces, response = [], {}
    for f in preset.frequencies_hz[::2]:
        for a in preset.sine_amplitudes:
            t = np.arange(0.0, 1.0 + max(2.0, 4.0 / f), 0.01)
            y = servo.response(InputSignal("sine", a, f, 0.5), t) + 3e-5 * rng.standard_normal(t.size)
            traces.append(_trace("sine", a, f, t, y, t0=0.5))
    t = np.arange(0.0, 2.0, 0.01)
    step = servo.response(InputSignal("step", preset.step_amplitude, None, 0.5), t)
    traces.append(_trace("step", preset.step_amplitude, None, t, step + 3e-5 * rng.standard_normal(t.size), t0=0.5))
    for tr in traces[:-1]:
        exact = ServoModel(servo.num, servo.den, dead_time_s=servo.dead_time_s, backlash=servo.backlash)
        fund = exact.response(InputSignal("sine", tr.amplitude, tr.frequency_hz, 0.5), tr.time_s)
        lo, hi = tr.window_s
        inside = (tr.time_s >= lo) & (tr.time_s <= hi)
        w = 2 * math.pi * tr.frequency_hz * (tr.time_s[inside] - 0.5)
        a, b, _ = np.linalg.lstsq(np.column_stack([np.sin(w), np.cos(w), np.ones_like(w)]), fund[inside], rcond=None)[0]
        response[tr.label] = (math.hypot(a, b) / tr.amplitude, math.degrees(math.atan2(b, a)), 1.0)
    # The puzzle: ζ = 0.65 overshoots 7 % when linear, and this step does not.
    final = np.mean(step[-30:])
    assert (np.max(step) - final) / final < 0.01 and (np.max(step) - final) / final >= 0.0
    sel = select_servo_model(traces, ["rate_limit", "backlash"], response=response)
    assert sel.selected.structure == "backlash"
    assert sel.selected.step_fit_percent > 95 and sel.selected.J <= 50
    linear = sel.candidates[0]
    assert linear.J > 50 or linear.step_fit_percent < 95
    assert sel.selected.params["backlash_rad"] == pytest.approx(0.012, rel=0.1)
    # Its CIFER J is the oracle's: the same cost of python-control's own frequency response for the linear part.
    assert dwell_cost(LINEAR, "linear", [traces[0]], {traces[0].label: response[traces[0].label]}) > 0


def test_summary_round_trips_and_bad_names_are_refused():
    from servoscope.errors import ServoscopeError
    from servoscope.sysid.servo_select import ServoModelSelection

    traces, response = _campaign(ServoModel(PAPER.num, PAPER.den, dead_time_s=TAU, backlash=0.004), 0)
    sel = select_servo_model(traces, ["backlash"], response=response)
    text = json.dumps(sel.summary())
    again = ServoModelSelection.from_summary(json.loads(text))
    assert json.dumps(again.summary()) == text
    with pytest.raises(ServoscopeError, match="did you mean 'backlash_rad'"):
        fit_servo_model(traces, "backlash", fix={"backlash": 0.1})
    with pytest.raises(ServoscopeError, match="outside its bounds"):
        fit_servo_model(traces, "linear", fix={"damping_ratio": 0.9}, bounds={"damping_ratio": (0.1, 0.5)})
    with pytest.raises(ServoscopeError, match="unknown model structure"):
        fit_servo_model(traces, "hysteresis")

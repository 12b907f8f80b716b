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
    fit_percent,
    fit_servo_model,
)
from servoscope.sysid.servo_select import select_servo_model
from servoscope.sysid.servo_sim import simulate_trace

from support import SERVO_LINEAR as LINEAR, SERVO_STRUCTURES as STRUCTURES, servo_campaign as _campaign
from support import servo_trace as _trace

PAPER = get_preset("quick").servo
ZETA, TAU = PAPER.damping_ratio, 0.085

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


def test_a_tied_parameter_follows_its_expression():
    from servoscope.errors import ServoscopeError

    traces, response = _campaign(ServoModel(PAPER.num, PAPER.den, dead_time_s=TAU, rate_limit_per_s=4.0), 0)
    free = fit_servo_model(traces, "rate_limit", response=response)
    tied = fit_servo_model(traces, "rate_limit", ties={"rate_limit_rad_s": "4*gain"}, response=response)
    # The truth is tied so: the twin limits its set-point to 4 input units/s, the blade to 4·K rad/s.
    assert tied.params["rate_limit_rad_s"] == pytest.approx(4 * tied.params["gain"], rel=1e-12)
    assert tied.tied == {"rate_limit_rad_s": "4*gain"} and tied.n_free == free.n_free - 1
    # Its error by the delta method: 4 times the gain's stated one (systematic part included).
    assert tied.stderr["rate_limit_rad_s"] == pytest.approx(4 * tied.stderr["gain"], rel=1e-4)
    for k, v in {**LINEAR, "rate_limit_rad_s": 4.0 * PAPER.gain}.items():
        assert tied.ci95[k][0] <= v <= tied.ci95[k][1], (k, tied.ci95[k], v)
    assert tied.params["rate_limit_rad_s"] == pytest.approx(4.0 * PAPER.gain, rel=2e-3)
    assert tied.summary()["tied"] == {"rate_limit_rad_s": "4*gain"}
    with pytest.raises(ServoscopeError, match="did you mean 'gain'"):
        fit_servo_model(traces, "rate_limit", ties={"rate_limit_rad_s": "4*gian"})
    with pytest.raises(ServoscopeError, match="cannot also be fixed"):
        fit_servo_model(traces, "rate_limit", ties={"rate_limit_rad_s": "4*gain"}, fix={"rate_limit_rad_s": 1.0})
    with pytest.raises(ServoscopeError, match="tied itself"):
        fit_servo_model(traces, "rate_limit", ties={"rate_limit_rad_s": "4*gain", "gain": "0.23*damping_ratio/0.65",
                                                    "damping_ratio": "0.65"})
    with pytest.raises(ServoscopeError, match="not an expression"):
        fit_servo_model(traces, "rate_limit", ties={"rate_limit_rad_s": "4*(gain"})

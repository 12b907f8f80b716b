"""Model selection between servo structures (issue 17, builds 3 and 5), on the twin's servos.

Each campaign is the quick preset's tests simulated by the twin's own servo simulator (not
rendered: what is tested here is the selection), with tracking-sized noise; the oracle is
the truth the servo was built with. Rendered footage: tests/campaign/test_joint.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from servoscope.simulate.presets import get_preset
from servoscope.simulate.servo import InputSignal, ServoModel
from servoscope.sysid.servo_fit import dwell_cost
from servoscope.sysid.servo_select import select_servo_model

from support import SERVO_LINEAR as LINEAR, SERVO_STRUCTURES as STRUCTURES, servo_campaign as _campaign
from support import servo_trace as _trace

PAPER = get_preset("quick").servo
TAU = 0.085


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

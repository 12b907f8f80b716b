"""--nonlinear without a step (issue 31, build 3): dwells at two amplitudes, or a sweep alone.

The twin's servo simulated (not rendered) for the selection's cases, one tiny rendered sweep
for the whole pipeline; the oracle is the truth the servo was built with. Measured on more
cases (rendered, two seeds): the issue's report.
"""

from __future__ import annotations

import math

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from servoscope.campaign.inputs import TestSpec
from servoscope.campaign.joint import check_nonlinear, identifiability_warnings
from servoscope.campaign.manifest import Campaign
from servoscope.errors import ServoscopeError
from servoscope.simulate.servo import InputSignal
from servoscope.sysid.servo_fit import fit_servo_model, trace_group
from servoscope.sysid.servo_select import TRACKER_BIAS_PX, cross_validate, select_servo_model
from servoscope.sysid.servo_sim import ServoTrace

from support import SERVO, SERVO_STRUCTURES, servo_trace

SWEEP = (0.5, 12.0, 6.0, "log")  # from_hz, to_hz, duration_s, shape
OTHERS = ("rate_limit", "backlash", "quantization", "saturation")


def _dwells(servo, rng, amplitudes=(0.05, 0.2), noise=3e-5):
    out = []
    for f in (1.0, 2.29, 5.24, 12.0):
        for a in amplitudes:
            t = np.arange(0.0, 0.6 + max(1.0, 2.0 / f), 0.01) + rng.uniform(0, 0.01)
            y = servo.response(InputSignal("sine", a, f, 0.3), t) + noise * rng.standard_normal(t.size) + 0.02
            out.append(servo_trace("sine", a, f, t, y, noise))
    return out


def _sweep(servo, rng, amplitude=0.1, noise=3e-5):
    lo, hi, duration, shape = SWEEP
    t = np.arange(0.0, 0.3 + duration + 0.5, 0.01) + rng.uniform(0, 0.01)
    y = servo.response(InputSignal("sweep", amplitude, None, 0.3, from_hz=lo, to_hz=hi, duration_s=duration,
                                   shape=shape), t) + noise * rng.standard_normal(t.size) - 0.01
    return ServoTrace("sweep", "sweep", amplitude, None, 0.3, t, y, noise, 0.0, None, math.nan, *SWEEP)


def _held_truth(fit, name, truth):
    assert fit.params[name] == pytest.approx(truth, rel=0.10)
    lo, hi = fit.ci95[name]
    assert lo <= truth <= hi, (name, truth, lo, hi)


@pytest.mark.parametrize("structure, source", [("backlash", "dwells"), ("rate_limit", "sweep")])
def test_the_structure_is_found_without_a_step(structure, source):
    option, name, truth = SERVO_STRUCTURES[structure]
    servo = replace(SERVO, **option)
    rng = np.random.default_rng(0)
    traces = _dwells(servo, rng) if source == "dwells" else [_sweep(servo, rng)]
    traces = [replace(tr, sticker_radius_px=133.0) for tr in traces]  # the 320×256 twin's
    sel = select_servo_model(traces, OTHERS)
    assert sel.selected.structure == structure, [(c.structure, c.bic) for c in sel.candidates]
    _held_truth(sel.selected, name, truth)
    if structure == "backlash":  # the tracker's sub-pixel bias, common to every test, widens the play's error
        assert sel.selected.stderr[name] >= TRACKER_BIAS_PX / 133.0
    _held_truth(sel.selected, "dead_time_s", 0.085)  # the input's start dates the phases: no step needed
    assert sel.cross_validation["verdict"].startswith("not done")
    assert "only" in sel.cross_validation["verdict"]


def test_a_sweep_trace_is_its_test_command_and_its_own_data_set():
    spec = TestSpec(Path("s.mp4"), "sweep", 0.1, from_hz=SWEEP[0], to_hz=SWEEP[1], duration_s=SWEEP[2],
                    shape="log")
    t = np.linspace(-0.5, 7.0, 4001)
    tr = ServoTrace("s", "sweep", 0.1, None, 0.5, t, np.zeros_like(t), 1e-4, 0.0, None, math.nan, *SWEEP)
    assert np.array_equal(tr.command(t), spec.command(t - 0.5))
    assert trace_group(tr) == "sweep" and tr.top_frequency_hz == 12.0
    with pytest.raises(ServoscopeError, match="to_hz"):
        ServoTrace("s", "sweep", 0.1, None, 0.5, t, t, 1e-4, 0.0, None, math.nan, 2.0, 1.0, 6.0, "log")


def test_dwells_and_a_sweep_cross_validate():
    rng = np.random.default_rng(1)
    traces = _dwells(SERVO, rng, amplitudes=(0.1,))[::2] + [_sweep(SERVO, rng)]
    fit = fit_servo_model(traces, "linear")
    cv = cross_validate(traces, fit, sigma={"dwells": 3e-5, "sweep": 3e-5})
    assert cv["dwells_to_sweep"]["fit_percent"] > 95
    assert cv["dwells_to_step"] is None
    assert "the dwells' model predicts the sweep" in cv["verdict"]


def test_a_campaign_without_a_step_says_what_it_cannot_tell_apart():
    rng = np.random.default_rng(2)
    sweep = [_sweep(SERVO, rng)]
    linear = fit_servo_model(sweep, "linear")
    notes = identifiability_warnings(sweep, OTHERS, linear)
    assert any("one input amplitude (0.1)" in n for n in notes)
    # The fastest slew commanded: K·A·2π·12 Hz.
    assert any(f"{SERVO.gain * 0.1 * 2 * math.pi * 12:.3g} rad/s" in n for n in notes)
    assert identifiability_warnings(sweep, ("linear",), linear) == []


def _campaign(tests) -> Campaign:
    return Campaign(Path("c.toml"), "red", "green", "yellow", None, None, "rad", 0.2, tests=tuple(tests))


def test_check_nonlinear_needs_no_step_but_enough_data():
    dwells = [TestSpec(Path(f"d{k}.mp4"), "sine", 0.1, 1.0 + k, label=f"d{k}") for k in range(5)]
    sweep = TestSpec(Path("s.mp4"), "sweep", 0.1, from_hz=0.5, to_hz=12.0, duration_s=6.0, shape="log", label="s")
    check_nonlinear(_campaign(dwells), "auto", (0, 2), {}, {})
    check_nonlinear(_campaign([sweep]), "backlash", (0, 2), {}, {})
    with pytest.raises(ServoscopeError, match="fits 5 parameters but the campaign has 4 sine dwell"):
        check_nonlinear(_campaign(dwells[:4]), "auto", (0, 2), {}, {})


def test_a_rendered_sweep_alone_finds_the_rate_limit(tmp_path):
    from servoscope.campaign import identify
    from servoscope.simulate import simulate_campaign

    option, name, truth = SERVO_STRUCTURES["rate_limit"]
    toml = simulate_campaign(tmp_path, "quick", 0, width=320, height=256, codec="raw", servo=replace(SERVO, **option),
                             include_step=False, frequencies_hz=(), sweep=SWEEP[:3], sine_amplitude=0.1,
                             settle_s=1.0)
    result = identify(toml, workers=1, nonlinear="auto")
    selected = result.servo_model.selected
    assert selected.structure == "rate_limit"
    _held_truth(selected, name, truth)
    assert any("one input amplitude" in w for w in result.warnings)

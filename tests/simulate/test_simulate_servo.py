"""The simulated actuator against python-control and closed-form answers."""

from __future__ import annotations

import math

import control
import numpy as np
import pytest

from servoscope.errors import ServoscopeError
from servoscope.simulate import PAPER_SERVO, InputSignal, ServoModel
from servoscope.simulate.servo import GRID_STEP_S

MODELS = {
    "paper": PAPER_SERVO,
    # third order with a zero: nothing 2nd-order specific may leak in
    "third_order": ServoModel(num=(0.5 * 30.0, 0.5 * 30.0 * 20.0), den=(1.0, 45.0, 1100.0, 20.0 * 1100.0 / 2.0),
                              dead_time_s=0.031),
    # biproper: a direct feed-through term (D != 0)
    "lead_lag": ServoModel(num=(0.4, 8.0), den=(1.0, 20.0), dead_time_s=0.0123),
}


@pytest.mark.parametrize("name", sorted(MODELS))
def test_step_response_matches_python_control_shifted_by_dead_time(name):
    model = MODELS[name]
    amp, t0 = 0.5, 0.3137
    sig = InputSignal("step", amp, t0_s=t0)
    tau = np.arange(0.0, 1.5, 1.0 / 997.0)  # control needs a uniform grid starting at 0
    _, y_ref = control.step_response(model.transfer_function, tau)
    y = model.response(sig, t0 + model.dead_time_s + tau)
    assert np.max(np.abs(y - amp * y_ref)) < 1e-6 * amp
    # at rest until the delayed onset
    before = np.linspace(0.0, t0 + model.dead_time_s - 1e-9, 50)
    assert np.all(model.response(sig, before) == 0.0)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_sine_response_matches_forced_response(name):
    model = MODELS[name]
    amp, f, t0 = 0.1, 7.3, 0.2071
    sig = InputSignal("sine", amp, f, t0_s=t0)
    # control interpolates the input linearly: (w dt)^2/12 < 1e-7 on this grid
    t = np.arange(0.0, 0.8, 2e-5)
    _, y_ref = control.forced_response(model.transfer_function, t, sig.value(t - model.dead_time_s))
    y = model.response(sig, t)
    assert np.max(np.abs(y - y_ref)) < 1e-6 * amp


def test_sine_reaches_the_frequency_response_in_steady_state():
    model = PAPER_SERVO
    amp, f, t0 = 0.1, 4.4, 0.5123
    sig = InputSignal("sine", amp, f, t0_s=t0)
    g = complex(model.transfer_function(2j * np.pi * f))
    # arbitrary, unsorted sample times after the transient (e^{-24 t}) has died out
    t = np.random.default_rng(5).uniform(t0 + 1.5, t0 + 3.0, 400)
    y = model.response(sig, t)
    expected = amp * abs(g) * np.sin(2 * np.pi * f * (t - t0 - model.dead_time_s) + np.angle(g))
    assert np.max(np.abs(y - expected)) < 1e-9


def test_input_signal_values():
    s = InputSignal("sine", 2.0, 3.0, t0_s=0.25)
    t = np.array([0.0, 0.2499, 0.25, 0.25 + 1 / 12, 0.25 + 1 / 4])
    assert np.allclose(s.value(t), [0.0, 0.0, 0.0, 2.0, 2.0 * np.sin(1.5 * np.pi)], atol=1e-12)
    st = InputSignal("step", -0.5, t0_s=1.0)
    assert np.array_equal(st.value([0.5, 0.999, 1.0, 3.0]), [0.0, 0.0, -0.5, -0.5])
    with pytest.raises(ServoscopeError):
        InputSignal("sine", 1.0, None)
    with pytest.raises(ServoscopeError):
        InputSignal("ramp", 1.0)


def test_model_properties_against_closed_forms():
    m = PAPER_SERVO
    assert m.gain == pytest.approx(0.23, rel=1e-15)
    assert m.natural_frequency_rad_s == pytest.approx(37.0, rel=1e-15)
    assert m.damping_ratio == pytest.approx(0.65, rel=1e-15)
    # -3 dB bandwidth of a 2nd-order low-pass, closed form
    z, wn = 0.65, 37.0
    a = 1 - 2 * z * z
    assert m.bandwidth_rad_s == pytest.approx(wn * math.sqrt(a + math.sqrt(a * a + 1)), rel=1e-10)
    first = ServoModel(num=(3.0 * 12.5,), den=(1.0, 12.5))
    assert first.bandwidth_rad_s == pytest.approx(12.5, rel=1e-10)
    assert first.natural_frequency_rad_s is None and first.damping_ratio is None
    assert isinstance(m.transfer_function, control.TransferFunction)
    with pytest.raises(ServoscopeError):
        ServoModel(num=(1.0, 0.0, 0.0), den=(1.0, 1.0))  # improper
    with pytest.raises(ServoscopeError):
        ServoModel(num=(1.0,), den=(1.0, 1.0), dead_time_s=-0.1)


STATIC = dict(num=(1.0,), den=(1.0,))  # G = 1: the output is the (post-backlash) reference


def test_quantization_levels():
    q = 0.25
    model = ServoModel(**STATIC, dead_time_s=0.02, input_quantization=q)
    sig = InputSignal("sine", 1.0, 2.0, t0_s=0.1)
    t_on = 0.12
    t = t_on + GRID_STEP_S * np.arange(0, 5000, 3)  # on the internal grid
    y = model.response(sig, t)
    levels = np.round(y / q)
    assert np.max(np.abs(y - q * levels)) < 1e-9
    assert set(levels.astype(int)) == set(range(-4, 5))
    # it is the delayed command, rounded to the nearest level
    u = sig.value(t - 0.02)
    assert np.max(np.abs(y - q * np.floor(u / q + 0.5))) < 1e-9


def test_quantized_input_through_dynamics_matches_python_control():
    model = ServoModel(PAPER_SERVO.num, PAPER_SERVO.den, dead_time_s=0.085, input_quantization=0.02)
    sig = InputSignal("sine", 0.1, 3.0, t0_s=0.05)
    t_on = sig.t0_s + model.dead_time_s
    grid = t_on + GRID_STEP_S * np.arange(8000)
    r = model.reference(sig, grid)
    assert len(np.unique(np.round(r / 0.02))) == 11
    _, y_ref = control.forced_response(model.transfer_function, grid - t_on, r)
    assert np.max(np.abs(model.response(sig, grid) - y_ref)) < 1e-9


def test_rate_limit_ramps_at_the_limit():
    rate = 2.0
    model = ServoModel(**STATIC, dead_time_s=0.05, rate_limit_per_s=rate)
    sig = InputSignal("step", 0.5, t0_s=0.1037)
    t = np.random.default_rng(2).uniform(0.0, 0.6, 300)
    expected = np.clip(rate * (t - 0.1537), 0.0, 0.5)
    assert np.max(np.abs(model.response(sig, t) - expected)) < 1e-9


def test_rate_limit_bounds_the_slope_of_a_fast_sine():
    rate = 5.0
    model = ServoModel(PAPER_SERVO.num, PAPER_SERVO.den, dead_time_s=0.085, rate_limit_per_s=rate)
    sig = InputSignal("sine", 1.0, 5.0, t0_s=0.0)  # peak slope 31/s: must be limited
    t = np.arange(0.0, 1.0, 1e-3)
    r = model.reference(sig, t)
    slope = np.abs(np.diff(r)) / 1e-3
    assert slope.max() <= rate * (1 + 1e-9)
    assert slope.max() >= rate * (1 - 1e-9)  # and the limit is active
    _, y_ref = control.forced_response(model.transfer_function, t, r)
    # the response is G driven by that reference (1 ms grid: linear interpolation error only)
    assert np.max(np.abs(model.response(sig, t) - y_ref)) < 1e-4


def test_slow_signal_is_not_rate_limited():
    model = ServoModel(PAPER_SERVO.num, PAPER_SERVO.den, dead_time_s=0.085, rate_limit_per_s=10.0)
    sig = InputSignal("sine", 0.1, 2.0, t0_s=0.2)  # peak slope 1.26/s
    t = np.linspace(0.0, 2.0, 777)
    assert np.max(np.abs(model.response(sig, t) - PAPER_SERVO.response(sig, t))) < 1e-6 * 0.1


def test_backlash_is_a_play_of_the_given_width():
    w = 0.2
    model = ServoModel(**STATIC, backlash=w)
    sig = InputSignal("sine", 1.0, 1.0, t0_s=0.0)
    t = GRID_STEP_S * np.arange(30000)  # three periods, on the grid
    u = sig.value(t)
    y = model.response(sig, t)
    assert np.max(np.abs(y - u)) <= w / 2 + 1e-12
    late = t > 0.75  # after the first reversal
    assert y[late].max() == pytest.approx(1.0 - w / 2, abs=1e-9)
    assert y[late].min() == pytest.approx(-1.0 + w / 2, abs=1e-9)
    # at the input's zero crossings, rising (t = 1, 2 s) vs falling (1.5, 2.5 s): the loop is w wide
    at = lambda s: y[int(round(s / GRID_STEP_S))]  # noqa: E731
    assert at(1.0) == pytest.approx(-w / 2, abs=1e-6) and at(2.0) == pytest.approx(-w / 2, abs=1e-6)
    assert at(1.5) == pytest.approx(w / 2, abs=1e-6) and at(2.5) == pytest.approx(w / 2, abs=1e-6)
    # after a reversal the output holds still until the gap is taken up
    k = int(round(0.25 / GRID_STEP_S))  # input peak
    assert np.all(y[k:k + 500] == y[k])

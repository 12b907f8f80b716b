"""The sysid results' .plot(ax=None): they draw their own numbers and return those artists."""

from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from servoscope.sysid import (  # noqa: E402
    FrequencyResponse,
    analyse_step,
    fit_sine,
    fit_transfer_function,
)

K, WN, ZETA = 0.23, 37.0, 0.45


def _response(w: np.ndarray) -> np.ndarray:
    s = 1j * w
    return K / (s**2 / WN**2 + 2 * ZETA * s / WN + 1)


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


@pytest.fixture(scope="module")
def dwell():
    t = np.arange(0.0, 3.0, 1 / 120)
    rng = np.random.default_rng(4)
    y = 0.1 + 0.05 * np.sin(2 * math.pi * 2.0 * (t - 0.25) - 0.6) + 1e-4 * rng.standard_normal(t.size)
    return fit_sine(t, y, 2.0, t0_s=0.25)


@pytest.fixture(scope="module")
def response():
    f = np.array([0.5, 1, 2, 3, 4, 5, 6, 7, 8, 10, 12])
    g = _response(2 * np.pi * f)
    return FrequencyResponse(
        frequency_hz=f,
        gain=np.abs(g) * (1 + 0.002 * np.cos(f)),
        gain_stderr=np.full(f.size, 0.002) * np.abs(g),
        phase_deg=np.degrees(np.angle(g)) + 0.1 * np.sin(f),
        phase_stderr_deg=np.full(f.size, 0.2),
        fidelity=np.full(f.size, 0.999),
        labels=tuple(f"d{i}" for i in range(f.size)),
    )


def test_sine_fit_plot_draws_its_window_and_model(dwell):
    fig, ax = plt.subplots()
    artists = dwell.plot(ax)
    measured, fitted, span, t0_line = artists
    assert measured.axes is ax and fitted.axes is ax
    np.testing.assert_array_equal(measured.get_xdata(), dwell.time_s)
    np.testing.assert_array_equal(measured.get_ydata(), dwell.y)
    np.testing.assert_array_equal(fitted.get_xdata(), dwell.time_s)
    np.testing.assert_array_equal(fitted.get_ydata(), dwell.model(dwell.time_s))
    assert t0_line.get_xdata()[0] == dwell.t0_s
    # The span covers the window.
    if hasattr(span, "get_width"):  # a Rectangle (matplotlib >= 3.9)
        x0, x1 = span.get_x(), span.get_x() + span.get_width()
    else:  # a Polygon
        x0, x1 = np.min(span.get_xy()[:, 0]), np.max(span.get_xy()[:, 0])
    assert (x0, x1) == pytest.approx(dwell.window_s)


def test_plot_without_axes_makes_a_figure(dwell):
    artists = dwell.plot()
    assert artists[0].figure is not None
    assert artists[0].axes in artists[0].figure.axes


def test_frequency_response_plot_draws_gain_db_and_phase(response):
    fig, (ax, axp) = plt.subplots(2, 1)
    container, phase = response.plot(ax, phase_ax=axp)
    line = container.lines[0]
    np.testing.assert_array_equal(line.get_xdata(), response.omega_rad_s)
    np.testing.assert_allclose(line.get_ydata(), response.gain_db, rtol=1e-14)
    # Error bars are ±1 standard error in dB.
    segs = container.lines[2][0].get_segments()
    half = np.array([abs(s[1, 1] - s[0, 1]) / 2 for s in segs])
    np.testing.assert_allclose(half, response.gain_db_stderr, rtol=1e-12)
    np.testing.assert_array_equal(phase.get_ydata(), response.phase_deg)
    assert phase.axes is axp and ax.get_xscale() == "log"


def test_transfer_function_fit_plot_draws_the_model(response):
    fit = fit_transfer_function(response, mode="complex")
    fig, (ax, axp) = plt.subplots(2, 1)
    w = np.geomspace(1.0, 200.0, 50)
    artists = fit.plot(ax, phase_ax=axp, omega_rad_s=w)
    gain_line, phase_line = artists[-2:]
    np.testing.assert_array_equal(gain_line.get_xdata(), w)
    np.testing.assert_allclose(gain_line.get_ydata(), 20 * np.log10(fit.magnitude(w)), rtol=1e-14)
    np.testing.assert_allclose(phase_line.get_ydata(), fit.phase_deg(w), rtol=1e-14)
    # The model drawn is the truth it was fitted to (within the data's 0.2 % errors).
    np.testing.assert_allclose(gain_line.get_ydata(), 20 * np.log10(np.abs(_response(w))), atol=0.05)
    np.testing.assert_array_equal(artists[0].lines[0].get_xdata(), response.omega_rad_s)


def test_step_analysis_plot_draws_samples_prediction_and_dead_time():
    import control

    model = control.tf([K * WN**2], [1, 2 * ZETA * WN, WN**2])
    t = np.arange(0.0, 1.0, 1 / 240)
    t0, tau, step = 0.2, 0.03, 0.5
    grid = np.linspace(0.0, 1.0, 4001)
    _, resp = control.step_response(model, T=grid)
    y = 0.01 + step * np.interp(t - t0 - tau, grid, resp, left=0.0)
    st = analyse_step(t, y, t0_s=t0, step_size=step, model=model)
    fig, ax = plt.subplots()
    measured, predicted, t0_line, dead_line = st.plot(ax)
    np.testing.assert_array_equal(measured.get_xdata(), st.time_s)
    np.testing.assert_array_equal(measured.get_ydata(), st.y)
    np.testing.assert_array_equal(predicted.get_ydata(), st.predicted(st.time_s))
    assert t0_line.get_xdata()[0] == st.t0_s
    assert dead_line.get_xdata()[0] == pytest.approx(st.t0_s + st.dead_time_s)
    assert st.dead_time_s == pytest.approx(tau, abs=2e-3)


def test_unit_names_agree(dwell, response):
    assert dwell.phase_stderr_deg == pytest.approx(math.degrees(dwell.phase_stderr_rad))
    np.testing.assert_allclose(response.phase_stderr_rad, np.radians(response.phase_stderr_deg))

"""One Parameters layer under the fits (issue 30, builds 1 and 2): the transfer function, the servo
structures and the dead time state their numbers through :class:`servoscope.parameters.Parameters`.

Oracles: scipy's Student-t and normal quantiles for the intervals, the fits' own stored
dictionaries (which result.json has always written) for the values, and the twin's servo
simulator for the traces.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.stats import norm, t as student_t

from servoscope.errors import ServoscopeError
from servoscope.parameters import FitResult, Parameters, check_held
from servoscope.simulate.presets import get_preset
from servoscope.simulate.servo import ServoModel
from servoscope.sysid import DeadTimeEstimate, FrequencyResponse, dead_time_estimates, fit_transfer_function
from servoscope.sysid.servo_fit import fit_servo_model
from servoscope.sysid.servo_select import select_servo_model
from servoscope.sysid.tf_result import TransferFunctionFit

from support import servo_campaign

PAPER = get_preset("quick").servo


def _response(seed: int = 0) -> FrequencyResponse:
    """The paper's servo measured at 10 frequencies with 0.5 % noise, phases included."""
    rng = np.random.default_rng(seed)
    f = np.geomspace(0.5, 12.0, 10)
    s = 2j * np.pi * f
    g = 0.23 * 37.0**2 / (s**2 + 2 * 0.65 * 37.0 * s + 37.0**2) * np.exp(-0.085 * s)
    g = g * (1 + 0.005 * rng.standard_normal(f.size)) * np.exp(1j * 0.005 * rng.standard_normal(f.size))
    return FrequencyResponse(frequency_hz=f, gain=np.abs(g), gain_stderr=0.005 * np.abs(g),
                             phase_deg=np.degrees(np.unwrap(np.angle(g))), phase_stderr_deg=np.full(f.size, 0.3),
                             fidelity=np.ones(f.size), labels=tuple(f"d{i}" for i in range(f.size)))


@pytest.fixture(scope="module")
def tf_fit() -> TransferFunctionFit:
    return fit_transfer_function(_response(), mode="complex")


def test_the_transfer_function_states_each_number_once(tf_fit):
    p = tf_fit.parameters
    assert isinstance(tf_fit, FitResult) and list(p) == list(tf_fit.param_names)
    dof = tf_fit.n_residuals - tf_fit.n_params
    q = student_t.ppf(0.975, dof)
    for name in tf_fit.param_names:
        assert p[name].value == tf_fit.params[name] and p[name].stderr == tf_fit.stderr[name]
        # nlparci's interval: value ± t(0.975, dof)·stderr, scipy's quantile the oracle.
        assert p[name].ci95 == pytest.approx((tf_fit.params[name] - q * tf_fit.stderr[name],
                                              tf_fit.params[name] + q * tf_fit.stderr[name]), rel=1e-12)
        assert p[name].interval == "student" and p[name].dof == dof
    # K, ωn, ζ and τ by name are the dictionaries' entries, not copies that could drift.
    assert (tf_fit.gain, tf_fit.natural_frequency_rad_s, tf_fit.damping_ratio, tf_fit.dead_time_s) == tuple(
        tf_fit.params[n] for n in ("gain", "natural_frequency_rad_s", "damping_ratio", "dead_time_s"))
    assert tf_fit.dead_time_stderr_s == tf_fit.stderr["dead_time_s"]
    assert p["natural_frequency_rad_s"].unit == "rad/s" and p["dead_time_s"].unit == "s"
    assert tf_fit.params["gain"] == pytest.approx(0.23, rel=0.01)


def test_the_transfer_functions_views_agree(tf_fit):
    report = tf_fit.fit_report()
    html = tf_fit._repr_html_()
    table = tf_fit.parameters.to_pandas()
    for name in tf_fit.param_names:
        assert f"{tf_fit.params[name]:.6g}" in report
        assert "</td><td>".join(tf_fit.parameters[name].cells()) in html
        assert table.loc[name, "value"] == tf_fit.params[name]
        assert table.loc[name, "ci95_low"] == tf_fit.ci95[name][0]
    assert "[[Correlations]]" in report and "C(" in report  # K, ωn, ζ and τ are correlated
    assert f"degrees of freedom = {tf_fit.n_residuals - tf_fit.n_params}" in report
    # result.json's fields are the same as before the layer: the flat names and the dictionaries.
    s = tf_fit.summary()
    assert s["gain"] == tf_fit.params["gain"] and s["gain_stderr"] == tf_fit.stderr["gain"]
    assert s["dead_time_stderr_s"] == tf_fit.stderr["dead_time_s"]
    again = TransferFunctionFit.from_summary(json.loads(json.dumps(s)))
    assert again.parameters == tf_fit.parameters


def test_a_held_parameter_reads_as_held(tf_fit):
    held = fit_transfer_function(_response(), mode="complex", fix={"damping_ratio": 0.65},
                                 bounds={"natural_frequency_rad_s": (20.0, 80.0)})
    p = held.parameters
    assert not p["damping_ratio"].vary and p["damping_ratio"].stderr == 0
    assert p["damping_ratio"].ci95 == (0.65, 0.65)
    assert (p["natural_frequency_rad_s"].min, p["natural_frequency_rad_s"].max) == (20.0, 80.0)
    assert "damping_ratio" not in p.correlated and "(fixed)" in held.fit_report()


@pytest.fixture(scope="module")
def rate_limited():
    """A rate-limited servo's traces (the twin's simulator) and its frequency-domain response."""
    return servo_campaign(ServoModel(PAPER.num, PAPER.den, dead_time_s=0.085, rate_limit_per_s=4.0), 0)


@pytest.fixture(scope="module")
def rate_selection(rate_limited):
    traces, response = rate_limited
    return select_servo_model(traces, ["rate_limit"], response=response)


def test_a_servo_models_positive_parameters_have_log_normal_intervals(rate_selection):
    fit = rate_selection.selected
    p = fit.parameters
    z = norm.ppf(0.975)
    for name in ("natural_frequency_rad_s", "damping_ratio", "rate_limit_rad_s"):
        v, se = fit.params[name], fit.stderr[name]  # the jackknife's where it was wider
        assert p[name].interval == "lognormal"
        assert p[name].ci95 == pytest.approx((v / math.exp(z * se / v), v * math.exp(z * se / v)), rel=1e-12)
    for name in ("gain", "dead_time_s"):
        assert p[name].interval == "normal"
        assert p[name].ci95 == pytest.approx((fit.params[name] - z * fit.stderr[name],
                                              fit.params[name] + z * fit.stderr[name]), rel=1e-12)
    assert fit.fit_statistics()["samples"] == fit.n_samples
    with pytest.raises(Exception):  # frozen: what the pipeline adds later is a new object
        fit.J = 0.0  # type: ignore[misc]


def test_the_jackknife_widens_without_going_below_zero(rate_selection):
    """The selection's jackknife widens an interval the way the fit made it: log-normal stays positive."""
    sel = rate_selection
    fit = sel.selected
    assert fit.structure == "rate_limit" and sel.candidates[1] is fit
    for name, par in fit.parameters.items():
        if par.interval == "lognormal":
            assert par.ci95[0] > 0, (name, par.ci95)
            v = par.value
            assert par.ci95[0] * par.ci95[1] == pytest.approx(v * v, rel=1e-9)  # symmetric on a log scale
        assert par.ci95 == tuple(fit.ci95[name])
    assert all(math.isfinite(c.bic) for c in sel.candidates)


def test_one_check_for_what_is_held_whichever_door(rate_limited):
    traces, _ = rate_limited
    known = ["gain", "natural_frequency_rad_s", "damping_ratio", "dead_time_s", "rate_limit_rad_s"]
    cases = [
        ({"gian": 1.0}, {}, {}, "has no parameter 'gian' (did you mean 'gain'?)"),
        ({"damping_ratio": 0.9}, {"damping_ratio": (0.1, 0.5)}, {}, "fixed at 0.9, outside its bounds [0.1, 0.5]"),
        ({}, {"gain": (2.0, 1.0)}, {}, "the lower limit 2.0 must be below the upper 1.0"),
        ({}, {}, {"rate_limit_rad_s": "4*gain", "gain": "damping_ratio"}, "gain is tied itself"),
        ({"rate_limit_rad_s": 1.0}, {}, {"rate_limit_rad_s": "4*gain"}, "cannot also be fixed or bounded"),
    ]
    for fix, bounds, ties, message in cases:
        with pytest.raises(ServoscopeError) as direct:
            check_held(known, fix, bounds, ties, who="the rate_limit model")
        assert message in str(direct.value)
        # The fit's own door gives the same words.
        with pytest.raises(ServoscopeError) as api:
            fit_servo_model(traces, "rate_limit", fix=fix, bounds=bounds, ties=ties)
        assert str(api.value) == str(direct.value)


def test_the_dead_times_two_estimates_are_fit_results(tf_fit):
    est = dead_time_estimates(tf_fit, None, 0.0004)
    phase = est["phase"]
    assert isinstance(phase, DeadTimeEstimate) and est["step"] is None
    se = math.hypot(tf_fit.stderr["dead_time_s"], 0.0004)
    assert phase.stderr_s == pytest.approx(se, rel=1e-12)
    assert phase.parameters["dead_time_s"].ci95 == pytest.approx(
        (phase.value_s - norm.ppf(0.975) * se, phase.value_s + norm.ppf(0.975) * se), rel=1e-12)
    assert phase.summary() == {"value_s": phase.value_s, "stderr_s": phase.stderr_s,
                               "ci95_s": list(phase.ci95_s), "shared_t0_stderr_s": 0.0004}
    assert "shared t0 stderr (s) = 0.0004" in phase.fit_report()


def test_parameters_round_trip_and_name_their_mistakes(tf_fit):
    p = tf_fit.parameters
    assert Parameters.from_summary(json.loads(json.dumps(p.summary()))) == Parameters(p.values())
    with pytest.raises(KeyError, match="did you mean 'damping_ratio'"):
        p["damping_ration"]
    with pytest.raises(TypeError):
        p["gain"] = p["gain"]  # type: ignore[index]

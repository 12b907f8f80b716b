"""Model parameters held at a value or within limits (issue 17, build 1), as lmfit's vary=False and min/max.

Oracles: the free fit itself (holding a parameter at its own optimum changes nothing else),
and scipy's least_squares on an independently written residual (ln-gain and wrapped phase
over their stated errors) with the parameter held.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.optimize import least_squares

from servoscope.errors import ServoscopeError
from servoscope.sysid import FrequencyResponse, check_held, fit_transfer_function

F_HZ = np.array([0.5, 1, 2, 3, 4, 5, 6, 7, 8, 10, 12, 15.0])


def _response(seed=0):
    w = 2 * np.pi * F_HZ
    g = 0.23 * 37**2 / ((1j * w) ** 2 + 2 * 0.65 * 37 * 1j * w + 37**2) * np.exp(-1j * w * 0.085)
    rng = np.random.default_rng(seed)
    gain = np.abs(g) * (1 + 0.003 * rng.standard_normal(w.size))
    phase = np.degrees(np.unwrap(np.angle(g))) + 0.2 * rng.standard_normal(w.size)
    return FrequencyResponse(frequency_hz=F_HZ, gain=gain, gain_stderr=0.003 * gain, phase_deg=phase,
                             phase_stderr_deg=np.full(w.size, 0.2), fidelity=np.ones(w.size),
                             labels=tuple(f"d{i}" for i in range(w.size)))


def test_holding_a_parameter_at_its_optimum_changes_nothing_else():
    fr = _response()
    free = fit_transfer_function(fr, mode="complex")
    held = fit_transfer_function(fr, mode="complex", fix={"damping_ratio": free.params["damping_ratio"]})
    for name in ("gain", "natural_frequency_rad_s", "dead_time_s"):
        assert held.params[name] == pytest.approx(free.params[name], rel=1e-6), name
    assert held.stderr["damping_ratio"] == 0.0
    assert held.ci95["damping_ratio"] == (held.params["damping_ratio"],) * 2
    # One parameter fewer to pay for: AIC = χ² + 2p over the free ones.
    assert (held.n_params, free.n_params) == (3, 4)
    assert held.aic == pytest.approx(2 * held.cost + 2 * 3) and free.aic == pytest.approx(2 * free.cost + 2 * 4)
    assert held.summary()["held"] == {"damping_ratio": {"fixed": free.params["damping_ratio"]}}


def test_a_held_fit_is_the_least_squares_fit_of_the_others():
    fr = _response(1)
    held = fit_transfer_function(fr, mode="complex", fix={"damping_ratio": 0.8})
    w = fr.omega_rad_s
    sig_ln, sig_ph = fr.gain_stderr / fr.gain, np.radians(fr.phase_stderr_deg)

    def residual(p):
        k, wn, tau = p
        g = k * wn**2 / ((1j * w) ** 2 + 2 * 0.8 * wn * 1j * w + wn**2) * np.exp(-1j * w * tau)
        dph = np.angle(np.exp(1j * (np.unwrap(np.angle(g)) - np.radians(fr.phase_deg))))
        return np.concatenate([(np.log(np.abs(g)) - np.log(fr.gain)) / sig_ln, dph / sig_ph])

    oracle = least_squares(residual, [0.24, 38.0, 0.08], method="trf", xtol=1e-14, ftol=1e-14, gtol=1e-14)
    for name, value in zip(("gain", "natural_frequency_rad_s", "dead_time_s"), oracle.x):
        assert held.params[name] == pytest.approx(value, rel=1e-5), name
    # The paper's puzzle in numbers: ζ held at 0.8 does not explain the dwells (CIFER's J).
    assert held.J > 50 * fit_transfer_function(fr, mode="complex").J


def test_a_bound_holds_and_says_when_it_is_reached():
    fr = _response()
    inside = fit_transfer_function(fr, mode="complex", bounds={"natural_frequency_rad_s": (20.0, 80.0)})
    assert inside.params["natural_frequency_rad_s"] == pytest.approx(37.0, rel=0.01)
    assert not any("its bound" in w for w in inside.warnings)
    at = fit_transfer_function(fr, mode="complex", bounds={"natural_frequency_rad_s": (20.0, 30.0)})
    assert at.params["natural_frequency_rad_s"] == pytest.approx(30.0, rel=1e-9)
    assert any("natural_frequency_rad_s ended at its bound" in w for w in at.warnings)


@pytest.mark.parametrize("fix, bounds, expected", [
    ({"zeta": 0.8}, {}, r"model of order \(0, 2\) has no parameter 'zeta'"),
    ({"damping_ratio": 0.8}, {"damping_ratio": (0.9, 1.0)}, "fixed at 0.8, outside its bounds"),
    ({"natural_frequency_rad_s": -3.0}, {}, "must be > 0"),
    ({}, {"natural_frequency_rad_s": (80.0, 20.0)}, "lower limit 80.0 must be below the upper 20.0"),
])
def test_bad_holds_are_one_clear_error(fix, bounds, expected):
    with pytest.raises(ServoscopeError, match=expected):
        fit_transfer_function(_response(), mode="complex", fix=fix, bounds=bounds)
    with pytest.raises(ServoscopeError, match=expected):
        check_held((0, 2), "minimum_phase", fix, bounds)
    with pytest.raises(ServoscopeError, match="need a given order"):
        fit_transfer_function(_response(), mode="complex", order="auto", fix={"damping_ratio": 0.8})


def test_campaign_manifest_and_command_line_hold_parameters(quick_campaign, tmp_path):
    from support import run_cli  # the command's entry point in this process, as a child ran it

    text = quick_campaign.read_text() + "\n[model]\nfix = {damping_ratio = 0.65}\n"
    manifest = quick_campaign.parent / "held.toml"
    manifest.write_text(text)
    out = tmp_path / "out"
    run = run_cli("identify", str(manifest), "--out", str(out),
                  "--workers", "1", "--quiet", "--bound", "natural_frequency_rad_s=20:80")
    assert run.returncode == 0, run.stderr
    result = json.loads((out / "result.json").read_text())
    assert result["model"]["params"]["damping_ratio"] == 0.65 and result["model"]["stderr"]["damping_ratio"] == 0
    assert result["model"]["held"] == {"damping_ratio": {"fixed": 0.65},
                                       "natural_frequency_rad_s": {"bounds": [20.0, 80.0]}}
    assert "(held fixed)" in (out / "report.html").read_text()
    # A name the model does not have: one line, exit 2, before anything is tracked or written.
    bad = run_cli("identify", str(manifest), "--out", str(tmp_path / "o2"), "--fix", "zeta=0.8")
    assert bad.returncode == 2 and "has no parameter 'zeta'" in bad.stderr and not (tmp_path / "o2").exists()
    assert len(bad.stderr.strip().splitlines()) == 1
    assert math.isfinite(result["model"]["params"]["gain"])

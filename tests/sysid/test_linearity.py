"""Amplitude as a test axis (issue 17, build 4): each frequency's gains at several amplitudes, compared.

Oracles: hand-made responses (equal gains within their errors; a 5 % drop) and the twin's
servo, linear and rate-limited (the reference's slew limited: large sines lose gain).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.stats import chi2

from servoscope.sysid import FrequencyResponse, gain_against_amplitude


def _fr(gains, se, freqs):
    n = len(gains)
    return FrequencyResponse(frequency_hz=np.asarray(freqs, float), gain=np.asarray(gains, float),
                             gain_stderr=np.full(n, se), phase_deg=np.full(n, np.nan),
                             phase_stderr_deg=np.full(n, np.nan), fidelity=np.ones(n),
                             labels=tuple(f"d{i}" for i in range(n)))


def test_equal_gains_are_linear_and_a_drop_is_not():
    freqs = [1.0, 1.0, 1.0, 5.0, 5.0, 12.0]
    amps = [0.05, 0.1, 0.2, 0.05, 0.2, 0.1]
    rng = np.random.default_rng(0)
    checks = gain_against_amplitude(_fr(0.23 + 0.001 * rng.standard_normal(6), 0.001, freqs), amps)
    assert [c.frequency_hz for c in checks] == [1.0, 5.0]  # 12 Hz has one amplitude
    assert checks[0].amplitudes == (0.05, 0.1, 0.2) and all(c.linear for c in checks)
    g = [0.23, 0.23, 0.23, 0.23, 0.2185, 0.23]  # 5 Hz loses 5 % at the large amplitude
    drop = gain_against_amplitude(_fr(g, 0.001, freqs), amps)[1]
    assert not drop.linear and drop.change == pytest.approx(-0.05)
    # The χ² of two gains 0.0115 apart with errors 0.001 each: (0.0115/√2/0.001)² over one dof.
    assert drop.chi2 == pytest.approx(0.0115**2 / 2 / 0.001**2, rel=1e-9)
    assert drop.p_value == pytest.approx(chi2.sf(drop.chi2, 1), rel=1e-9)
    assert "not linear" in drop.warning() and "5 Hz" in drop.warning()


@pytest.mark.parametrize("rate_limit", [None, 4.0])
def test_twin_campaign_at_two_amplitudes(tmp_path, rate_limit):
    from dataclasses import replace

    from servoscope.campaign.runner import identify
    from servoscope.simulate import simulate_campaign
    from servoscope.simulate.presets import get_preset

    servo = replace(get_preset("quick").servo, rate_limit_per_s=rate_limit)
    toml = simulate_campaign(tmp_path, "quick", 0, width=480, height=384, codec="raw", servo=servo,
                             sine_amplitudes=(0.05, 0.2), include_step=False)
    res = identify(toml, workers=1)
    checks = {round(c.frequency_hz, 2): c for c in res.amplitude_checks}
    assert sorted(checks) == [1.0, 2.29, 5.24, 12.0]
    if rate_limit is None:
        assert all(c.linear for c in checks.values()), [(f, c.p_value) for f, c in checks.items()]
        assert not any("changes with the input amplitude" in w for w in res.warnings)
    else:
        # The reference's slew 2π·f·a: 6.6/s at 5.24 Hz and 15/s at 12 Hz for a = 0.2 (limited to 4/s), under 4/s
        # for a = 0.05 there and for both amplitudes at 1 Hz.
        assert checks[1.0].linear
        for f in (5.24, 12.0):
            assert not checks[f].linear and checks[f].change < -0.1, (f, checks[f].change)
        assert any("changes with the input amplitude at 12 Hz" in w for w in res.warnings)
    s = json.loads(json.dumps(res.summary()))
    assert len(s["gain_against_amplitude"]) == 4
    from servoscope.report.build import build_report

    assert "Gain against input amplitude" in build_report(res)


def test_checks_follow_each_dwells_label_not_its_place():
    # The response is sorted by frequency; a dwell's amplitude must follow its label.
    freqs = [5.0, 5.0001, 4.9999]
    fr = _fr([0.2, 0.19, 0.21], 0.0005, freqs)
    checks = gain_against_amplitude(fr, [0.1, 0.2, 0.05])
    assert checks[0].amplitudes == (0.05, 0.1, 0.2) and checks[0].gains == (0.21, 0.2, 0.19)

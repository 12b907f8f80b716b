"""identify --nonlinear on a linear servo (issue 17): the joint fit agrees with today's, and a codec is no nonlinearity.

Oracles: the frequency-domain fit's intervals and the twin's truth.
"""

from __future__ import annotations

import json


def test_the_joint_linear_fit_equals_todays_within_its_intervals(quick_campaign, quick_result):
    from servoscope.campaign import identify

    # The quick campaign at full size (H.264, seed 3), its tracks reused: the time-domain linear model
    # fitted to the dwells and the step together against the frequency-domain fit of the dwells alone.
    res = identify(quick_campaign, tracks=quick_result.tracks, nonlinear="linear")
    joint = res.servo_model.selected
    assert joint.structure == "linear" and [c.structure for c in res.servo_model.candidates] == ["linear"]
    today = quick_result.model
    for name in ("natural_frequency_rad_s", "damping_ratio"):
        lo, hi = today.ci95[name]
        assert lo <= joint.params[name] <= hi, (name, joint.params[name], (lo, hi))
    lo, hi = today.ci95["gain"]
    assert lo <= joint.params["gain"] <= hi
    # Both against the truth the twin rendered.
    truth = json.loads((quick_campaign.parent / "truth.json").read_text())["model"]
    for name in ("gain", "natural_frequency_rad_s", "damping_ratio"):
        lo, hi = joint.ci95[name]
        assert lo <= truth[name] <= hi, (name, truth[name], (lo, hi))
    s = res.summary()
    assert s["model"]["structure"] == "linear" and "rate_limit_rad_s" not in s["model"]
    assert s["step"]["predicted_fit_percent"] > 99 and s["step"]["fit_percent"] == joint.step_fit_percent


def test_a_codec_does_not_make_a_linear_servo_nonlinear(tmp_path):
    from servoscope.campaign import identify
    from servoscope.simulate import simulate_campaign

    # H.264 holds a sticker still near each turn of a sine: on the twin's linear servo that reads as a
    # play of 0.00026 rad, which wins the BIC but moves the stickers 0.015 px: the linear model is kept.
    toml = simulate_campaign(tmp_path / "c", "quick", 0, width=480, height=384, sine_amplitudes=(0.05, 0.2))
    res = identify(toml, workers=1, nonlinear="auto")
    sel = res.servo_model
    assert sel.selected.structure == "linear"
    best = min(sel.candidates, key=lambda c: c.bic)
    if best.structure != "linear":
        assert any("a codec's motion prediction can fake" in w for w in res.warnings)
    truth = json.loads((tmp_path / "c" / "truth.json").read_text())["model"]
    for name in ("gain", "natural_frequency_rad_s", "damping_ratio"):
        lo, hi = sel.selected.ci95[name]
        assert lo <= truth[name] <= hi, (name, truth[name], lo, hi)

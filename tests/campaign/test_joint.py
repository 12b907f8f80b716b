"""identify --nonlinear on rendered footage (issue 17): the whole pipeline, result.json, the report, bad input.

Oracle: the twin's truth (its servo's backlash and linear part).
"""

from __future__ import annotations

import json

from dataclasses import replace

import pytest

from support import check_every_view


def test_backlash_found_in_rendered_footage(backlash_identified):
    from servoscope.campaign.result import IdentificationResult

    res, out_dir, servo = backlash_identified
    data = json.loads((out_dir / "result.json").read_text())
    model = data["model"]
    assert model["structure"] == "backlash" and model["backlash_rad"] == pytest.approx(0.004, rel=0.1)
    lo, hi = model["ci95"]["backlash_rad"]
    assert lo <= 0.004 <= hi
    assert [c["structure"] for c in model["candidates"]] == ["linear", "rate_limit", "backlash", "quantization",
                                                             "saturation"]
    selected = next(c for c in model["time_domain"]["candidates"] if c["structure"] == "backlash")
    assert selected["gain"] == pytest.approx(servo.gain, rel=0.02)
    assert selected["natural_frequency_rad_s"] == pytest.approx(37.0, rel=0.02)
    # The step's fit by the selected model, and as the dwells' model alone predicts it.
    assert selected["step_fit_percent"] > 99
    assert model["time_domain"]["cross_validation"]["dwells_to_step"]["fit_percent"] > 95
    # The step analysis: against the frequency-domain model, or where that one ended unstable (this
    # servo's dwells at two amplitudes disagree by up to 150 %), against the selected model's linear part.
    assert data["step"]["fit_percent"] == selected["step_fit_percent"]
    assert data["step"]["model_source"] in ("frequency-domain model", "backlash model's linear part")
    assert abs(data["step"]["dead_time_s"] - 0.085) < 0.002
    assert model["fixed"] == []
    # The headline is the selected model (issue 30): its K and ωn right with intervals holding the truth,
    # where the transfer function fitted to the dwells (a describing function at their amplitudes) is not.
    assert model["domain"] == "time domain" and model["gain"] == selected["gain"]
    for name, true in (("gain", servo.gain), ("natural_frequency_rad_s", 37.0), ("dead_time_s", 0.085)):
        lo, hi = model["ci95"][name]
        assert lo <= true <= hi, (name, lo, hi, true)
    fd = data["frequency_domain_model"]
    assert "describing function" in fd["describes"] and fd["gain"] != model["gain"]
    assert data["dead_time"]["source"] == "time_domain" and data["dead_time_s"] == model["dead_time_s"]
    html = (out_dir / "report.html").read_text()
    assert "One model for the sines and the step" in html and "Measured and modelled traces" in html
    assert "Describing function" in html and "Candidates against one trace" in html
    # The describing function the report draws is the model's: at 5.24 Hz it meets the measured gains.
    fit = res.servo_model.selected
    fr = res.frequency_response
    for label, f, g, se in zip(fr.labels, fr.frequency_hz, fr.gain, fr.gain_stderr):
        if abs(f - 5.24) < 0.01:
            a = next(t.amplitude for t in res.campaign.tests if t.label == label)
            assert abs(abs(fit.describing_function(f, [a])[0]) - g) < max(4 * se, 0.005 * g), (label, g, se)
    again = IdentificationResult.load(out_dir)
    assert json.dumps(again.summary(), sort_keys=True) == json.dumps(data, sort_keys=True)


def test_a_servo_with_play_is_stated_by_its_selected_model_everywhere(backlash_identified, capsys):
    result, out, servo = backlash_identified
    names = check_every_view(result, out, capsys)
    assert names == ["gain", "natural_frequency_rad_s", "damping_ratio", "dead_time_s", "backlash_rad"]
    p = result.parameters
    for name, true in (("gain", servo.gain), ("natural_frequency_rad_s", 37.0), ("backlash_rad", 0.004)):
        assert p[name].holds(true), (name, p[name], true)
        assert abs(p[name].value - true) < 0.03 * true
    # The transfer function fitted to the dwells is kept beside it, under its own name, and is not right.
    assert abs(result.model.gain - servo.gain) > 0.05 * servo.gain
    report = (out / "report.html").read_text()
    assert "a describing function" in report and "not its linear part" in report


def test_bad_nonlinear_requests_are_one_line_and_write_nothing(quick_campaign, tmp_path, capsys):
    from servoscope.cli import main

    def run(*args):
        # In-process (the command's own entry point, its error handling included): no interpreter to start.
        out = tmp_path / f"o{len(list(tmp_path.iterdir()))}"
        with pytest.raises(SystemExit) as exited:
            main(["identify", str(quick_campaign), "--out", str(out), *args])
        printed = capsys.readouterr()
        assert exited.value.code == 2 and printed.out == "", printed
        assert len(printed.err.strip().splitlines()) == 1 and printed.err.startswith("servoscope: error: "), printed.err
        assert not out.exists()
        return printed.err

    # The quick preset has 4 dwells: a nonlinear structure's 5 parameters need 5.
    assert "fits 5 parameters but the campaign has 4 sine dwell(s)" in run("--nonlinear", "backlash")
    assert "did you mean 'backlash_rad'" in run("--nonlinear", "backlash", "--fix", "backlash=0.1")
    assert "add --nonlinear backlash" in run("--fix", "backlash_rad=0.01")
    assert "use --order 2" in run("--nonlinear", "linear", "--order", "3")
    assert "tied in the time-domain fits only" in run("--tie", "rate_limit_rad_s=4*gain")
    assert "did you mean 'gain'" in run("--nonlinear", "linear", "--tie", "dead_time_s=0.4*gian")
    assert "not an expression" in run("--nonlinear", "linear", "--tie", "dead_time_s=4*(gain")


def test_manifest_model_tie(quick_campaign):
    from servoscope.campaign import load_campaign
    from servoscope.errors import ServoscopeError

    # The videos are beside the original manifest: written there.
    good = quick_campaign.parent / "tie.toml"
    good.write_text(quick_campaign.read_text() + '\n[model]\ntie = {rate_limit_rad_s = "4*gain"}\n')
    assert load_campaign(good).model_ties == {"rate_limit_rad_s": "4*gain"}
    bad = quick_campaign.parent / "tie_bad.toml"
    bad.write_text(quick_campaign.read_text() + "\n[model]\ntie = {rate_limit_rad_s = 4}\n")
    with pytest.raises(ServoscopeError, match="model.tie.rate_limit_rad_s: must be an expression"):
        load_campaign(bad)

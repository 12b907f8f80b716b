"""`servoscope plan --rotor-hz --blades`: dwells below the passes' Nyquist frequency, and the plan says so."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from servoscope.errors import ServoscopeError
from servoscope.rig.cli import plan as plan_command
from servoscope.rig.plan import plan_sweep, plan_to_toml, read_plan
from servoscope.rig.rotor_plan import ROTOR_TOP_FRACTION, plan_rotor_sweep, rotor_top_hz


def test_the_command_plans_below_the_pass_rate_nyquist_and_says_so(tmp_path):
    out = tmp_path / "plan.toml"
    result = CliRunner().invoke(plan_command, ["--fps", "2000", "--rotor-hz", "20", "--blades", "2", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "rotor 20 rev/s × 2 blades: a pass every 25.0 ms" in result.output
    assert "Nyquist frequency is 20 Hz, every dwell is below it (highest 14 Hz, 70 % of it" in result.output
    assert "dead time comes from the dwells' phases and the LED" in result.output
    plan = read_plan(out)
    sines = [d.frequency_hz for d in plan.dwells if d.kind == "sine"]
    assert len(sines) == 14 and sines[0] == 0.5 and max(sines) == 14.0 and all(f < 20.0 for f in sines)
    assert plan.dwells[-1].kind == "step"
    assert not any("rotor" in w for w in plan.warnings)


def test_a_higher_to_is_lowered_and_three_blades_raise_the_nyquist(tmp_path):
    out = tmp_path / "plan.toml"
    result = CliRunner().invoke(plan_command, ["--fps", "5000", "--rotor-hz", "20", "--blades", "3", "--from", "1",
                                               "--to", "40", "--points", "6", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "--to 40 Hz lowered to 21 Hz: the passes' Nyquist frequency is 30 Hz" in result.output
    sines = [d.frequency_hz for d in read_plan(out).dwells if d.kind == "sine"]
    assert sines[0] == 1.0 and max(sines) == 21.0


def test_a_dwell_on_a_rotor_harmonic_is_warned_about():
    plan = plan_rotor_sweep(5000, 20.0, 3, from_hz=19.0, to_hz=21.0, points=3, step=False)
    warned = {d.frequency_hz: d.warnings for d in plan.dwells}
    assert any("rotor speed (20 Hz)" in w and "blades' pitch offsets" in w for w in warned[20.0])
    assert not any("rotor speed" in w for w in warned[19.0] + warned[21.0])


def test_the_top_dwell_never_exceeds_70_percent_of_the_nyquist():
    for rev in np.linspace(5.0, 60.0, 111):
        for blades in (2, 3, 4, 5):
            nyq = blades * rev / 2
            top = rotor_top_hz(rev, blades)
            assert top <= ROTOR_TOP_FRACTION * nyq + 1e-12
            assert top > 0.99 * ROTOR_TOP_FRACTION * nyq
            plan = plan_rotor_sweep(10000, rev, blades, points=5, step=False)
            assert max(d.frequency_hz for d in plan.dwells) <= ROTOR_TOP_FRACTION * nyq + 1e-12


def test_bad_rotor_options_name_the_option(tmp_path):
    runner = CliRunner()
    out = str(tmp_path / "p.toml")
    result = runner.invoke(plan_command, ["--fps", "2000", "--rotor-hz", "20", "--sweep", "0.5:10", "--duration", "10",
                                          "--out", out])
    assert isinstance(result.exception, ServoscopeError) and "--sweep" in str(result.exception)
    result = runner.invoke(plan_command, ["--fps", "2000", "--rotor-hz", "20", "--from", "15", "--out", out])
    assert isinstance(result.exception, ServoscopeError) and "--from 15 Hz is above 14 Hz" in str(result.exception)
    for args, option in ((["--rotor-hz", "0"], "--rotor-hz"), (["--rotor-hz", "20", "--blades", "0"], "--blades")):
        result = runner.invoke(plan_command, ["--fps", "2000", *args, "--out", out])
        assert isinstance(result.exception, ServoscopeError) and option in str(result.exception)
    result = runner.invoke(plan_command, ["--fps", "2000", "--from", "1", "--to", "5", "--blades", "3", "--out", out])
    assert isinstance(result.exception, ServoscopeError) and "--blades goes with --rotor-hz" in str(result.exception)
    with pytest.raises(ServoscopeError, match="--rotor-hz"):
        plan_rotor_sweep(2000, -1.0, 2)


def test_a_static_plan_is_unchanged():
    plan = plan_sweep(100, 0.5, 15, points=14)
    assert plan.rotor == {}
    text = plan_to_toml(plan)
    assert "rotor" not in text
    # The rotor's plan is a static plan of its dwells until campaign.toml's [rotor] takes the rotor.
    rotor = plan_rotor_sweep(100, 20.0, 2, points=14)
    assert rotor.rotor["pass_nyquist_hz"] == 20.0 and rotor.rotor["n_blades"] == 2
    assert [d.frequency_hz for d in rotor.dwells] == [d.frequency_hz for d in plan_sweep(100, 0.5, 14.0).dwells]


def test_the_plan_writes_the_rotor_and_reads_it_back(tmp_path):
    from servoscope.campaign import Campaign
    from servoscope.defaults import ROTOR_BLADE_COLOURS

    out = tmp_path / "plan.toml"
    result = CliRunner().invoke(plan_command, ["--fps", "4000", "--rotor-hz", "20", "--out", str(out)])
    assert result.exit_code == 0, result.output
    campaign = Campaign.load(out, planned=True)
    assert campaign.rotor.blades == ROTOR_BLADE_COLOURS[:2] and campaign.rotor.rev_per_s == 20.0
    plan = read_plan(out)
    assert plan.rotor["n_blades"] == 2 and plan.rotor["pass_nyquist_hz"] == 20.0
    # Four blades with their own colours; four without are one clear error, and no file.
    colours = "#ff0000/#00ff00,#0000ff/#ff00ff,#00ffff/#ffff00,#ff8800/#8800ff"
    four = tmp_path / "four.toml"
    result = CliRunner().invoke(plan_command, ["--fps", "5000", "--rotor-hz", "20", "--blade-colours", colours,
                                               "--out", str(four)])
    assert result.exit_code == 0, result.output
    assert [b[0] for b in Campaign.load(four, planned=True).rotor.blades] == ["#ff0000", "#0000ff", "#00ffff",
                                                                             "#ff8800"]
    assert read_plan(four).rotor["pass_nyquist_hz"] == 40.0
    bad = tmp_path / "bad.toml"
    result = CliRunner().invoke(plan_command, ["--fps", "5000", "--rotor-hz", "20", "--blades", "4", "--out", str(bad)])
    assert result.exit_code != 0 and "--blade-colours" in str(result.exception or result.output)
    assert not bad.exists()
    result = CliRunner().invoke(plan_command, ["--fps", "5000", "--blade-colours", "#ff0000/#00ff00", "--out", str(bad)])
    assert result.exit_code != 0 and "--rotor-hz" in str(result.exception or result.output)

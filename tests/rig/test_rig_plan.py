"""Sweep planning: frequencies, dwell lengths, warnings, the plan file and `servoscope plan`."""

from __future__ import annotations

import math
import tomllib

import numpy as np
import pytest
from click.testing import CliRunner

from servoscope.errors import ServoscopeError
from servoscope.rig.cli import plan as plan_command
from servoscope.rig.plan import (
    Dwell,
    dwell_duration_s,
    fold_hz,
    frequency_warnings,
    plan_sweep,
    plan_to_toml,
    read_plan,
    write_plan,
)


def test_frequencies_are_log_spaced_and_end_with_a_step():
    plan = plan_sweep(100, 0.5, 15, points=14, amplitude=0.1, periods=8, min_seconds=3)
    sines = [d for d in plan.dwells if d.kind == "sine"]
    assert len(sines) == 14 and plan.dwells[-1].kind == "step"
    freqs = np.array([d.frequency_hz for d in sines])
    assert freqs[0] == 0.5 and freqs[-1] == 15.0
    # Equal ratios, up to the rounding to 3 significant digits (≤ 0.5 % per value).
    log_steps = np.diff(np.log(freqs))
    assert np.allclose(log_steps, math.log(30) / 13, atol=0.011)
    assert all(d.amplitude == 0.1 for d in sines)
    assert plan.dwells[-1].amplitude == 0.5 and plan.dwells[-1].frequency_hz is None


def test_dwell_durations_follow_periods_settling_and_minimum():
    # 0.5 Hz: 1 s settling + 8 periods = 17 s → 9 whole periods = 18 s.
    assert dwell_duration_s(0.5, 8, 1.0, 3.0) == pytest.approx(18.0)
    # 15 Hz: 1 + 8/15 s is below the 3 s minimum → 45 periods = 3 s.
    assert dwell_duration_s(15.0, 8, 1.0, 3.0) == pytest.approx(3.0)
    plan = plan_sweep(100, 0.5, 15, points=14, periods=8, min_seconds=3, settle_s=1.0)
    for d in plan.dwells[:-1]:
        f = d.frequency_hz
        n_periods = d.duration_s * f
        assert n_periods == pytest.approx(round(n_periods), abs=1e-9), "a dwell ends on a whole period"
        wanted = max(3.0, 1.0 + 8 / f)
        assert wanted - 1e-9 <= d.duration_s < wanted + 1 / f, "the shortest whole-period length that suffices"
        assert d.duration_s - 1.0 >= 8 / f - 1e-9
    assert plan.dwells[-1].duration_s == 3.0


def test_the_paper_sweep_has_no_warnings_and_bad_frequencies_do():
    assert plan_sweep(100, 0.5, 15, points=14).warnings == []
    # Camera: 8 Hz at 30 fps is 3.75 frames per period.
    w = frequency_warnings(8, fps=30, update_hz=50)
    assert len(w) == 1 and "frames per period" in w[0]
    # Camera: above half the frame rate.
    w = frequency_warnings(20, fps=30, update_hz=50)
    assert any("above half the frame rate" in x and "10 Hz" in x for x in w)
    # Servo: above half the update rate, folded to 24 Hz.
    w = frequency_warnings(26, fps=200, update_hz=50)
    assert any("half the servo update rate" in x and "24 Hz" in x for x in w)
    # Servo: exactly half the update rate, a sine started at 0 is sampled at its zeros.
    w = frequency_warnings(25, fps=1000, update_hz=50)
    assert any("zero crossing" in x for x in w)
    # Servo: on the update rate itself folds to 0.
    w = frequency_warnings(50, fps=1000, update_hz=50)
    assert any("alias at 0 Hz" in x for x in w)
    # Servo: 22 Hz is only 2.3 updates per period.
    w = frequency_warnings(22, fps=200, update_hz=50)
    assert any("servo updates per period" in x for x in w)
    # PWM ripple: 50 Hz seen at 60 fps lands on 10 Hz.
    assert fold_hz(50, 60) == 10
    w = frequency_warnings(10.2, fps=60, update_hz=50, analysed_s=2.0)
    assert any("PWM ripple" in x for x in w)
    assert frequency_warnings(11, fps=60, update_hz=50, analysed_s=2.0) == []
    assert frequency_warnings(10, fps=100, update_hz=50, analysed_s=2.0) == []
    # The plan carries them, dwell by dwell.
    plan = plan_sweep(30, 1, 8, points=4)
    assert plan.dwells[-2].frequency_hz == 8 and plan.dwells[-2].warnings
    assert plan.dwells[0].warnings == ()


def test_input_convention():
    sine = Dwell("sine", 0.2, 2.0, 1.0)
    t = np.array([-0.1, 0.0, 0.125, 0.5, 1.0, 1.2])
    assert np.allclose(sine.input_at(t), [0, 0, 0.2, 0, 0, 0], atol=1e-12)
    step = Dwell("step", -0.5, None, 1.0)
    assert np.allclose(step.input_at(t), [0, -0.5, -0.5, -0.5, 0, 0])


def test_plan_file_round_trips_and_has_no_videos(tmp_path):
    plan = plan_sweep(120, 0.5, 15, points=5, markers={"lead": "red", "trail": "#00ff00", "led": "#ffd400"})
    path = write_plan(plan, tmp_path / "plan.toml")
    data = tomllib.loads(path.read_text())
    assert set(data) == {"markers", "input", "analysis", "tests", "plan"}
    assert all("video" not in t for t in data["tests"])
    assert set(data["tests"][0]) == {"kind", "frequency_hz", "amplitude"}
    assert set(data["plan"]) == {"fps", "update_hz", "settle_s", "periods", "min_seconds", "lead_in_s",
                                 "tail_s", "rest_s", "dwells"}
    assert len(data["plan"]["dwells"]) == len(data["tests"]) == 6
    assert data["analysis"]["settle_s"] == plan.settle_s
    back = read_plan(path)
    assert back == plan
    assert plan_to_toml(back) == path.read_text()


def test_strings_with_quotes_survive_the_toml_writer(tmp_path):
    plan = plan_sweep(100, 1, 2, points=2, units='deg "collective"\\pitch')
    back = read_plan(write_plan(plan, tmp_path / "p.toml"))
    assert back.units == 'deg "collective"\\pitch'


@pytest.mark.parametrize(
    "kwargs, option",
    [
        (dict(fps=0), "--fps"),
        (dict(from_hz=-1), "--from"),
        (dict(to_hz=0.2), "--to"),
        (dict(amplitude=0), "--amplitude"),
        (dict(points=0), "--points"),
        (dict(points=1), "--points"),
        (dict(periods=0), "--periods"),
        (dict(min_seconds=-1), "--min-seconds"),
        (dict(step_amplitude=0), "--step-amplitude"),
        (dict(from_hz=1.0, to_hz=1.001, points=5), "--points"),
    ],
)
def test_bad_options_name_the_option(kwargs, option):
    args = dict(fps=100, from_hz=0.5, to_hz=15)
    args.update(kwargs)
    with pytest.raises(ServoscopeError, match=option):
        plan_sweep(args.pop("fps"), args.pop("from_hz"), args.pop("to_hz"), **args)


def test_read_plan_refuses_bad_files(tmp_path):
    with pytest.raises(ServoscopeError, match="no such plan"):
        read_plan(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[markers\n")
    with pytest.raises(ServoscopeError, match="not valid TOML"):
        read_plan(bad)
    campaign = tmp_path / "campaign.toml"
    campaign.write_text('[markers]\nlead="red"\ntrail="green"\n[[tests]]\nvideo="a.mp4"\nkind="step"\namplitude=1\n')
    with pytest.raises(ServoscopeError, match=r"no \[plan\] table"):
        read_plan(campaign)
    text = plan_to_toml(plan_sweep(100, 1, 2, points=2))
    short = tmp_path / "short.toml"
    short.write_text(text[: text.rindex("[[plan.dwells]]")])  # drop the last dwell's entry
    with pytest.raises(ServoscopeError, match="one entry per"):
        read_plan(short)


def test_plan_command_writes_the_plan_and_prints_warnings(tmp_path):
    out = tmp_path / "plan.toml"
    runner = CliRunner()
    result = runner.invoke(plan_command, ["--fps", "30", "--from", "1", "--to", "12", "--points", "4", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "wrote" in result.output and "warning: 12 Hz" in result.output
    plan = read_plan(out)
    assert [d.frequency_hz for d in plan.dwells[:-1]] == [1.0, 2.29, 5.24, 12.0]
    assert plan.fps == 30


def test_plan_command_bad_input_is_a_servoscope_error(tmp_path):
    runner = CliRunner()
    result = runner.invoke(plan_command, ["--fps", "100", "--from", "5", "--to", "1", "--out", str(tmp_path / "p.toml")])
    assert isinstance(result.exception, ServoscopeError) and "--to" in str(result.exception)
    result = runner.invoke(plan_command, ["--fps", "100", "--from", "1", "--to", "5", "--lead", "notacolour",
                                          "--out", str(tmp_path / "p.toml")])
    assert isinstance(result.exception, ServoscopeError) and "--lead" in str(result.exception)


def test_one_settle_and_min_seconds_default_made_written_and_read_back(tmp_path):
    """A plan's settle_s and min_seconds default as identify and the command line do, and read back as written."""
    from servoscope.defaults import MIN_DWELL_S, SETTLE_S

    plan = plan_sweep(100, 1, 10, points=3)
    assert plan.settle_s == SETTLE_S and plan.min_seconds == MIN_DWELL_S
    for minimum in (0.0, 1.25, 7.0):
        plan = plan_sweep(100, 1, 10, points=3, min_seconds=minimum)
        assert read_plan(write_plan(plan, tmp_path / "p.toml")).min_seconds == minimum
    # A hand-made [plan] without the two: the defaults, not 0 (which would plan shorter dwells than asked).
    text = plan_to_toml(plan_sweep(100, 1, 10, points=3))
    lean = tmp_path / "lean.toml"
    lean.write_text(text.replace("min_seconds = 3.0\n", "").replace("settle_s = 0.5\n", ""))
    back = read_plan(lean)
    assert back.min_seconds == MIN_DWELL_S and back.settle_s == SETTLE_S
    # The command line's help shows the same defaults.
    help_text = CliRunner().invoke(plan_command, ["--help"], terminal_width=200).output
    assert f"[default: {MIN_DWELL_S}]" in help_text and f"[default: {SETTLE_S}]" in help_text


def test_an_auto_analysis_settle_is_kept_and_the_dwells_timed_with_seconds(tmp_path):
    from servoscope.defaults import SETTLE_S

    text = plan_to_toml(plan_sweep(100, 1, 10, points=3, settle_s=0.75))
    assert '[analysis]\nsettle_s = 0.75\n' in text
    auto = tmp_path / "auto.toml"
    auto.write_text(text.replace("[analysis]\nsettle_s = 0.75\n", '[analysis]\nsettle_s = "auto"\n'))
    back = read_plan(auto)
    assert back.settle_auto and back.settle_s == 0.75  # [plan] settle_s still times the dwells
    assert '[analysis]\nsettle_s = "auto"\n' in plan_to_toml(back)
    # No [plan] settle_s: an "auto" analysis leaves the plan the default seconds.
    auto.write_text(auto.read_text().replace("settle_s = 0.75\n", ""))
    assert read_plan(auto).settle_s == SETTLE_S

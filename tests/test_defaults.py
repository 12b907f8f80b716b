"""servoscope/defaults.py is the one home of the defaults the stages, the commands and the twin share (issue 30)."""

from __future__ import annotations

import click
import pytest

from servoscope import defaults
from servoscope.cli import cli
from servoscope.errors import ServoscopeError
from servoscope.markers.led_timing import TIMESTAMP_CONVENTIONS, exposure_middle_offset_s
from servoscope.markers.settings import TrackerSettings


def _choices(command: str, option: str) -> tuple[str, ...]:
    param = next(p for p in cli.commands[command].params if p.name == option)
    assert isinstance(param.type, click.Choice)
    return tuple(param.type.choices)


def test_the_timestamp_choices_are_one_list():
    assert defaults.TIMESTAMPS == ("middle", "start", "end") and defaults.TIMESTAMP == "middle"
    assert tuple(TIMESTAMP_CONVENTIONS) == defaults.TIMESTAMPS  # what each one means, in the same order
    assert _choices("track", "timestamp") == defaults.TIMESTAMPS
    assert _choices("simulate", "timestamp_at") == defaults.TIMESTAMPS
    assert TrackerSettings().timestamp == defaults.TIMESTAMP
    with pytest.raises(ValueError, match="use one of middle, start, end"):
        exposure_middle_offset_s("centre", 0.001)


def test_the_twin_takes_its_timestamp_and_settling_from_the_defaults():
    from dataclasses import replace

    from servoscope.simulate.presets import CampaignPreset, PAPER_SERVO

    preset = CampaignPreset("mine", PAPER_SERVO, (1.0, 2.0))
    assert preset.timestamp_at == defaults.TIMESTAMP and preset.settle_s == defaults.SETTLE_S
    with pytest.raises(ServoscopeError, match="timestamp_at must be one of middle, start, end"):
        replace(preset, timestamp_at="later")


def test_fit_sine_and_the_manifest_share_the_word_auto():
    import inspect

    from servoscope.sysid import fit_sine

    assert inspect.signature(fit_sine).parameters["settle_s"].default == defaults.SETTLE_AUTO == "auto"
    assert isinstance(defaults.SETTLE_S, float) and defaults.SETTLE_S >= 0

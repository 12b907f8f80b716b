"""campaign.toml validation: every mistake is one clear ServoscopeError."""

from pathlib import Path

import re

import av
import numpy as np
import pytest

from servoscope.campaign import load_campaign
from servoscope.errors import ServoscopeError
from support import GOOD, tiny_video as _tiny_video


@pytest.fixture
def folder(tmp_path):
    _tiny_video(tmp_path / "a.mp4")
    _tiny_video(tmp_path / "b.mp4")
    return tmp_path


def _write(folder: Path, text: str) -> Path:
    p = folder / "campaign.toml"
    p.write_text(text)
    return p


def test_good_manifest(folder):
    c = load_campaign(_write(folder, GOOD))
    assert [t.kind for t in c.tests] == ["sine", "step"]
    assert c.tests[0].video == (folder / "a.mp4").resolve()
    assert c.tests[0].frequency_hz == 1.0 and c.tests[1].frequency_hz is None
    assert c.tests[1].label == "stepper" and c.tests[0].label == "a"
    assert c.camera is None and c.led == "#ffd400"


@pytest.mark.parametrize(
    "text, expected",
    [
        ("this is [not toml", "not valid TOML"),
        (GOOD.replace('kind = "sine"', 'kind = "chirp"'), "unknown kind 'chirp'"),
        (GOOD.replace("frequency_hz = 1.0", "frequency_hz = 0.0"), "tests[1].frequency_hz: must be > 0"),
        (GOOD.replace("frequency_hz = 1.0", "frequency_hz = -3"), "tests[1].frequency_hz: must be > 0, got -3"),
        (GOOD.replace("frequency_hz = 1.0", 'frequency_hz = "fast"'), "must be a finite number"),
        (GOOD.replace("frequency_hz = 1.0\n", ""), "tests[1].frequency_hz: missing"),
        (GOOD.replace('video = "a.mp4"\nkind = "sine"', 'video = "missing.mp4"\nkind = "sine"'), "missing.mp4: video not found"),
        (GOOD.replace('lead = "#d62728"', 'lead = "#zz0000"'), "is not a colour"),
        (GOOD.replace('lead = "#d62728"\n', ""), "markers.lead: missing"),
        (GOOD.replace('video = "b.mp4"', 'video = "a.mp4"'), "tests[2].video: 'a.mp4' is also the video of tests[1]"),
        # A name no file can have (found by tests/test_properties.py): one line, not a ValueError from the OS.
        (GOOD.replace('video = "b.mp4"', 'video = "b\\u0000.mp4"'), "tests[2].video: 'b\\x00.mp4' holds a NUL character"),
        (GOOD.replace('video = "b.mp4"', 'frames = "f\\u0000/*.tif"\nfps = 100'),
         "tests[2].frames: 'f\\x00/*.tif' holds a NUL character"),
        (GOOD.replace("frequency_hz = 1.0", "frequency_hz = 20.0"), "tests[1].frequency_hz: 20 Hz is at or above half the video's frame rate"),
        (GOOD.replace("amplitude = 0.1", "amplitud = 0.1"), "tests[1].amplitud: unknown key (did you mean 'amplitude'?)"),
        ("[markers]\nlead='red'\ntrail='blue'\n", "no [[tests]]"),
        (GOOD.replace('[markers]', '[camera]\ncalibration = "nope.json"\n[markers]'), "calibration file not found"),
    ],
)
def test_bad_manifests(folder, text, expected):
    with pytest.raises(ServoscopeError, match=re.escape(expected)):
        load_campaign(_write(folder, text))


def test_every_problem_reported_at_once(folder):
    text = GOOD.replace('kind = "sine"', 'kind = "ramp"').replace("amplitude = 0.5", "amplitude = 0").replace('lead = "#d62728"', 'lead = "#12"')
    with pytest.raises(ServoscopeError) as info:
        load_campaign(_write(folder, text))
    message = str(info.value)
    assert "3 problems" in message and "\n" not in message
    for part in ("markers.lead: '#12' is not a colour", "tests[1].kind: unknown kind 'ramp'", "tests[2].amplitude: must not be 0"):
        assert part in message


def test_not_a_video(folder):
    (folder / "a.mp4").write_text("hello, I am text\n")
    with pytest.raises(ServoscopeError, match="a.mp4: not a readable video"):
        load_campaign(_write(folder, GOOD))


def test_missing_manifest(tmp_path):
    with pytest.raises(ServoscopeError, match="manifest not found"):
        load_campaign(tmp_path / "nothing.toml")


def test_settle_s_defaults_to_the_one_default_and_may_be_auto(folder):
    from servoscope.defaults import SETTLE_S, TIMESTAMP

    c = load_campaign(_write(folder, GOOD))
    assert c.settle_s == SETTLE_S and c.timestamp == TIMESTAMP
    assert load_campaign(_write(folder, GOOD + "[analysis]\nsettle_s = 0\n")).settle_s == 0.0
    assert load_campaign(_write(folder, GOOD + '[analysis]\nsettle_s = "auto"\n')).settle_s == "auto"


@pytest.mark.parametrize("value, expected", [
    ('"soon"', "analysis.settle_s: must be a number of seconds ≥ 0 or \"auto\", got 'soon'"),
    ('"Auto"', "analysis.settle_s: must be a number of seconds ≥ 0 or \"auto\""),
    ("-0.5", "analysis.settle_s: must be ≥ 0"),
    ("true", "analysis.settle_s: must be a finite number"),
])
def test_bad_settle_s_is_refused(folder, value, expected):
    with pytest.raises(ServoscopeError, match=re.escape(expected)):
        load_campaign(_write(folder, GOOD + f"[analysis]\nsettle_s = {value}\n"))


def test_a_bad_timestamp_names_the_choices(folder):
    with pytest.raises(ServoscopeError, match=re.escape(
            'camera.timestamp: \'centre\': which point of its exposure a frame\'s time marks, one of '
            '"middle" (the default), "start", "end"')):
        load_campaign(_write(folder, '[camera]\ntimestamp = "centre"\n' + GOOD))

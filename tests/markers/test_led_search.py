"""The LED found by its switch, wherever the rig put it (issue 28, build 2; issue 29, build 3).

The twin fixes its LED to the stand (``led_place="stand"``) beside a screw
head brighter than the LED's off level, with a glint by the hub brighter and
larger than the LED in its hue: the largest blob of the LED's colour by the
blade is the glint, which never switches. Oracles: truth.json's t0 and the
LED's place; a light that goes out in the last frame is no switch.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

from servoscope.cli import main
from servoscope.pipeline import TrackerSettings, track_video
from servoscope.markers.led_level import disk_level, stays_down
from servoscope.markers.led_search import switch_of
from servoscope.simulate import simulate_campaign
from servoscope.video import frame_source
from servoscope.video.reader import iter_frames


def _run(args: list[str]) -> int:
    with pytest.raises(SystemExit) as exc:
        main(args)
    return int(exc.value.code or 0)

SMALL = dict(width=320, height=256, frequencies_hz=(2.0, 3.0), include_step=False, led_place="stand",
             led_distractors=True)
EXPOSURE_S = 0.01  # the quick preset's shutter


@pytest.fixture(scope="module")
def twins(tmp_path_factory):
    """A colour campaign (two dwells) and a 12-bit monochrome one (one dwell), LED on the stand, with look-alikes."""
    root = tmp_path_factory.mktemp("led_stand")
    simulate_campaign(root / "colour", "quick", 3, **SMALL)
    simulate_campaign(root / "mono", "quick", 4, **{**SMALL, "frequencies_hz": (2.0,)}, monochrome=True,
                      frames_format="tiff16", bit_depth=12)
    return root


def _truth(folder: Path) -> dict:
    return json.loads((folder / "truth.json").read_text())


def _check_t0(track, test: dict) -> None:
    assert track.t0_s is not None, track.warnings
    # Within the stated uncertainty (3σ), which is what the partly lit frame gives (well under a frame).
    assert abs(track.t0_s - test["t0_s"]) <= 3.0 * track.t0_uncertainty_s
    assert track.t0_uncertainty_s < 0.01 / math.sqrt(12.0)


def test_the_twin_puts_its_led_on_the_stand_beside_look_alikes(twins):
    led = _truth(twins / "colour")["led"]
    assert led["place"] == "stand" and [d["kind"] for d in led["distractors"]] == ["glint", "screw"]
    frame = next(iter(iter_frames(twins / "colour" / _truth(twins / "colour")["tests"][0]["video"]))).rgb
    x, y = (int(round(v)) for v in led["xy_px"])
    gx, gy = (int(round(v)) for v in led["distractors"][0]["xy_px"])
    # The glint is brighter than the lit LED: the blob an LED 'largest by the blade' would take.
    assert frame[gy, gx].astype(int).sum() > frame[y, x].astype(int).sum()


def test_a_fixed_led_is_found_by_its_switch_on_every_test(twins):
    truth = _truth(twins / "colour")
    found = 0
    for test in truth["tests"]:
        track = track_video(twins / "colour" / test["video"], TrackerSettings(exposure_s=EXPOSURE_S))
        _check_t0(track, test)
        assert not any(w.startswith("LED") for w in track.warnings), track.warnings
        found += 1
    assert found == len(truth["tests"]) == 2


def test_a_fixed_led_is_found_in_monochrome_footage(twins):
    test = _truth(twins / "mono")["tests"][0]
    source = frame_source(f"{twins / 'mono' / test['video']}/*.tif", fps=100, bits=12)
    track = track_video(source, TrackerSettings(lead="bright", trail="bright", led="bright", exposure_s=EXPOSURE_S))
    _check_t0(track, test)


def test_the_led_pinned_by_position_on_the_command_line(twins, tmp_path, capsys):
    truth = _truth(twins / "mono")
    test = truth["tests"][0]
    x, y = truth["led"]["xy_px"]
    folder = twins / "mono" / test["video"]
    args = ["track", f"{folder}/*.tif", "--fps", "100", "--bits", "12", "--lead", "bright", "--trail", "bright",
            "--exposure", str(EXPOSURE_S), "--out", str(tmp_path / "t.csv")]
    assert _run([*args, "--led", f"bright@{x + 2:.0f},{y - 1:.0f}"]) == 0
    said = capsys.readouterr().out
    t0 = float(said.split("LED switch t0 = ")[1].split(" s")[0])
    assert t0 == pytest.approx(test["t0_s"], abs=2e-4)
    # Pinned on the screw head (a bright blob that never switches): no t0, and the warning says so.
    sx, sy = truth["led"]["distractors"][1]["xy_px"]
    assert _run([*args, "--led", f"bright@{sx:.0f},{sy:.0f}"]) == 0
    err = capsys.readouterr()
    assert "LED switch t0 = none" in err.out and "pinned blob steps down" in err.err
    # Pinned where nothing bright is: one line, exit 2.
    assert _run([*args, "--led", "bright@160,250"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("servoscope: error: LED pinned at (160, 250)")


def test_a_light_that_goes_out_with_the_video_is_no_switch(twins, tmp_path):
    """The stand's LED lit throughout, put out (painted over) only in the last frame: no switch reported."""
    truth = _truth(twins / "colour")
    frame = next(iter(iter_frames(twins / "colour" / truth["tests"][0]["video"]))).rgb
    x, y = truth["led"]["xy_px"]
    r = int(math.ceil(1.5 * truth["led"]["diameter_px"]))
    last = frame.copy()
    cv2.circle(last, (int(round(x)), int(round(y))), r, (60, 60, 60), -1)
    for i in range(30):
        cv2.imwrite(str(tmp_path / f"f{i:03d}.png"), (last if i == 29 else frame)[..., ::-1])
    track = track_video(frame_source(f"{tmp_path}/*.png", fps=100), TrackerSettings(exposure_s=EXPOSURE_S))
    assert track.t0_s is None
    said = [w for w in track.warnings if w.startswith("LED")]
    assert len(said) == 1 and "steps down once" in said[0] and "pin it" in said[0], said
    # The candidates it looked at, each with its levels: the LED's among them.
    looked = [tuple(map(float, m)) for m in re.findall(r"\((\d+), (\d+)\) level \d+-\d+", said[0])]
    assert any(math.hypot(px - x, py - y) < 2.0 for px, py in looked), said


def test_no_blob_of_the_led_colour_says_so(twins):
    test = _truth(twins / "colour")["tests"][0]
    track = track_video(twins / "colour" / test["video"], TrackerSettings(led="#00e5ff", exposure_s=EXPOSURE_S))
    assert track.t0_s is None
    said = [w for w in track.warnings if w.startswith("LED")]
    assert len(said) == 1 and "no blob of its colour" in said[0], track.warnings


def test_a_switch_steps_down_once_and_stays_down():
    lit, dark = np.full(20, 200.0), np.full(20, 60.0)
    rng = np.random.default_rng(0)
    level = np.concatenate([lit, [130.0], dark]) + rng.normal(0, 1.0, 41)
    sw, why = switch_of(level)
    assert sw is not None and sw.frame == 20 and why == ""
    # Out in the last three frames, or back on, or a slow fade: no switch.
    assert switch_of(np.concatenate([np.full(37, 200.0), np.full(3, 60.0)]))[0] is None
    assert switch_of(np.concatenate([lit, dark, lit, dark]))[0] is None
    assert switch_of(np.linspace(200, 60, 40))[0] is None
    assert "last 3 frames" in stays_down(np.concatenate([np.ones(30), np.zeros(3)]))
    assert stays_down(np.concatenate([np.ones(10), np.zeros(30)])) == ""


def test_the_led_pinned_in_the_manifest(twins, tmp_path):
    """``led = {colour = …, near = [x, y]}`` (and the brightness form) reaches the tracker; a bad pin is refused."""
    from servoscope.campaign.manifest import load_campaign
    from servoscope.campaign.runner import track_campaign
    from servoscope.errors import ServoscopeError

    truth = _truth(twins / "colour")
    x, y = truth["led"]["xy_px"]
    text = (twins / "colour" / "campaign.toml").read_text()
    pinned = tmp_path / "campaign.toml"
    for test in truth["tests"]:
        (tmp_path / test["video"]).symlink_to(twins / "colour" / test["video"])
    (tmp_path / "camera.json").symlink_to(twins / "colour" / "camera.json")
    pinned.write_text(text.replace('led = "#ffd400"', f'led = {{colour = "#ffd400", near = [{x:.1f}, {y:.1f}]}}'))
    campaign = load_campaign(pinned)
    assert campaign.led == "#ffd400" and campaign.led_near == pytest.approx((x, y), abs=0.05)
    tracks = track_campaign(replace(campaign, tests=campaign.tests[:1]), workers=1)
    (track,) = tracks.values()
    _check_t0(track, truth["tests"][0])
    pinned.write_text(text.replace('led = "#ffd400"', 'led = {brightness = "bright", near = [10, 20]}'))
    assert load_campaign(pinned).led_near == (10.0, 20.0)
    pinned.write_text(text.replace('led = "#ffd400"', 'led = {colour = "#ffd400", near = [10]}'))
    with pytest.raises(ServoscopeError, match="markers.led.near"):
        load_campaign(pinned)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_disk_level_matches_a_numpy_mask(dtype):
    """The compiled disk (mean and peak) against NumPy's mask of the same disk: inside, at the borders, off the picture."""
    rng = np.random.default_rng(7)
    image = rng.integers(0, 255 if dtype == np.uint8 else 4095, size=(40, 60)).astype(dtype)
    yy, xx = np.mgrid[0:40, 0:60]
    for cx, cy, r in [(30.3, 20.7, 5.2), (0.4, 0.2, 3.0), (59.6, 39.9, 4.5), (10.0, 10.0, 0.7), (-8.0, 5.0, 3.0),
                      (30.5, -1.5, 2.5)]:
        inside = (xx - cx) ** 2 + (yy - cy) ** 2 <= r * r
        mean, peak = disk_level(image, cx, cy, r)
        if not inside.any():
            assert math.isnan(mean) and math.isnan(peak)
            continue
        assert mean == image[inside].astype(np.float64).mean()  # integer samples: exact either way
        assert peak == float(image[inside].max())
    assert all(math.isnan(v) for v in disk_level(image, math.nan, 3.0, 2.0))

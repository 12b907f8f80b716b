"""Monochrome footage: markers told by brightness (issue 16, build 3).

The twin renders a monochrome high-speed camera (BT.601 luma at 8 or 12 bits,
gray TIFF sequences, white dots on the dark blade, the LED a bright spot); the
tracker takes ``"bright"`` markers (and LED) on the RGB engine's soft moments.
Oracles: the renderer's truth (angles, t0, the model).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from servoscope.errors import ServoscopeError
from servoscope.pipeline import TrackerSettings, track_video
from servoscope.simulate import simulate_campaign

# run_cli: the command's entry point in this process, as a child ran it (no interpreter to start a call).
from support import run_cli

SMALL = dict(width=480, height=384, frames_format="tiff16", monochrome=True)


@pytest.fixture(scope="module")
def dwell(tmp_path_factory):
    folder = tmp_path_factory.mktemp("mono")
    simulate_campaign(folder, "quick", 0, frequencies_hz=(2.0,), include_step=False, **SMALL)
    return folder, json.loads((folder / "truth.json").read_text())["tests"][0]


def _source(folder):
    return f"{folder}/dwell_01_2.00Hz/*.tif#fps=100"


def test_bright_markers_track_to_the_twins_accuracy(dwell):
    folder, truth = dwell
    from servoscope.camera import CameraModel

    camera = CameraModel.load(folder / "camera.json")
    track = track_video(_source(folder), TrackerSettings(lead="bright", trail="bright", led="bright", exposure_s=0.01,
                                                         camera=camera))
    assert track.n_valid == track.n_frames
    err = track.angle_rad - np.asarray(truth["angle_rad"])
    # The colour engines' accuracy on this scene is ~0.002° RMS; the gray path keeps it.
    assert math.degrees(float(np.std(err))) < 0.005
    np.testing.assert_allclose(track.lead_xy_px[0], truth["lead_xy_px"][0], atol=0.3)  # the lead is the right dot
    assert track.t0_s == pytest.approx(truth["t0_s"], abs=3 * track.t0_uncertainty_s)


def test_pins_decide_which_dot_is_which(dwell):
    folder, truth = dwell
    lead, trail = truth["lead_xy_px"][0], truth["trail_xy_px"][0]
    plain = track_video(_source(folder), TrackerSettings(lead="bright", trail="bright", led=None))
    swapped = track_video(_source(folder), TrackerSettings(lead="bright", trail="bright", led=None,
                                                           lead_near=tuple(trail), trail_near=tuple(lead)))
    # Lead and trail swapped: the line between them points the other way, every frame.
    turn = np.angle(np.exp(1j * (swapped.angle_rad - plain.angle_rad)))
    np.testing.assert_allclose(np.abs(turn), math.pi, atol=1e-9)


@pytest.mark.parametrize("bits, seed", [(8, 1), (12, 2)])
def test_monochrome_campaign_identifies_the_servo(tmp_path, bits, seed):
    from servoscope.campaign.runner import identify

    toml = simulate_campaign(tmp_path, "quick", seed, bit_depth=bits, **SMALL)
    assert f"bits = {bits}" in toml.read_text() and 'lead = "bright"' in toml.read_text()
    truth = json.loads((tmp_path / "truth.json").read_text())["model"]
    s = identify(toml, workers=1).summary()
    for name in ("gain", "natural_frequency_rad_s"):
        assert s["model"][name] == pytest.approx(truth[name], rel=0.01), name
    for name in ("gain", "natural_frequency_rad_s", "damping_ratio", "dead_time_s"):
        lo, hi = s["model"]["ci95"][name]
        assert lo <= truth[name] <= hi, (name, lo, hi)


def test_colour_markers_on_monochrome_footage_say_how_to_give_brightness(dwell, tmp_path):
    folder, _ = dwell
    out = tmp_path / "t.csv"
    run = run_cli("track", f"{folder}/dwell_01_2.00Hz/*.tif", "--fps", "100", "--out", str(out))
    assert run.returncode == 2 and not out.exists()
    line = run.stderr.strip()
    assert "\n" not in line and "monochrome" in line and "bright@x,y" in line and "brightness = " in line
    with pytest.raises(ServoscopeError, match="tells markers by colour"):
        track_video(_source(folder), TrackerSettings(lead="bright", trail="bright", engine="numba"))


def test_manifest_brightness_markers(tmp_path):
    from servoscope.campaign.manifest import load_campaign

    base = ('[markers]\nlead = {brightness = "bright", near = [400, 180]}\ntrail = "bright"\nled = "bright"\n'
            '[[tests]]\nvideo = "a.mp4"\nkind = "sine"\nfrequency_hz = 1.0\namplitude = 0.1\n')
    manifest = tmp_path / "campaign.toml"
    manifest.write_text(base)
    c = load_campaign(manifest, check_videos=False)
    assert (c.lead, c.lead_near, c.trail, c.led) == ("bright", (400.0, 180.0), "bright", "bright")
    manifest.write_text(base.replace('brightness = "bright"', 'brightness = "shiny"'))
    with pytest.raises(ServoscopeError, match='"bright" or "dark"'):
        load_campaign(manifest, check_videos=False)


def test_an_mraw_of_the_monochrome_twin_tracks_as_its_tiff_sequence(tmp_path):
    """The issue's target: a high-speed camera's MRAW (written by pyMRAW) and the image sequence of the same
    12-bit footage give the same track to the last bit."""
    pyMRAW = pytest.importorskip("pyMRAW")
    import tifffile

    simulate_campaign(tmp_path, "quick", 0, frequencies_hz=(2.0,), include_step=False, bit_depth=12, **SMALL)
    folder = tmp_path / "dwell_01_2.00Hz"
    images = np.stack([tifffile.imread(f) for f in sorted(folder.glob("*.tif"))])
    assert images.dtype == np.uint16 and images.max() < 4096 and images.max() > 2000  # 12 bits used
    mraw, cih = pyMRAW.save_mraw(images, str(tmp_path / "rec.cih"), bit_depth=16,
                                 info_dict={"Record Rate(fps)": 100})
    settings = TrackerSettings(lead="bright", trail="bright", led="bright", exposure_s=0.01)
    from servoscope.video import frame_source

    from_tiff = track_video(frame_source(f"{folder}/*.tif", fps=100, bits=12), settings)
    from_mraw = track_video(cih, settings)
    for name in ("time_s", "lead_xy_px", "trail_xy_px", "angle_rad", "valid", "led_level", "angle_sigma_rad"):
        assert np.array_equal(getattr(from_tiff, name), getattr(from_mraw, name), equal_nan=name != "valid"), name
    assert from_tiff.t0_s == from_mraw.t0_s and from_tiff.n_valid == from_tiff.n_frames

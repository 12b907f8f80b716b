"""The exposure read from the stickers' motion blur (servoscope.camera.exposure), and its use.

Three kinds of check:
* the regression on hand-made tracks whose moments grow by a known (e²/12)·v·vᵀ
  (the slope, its interval, the support's cut taken by the second regressor);
* twin campaigns rendered with real motion blur (``motion_blur=True``), exposure
  hidden from the manifest, raw and H.264: the estimate within 20 % of the
  truth, its interval holding it; the same scene without blur: "not seen" and
  an upper bound, never an exposure;
* the frequency response corrected with an estimated exposure: gains' standard
  errors grow by the derivative of sinc (checked by finite differences).
"""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest

from servoscope.camera.exposure import BLUR_MIN_Z, blur_evidence, estimate_exposure, pool_blur
from servoscope.markers.track import Track


def _synthetic_track(exposure_s: float, *, seed: int, fps: float = 100.0, n: int = 400, cut: float = 0.0,
                     noise_px2: float = 0.05, strip: bool = True) -> Track:
    """Two stickers on a blade swinging ±0.15 rad at 2 Hz about a pivot 200 px away.

    Each sticker's moments: its still shape turned with the blade (a 4:1 strip, or a
    disc), plus (e²/12)·v·vᵀ, less ``cut``·|v|²·(e²/12)·v·vᵀ (what a support that cuts
    a long smear's ends does), plus white noise.
    """
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fps
    theta = 0.15 * np.sin(2 * math.pi * 2.0 * t)
    dtheta = 0.15 * 2 * math.pi * 2.0 * np.cos(2 * math.pi * 2.0 * t)
    track = {}
    for name, radius in (("lead", 260.0), ("trail", 140.0)):
        xy = np.stack([300 + radius * np.cos(theta), 200 - radius * np.sin(theta)], axis=1)
        v = np.stack([-radius * np.sin(theta) * dtheta, -radius * np.cos(theta) * dtheta], axis=1)
        still = np.diag([48.0, 3.0]) if strip else np.diag([9.0, 9.0])
        shape = np.empty((n, 3))
        for i in range(n):
            c, s = math.cos(theta[i]), math.sin(theta[i])
            rot = np.array([[c, s], [-s, c]])  # the blade's direction, y down
            blur = exposure_s**2 / 12 * np.outer(v[i], v[i])
            blur *= 1.0 - cut * float(v[i] @ v[i])
            m = rot @ still @ rot.T + blur
            shape[i] = m[0, 0], m[0, 1], m[1, 1]
        shape += rng.normal(0.0, noise_px2, shape.shape)
        track[name] = (xy, shape)
    (lxy, lsh), (txy, tsh) = track["lead"], track["trail"]
    return Track(video="synthetic", frame=np.arange(n), time_s=t, lead_xy_px=lxy, trail_xy_px=txy,
                 lead_area_px=np.full(n, 100.0), trail_area_px=np.full(n, 100.0), angle_rad=theta,
                 valid=np.ones(n, bool), reason=[""] * n, led_level=np.full(n, np.nan),
                 lead_shape_px2=lsh, trail_shape_px2=tsh)


@pytest.mark.parametrize("strip", [True, False])
@pytest.mark.parametrize("exposure_s", [0.004, 0.008])
def test_slope_recovers_the_exposure_of_a_known_smear(exposure_s, strip):
    ev = blur_evidence(_synthetic_track(exposure_s, seed=1, strip=strip))
    assert ev.seen and ev.z >= BLUR_MIN_Z
    assert ev.exposure_s == pytest.approx(exposure_s, rel=0.03)
    lo, hi = ev.ci95_s
    assert lo <= exposure_s <= hi


def test_the_supports_cut_is_taken_by_the_second_regressor():
    # Growth 15 % short at the fastest frames (|v| ≈ 490 px/s): a slope on v·vᵀ alone reads low.
    ev = blur_evidence(_synthetic_track(0.008, seed=2, cut=0.15 / 490.0**2))
    assert ev.exposure_s == pytest.approx(0.008, rel=0.03)


def test_no_blur_is_not_an_exposure_but_a_bound():
    ev = blur_evidence(_synthetic_track(0.0, seed=3))
    assert not ev.seen and ev.exposure_s is None and ev.ci95_s is None
    assert 0 < ev.upper_bound_s < 0.01  # a 2 Hz swing of 260 px shows blur well under a frame
    assert "no motion blur seen" in ev.describe()


def test_campaign_pools_videos_and_combines_with_the_led():
    evs = [blur_evidence(_synthetic_track(0.006, seed=s, n=150)) for s in range(4)]
    pooled = pool_blur(evs)
    assert pooled.frames == sum(e.frames for e in evs) and pooled.blocks == sum(e.blocks for e in evs)
    assert pooled.exposure_s == pytest.approx(0.006, rel=0.03)
    # 3 of 6 switches partly lit: the LED says half the frame (5 ms), coarsely; the two combine
    # by their inverse variances, nearer the blur's.
    both = estimate_exposure([(1, 0.01)] * 3 + [(0, 0.01)] * 3, None, pooled)
    assert both.source == "LED+blur"
    assert abs(both.value_s - 0.006) < abs(0.005 - 0.006)
    assert both.stderr_s < pooled.exposure_stderr_s
    # Given wins, and the blur still rides along for the report.
    given = estimate_exposure([], 0.002, pooled)
    assert given.source == "given" and given.value_s == 0.002 and given.summary()["blur"]["seen"]


def test_a_shape_change_longer_than_a_frame_is_not_read_as_blur():
    ev = blur_evidence(_synthetic_track(0.03, seed=4))  # 30 ms "exposure" at 100 frames/s
    assert ev.too_long and not ev.seen and ev.exposure_s is None
    assert "not read as blur" in ev.describe()
    assert estimate_exposure([], None, ev).source == "unknown"


def test_corrected_gain_error_includes_the_exposures_uncertainty():
    from servoscope.sysid.frequency_response import FrequencyResponse

    f = np.array([1.0, 5.0, 12.0])
    fr = FrequencyResponse(frequency_hz=f, frequency_stderr_hz=np.zeros(3), gain=np.array([0.23, 0.2, 0.1]),
                           gain_stderr=np.full(3, 1e-4), phase_deg=np.array([-10.0, -50.0, -120.0]),
                           phase_stderr_deg=np.full(3, 0.1), fidelity=np.ones(3), thd=np.zeros(3),
                           labels=["a", "b", "c"])
    e, se = 0.01, 0.001
    plain = fr.corrected_for_exposure(e)
    widened = fr.corrected_for_exposure(e, se)
    np.testing.assert_array_equal(plain.gain, widened.gain)
    h = 1e-7
    dlog = (np.log(np.sinc(f * (e + h))) - np.log(np.sinc(f * (e - h)))) / (2 * h)  # finite differences
    expected = np.hypot(plain.gain_stderr, plain.gain * np.abs(dlog) * se)
    np.testing.assert_allclose(widened.gain_stderr, expected, rtol=1e-6)


# -- twin campaigns with real motion blur -------------------------------------------------------
def _identify_hidden(tmp_path, **options):
    from servoscope.campaign.runner import identify
    from servoscope.simulate import simulate_campaign

    toml = simulate_campaign(tmp_path, "quick", 0, width=480, height=384, **options)
    toml.write_text(re.sub(r"\nexposure_s = .*", "", toml.read_text()))
    truth = json.loads((tmp_path / "truth.json").read_text())
    return identify(toml, workers=1), truth


@pytest.fixture(scope="module")
def full_frame_blur(tmp_path_factory):
    """codec → the scene of a full-frame shutter (10 ms at 100 frames/s) with its blur, the manifest silent:
    rendered once, raw, and its videos encoded again as H.264 (the bytes rendering with H.264 writes)."""
    from servoscope.simulate import reencode_campaign, simulate_campaign

    raw = simulate_campaign(tmp_path_factory.mktemp("blur_raw"), "quick", 0, width=480, height=384, codec="raw",
                            exposure_s=0.01, motion_blur=True)
    h264 = reencode_campaign(raw, tmp_path_factory.mktemp("blur_h264"), codec="h264")
    for toml in (raw, h264):
        toml.write_text(re.sub(r"\nexposure_s = .*", "", toml.read_text()))
    return {"raw": raw, "h264": h264}


@pytest.mark.parametrize("codec", ["raw", "h264"])
def test_twin_full_frame_blur_read_within_20_percent(full_frame_blur, codec):
    """A full-frame shutter (10 ms at 100 frames/s) with the blur it implies, the manifest silent."""
    from servoscope.campaign.runner import identify

    toml = full_frame_blur[codec]
    res, truth = identify(toml, workers=1), json.loads(toml.with_name("truth.json").read_text())
    assert truth["video"]["codec"] == codec
    e = res.exposure
    assert "blur" in e.source and e.blur.seen
    assert e.blur.exposure_s == pytest.approx(0.01, rel=0.2)
    lo, hi = e.blur.ci95_s
    assert lo <= 0.01 <= hi
    lo, hi = e.ci95_s
    assert lo <= 0.01 <= hi
    s = res.summary()
    assert s["exposure"]["blur"]["seen"] is True
    for name in ("gain", "natural_frequency_rad_s", "damping_ratio"):
        lo, hi = s["model"]["ci95"][name]
        assert lo <= truth["model"][name] <= hi, (name, lo, hi)
    from servoscope.report.build import exposure_text

    assert "motion blur" in exposure_text(res)


def test_twin_without_blur_says_not_seen_and_bounds_it(tmp_path):
    """The same scene drawn at an instant (no blur), exposure hidden: no exposure is invented."""
    res, _ = _identify_hidden(tmp_path, codec="h264", exposure_s=0.01, motion_blur=False)
    blur = res.exposure.blur
    assert not blur.seen and blur.upper_bound_s is not None
    assert "blur" not in res.exposure.source


def test_track_command_says_what_the_blur_shows(tmp_path):
    from support import run_cli  # the command's entry point in this process, as a child ran it

    from servoscope.simulate import simulate_campaign

    simulate_campaign(tmp_path, "quick", 0, width=480, height=384, codec="raw", exposure_s=0.01, motion_blur=True,
                      frequencies_hz=(1.0,))
    out = run_cli("track", str(tmp_path / "step.avi"), "--out", str(tmp_path / "step.csv"))
    assert out.returncode == 0, out.stderr
    line = next(line for line in out.stdout.splitlines() if "exposure:" in line)
    ms = float(re.search(r"exposure ([0-9.]+) ms", line).group(1))
    assert 8.0 <= ms <= 12.0, line

"""The LED's sub-frame switch time and its stated uncertainty, against exposures with a known switch.

A box exposure e centred on each frame time integrates the LED's light: the
level of frame n is the lit fraction of its exposure, plus the level noise of
a real sensor. The switch times are drawn at random, near exposure edges too,
where a frame that is 99 % lit looks whole.
"""

from __future__ import annotations

import numpy as np
import pytest

from servoscope.markers.led_timing import led_switch_time


def _led_switch_time(time_s, level, exposure_s):
    switch, why = led_switch_time(time_s, level, exposure_s)
    return (None, None, why) if switch is None else (switch.t0_s, switch.stderr_s, why)


def _levels(t0_s: float, time_s: np.ndarray, exposure_s: float, noise: float, rng) -> np.ndarray:
    lit_fraction = np.clip((t0_s - (time_s - exposure_s / 2.0)) / exposure_s, 0.0, 1.0)
    return lit_fraction + noise * rng.standard_normal(time_s.size)


@pytest.mark.parametrize("exposure_fraction", [1.0, 0.5])
@pytest.mark.parametrize("noise", [0.002, 0.01, 0.03])
def test_switch_time_within_its_stated_uncertainty(exposure_fraction, noise):
    rng = np.random.default_rng(7)
    period = 0.01
    exposure = exposure_fraction * period
    time_s = np.arange(60) * period
    z = []
    sigmas = []
    for _ in range(400):
        # Half anywhere after the lead-in, half within 2 % of an exposure's edge (the hard case).
        base = period * rng.integers(20, 40)
        if rng.random() < 0.5:
            t0 = base + rng.uniform(0.0, period)
        else:
            t0 = base + exposure / 2.0 + rng.choice([-1.0, 1.0]) * rng.uniform(0.0, 0.02) * exposure
        level = _levels(t0, time_s, exposure, noise, rng)
        t0_hat, sigma, why = _led_switch_time(time_s, level, exposure)
        assert why is None and sigma > 0
        z.append((t0_hat - t0) / sigma)
        sigmas.append(sigma)
    z = np.abs(np.asarray(z))
    # Stated σ honest: errors beyond 3σ are rare (uniform intervals have none).
    assert np.mean(z > 3.0) < 0.01
    print(f"median |z| {np.median(z):.2f}, beyond 3σ {np.mean(z > 3.0):.3f}")
    if exposure_fraction == 1.0:
        # End-to-end exposures: Gaussian errors (median |z| 0.67); a σ stated twice too
        # large or too small would put it outside.
        assert 0.4 < np.median(z) < 1.0
    else:
        # A switch near an exposure's edge falls at the end of its gap's interval: |z| ≤ √3.
        assert 0.4 < np.median(z) <= np.sqrt(3.0)
    # And useful: where some frame is partly lit, a small fraction of a frame; a switch in
    # the gap between exposures (exposure half the frame interval) is known only to the gap.
    gap = period - exposure
    # (the gap widened by the ±3σ band in which a level cannot be told from 0 or 1)
    limit = 0.06 * period if gap == 0 else 1.05 * (gap + 6.0 * noise * exposure) / np.sqrt(12)
    assert np.median(sigmas) < limit


def test_switch_between_exposures_is_the_gap_midpoint():
    time_s = np.arange(40) * 0.01
    exposure = 0.004  # 4 ms of a 10 ms frame: a switch in the 6 ms gap lights no frame partly
    level = _levels(0.2072, time_s, exposure, 0.0, np.random.default_rng(0))
    t0, sigma, why = _led_switch_time(time_s, level, exposure)
    gap_start, gap_end = 0.2 + exposure / 2, 0.21 - exposure / 2
    assert why is None
    assert t0 == pytest.approx(0.5 * (gap_start + gap_end), abs=1e-9)
    # Uniform over the gap (widened by the 3σ band of a noise-free level, its floor).
    assert (gap_end - gap_start) / np.sqrt(12) <= sigma <= 1.1 * (gap_end - gap_start) / np.sqrt(12)


def _overexposed_copy(src, dst, gain: float) -> None:
    """The same footage with its luma amplified and clipped at limited-range white (235), chroma kept."""
    import av

    from servoscope.video.reader import iter_yuv_frames

    with av.open(str(dst), "w") as container:
        stream = None
        for f in iter_yuv_frames(src):
            h, w = f.luma.shape
            if stream is None:
                stream = container.add_stream("rawvideo", rate=100)
                stream.pix_fmt, stream.width, stream.height = "yuv420p", w, h
            i420 = np.empty((h * 3 // 2, w), np.uint8)
            i420[:h] = np.clip(16 + (f.luma.astype(np.float64) - 16) * gain, 16, 235).astype(np.uint8)
            chroma = i420[h:].reshape(2, h // 2, w // 2)
            chroma[0], chroma[1] = f.u, f.v
            for packet in stream.encode(av.VideoFrame.from_ndarray(i420, format="yuv420p")):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)


def test_a_clipped_led_widens_t0_to_its_exposure(tmp_path):
    """An LED at the video's white level reads fully lit for part of the exposure it was dark:
    the partly lit frame's level, and t0 within it, are not known. Said, and in t0's σ."""
    from servoscope.pipeline import track_video
    from servoscope.simulate import Scene
    from servoscope.simulate.clips import render_clip

    n, switch = 60, 29
    led = np.ones(n)
    led[switch] = 0.4  # lit for 40 % of frame 29's exposure (1/fps, centred on its time)
    led[switch + 1:] = 0.0
    true_t0 = switch / 100.0 - 0.005 + 0.4 * 0.01
    render_clip(tmp_path / "c.avi", Scene(), 0.02 * np.sin(np.arange(n) / 10.0), fps=100, led_level=led, codec="raw")
    from servoscope.markers import TrackerSettings

    normal = track_video(tmp_path / "c.avi", TrackerSettings(exposure_s=0.01))
    assert not any("white level" in w for w in normal.warnings)
    assert abs(normal.t0_s - true_t0) < 3 * normal.t0_uncertainty_s < 0.5e-3
    # Not told the exposure, one partly lit frame dates t0 only to within what exposures
    # from nothing to the whole frame would give: between t[29] and t[29] + (0.4 − ½)/fps.
    unknown = track_video(tmp_path / "c.avi")
    assert unknown.t0_earliest_s == pytest.approx(switch / 100.0 - 0.001, abs=2e-4)
    assert unknown.t0_latest_s == pytest.approx(switch / 100.0, abs=1e-9)
    assert unknown.t0_earliest_s <= true_t0 <= unknown.t0_latest_s
    _overexposed_copy(tmp_path / "c.avi", tmp_path / "bright.avi", gain=2.0)
    bright = track_video(tmp_path / "bright.avi")
    assert bright.n_valid == n  # the stickers are still found by their chroma
    assert any("white level" in w for w in bright.warnings)
    # The clipped level moves t0 by milliseconds; the stated σ (exposure/√12) covers it.
    assert abs(bright.t0_s - true_t0) > 1e-3
    assert bright.t0_uncertainty_s == pytest.approx(0.01 / np.sqrt(12.0))
    assert abs(bright.t0_s - true_t0) < 3 * bright.t0_uncertainty_s


@pytest.mark.parametrize("phase", np.linspace(0.0, 2 * np.pi, 8, endpoint=False))
def test_lamp_flicker_on_the_unlit_led_is_not_a_partly_lit_frame(phase):
    """120 Hz lamps at 20 % depth, 100 frames/s, a quarter-frame shutter: the unlit LED's
    housing reflects the lamps, so its level swings ±0.2 at the 20 Hz alias while the lit
    LED's varies less. A switch between two exposures must stay a gap with the truth in it;
    a level noise capped at 0.03 read a 0.24 frame as partly lit and put t0 5.6 ms late."""
    fps, e = 100.0, 0.0025
    t = np.arange(60) / fps
    t0 = 0.2037  # between frame 20's exposure (ends 0.20125) and frame 21's (starts 0.20875)
    alias = 0.2 * np.sin(2 * np.pi * 20.0 * t + phase)
    level = np.where(t < t0, 1.0 + 0.5 * alias, alias)
    switch, reason = led_switch_time(t, level, e)
    assert reason is None
    assert switch.how == "gap"
    assert switch.earliest_s <= t0 <= switch.latest_s
    assert abs(switch.t0_s - t0) < 3 * switch.stderr_s

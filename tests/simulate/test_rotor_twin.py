"""The rotor twin (issue 33): the turning rotor's stickers where its geometry says, its pass table, its pitch.

The oracle is independent of the renderer: each sticker's share of every pixel is unmixed from the
picture against the two colours it lies between (the blade's and the sticker's), and
scikit-image's ``regionprops`` takes the weighted centroid of it.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from skimage.measure import label, regionprops

from servoscope.simulate import simulate_campaign
from servoscope.simulate.rotor import ROTOR_BLADE_COLOURS, RotorRig
from servoscope.simulate.rotor_campaign import rotor_rig_of_test
from servoscope.simulate.rotor_render import RotorRenderer, render_rotor_clip
from servoscope.simulate.scene import colour_rgb, marker_angle_rad
from servoscope.video import iter_frames

W, H, FPS = 320, 240, 4000


def collective(t):
    """A collective of 5° with a 3 Hz swing of ±1.1°."""
    return np.radians(5.0) + 0.02 * np.sin(2.0 * np.pi * 3.0 * np.asarray(t, dtype=float))


def sticker_centroid(frame: np.ndarray, colour: str, ground: str, threshold: float = 0.2) -> np.ndarray | None:
    """(x, y) of the largest blob of ``colour`` on ``ground``: its share of each pixel, weighted centroid (skimage)."""
    c, g = colour_rgb(colour), colour_rgb(ground)
    d = c - g
    alpha = np.clip((frame.astype(float) - g) @ d / (d @ d), 0.0, 1.0)
    # Only pixels that lie near the line between the two colours: not the background, nor another sticker.
    off = np.linalg.norm(frame.astype(float) - g - alpha[..., None] * d, axis=-1)
    alpha[off > 25.0] = 0.0
    labels = label(alpha > threshold)
    if labels.max() == 0:
        return None
    region = max(regionprops(labels, intensity_image=alpha), key=lambda r: r.area)
    # The soft edge outside the mask: grow it by two pixels (the stickers are ≥ 4 px from other colours).
    from scipy.ndimage import binary_dilation

    mask = binary_dilation(labels == region.label, iterations=2)
    w = np.where(mask, alpha, 0.0)
    ys, xs = np.nonzero(w)
    weights = w[ys, xs]
    return np.array([np.sum(xs * weights), np.sum(ys * weights)]) / weights.sum()


@pytest.fixture(scope="module")
def rig() -> RotorRig:
    return RotorRig(blade_offsets_rad=(0.0, math.radians(0.2)), azimuth0_rad=-0.7, drift_phase_rad=0.4,
                    cyclic_rad=math.radians(0.5), cyclic_phase_rad=0.3)


@pytest.fixture(scope="module")
def clip(rig, tmp_path_factory):
    """0.1 s at 4,000 frames/s, colour H.264: 4 passes; its truth and its decoded frames."""
    path = tmp_path_factory.mktemp("rotor") / "clip.mp4"
    truth = render_rotor_clip(path, rig, collective, 0.1, fps=FPS, exposure_s=1 / 40000, width=W, height=H,
                              led_off_s=0.05, noise_seed=4, bit_rate=20_000_000)
    frames = np.stack([f.rgb for f in iter_frames(path)])
    return truth, frames


def test_still_stickers_where_the_geometry_projects_them(rig):
    """At ψ = 0 (no blur, no noise) each sticker's measured centroid is its centre's projection to 0.02 px, and the
    angle between them is the blade's pitch."""
    renderer = RotorRenderer(rig, W, H, exposure_s=0.0, noise_sigma_dn=0.0)
    times, blades = rig.pass_times_s(0.0, 0.2)
    assert len(times) >= 4
    for t, b in zip(times[:4], blades[:4]):
        frame = renderer.composite(float(t), collective)
        pitch = float(rig.blade_pitch_rad(collective(t), t, int(b)))
        lead, trail = rig.sticker_centres_px(rig.azimuth_rad(t, int(b)), pitch, W, H)
        got = [sticker_centroid(frame, c, rig.blade_colour) for c in rig.blades[b]]
        np.testing.assert_allclose(got[0], lead, atol=0.02)
        np.testing.assert_allclose(got[1], trail, atol=0.02)
        # ψ = 0: the tip face is square to the camera; the stickers' line is the chord, turned by the pitch.
        assert abs(float(marker_angle_rad(got[0], got[1])) - pitch) < 3e-4
        assert abs(float(marker_angle_rad(lead, trail)) - pitch) < 1e-12


def test_pass_table_once_a_revolution_a_blade(rig, clip):
    """Passes alternate 0, 1, 0, …, 1/(N·Ω) apart (within the speed's drift), each at ψ = 0 of its blade."""
    truth, frames = clip
    passes = truth["passes"]
    t = np.array([p["time_s"] for p in passes])
    b = np.array([p["blade"] for p in passes])
    assert len(passes) >= 4
    assert np.all(np.diff(b) % 2 == 1)  # two blades take turns
    gaps = np.diff(t) * rig.n_blades * rig.rev_per_s
    np.testing.assert_allclose(gaps, 1.0, atol=1.1 * rig.drift_fraction)
    psi = np.array([rig.azimuth_rad(ti, bi) for ti, bi in zip(t, b)])
    np.testing.assert_allclose(np.mod(psi + np.pi, 2 * np.pi) - np.pi, 0.0, atol=1e-9)
    # The passes in the clip: N·Ω a second.
    inside = np.sum((t >= 0) & (t < 0.1))
    assert abs(inside - 0.1 * rig.n_blades * rig.rev_per_s) <= 1
    assert abs(truth["rev_per_s"] - rig.rev_per_s) < rig.rev_per_s * rig.drift_fraction
    # The pitch is the collective + cyclic at ψ = 0 + the blade's offset.
    for p in passes:
        want = collective(p["time_s"]) + rig.cyclic_rad * math.cos(rig.cyclic_phase_rad) + rig.offset_rad(p["blade"])
        assert abs(p["pitch_rad"] - want) < 1e-12


def test_pass_frames_show_that_blade_only(rig, clip):
    """The frames a pass lists show its blade's stickers (≥ 8 of them); a frame either side shows none of them."""
    truth, frames = clip
    for p in truth["passes"]:
        k0, k1 = p["first_frame"], p["last_frame"]
        lead, trail = rig.blades[p["blade"]]
        other = rig.blades[1 - p["blade"]]
        if k0 > 0 and k1 < len(frames) - 1:
            assert k1 - k0 + 1 >= 8
        for k in range(k0 + 1, k1):  # the first and last may show a sliver only
            # The tip crosses left to right: the lead sticker (on the right) comes in first and leaves first.
            assert any(sticker_centroid(frames[k], c, rig.blade_colour, 0.5) is not None for c in (lead, trail))
            assert all(sticker_centroid(frames[k], c, rig.blade_colour, 0.5) is None for c in other)
        for k in (k0 - 2, k1 + 2):
            if 0 <= k < len(frames):
                assert sticker_centroid(frames[k], lead, rig.blade_colour, 0.5) is None
                assert sticker_centroid(frames[k], trail, rig.blade_colour, 0.5) is None


def test_pitch_read_at_the_pass(rig):
    """Frames as the camera exposes them (1/40,000 s of blur, sensor noise), at the frame nearest each pass's ψ = 0:
    the stickers' centroids are the geometry's projection within 0.06 px, and the angle between them, corrected by
    the geometry's own turn of the line at that frame's azimuth, is the pass's pitch within 0.01°."""
    renderer = RotorRenderer(rig, W, H, exposure_s=1 / 40000, noise_sigma_dn=1.5, noise_seed=9)
    assert renderer.blur_samples >= 3
    times, blades = rig.pass_times_s(0.0, 0.15)
    errors = []
    for tp, b in zip(times, blades):
        k = int(round(tp * FPS))
        t = k / FPS
        frame = renderer.render(t, collective, 1.0, k)
        got = [sticker_centroid(frame, c, rig.blade_colour) for c in rig.blades[b]]
        pitch_k = float(rig.blade_pitch_rad(collective(t), t, int(b)))
        lead, trail = rig.sticker_centres_px(rig.azimuth_rad(t, int(b)), pitch_k, W, H)
        np.testing.assert_allclose(got[0], lead, atol=0.06)
        np.testing.assert_allclose(got[1], trail, atol=0.06)
        view_turn = float(marker_angle_rad(lead, trail)) - pitch_k  # the oblique view's turn of the line at ψ_k
        pitch_at_pass = float(rig.blade_pitch_rad(collective(tp), tp, int(b)))
        errors.append(float(marker_angle_rad(got[0], got[1])) - view_turn + (pitch_at_pass - pitch_k) - pitch_at_pass)
    assert len(errors) >= 5
    assert np.max(np.abs(errors)) < math.radians(0.01)


def test_h264_footage_is_the_rendered_picture(rig, clip):
    """The written H.264 (4:2:0 chroma) shows the stickers where the geometry puts them, within 0.25 px."""
    truth, frames = clip
    checked = 0
    for p in truth["passes"]:
        b = p["blade"]
        for k in range(p["first_frame"] + 2, p["last_frame"] - 1):
            t = k / FPS
            pitch_k = float(rig.blade_pitch_rad(collective(t), t, b))
            centres = rig.sticker_centres_px(rig.azimuth_rad(t, b), pitch_k, W, H)
            for colour, centre in zip(rig.blades[b], centres):
                if 8 < centre[0] < W - 8:
                    np.testing.assert_allclose(sticker_centroid(frames[k], colour, rig.blade_colour), centre, atol=0.25)
                    checked += 1
    assert checked > 40


def test_three_blades_at_another_speed(tmp_path):
    """Three blades at 27 rev/s, 5,000 frames/s: each blade in turn, its own colours where its stickers project."""
    rig = RotorRig(blades=ROTOR_BLADE_COLOURS[:3], rev_per_s=27.0, azimuth0_rad=0.3)
    truth = render_rotor_clip(tmp_path / "three.mp4", rig, collective, 0.05, fps=5000, exposure_s=1 / 50000,
                              width=W, height=H, noise_seed=2, bit_rate=20_000_000)
    frames = np.stack([f.rgb for f in iter_frames(tmp_path / "three.mp4")])
    order = [p["blade"] for p in truth["passes"]]
    assert len(order) >= 4 and all((b1 - b0) % 3 == 1 for b0, b1 in zip(order, order[1:]))
    assert abs(truth["rev_per_s"] - 27.0) < 27.0 * rig.drift_fraction
    shown = 0
    for p in truth["passes"]:
        k = int(round(p["time_s"] * 5000))
        if 0 <= k < len(frames):
            t = k / 5000
            centres = rig.sticker_centres_px(rig.azimuth_rad(t, p["blade"]), float(
                rig.blade_pitch_rad(collective(t), t, p["blade"])), W, H)
            for colour, centre in zip(rig.blades[p["blade"]], centres):
                x, y = (int(round(v)) for v in centre)
                assert np.linalg.norm(frames[k][y, x].astype(float) - colour_rgb(colour)) < 40
                np.testing.assert_allclose(sticker_centroid(frames[k], colour, rig.blade_colour), centre, atol=0.25)
            shown += 1
    assert shown >= 3


def test_monochrome_mraw(tmp_path, rig):
    """A monochrome 12-bit MRAW: all its frames, the stickers white on the dark tip face at the pass."""
    from servoscope.video import frame_source

    truth = render_rotor_clip(tmp_path / "mono", rig, collective, 0.03, monochrome=True, bit_depth=12,
                              noise_seed=1, led_off_s=0.01)
    frames = [f.rgb for f in iter_frames(frame_source(tmp_path / "mono" / "frames.cih", fps=FPS, bits=12))]
    assert len(frames) == len(truth["time_s"])
    p = next(p for p in truth["passes"] if 0 <= round(p["time_s"] * FPS) < len(frames))
    k = int(round(p["time_s"] * FPS))
    frame = frames[k].astype(float).mean(axis=-1)
    for centre in rig.sticker_centres_px(rig.azimuth_rad(k / FPS, p["blade"]), p["pitch_rad"], W, H):
        x, y = int(round(centre[0])), int(round(centre[1]))
        assert frame[y, x] > 230 and frame[y - 40, x] < 160  # white sticker; the background above the blade


def test_paper_rotor_campaign(tmp_path):
    """``simulate_campaign`` dispatches a rotor preset: videos, campaign.toml with [rotor], truth.json's passes."""
    from servoscope.campaign.manifest import Campaign

    toml = simulate_campaign(tmp_path / "c", "paper-rotor", seed=2, frequencies_hz=(14.0,), include_step=False,
                             min_dwell_s=0.1, min_periods=0.0, settle_s=0.05, pre_roll_s=0.02)
    campaign = Campaign.load(toml)
    assert campaign.rotor is not None and campaign.rotor.blades == ROTOR_BLADE_COLOURS[:2]
    assert campaign.rotor.rev_per_s == 20.0
    truth = json.loads((tmp_path / "c" / "truth.json").read_text())
    test = truth["tests"][0]
    assert test["kind"] == "sine" and test["frequency_hz"] == 14.0 and len(test["passes"]) >= 6
    rig = rotor_rig_of_test(truth, 0)
    for p in test["passes"]:
        assert abs(math.remainder(float(rig.azimuth_rad(p["time_s"], p["blade"])), 2 * math.pi)) < 1e-9
    # Before the servo moves (its dead time after the input's start): no collective, the blades' rigging alone.
    still = [p for p in test["passes"] if p["time_s"] < test["t0_s"] + truth["model"]["dead_time_s"]]
    assert {p["blade"] for p in still} == {0, 1}
    for p in still:
        assert p["pitch_rad"] == pytest.approx(math.radians(0.2) * p["blade"], abs=1e-12)


def test_an_unknown_preset_lists_the_rotors_too():
    from servoscope.errors import ServoscopeError
    from servoscope.simulate import PRESETS, simulate_campaign
    from servoscope.simulate.rotor_campaign import ROTOR_PRESETS

    with pytest.raises(ServoscopeError) as err:
        simulate_campaign("/nonexistent-never-written", "nonesuch")
    listed = str(err.value).split("choose from ", 1)[1].rstrip(")").split(", ")
    assert sorted(listed) == sorted([*PRESETS, *ROTOR_PRESETS])


def test_a_coned_blade_rises_and_its_stickers_are_where_the_geometry_puts_them(rig):
    """Coning β lifts the tip by R·sin β and tilts its face: the rendered stickers (scikit-image) sit at their
    coned projections to 0.02 px, above the flat rotor's by f·R·sin β / (D − R cos β), and their line is no longer
    the pitch: what the camera reads is the geometry's (docs/rotor.md: the method's error under flapping)."""
    from dataclasses import replace

    coned = replace(rig, coning_rad=math.radians(2.0))
    renderer = RotorRenderer(coned, W, H, exposure_s=0.0, noise_sigma_dn=0.0)
    times, blades = coned.pass_times_s(0.0, 0.1)
    t, b = float(times[0]), int(blades[0])
    pitch = float(coned.blade_pitch_rad(collective(t), t, b))
    frame = renderer.composite(t, collective)
    lead, trail = coned.sticker_centres_px(coned.azimuth_rad(t, b), pitch, W, H)
    flat_lead, _ = rig.sticker_centres_px(rig.azimuth_rad(t, b), pitch, W, H)
    got = [sticker_centroid(frame, c, coned.blade_colour) for c in coned.blades[b]]
    np.testing.assert_allclose(got[0], lead, atol=0.02)
    np.testing.assert_allclose(got[1], trail, atol=0.02)
    beta, r, d, f = coned.coning_rad, coned.tip_radius_m, coned.camera_distance_m, coned.focal_length_px
    assert float(flat_lead[1] - lead[1]) == pytest.approx(f * r * math.sin(beta) / (d - r * math.cos(beta)), rel=0.05)
    # The tilted face foreshortens the chord's rise: the line reads a little under the pitch (cos β in the
    # orthographic limit), not exactly it.
    read = float(marker_angle_rad(np.asarray(got[0]), np.asarray(got[1])))
    assert 0.0 < pitch - read < 2.5 * pitch * (1.0 - math.cos(beta)) + 3e-4

"""Messy footage: a blob of a marker's colour elsewhere, a sticker leaving the frame."""

from __future__ import annotations

import numpy as np

from servoscope.pipeline import TrackerSettings, track_video
from servoscope.simulate import Scene
from servoscope.simulate.clips import Occluder, render_clip


def _angle_err_deg(track, truth) -> np.ndarray:
    return np.degrees(np.angle(np.exp(1j * (track.angle_rad - truth["angle_rad"]))))[track.valid]


def test_second_blob_of_the_lead_colour_does_not_steal_its_identity(tmp_path):
    scene = Scene(background_seed=2)
    n = 40
    # A small red patch (the lead's colour) crossing the top of the image, far from both stickers.
    decoy = Occluder(scene.lead_colour, (60.0, 76.0), 16.0, 40.0, 640.0)
    truth = render_clip(tmp_path / "d.mp4", scene, 0.03 * np.sin(np.arange(n) / 6.0), occluder=decoy)
    track = track_video(tmp_path / "d.mp4", TrackerSettings(led=None))
    assert track.valid.all()
    err_px = np.hypot(*(track.lead_xy_px - truth["lead_xy_px"]).T)
    assert err_px.max() < 0.3  # never jumped to the decoy (hundreds of px away)
    assert np.sqrt(np.mean(_angle_err_deg(track, truth) ** 2)) < 0.01


def test_sticker_leaving_the_frame_gives_invalid_frames_then_resumes(tmp_path):
    # Blade near the top of the image; a large pitch excursion carries the lead sticker out and back.
    scene = Scene(pivot_xy_px=(535.37, 60.0), background_seed=3)
    n = 60
    pitch = 0.6 * np.concatenate([np.linspace(0, 1, n // 2), np.linspace(1, 0, n - n // 2)])
    truth = render_clip(tmp_path / "out.mp4", scene, pitch)
    track = track_video(tmp_path / "out.mp4", TrackerSettings(led=None))
    radius = scene.sticker_diameter_px / 2
    lead_y = truth["lead_xy_px"][:, 1]
    gone = lead_y + radius < 0
    inside = lead_y - radius > 3
    assert gone.sum() >= 5 and inside.sum() >= 16
    assert not track.valid[gone].any()
    assert all("lead" in track.reason[i] for i in np.flatnonzero(gone))
    # Both before leaving and after coming back, the frames are measured.
    first_back = np.flatnonzero(gone)[-1] + 1
    assert track.valid[:5].all() and track.valid[inside & (np.arange(n) > first_back)].sum() >= 6
    assert np.sqrt(np.mean(_angle_err_deg(track, truth) ** 2)) < 0.02

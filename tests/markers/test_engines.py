"""The engine suite: every tracking engine on one small twin clip, against the renderer's truth and each other.

Engines: ``"numba"`` (the default), ``"numpy"`` (the same maths in plain numpy,
the numba kernel's reference) and ``"reference-rgb"`` (the RGB path). No GPU
engine exists: ``backend="cuda"`` is refused (last test).

The clip: the twin's scene at half scale (stickers ~13 px, ~300 px apart),
uncompressed, 1 DN of noise, 24 frames of a 0.05 rad sine. Tolerances are
a few times what each engine measured here (numba/numpy 0.005° RMS, 0.07 px;
reference-rgb 0.084° RMS, 0.75 px: its HSV mask takes in part of the blue
sticker's blurred edge).
"""

from __future__ import annotations

import numpy as np
import pytest

from servoscope.errors import ServoscopeError
from servoscope.pipeline import TrackerSettings, track_video
from servoscope.simulate import Scene
from servoscope.simulate.clips import render_clip

N_FRAMES = 24
#: engine -> (angle RMS error, deg; largest centroid error, px)
TOLERANCE = {"numba": (0.02, 0.2), "numpy": (0.02, 0.2), "reference-rgb": (0.2, 1.2)}


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    path = tmp_path_factory.mktemp("engines") / "twin.avi"
    scene = Scene.for_size(360, 288, background_seed=1)
    truth = render_clip(path, scene, 0.05 * np.sin(np.linspace(0.0, 4.0, N_FRAMES)), codec="raw", fps=60,
                        noise_sigma_dn=1.0)
    return path, truth


@pytest.fixture(scope="module")
def tracks(clip):
    path, _ = clip
    return {engine: track_video(path, TrackerSettings(led=None, engine=engine)) for engine in TOLERANCE}


@pytest.mark.parametrize("engine", sorted(TOLERANCE))
def test_engine_against_the_renderers_truth(clip, tracks, engine):
    _, truth = clip
    track = tracks[engine]
    assert track.valid.all(), track.reason
    np.testing.assert_allclose(track.time_s, np.arange(N_FRAMES) / 60.0, atol=1e-9)
    err_deg = np.degrees(np.angle(np.exp(1j * (track.angle_rad - truth["angle_rad"]))))
    max_rms_deg, max_px = TOLERANCE[engine]
    assert np.sqrt(np.mean(err_deg**2)) < max_rms_deg
    for name in ("lead", "trail"):
        miss = np.hypot(*(getattr(track, f"{name}_xy_px") - truth[f"{name}_xy_px"]).T)
        assert miss.max() < max_px, (name, miss.max())
    # The angle follows the motion (a frozen track would miss by the swing, 5°).
    np.testing.assert_allclose(np.ptp(track.angle_rad), np.ptp(truth["angle_rad"]), rtol=0.05)


def test_numpy_is_the_numba_kernels_reference(tracks):
    a, b = tracks["numpy"], tracks["numba"]
    np.testing.assert_allclose(a.lead_xy_px, b.lead_xy_px, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.trail_xy_px, b.trail_xy_px, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.angle_rad, b.angle_rad, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.lead_sigma_px, b.lead_sigma_px, rtol=1e-9)
    assert a.reason == b.reason


def test_rgb_reference_agrees_with_the_yuv_engine(tracks):
    diff_deg = np.degrees(np.abs(tracks["reference-rgb"].angle_rad - tracks["numba"].angle_rad))
    assert diff_deg.max() < 0.3
    for name in ("lead", "trail"):
        gap = np.hypot(*(getattr(tracks["reference-rgb"], f"{name}_xy_px") - getattr(tracks["numba"], f"{name}_xy_px")).T)
        assert gap.max() < 1.2


def test_cuda_backend_is_refused_naming_auto(clip):
    path, _ = clip
    with pytest.raises(ServoscopeError, match="backend=\"auto\""):
        track_video(path, TrackerSettings(led=None, backend="cuda"))

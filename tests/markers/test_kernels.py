"""The fused YUV kernel: numpy reference and numba agree; engines agree (the GPU pass: test_gpu.py)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from servoscope.pipeline import TrackerSettings, track_video
from servoscope.markers import kernels as K
from servoscope.markers import kernel_numpy
from servoscope.simulate import Scene
from servoscope.simulate.clips import render_clip
from servoscope.video.reader import iter_yuv_frames
from servoscope.video.writer import rgb_to_yuv420p

from support import kernel_frame as _frame, kernel_params as _params, run_kernel as _run

ENGINES = ["numpy", "numba"]


@pytest.mark.parametrize("engine", ENGINES)
def test_kernel_finds_disks(engine):
    i420 = _frame()
    out, led_out = _run(engine, i420, _params(i420), np.array([1.0, 0.2, 0.1, 3.0]))
    # Pixel centres at integers: a disk centred at 85.3 (in pixel-edge units) sits at 84.8.
    np.testing.assert_allclose(out[0, [K.Q.X, K.Q.Y]], [84.8, 40.2], atol=0.08)
    np.testing.assert_allclose(out[1, [K.Q.X, K.Q.Y]], [30.1, 51.7], atol=0.08)
    np.testing.assert_allclose(out[:, K.Q.M00], [np.pi * 81, np.pi * 64], rtol=0.05)
    assert np.isfinite(led_out[0]) and led_out[1] > 0


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("fields", [(0, 1), (1, 2)])
def test_numpy_and_numba_agree(seed, fields):
    i420 = _frame(seed)
    params = _params(i420)
    if seed == 2:  # the recentring centre given, one pass, no background ring (window at the edge)
        params[:, K.P.USE_CENTRE] = 1
        params[:, K.P.CX], params[:, K.P.CY] = (84.0, 29.0), (40.0, 53.0)
        params[:, K.P.ITER] = 1
        params[1, K.P.RING] = 0.0
    if fields[1] == 2:
        params[:, K.P.Y0] //= 2
        params[:, K.P.Y1] //= 2
        params[:, K.P.CY] /= 2
    led = np.array([1.0, 0.3, -0.05, 4.0])
    a, la = _run("numpy", i420, params, led, *fields)
    b, lb = _run("numba", i420, params, led, *fields)
    assert a[:, K.Q.M00].min() > 10
    np.testing.assert_allclose(b, a, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(lb, la, rtol=1e-9, atol=1e-9)


def test_luma_alpha_at_chroma_resolution_agrees_with_chroma():
    """Luma's α resampled as the writer sampled the chroma matches chroma's α across the edge.

    A noise-free magenta disk (luma contrast 86 DN, chroma 45 DN) on a flat dark background:
    pixel by pixel, luma's sharp α and the half-resolution chroma's smeared α disagree by far
    more than the agreement test's tolerance along the whole edge; resampled through the
    writer's 2×2 blocks and read at chroma's siting, luma's α agrees with chroma's to the
    8-bit rounding. A block or siting off by one pixel would not.
    """
    from servoscope.markers.colour import ycbcr_bt601 as _bt601

    h, w = 64, 80
    cx, cy, r = 40.3, 31.6, 13.0
    bg, mk = np.array([58.0, 60.0, 64.0]), np.array([227.0, 119.0, 194.0])
    yy, xx = np.mgrid[0:h, 0:w]
    # Coverage of a pixel square by the disk (its edge as a 1-px linear ramp).
    cov = np.clip(r + 0.5 - np.hypot(xx - cx, yy - cy), 0.0, 1.0)
    rgb = cov[..., None] * mk + (1.0 - cov[..., None]) * bg
    i420 = rgb_to_yuv420p(np.clip(rgb, 0, 255).round().astype(np.uint8))
    Y = i420[:h].astype(np.float64)
    U, V = i420[h:].reshape(2, h // 2, -1)
    (yb, ub, vb), (ym, um, vm) = _bt601(bg), _bt601(mk)
    prm = np.zeros(K.NP)
    prm[[K.P.YM, K.P.UM, K.P.VM]] = ym, um, vm
    prm[K.P.ALPHA_LO], prm[K.P.ALPHA_HI] = -0.5, 1.5
    px, py = xx.ravel().astype(np.float64), yy.ravel().astype(np.float64)
    dx, dy = px - cx, py - cy
    d2 = dx * dx + dy * dy
    radius = r + 2.0
    sup = d2 <= radius**2
    aY = (Y.ravel()[sup] - yb) / (ym - yb)
    sU = K.chroma_np(U, px[sup], py[sup], 0, 1)
    sV = K.chroma_np(V, px[sup], py[sup], 0, 1)
    cu, cv = um - ub, vm - vb
    aC = (cu * (sU - ub) + cv * (sV - vb)) / (cu * cu + cv * cv)
    my = np.full(K.N_BINS, yb)
    aref = kernel_numpy._luma_alpha_at_chroma_res_np(prm, Y.ravel(), px, py, dx, dy, d2, radius, my, 0, 1, U.shape,
                                          px[sup], py[sup], aY)
    edge = (aC > 0.05) & (aC < 0.95)
    assert edge.sum() > 100
    assert np.abs(aY - aC)[edge].max() > 0.3  # pixel by pixel: the smear
    assert np.abs(aref - aC)[edge].max() < 0.04  # at chroma's resolution: rounding only
    assert np.abs(aref - aC).max() < 0.04


def test_disabled_and_empty_windows():
    i420 = _frame()
    params = _params(i420)
    params[0, K.P.ENABLED] = 0
    params[1, K.P.DIR_U], params[1, K.P.DIR_V] = -params[1, K.P.DIR_U], -params[1, K.P.DIR_V]  # matches nothing
    for engine in ENGINES:
        out, led_out = _run(engine, i420, params, np.array([1.0, 0.0, 0.0, 3.0]))
        assert not out.any() and np.isnan(led_out[0])


@pytest.fixture(scope="module")
def small_clip(tmp_path_factory):
    path = tmp_path_factory.mktemp("k") / "c.avi"
    truth = render_clip(path, Scene.for_size(360, 288, background_seed=1), 0.03 * np.sin(np.arange(12) / 3.0),
                        codec="raw", fps=50)
    return path, truth


def test_engines_agree_on_a_clip(small_clip):
    path, truth = small_clip
    a = track_video(path, TrackerSettings(led=None, engine="numpy"))
    b = track_video(path, TrackerSettings(led=None, engine="numba"))
    assert a.valid.all() and b.valid.all()
    np.testing.assert_allclose(b.lead_xy_px, a.lead_xy_px, atol=1e-9)
    np.testing.assert_allclose(b.trail_xy_px, a.trail_xy_px, atol=1e-9)
    ref = track_video(path, TrackerSettings(led=None, engine="reference-rgb"))
    assert ref.valid.all()
    err = np.degrees(np.abs(b.angle_rad - truth["angle_rad"]))
    assert err.max() < 0.03


def test_streaming_reader_matches_planes(small_clip):
    import av

    path, _ = small_clip
    with av.open(str(path)) as c:
        planes = [f.to_ndarray() for f in c.decode(c.streams.video[0])]
    got = list(iter_yuv_frames(path, queue_size=2))
    assert len(got) == len(planes)
    for f, p in zip(got, planes):
        np.testing.assert_array_equal(f.i420, p)
    # Stopping early ends the decoder thread (bounded queue, nothing left running).
    gen = iter_yuv_frames(path, queue_size=1)
    next(gen)
    gen.close()
    import threading

    assert not any(t.name == "servoscope-decode" and t.is_alive() for t in threading.enumerate())


def test_bad_engine_names():
    from servoscope.errors import ServoscopeError
    from servoscope.markers.settings import resolve_engine

    assert resolve_engine(TrackerSettings()) == "numba"
    assert resolve_engine(TrackerSettings(centroid="projected")) == "reference-rgb"
    with pytest.raises(ServoscopeError, match="engine"):
        resolve_engine(TrackerSettings(engine="opencl"))
    with pytest.raises(ServoscopeError, match="backend"):
        resolve_engine(TrackerSettings(backend="tpu"))


def test_cpu_backend_is_a_deprecated_alias_of_auto():
    """backend="cpu" did what "auto" does: it warns and reads as "auto" (the same track and cache key)."""
    from servoscope.campaign.cache import settings_fingerprint
    from servoscope.errors import ServoscopeError
    from servoscope.markers.settings import BACKENDS, resolve_engine

    assert BACKENDS == ("auto",)
    with pytest.warns(DeprecationWarning, match='backend="auto"'):
        old = TrackerSettings(backend="cpu")
    assert old.backend == "auto" and old == TrackerSettings()
    assert resolve_engine(old) == "numba"
    assert settings_fingerprint(old) == settings_fingerprint(TrackerSettings())
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        TrackerSettings()  # "auto" itself warns nothing
        cuda = TrackerSettings(backend="cuda")  # refused when used, not when made
    with pytest.raises(ServoscopeError, match='backend: \'cuda\'.*backend="auto"'):
        resolve_engine(cuda)

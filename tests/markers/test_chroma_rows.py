"""A low-luma-contrast sticker's height from native 4:2:0 chroma rows (markers.pass_centroid.chroma_row_centroid),
against drawn truth: an area-sampled disc (the twin's blue tip sticker on its dark blade) at sub-pixel rows,
converted by the writer's own RGB → yuv420p (BT.601, 2×2 block mean)."""

import math

import numpy as np
import pytest

from servoscope.markers.pass_centroid import chroma_row_centroid
from servoscope.video.writer import rgb_to_yuv420p

W, H = 64, 48
BLADE, STICKER, SKY = (0x3A, 0x3C, 0x40), (0x1D, 0x4F, 0xD8), (0x9A, 0xA8, 0xB4)
RADIUS_PX = 7.0
CX = 31.3


def _planes(rgb):
    a = rgb_to_yuv420p(rgb)
    c = a[H:].reshape(2, H // 2, W // 2)
    return a[:H], c[0], c[1]


def _frame(cy, edge_px):
    """The disc at (CX, cy) on the blade; sky beyond the section's edges, ``edge_px`` above and below the disc."""
    yy, xx = np.mgrid[0:H, 0:W]
    sub = (np.arange(16) + 0.5) / 16 - 0.5
    cov = np.zeros((H, W))
    for dy in sub:
        for dx in sub:
            cov += (xx + dx - CX) ** 2 + (yy + dy - cy) ** 2 <= RADIUS_PX ** 2
    cov /= 256
    rgb = np.empty((H, W, 3))
    rgb[:] = BLADE
    rgb[((yy + 0.5) <= cy - RADIUS_PX - edge_px) | ((yy - 0.5) >= cy + RADIUS_PX + edge_px)] = SKY
    rgb = rgb * (1 - cov[..., None]) + np.array(STICKER, float) * cov[..., None]
    return np.clip(np.rint(rgb), 0, 255).astype(np.uint8)


@pytest.fixture(scope="module")
def sticker_yuv():
    Y, U, V = _planes(np.full((H, W, 3), STICKER, np.uint8))
    return float(Y[0, 0]), float(U[0, 0]), float(V[0, 0])


def _height(frame, cy, yuv, split=True, var=0.25):
    Y, U, V = _planes(frame)
    return chroma_row_centroid(Y, U, V, CX, cy + 0.3, RADIUS_PX, RADIUS_PX, 1.0, yuv, var, var, split)


def test_no_bias_with_the_row_across_a_whole_chroma_period(sticker_yuv):
    rows = np.linspace(22.0, 24.0, 21)  # every phase of the 2-px chroma rows
    # The section's edge 4 px beyond the sticker (the twin's tip leaves ~3-5): outside the window, read as blade.
    split = np.array([_height(_frame(cy, 4.0), cy, sticker_yuv)[0] - cy for cy in rows])
    plain = np.array([_height(_frame(cy, 4.0), cy, sticker_yuv, split=False)[0] - cy for cy in rows])
    # Luma's contrast is 17 DN; the chroma's alone, binned by 2 rows, has a ±0.012 px bias (measured), the split
    # of each chroma row from luma ≤ 0.0053 px (the luma's 1-DN steps); the upsampled kernel's is ±0.03 px.
    assert np.abs(split).max() < 0.008
    assert np.abs(plain).max() > 0.009
    assert abs(split.mean()) < 0.002


def test_the_section_edge_within_a_chroma_row_is_refused(sticker_yuv):
    # Sky 1-2 px beyond the disc reaches the window's end rows: no height (the caller keeps the kernel's).
    for edge in (1.0, 2.0):
        for cy in (22.0, 22.5, 23.0, 23.5):
            assert math.isnan(_height(_frame(cy, edge), cy, sticker_yuv)[0])
    # No chroma contrast (a grey sticker on the grey blade): none either.
    grey = _frame(23.0, 10.0)
    grey[:] = BLADE
    Y, U, V = _planes(grey)
    assert math.isnan(chroma_row_centroid(Y, U, V, CX, 23.0, RADIUS_PX, RADIUS_PX, 1.0, (70.0, 130.0, 127.0),
                                          0.25, 0.25)[0])


def test_standard_error_matches_the_scatter(sticker_yuv):
    rng = np.random.default_rng(7)
    clean = _frame(23.3, 10.0).astype(float)
    sd_dn = 2.0
    errs, sigmas = [], []
    for _ in range(150):
        noisy = np.clip(np.rint(clean + rng.normal(0.0, sd_dn, clean.shape)), 0, 255).astype(np.uint8)
        Y, U, V = _planes(noisy)
        # The noise variances as the tracker learns them: from the blade (left of the sticker, clear of the sky).
        y, s = chroma_row_centroid(Y, U, V, CX, 23.6, RADIUS_PX, RADIUS_PX, 1.0, sticker_yuv,
                                   float(np.var(U[8:16, :4].astype(float))), float(np.var(Y[16:32, :8].astype(float))))
        errs.append(y - 23.3)
        sigmas.append(s)
    errs = np.array(errs)
    assert np.isfinite(errs).all()
    assert abs(errs.mean()) < 0.01
    ratio = errs.std() / np.median(sigmas)
    assert 0.7 < ratio < 1.4

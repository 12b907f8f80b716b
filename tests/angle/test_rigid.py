"""The blade's rigid motion fitted to any number of markers, and each marker's bending (issue 18, build 1).

Oracles: scipy's weighted Kabsch (``Rotation.align_vectors``) for the rotation, the
two-marker angle (``angle_rad_from_centroids``) for the chord line, and bending put in
by hand.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from servoscope.angle import angle_rad_from_centroids, rigid_motion
from servoscope.errors import ServoscopeError


def _blade(n: int, rng, bend_px: np.ndarray | None = None):
    """Four markers (lead, trail, two between) on a blade turning and moving, image px (y down)."""
    body = np.array([[300.0, 0.0], [-300.0, 0.0], [0.0, 3.0], [-150.0, -2.0]])
    theta = 0.2 * np.sin(np.linspace(0, 6, n)) + 0.05
    shift = np.column_stack([400 + 5 * np.cos(np.linspace(0, 3, n)), 300 + 4 * np.sin(np.linspace(0, 5, n))])
    bend = np.zeros((n, 4)) if bend_px is None else bend_px
    v = body[None, :, 1] + bend
    c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
    x = shift[:, None, 0] + body[None, :, 0] * c - v * s
    y = shift[:, None, 1] - (body[None, :, 0] * s + v * c)
    return np.stack([x, y], axis=-1), theta


def test_the_fit_to_all_markers_is_scipys_weighted_kabsch():
    rng = np.random.default_rng(0)
    pts, theta = _blade(40, rng)
    sigma = np.tile([0.02, 0.03, 0.05, 0.04], (40, 1))
    noisy = pts + rng.standard_normal(pts.shape) * sigma[..., None]
    fit = rigid_motion(noisy, sigma, np.ones(40, bool))
    for i in (0, 17, 39):
        w = 1.0 / sigma[i] ** 2
        p = noisy[i] * [1, -1]  # y up
        q = fit.template_uv_px
        pc, qc = (w @ p) / w.sum(), (w @ q) / w.sum()
        rot, _ = Rotation.align_vectors(np.c_[p - pc, np.zeros(4)], np.c_[q - qc, np.zeros(4)], weights=w)
        assert fit.angle_rad[i] == pytest.approx(rot.as_euler("xyz")[2], abs=1e-12)
    assert np.max(np.abs(fit.angle_rad - theta)) < 5e-4
    # Its stated error is its scatter (1σ of the fit's rotation from the centroids' noise).
    many = [rigid_motion(pts + rng.standard_normal(pts.shape) * sigma[..., None], sigma, np.ones(40, bool)).angle_rad
            for _ in range(200)]
    assert np.std(np.array(many) - theta, axis=0).mean() == pytest.approx(np.nanmean(fit.angle_sigma_rad), rel=0.15)


def test_the_chord_fit_is_the_two_marker_angle_and_bending_is_recovered():
    rng = np.random.default_rng(1)
    n = 60
    true_bend = np.zeros((n, 4))
    true_bend[:, 2] = 1.5 * np.sin(np.linspace(0, 20, n))  # the middle marker flaps against the line
    true_bend[:, 3] = -0.7 * np.sin(np.linspace(0, 20, n))
    pts, theta = _blade(n, rng, true_bend)
    sigma = np.full((n, 4), 0.03)
    fit = rigid_motion(pts, sigma, np.ones(n, bool), fit_markers=2)
    assert np.allclose(fit.angle_rad, angle_rad_from_centroids(pts[:, 0], pts[:, 1]), atol=1e-12)
    # Bending across the line, from the marker's place at rest (the template's median).
    b = fit.bending_px - np.median(fit.bending_px, axis=0)
    ref = true_bend - np.median(true_bend, axis=0)
    assert np.allclose(b, ref, atol=1e-9)
    assert np.allclose(fit.bending_px[:, :2], 0.0, atol=1e-9)
    # Fitted to every marker instead, the flapping middle markers turn the "pitch": what the chord fit avoids.
    allfit = rigid_motion(pts, sigma, np.ones(n, bool))
    assert np.max(np.abs(allfit.angle_rad - theta)) > 5e-4 > 1e-9 > np.max(np.abs(fit.angle_rad - theta))


def test_invalid_frames_and_degenerate_markers():
    rng = np.random.default_rng(2)
    pts, _ = _blade(10, rng)
    valid = np.ones(10, bool)
    valid[3] = False
    pts[5, 2] = np.nan  # a marker lost: the frame cannot be fitted
    fit = rigid_motion(pts, np.full((10, 4), 0.03), valid)
    assert np.isnan(fit.angle_rad[[3, 5]]).all() and np.isfinite(np.delete(fit.angle_rad, [3, 5])).all()
    assert np.isnan(fit.bending_px[5]).all()
    with pytest.raises(ServoscopeError, match="one point"):
        rigid_motion(np.zeros((5, 3, 2)), np.full((5, 3), 0.1), np.ones(5, bool))
    with pytest.raises(ServoscopeError, match="no frame"):
        rigid_motion(pts, np.full((10, 4), 0.03), np.zeros(10, bool))
    assert math.isfinite(float(fit.angle_sigma_rad[0]))

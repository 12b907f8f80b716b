"""The camera's view of the blade's plane from the stickers' shapes and sizes (servoscope.angle.view).

Oracles: the view is built with OpenCV (``cv2.projectPoints`` of a pinhole camera turned off
square, which includes the perspective), the true angle gain is the slope of the angles it
produces against the plane's, by numpy's polyfit.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from servoscope.angle.view import oblique_view
from servoscope.pipeline.plane_view import view_warning


def _filmed(yaw_deg: float, tilt_deg: float, swing_deg: float, *, noise_px: float = 0.02, n: int = 4000,
            focal_px: float = 1100.0, seed: int = 0):
    """Two stickers 600 px apart on a blade pitching about a point 125 px from their midpoint, filmed by
    a pinhole camera orbiting the plane's centre (cv2.projectPoints); areas from the local Jacobian."""
    rng = np.random.default_rng(seed)
    theta = np.radians(swing_deg) * 0.5 * (1.0 + np.sin(np.linspace(0.0, 60.0, n)))
    pivot = np.array([175.0, 0.0])
    lead_uv, trail_uv = np.array([-125.0 + 300.0, 10.0]), np.array([-125.0 - 300.0, 10.0])

    def at(uv):
        c, s = np.cos(theta), np.sin(theta)
        return np.c_[pivot[0] + uv[0] * c - uv[1] * s, pivot[1] - (uv[0] * s + uv[1] * c)]

    yaw, tilt = math.radians(yaw_deg), math.radians(tilt_deg)
    r_yaw = cv2.Rodrigues(np.array([0.0, yaw, 0.0]))[0]
    r_tilt = cv2.Rodrigues(np.array([tilt, 0.0, 0.0]))[0]
    rot = r_tilt @ r_yaw
    tvec = np.array([0.0, 0.0, focal_px])
    k = np.array([[focal_px, 0.0, 640.0], [0.0, focal_px, 360.0], [0.0, 0.0, 1.0]])

    def project(xy):
        obj = np.c_[xy, np.zeros(len(xy))].astype(np.float64)
        img, _ = cv2.projectPoints(obj, cv2.Rodrigues(rot)[0], tvec, k, None)
        return img.reshape(-1, 2)

    def seen_disc(xy, radius=13.0):
        """A disc's area and second moments in the image: the local Jacobian of the view (numerical)."""
        h = 0.5
        jx = (project(xy + [h, 0.0]) - project(xy - [h, 0.0])) / (2 * h)
        jy = (project(xy + [0.0, h]) - project(xy - [0.0, h])) / (2 * h)
        # Plane points have y up, the image y down: the disc's moments are isotropic either way.
        jac = np.stack([jx, jy], axis=-1)
        moments = 0.25 * radius**2 * jac @ np.swapaxes(jac, -1, -2)
        return math.pi * radius**2 * np.abs(np.linalg.det(jac)), moments

    lead_p, trail_p = at(lead_uv), at(trail_uv)
    lead, trail = project(lead_p), project(trail_p)
    lead += rng.normal(0.0, noise_px, lead.shape)
    trail += rng.normal(0.0, noise_px, trail.shape)
    la, lm = seen_disc(lead_p)
    ta, tm = seen_disc(trail_p)
    la = la * (1.0 + rng.normal(0.0, 0.003, n))
    ta = ta * (1.0 + rng.normal(0.0, 0.003, n))
    # The moments' noise: 0.3 % of each entry's scale, independently per frame.
    lm = lm + rng.normal(0.0, 0.003 * 42.0, (n, 2, 2)) * np.array([[1.0, 0.5], [0.5, 1.0]])
    tm = tm + rng.normal(0.0, 0.003 * 42.0, (n, 2, 2)) * np.array([[1.0, 0.5], [0.5, 1.0]])
    lm = 0.5 * (lm + np.swapaxes(lm, -1, -2))
    tm = 0.5 * (tm + np.swapaxes(tm, -1, -2))
    seen = np.unwrap(np.arctan2(trail[:, 1] - lead[:, 1], lead[:, 0] - trail[:, 0]))
    # The gain where the blade spends its time: the slope at its median angle (perspective bends the relation).
    true_gain = np.polyfit(theta - np.median(theta), seen, 2)[1]
    view_deg = math.degrees(math.acos(math.cos(yaw) * math.cos(tilt)))
    return lead, trail, lm, tm, la, ta, true_gain, view_deg


@pytest.mark.parametrize("yaw, tilt", [(10.0, 0.0), (0.0, 20.0), (22.0, 9.0), (20.0, 22.0), (-30.0, 5.0)])
def test_view_angle_and_gain_under_perspective(yaw, tilt):
    lead, trail, lm, tm, la, ta, true_gain, view_deg = _filmed(yaw, tilt, 8.0)
    view = oblique_view(lead, trail, lm, tm, la, ta, np.ones(len(lead), bool), centre_px=(640.0, 360.0))
    assert view.determined
    assert abs(view.view_angle_deg - view_deg) < 1.0
    lo, hi = view.view_angle_ci95_deg
    assert lo <= view.view_angle_deg <= hi
    # The gain, perspective included (10° of yaw: −1.3 % where foreshortening alone says +1.5 %).
    assert view.angle_gain == pytest.approx(true_gain, rel=1e-3)
    lo, hi = view.angle_gain_ci95
    assert lo <= true_gain <= hi
    said = view_warning(view, plane=None)
    assert said is not None and "lens" not in said
    # Tracked without a lens model: the lens's distortion can look like a view, and the warning says so.
    assert "no lens calibration given" in view_warning(view, plane=None, lens=False)


def test_square_on_camera_is_not_warned_and_its_interval_holds_zero():
    lead, trail, lm, tm, la, ta, true_gain, _ = _filmed(0.0, 0.0, 8.0)
    view = oblique_view(lead, trail, lm, tm, la, ta, np.ones(len(lead), bool), centre_px=(640.0, 360.0))
    assert true_gain == pytest.approx(1.0, abs=1e-4)  # the centroids' noise only
    assert view.view_angle_deg < 1.0
    assert view.view_angle_ci95_deg[0] == 0.0
    assert view.angle_gain_ci95[0] <= 1.0 <= view.angle_gain_ci95[1]
    assert view_warning(view, plane=None) is None


def test_the_correction_gives_the_planes_angles():
    lead, trail, lm, tm, la, ta, _, _ = _filmed(22.0, 9.0, 8.0, noise_px=0.0)
    view = oblique_view(lead, trail, lm, tm, la, ta, np.ones(len(lead), bool))
    h = view.correction
    pts = cv2.perspectiveTransform(np.stack([lead, trail], axis=1).reshape(-1, 1, 2), h).reshape(-1, 2, 2)
    corrected = np.unwrap(np.arctan2(pts[:, 1, 1] - pts[:, 0, 1], pts[:, 0, 0] - pts[:, 1, 0]))
    seen = np.unwrap(np.arctan2(trail[:, 1] - lead[:, 1], lead[:, 0] - trail[:, 0]))
    assert np.polyfit(seen - np.median(seen), corrected, 2)[1] == pytest.approx(1.0 / view.angle_gain, rel=1e-3)
    # The blade's midpoint stays put, and so does the picture's scale there.
    mid = np.median(0.5 * (lead + trail), axis=0)
    assert np.allclose(cv2.perspectiveTransform(mid.reshape(1, 1, 2), h).ravel(), mid, atol=0.5)


def test_strip_stickers_do_not_tell_the_view():
    # A sticker 4× longer than wide along the chord: its own anisotropy turns with the blade.
    lead, trail, lm, tm, la, ta, _, _ = _filmed(0.0, 0.0, 8.0)
    theta = np.unwrap(np.arctan2(trail[:, 1] - lead[:, 1], lead[:, 0] - trail[:, 0]))
    c, s = np.cos(theta), -np.sin(theta)
    rot = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)
    strip = rot @ np.diag([16.0, 1.0]) @ np.swapaxes(rot, -1, -2) * (42.0 / 8.5)
    view = oblique_view(lead, trail, strip, strip, la, ta, np.ones(len(lead), bool))
    assert not view.determined
    assert "round or square" in view.why


def test_same_footage_same_answer_and_too_few_sharp_frames():
    lead, trail, lm, tm, la, ta, _, _ = _filmed(15.0, 5.0, 6.0)
    valid = np.ones(len(lead), bool)
    a = oblique_view(lead, trail, lm, tm, la, ta, valid).summary()
    b = oblique_view(lead, trail, lm, tm, la, ta, valid).summary()
    assert a == b
    few = np.zeros(len(lead), bool)
    few[:10] = True
    assert oblique_view(lead, trail, lm, tm, la, ta, few) is None

"""Exact-coverage rasterizer, scene geometry and frame rendering."""

from __future__ import annotations

import numpy as np
import pytest

from servoscope.camera.model import CameraModel
from servoscope.errors import ServoscopeError
from servoscope.simulate import FrameRenderer, Scene, led_exposure_fraction, marker_angle_rad, polygon_coverage
from servoscope.simulate.scene import colour_rgb


def regular_polygon(centre, radius, k=256, phase=0.0):
    a = phase + 2 * np.pi * np.arange(k) / k
    return np.asarray(centre) + radius * np.stack([np.cos(a), np.sin(a)], axis=1)


def shoelace(xy):
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def polygon_centroid(xy):
    x, y = xy[:, 0], xy[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    a = cross.sum() / 2
    return np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (6 * a)


def weighted_centroid(cov, x0, y0):
    ys, xs = np.mgrid[y0:y0 + cov.shape[0], x0:x0 + cov.shape[1]]
    m = cov.sum()
    return np.array([(cov * xs).sum() / m, (cov * ys).sum() / m])


def clip_area_oracle(poly, x, y):
    """Area of ``poly`` inside the pixel square of (x, y): Sutherland–Hodgman, then shoelace.

    Valid for any simple subject polygon because the clip window is convex.
    """
    pts = [tuple(p) for p in poly]
    for axis, bound, keep_below in ((0, x - 0.5, False), (0, x + 0.5, True), (1, y - 0.5, False), (1, y + 0.5, True)):
        inside = (lambda p: p[axis] <= bound) if keep_below else (lambda p: p[axis] >= bound)
        out = []
        for i, cur in enumerate(pts):
            prev = pts[i - 1]
            if inside(cur):
                if not inside(prev):
                    out.append(_cross(prev, cur, axis, bound))
                out.append(cur)
            elif inside(prev):
                out.append(_cross(prev, cur, axis, bound))
        pts = out
        if not pts:
            return 0.0
    return shoelace(np.array(pts)) if len(pts) >= 3 else 0.0


def _cross(p, q, axis, bound):
    t = (bound - p[axis]) / (q[axis] - p[axis])
    return (p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1]))


def test_disk_coverage_area_and_centroid_at_random_subpixel_positions():
    rng = np.random.default_rng(11)
    for _ in range(40):
        centre = rng.uniform(50, 51, 2)
        poly = regular_polygon(centre, 13.0, 256, phase=rng.uniform(0, 1))
        cov, x0, y0 = polygon_coverage(poly)
        area = shoelace(poly)
        assert abs(cov.sum() - area) < 1e-9 * area
        assert np.hypot(*(weighted_centroid(cov, x0, y0) - centre)) < 2e-3
        assert cov.min() >= 0.0 and cov.max() <= 1.0


def test_signed_area_is_opencvs_oriented_contour_area():
    import cv2

    from servoscope.simulate.coverage import signed_area

    rng = np.random.default_rng(11)
    for n in (3, 4, 7, 40):
        for _ in range(20):
            xy = rng.uniform(-50, 50, size=(n, 2))
            oracle = cv2.contourArea(xy.astype(np.float32), oriented=True)
            assert signed_area(xy) == pytest.approx(oracle, rel=1e-5, abs=1e-3)
            assert signed_area(xy[::-1]) == pytest.approx(-signed_area(xy), rel=1e-12, abs=1e-12)


def test_rotated_rectangle_coverage_area_and_centroid():
    rng = np.random.default_rng(12)
    w, h = 60.3, 25.7
    for _ in range(40):
        centre = rng.uniform(80, 81, 2)
        # generic angles: an edge almost parallel to the pixel grid aliases the
        # box-filtered centroid by up to 1/(8 * size) px, which is not a bug
        th = rng.uniform(0.2, np.pi / 2 - 0.2) + rng.integers(0, 4) * np.pi / 2
        rot = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
        poly = centre + np.array([[-w / 2, -h / 2], [w / 2, -h / 2], [w / 2, h / 2], [-w / 2, h / 2]]) @ rot.T
        cov, x0, y0 = polygon_coverage(poly[::-1] if rng.uniform() < 0.5 else poly)  # either orientation
        assert abs(cov.sum() - w * h) < 1e-9 * w * h
        assert np.hypot(*(weighted_centroid(cov, x0, y0) - centre)) < 2e-3


def test_coverage_equals_per_pixel_clipping_oracle_for_a_nonconvex_polygon():
    rng = np.random.default_rng(13)
    k = 11
    a = 2 * np.pi * np.arange(2 * k) / (2 * k)
    r = np.where(np.arange(2 * k) % 2 == 0, 9.0, 3.5) * rng.uniform(0.8, 1.2, 2 * k)
    star = np.array([20.37, 17.81]) + np.stack([r * np.cos(a), r * np.sin(a)], axis=1)
    cov, x0, y0 = polygon_coverage(star)
    worst = 0.0
    for j in range(cov.shape[0]):
        for i in range(cov.shape[1]):
            worst = max(worst, abs(cov[j, i] - clip_area_oracle(star, x0 + i, y0 + j)))
    assert worst < 1e-12


def test_coverage_clipped_to_the_image_keeps_exact_values():
    star = regular_polygon((1.3, 5.2), 4.0, 9)  # hangs over the left and top edges
    cov, x0, y0 = polygon_coverage(star, image_size=(12, 12))
    assert (x0, y0) == (0, 1)
    for j in range(cov.shape[0]):
        for i in range(cov.shape[1]):
            assert cov[j, i] == pytest.approx(clip_area_oracle(star, x0 + i, y0 + j), abs=1e-12)


def test_pitch_rotates_counter_clockwise_and_angle_is_pitch_plus_offset():
    scene = Scene()
    pitch = np.linspace(-0.2, 0.2, 9)
    lead, trail = scene.sticker_centres_px(pitch)
    assert np.max(np.abs(marker_angle_rad(lead, trail) - (pitch + scene.sticker_offset_rad))) < 1e-12
    assert np.hypot(*(lead - trail).T) == pytest.approx(np.full(9, 600.0))
    # positive pitch lifts the leading (right) sticker: y decreases in the image
    assert lead[0, 0] > trail[0, 0] and np.all(np.diff(lead[:, 1]) < 0)
    # the pivot does not move
    piv = scene.to_image(np.zeros(2), pitch)
    assert np.allclose(piv, scene.pivot_xy_px)


def test_scene_scales_with_image_size_and_rejects_bad_colours():
    half = Scene.for_size(360, 288)
    assert half.sticker_separation_px == pytest.approx(300.0) and half.chord_px == pytest.approx(350.0)
    lead, trail = half.sticker_centres_px(0.0)
    ref_lead, _ = Scene().sticker_centres_px(0.0)
    assert np.allclose(lead - (180, 144), 0.5 * (ref_lead - (360, 288)))
    assert np.allclose(colour_rgb("red"), (255, 0, 0))
    with pytest.raises(ServoscopeError):
        Scene(lead_colour="#12345")
    with pytest.raises(ServoscopeError):
        Scene.for_size(360, 288, sticker_size=3)


def test_background_is_not_uniform_and_far_from_marker_colours():
    scene = Scene()
    bg = scene.background().reshape(-1, 3).astype(float)
    assert bg.std(axis=0).min() > 3.0
    for c in (scene.lead_colour, scene.trail_colour, scene.led_colour):
        assert np.min(np.linalg.norm(bg - colour_rgb(c), axis=1)) > 100.0
    assert np.array_equal(Scene(background_seed=1).background(), Scene(background_seed=1).background())
    assert not np.array_equal(Scene(background_seed=1).background(), Scene(background_seed=2).background())


def _flat_scene(**kw):
    # black everything except a pure-red lead sticker: the red channel is its coverage
    return Scene(blade_colour="black", trail_colour="black", led_colour="black", led_off_colour="black",
                 background_top="black", background_bottom="black", blotch_amplitude_dn=0.0,
                 lead_colour="#ff0000", **kw)


@pytest.mark.parametrize("pitch", [-0.11, 0.0234, 0.13])
def test_rendered_sticker_centroid_maps_back_to_the_true_centre_through_the_lens(pitch):
    scene = _flat_scene()
    k = np.array([[1100.0, 0, 362.7], [0, 1100.0, 285.4], [0, 0, 1]])
    cam = CameraModel((720, 576), k, [-0.08, 0.02, 4e-4, -3e-4, 0.0])
    renderer = FrameRenderer(scene, cam, noise_sigma_dn=0.0)
    img = renderer.composite(pitch, 1.0)
    red = img[:, :, 0].astype(np.float64) / 255.0
    lead, _ = scene.sticker_centres_px(pitch)
    x0, y0 = int(lead[0]) - 30, int(lead[1]) - 30
    cov = red[y0:y0 + 60, x0:x0 + 60]
    c = weighted_centroid(cov, x0, y0)
    assert cov.sum() == pytest.approx(np.pi * 13**2, rel=0.05)  # barrel distortion shrinks it ~2 %
    # the image holds the lens-distorted sticker outline, area-exactly
    outline = renderer.outlines_px(pitch)[1]
    assert np.allclose(outline, cam.distort_points(scene.to_image(renderer._parts_uv[1], pitch)))
    assert np.hypot(*(c - polygon_centroid(outline))) < 2e-3
    # undistorting the centroid recovers the true centre up to the lens's
    # curvature across the disk (a second-order effect of ~0.01 px)
    recovered, ok = cam.undistort_points(c[None, :])
    assert ok.all()
    assert np.hypot(*(recovered[0] - lead)) < 0.03
    # and the lens matters here: the distorted centroid is far from the ideal centre
    assert np.hypot(*(c - lead)) > 1.0


def test_led_level_blends_colours_and_exposure_fraction():
    scene = Scene()
    r = FrameRenderer(scene, noise_sigma_dn=0.0)
    cx, cy = np.round(scene.led_centre_px(0.0)).astype(int)
    on = colour_rgb(scene.led_colour)
    off = colour_rgb(scene.led_off_colour)
    for level in (0.0, 0.3, 1.0):
        px = r.composite(0.0, level)[cy, cx].astype(float)
        assert np.allclose(px, off + level * (on - off), atol=1e-3)
    e, t0 = 0.004, 0.5037
    t = np.array([0.49, t0 - e / 2, t0, t0 + e / 4, t0 + e / 2, 0.6])
    assert np.allclose(led_exposure_fraction(t, t0, e), [1.0, 1.0, 0.5, 0.25, 0.0, 0.0])


def test_noise_is_seeded_per_frame_with_the_requested_sigma():
    scene = Scene.for_size(360, 288)
    a = FrameRenderer(scene, noise_sigma_dn=1.5, noise_seed=4)
    b = FrameRenderer(scene, noise_sigma_dn=1.5, noise_seed=4)
    f0 = a.render(0.01, 1.0, 0)
    f1 = a.render(0.01, 1.0, 1)
    assert np.array_equal(f0, b.render(0.01, 1.0, 0))
    assert not np.array_equal(f0, f1)
    clean = a.composite(0.01, 1.0).astype(float)
    noise = f0 - clean
    assert noise.std() == pytest.approx(np.sqrt(1.5**2 + 1 / 12), rel=0.03)  # + rounding
    assert abs(noise.mean()) < 0.02
    assert abs(np.corrcoef(noise.ravel(), (f1 - clean).ravel())[0, 1]) < 0.01
    # the renderer redraws only what moved: a frame after a different pose is still right
    a.render(-0.1, 0.0, 7)
    assert np.array_equal(a.render(0.01, 1.0, 0), f0)


@pytest.mark.parametrize("bits", [8, 12, 16])
def test_monochrome_frame_is_luma_at_the_depth_with_its_noise(bits):
    """The twin's monochrome samples against OpenCV's BT.601 luma (an independent oracle): scaled to the depth
    and the light level, the noise σ scaled with them, seeded per frame, clipped to the depth's range."""
    import cv2

    from servoscope.simulate.render_parts import gray_frame

    scene = Scene.for_size(360, 288)
    clean = FrameRenderer(scene, noise_sigma_dn=0.0).composite(0.01, 1.0)
    top = 2**bits - 1
    frame = gray_frame(clean, bits, 0.7, 1.5, (4, 0x6A7, 0))
    assert frame.dtype == (np.uint8 if bits == 8 else np.uint16) and frame.shape == clean.shape[:2]
    luma = cv2.cvtColor(clean, cv2.COLOR_RGB2GRAY).astype(float) * (0.7 * top / 255)
    noise = (frame - luma) / (top / 255)  # in 8-bit DN
    rounding = 1 / 12 / (top / 255) ** 2
    assert noise.std() == pytest.approx(np.sqrt(1.5**2 + rounding), rel=0.03)
    assert abs(noise.mean()) < 0.02
    assert np.array_equal(frame, gray_frame(clean, bits, 0.7, 1.5, (4, 0x6A7, 0)))
    other = gray_frame(clean, bits, 0.7, 1.5, (4, 0x6A7, 1))
    assert abs(np.corrcoef(noise.ravel(), (other - luma).ravel())[0, 1]) < 0.01
    # An over-exposed picture clips at the depth's top, a black one at 0 (noise both ways).
    assert gray_frame(np.full((8, 8, 3), 300.0, np.float32), bits, 1.0, 1.5, (1,)).max() == top
    dark = gray_frame(np.zeros((64, 64, 3), np.float32), bits, 1.0, 1.5, (1,))
    from scipy.stats import norm

    # A sample reads 0 when its noise is below half a step: Φ(0.5 / σ at the depth).
    assert (dark == 0).mean() == pytest.approx(norm.cdf(0.5 / (1.5 * top / 255)), abs=0.03)


def test_renderer_rejects_mismatched_camera():
    with pytest.raises(ServoscopeError):
        FrameRenderer(Scene(), CameraModel.ideal(640, 480))

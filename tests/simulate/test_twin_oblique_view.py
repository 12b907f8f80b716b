"""Oblique views of the blade's plane: the homography, the renders through it, the board photo."""

from __future__ import annotations

import json
import math

from dataclasses import replace

import cv2
import numpy as np
import pytest

from servoscope.errors import ServoscopeError
from servoscope.simulate import FrameRenderer, Scene, simulate_campaign
from servoscope.simulate.board import PLANE_MM_PER_PX, board_corners_plane_px, render_board_photo
from servoscope.simulate.campaign import reference_stickers
from servoscope.simulate.presets import CampaignPreset, get_preset
from servoscope.simulate.render import airframe_motion
from servoscope.simulate.scene import colour_rgb
from servoscope.simulate.view import ObliqueView
from servoscope.video.reader import iter_frames

W, H = 320, 256
POSES = [(22.0, 9.0), (30.0, 0.0), (0.0, 30.0), (-35.0, 20.0), (5.0, -60.0)]


def _preset(**kw) -> CampaignPreset:
    return replace(get_preset("quick"), width=W, height=H, **kw)


def _camera():
    return _preset().camera()


def _focal() -> float:
    return float(_camera().camera_matrix[0, 0])


def _look_at_pose(yaw_deg, tilt_deg, f):
    """World→camera (R, t) of a camera at the spherical position the docs give, built by cross products."""
    a, b = math.radians(yaw_deg), math.radians(tilt_deg)
    centre = f * np.array([math.sin(a) * math.cos(b), -math.sin(b), -math.cos(a) * math.cos(b)])
    z = -centre / np.linalg.norm(centre)  # looks at the origin, the look-at point
    x = np.cross([0.0, 1.0, 0.0], z)  # level rows: x is horizontal (y is the plane's vertical)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    r = np.stack([x, y, z])  # rows: the camera's axes in world coordinates
    return r, -r @ centre, centre


def _plane_grid(n=7):
    xs, ys = np.meshgrid(np.linspace(-40, W + 40, n), np.linspace(-30, H + 30, n))
    return np.stack([xs.ravel(), ys.ravel()], axis=1)


@pytest.mark.parametrize("yaw,tilt", POSES)
def test_homography_is_the_pinhole_camera_opencv_projects(yaw, tilt):
    f = _focal()
    view = ObliqueView(yaw, tilt, f, W, H)
    r, t, _ = _look_at_pose(yaw, tilt, f)
    cx, cy = (W - 1) / 2, (H - 1) / 2
    k = np.array([[f, 0, cx], [0, f, cy], [0, 0, 1.0]])
    plane = _plane_grid()
    world = np.column_stack([plane - [cx, cy], np.zeros(len(plane))])
    rvec, _ = cv2.Rodrigues(r)
    projected = cv2.projectPoints(world, rvec, t, k, None)[0].reshape(-1, 2)
    assert np.abs(view.apply(plane) - projected).max() < 1e-9
    # OpenCV's homography from the projected points: its solver stops at ~1e-6 in the matrix
    # (1e-5 px in the map; the pose above pins ours to 1e-9), so the two are compared as maps.
    h, _ = cv2.findHomography(plane, projected, 0)
    assert np.abs(cv2.perspectiveTransform(plane[None], h)[0] - view.apply(plane)).max() < 1e-4
    assert view.homography[2, 2] == 1.0 and not view.homography.flags.writeable
    # The look-at point stays at the picture's centre; inverse undoes apply, whatever the leading shape.
    assert np.allclose(view.apply([cx, cy]), [cx, cy], atol=1e-9)
    grid = plane.reshape(7, 7, 2)
    assert view.apply(grid).shape == (7, 7, 2)
    assert np.abs(view.inverse(view.apply(grid)) - grid).max() < 1e-9


def test_signs_the_nearer_side_is_drawn_larger():
    f = _focal()
    cx, cy = (W - 1) / 2, (H - 1) / 2

    def length(view, a, b):
        return float(np.hypot(*(view.apply(np.array(b)) - view.apply(np.array(a)))))

    right = ObliqueView(25.0, 0.0, f, W, H)  # the camera moves to the blade's right
    assert right.camera_centre[0] > 0
    assert length(right, [W - 40, cy], [W - 30, cy]) > 1.05 * length(right, [30, cy], [40, cy])
    up = ObliqueView(0.0, 25.0, f, W, H)  # the camera moves up and looks down
    assert up.camera_centre[1] < 0
    assert length(up, [cx, 20], [cx, 30]) > 1.05 * length(up, [cx, H - 30], [cx, H - 20])


@pytest.mark.parametrize("yaw,tilt", POSES)
def test_view_angle_is_between_the_normal_and_the_line_of_sight(yaw, tilt):
    f = _focal()
    view = ObliqueView(yaw, tilt, f, W, H)
    _, _, centre = _look_at_pose(yaw, tilt, f)
    assert np.allclose(view.camera_centre, centre, atol=1e-9)
    sight = -centre / np.linalg.norm(centre)
    assert view.view_angle_deg == pytest.approx(math.degrees(math.acos(sight[2])), abs=1e-9)
    assert view.view_angle_deg == pytest.approx(math.degrees(math.acos(math.cos(math.radians(yaw))
                                                                       * math.cos(math.radians(tilt)))), abs=1e-12)
    d = view.to_dict()
    assert (d["yaw_deg"], d["tilt_deg"], d["focal_px"]) == (yaw, tilt, f)
    assert np.array_equal(d["homography_plane_to_image"], view.homography)
    json.dumps(d, allow_nan=False)


def test_square_on_is_the_identity_and_renders_the_same_bytes():
    f = _focal()
    square = ObliqueView(0.0, 0.0, f, W, H)
    assert square.is_square_on and square.view_angle_deg == 0.0
    assert np.array_equal(square.homography, np.eye(3))
    scene = Scene.for_size(W, H, background_seed=4)
    scene = replace(scene, clutter=reference_stickers(scene))
    plain = FrameRenderer(scene, _camera(), noise_sigma_dn=1.5, noise_seed=9)
    viewed = FrameRenderer(scene, _camera(), noise_sigma_dn=1.5, noise_seed=9, view=square)
    assert viewed.view is None
    rows = np.linspace(-0.05, 0.05, H)
    assert plain.render(0.03, 0.5, 2).tobytes() == viewed.render(0.03, 0.5, 2).tobytes()
    # Flicker, shake, roll and the airframe's rocking: the lit path, clutter and all.
    assert (plain.render(0.03, 1.0, 3, 0.9, (0.4, -0.2), 0.01, 0.02).tobytes()
            == viewed.render(0.03, 1.0, 3, 0.9, (0.4, -0.2), 0.01, 0.02).tobytes())
    assert plain.render_rolling(rows, np.ones(H), 4).tobytes() == viewed.render_rolling(rows, np.ones(H), 4).tobytes()


def _sticker_alpha(scene, view, camera, pitch, **composite_kw):
    """Each sticker's exact coverage, from two noise-free renders differing only in the stickers' colours."""
    dark = replace(scene, lead_colour="#000000", trail_colour="#000000")
    a = FrameRenderer(scene, camera, noise_sigma_dn=0.0, view=view).composite(pitch, 1.0, **composite_kw)
    b = FrameRenderer(dark, camera, noise_sigma_dn=0.0, view=view).composite(pitch, 1.0, **composite_kw)
    diff = a.astype(np.float64) - b
    lead, trail = colour_rgb(scene.lead_colour), colour_rgb(scene.trail_colour)
    return diff[..., 0] / lead[0], diff[..., 1] / trail[1]  # red lead, green trail


def _moments_centroid(alpha, near_xy, half=20):
    x0, y0 = int(near_xy[0]) - half, int(near_xy[1]) - half
    window = np.zeros_like(alpha)
    window[y0:y0 + 2 * half, x0:x0 + 2 * half] = alpha[y0:y0 + 2 * half, x0:x0 + 2 * half]
    m = cv2.moments(window)
    return np.array([m["m10"] / m["m00"], m["m01"] / m["m00"]])


def _area_centroid(xy):
    x, y = xy[:, 0], xy[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    return np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (3 * cross.sum())


@pytest.mark.parametrize("yaw,tilt", [(30.0, 0.0), (22.0, 9.0), (-25.0, 15.0)])
def test_oblique_stickers_are_where_the_view_and_lens_put_them(yaw, tilt):
    scene, camera, pitch = Scene.for_size(W, H), _camera(), 0.06
    view = ObliqueView(yaw, tilt, _focal(), W, H)
    alphas = _sticker_alpha(scene, view, camera, pitch)
    for alpha, centre_uv in zip(alphas, scene.sticker_centres_uv()):
        centre = camera.distort_points(view.apply(scene.to_image(centre_uv, pitch))[None])[0]
        measured = _moments_centroid(alpha, centre)
        # Perspective moves a disc's area centroid off the image of its centre, toward the nearer
        # side: by at most 0.047 px for these 11.6 px stickers at 30° (0.10 px for the default
        # 26 px stickers at 720×576, 0.15 px at 45–60°).
        assert np.hypot(*(measured - centre)) < 0.1
        # The render itself is exact: the moments are those of the mapped outline (pixel-centre
        # moments of an exact coverage differ from the area centroid by a few 1e-3 px).
        outline = camera.distort_points(view.apply(scene.to_image(centre_uv + scene.sticker_outline_uv(), pitch)))
        assert np.hypot(*(measured - _area_centroid(outline))) < 0.01
        square_on = camera.distort_points(scene.to_image(centre_uv, pitch)[None])[0]
        assert np.hypot(*(measured - square_on)) > 1.0  # the view moved it, ten times the tolerance


def test_rolling_path_and_airframe_clutter_go_through_the_view():
    scene, camera = Scene.for_size(W, H), _camera()
    view = ObliqueView(25.0, 10.0, _focal(), W, H)
    r = FrameRenderer(scene, camera, noise_sigma_dn=0.0, view=view)
    steady = r.composite(0.04, 1.0).copy()
    rolled = r.composite_rolling(np.full(H, 0.04), np.ones(H))
    assert np.abs(rolled - steady).max() < 1e-3  # one pose on every row: the global-shutter frame
    # A reference sticker on the rocking airframe: back through the lens to the plane, rocked there,
    # then the view and the lens.
    refs = reference_stickers(scene)
    grey = replace(scene, clutter=tuple(replace(c, colour="#000000") for c in refs))
    lit = [FrameRenderer(s, camera, noise_sigma_dn=0.0, view=view).composite(0.0, 1.0, rock_rad=0.02).copy()
           for s in (replace(scene, clutter=refs), grey)]
    colour = colour_rgb(refs[0].colour)
    channel = int(np.argmax(colour))
    alpha = (lit[0][..., channel].astype(np.float64) - lit[1][..., channel]) / colour[channel]
    plane = camera.undistort_points(np.array([refs[0].centre_px]))[0]
    rock = airframe_motion(scene, 0.02)
    centre = camera.distort_points(view.apply(plane @ rock[:, :2].T + rock[:, 2]))[0]
    assert np.hypot(*(_moments_centroid(alpha, centre, half=14) - centre)) < 0.1


@pytest.fixture(scope="module")
def board_photo():
    scene, camera = Scene.for_size(W, H, background_seed=2), _camera()
    view = ObliqueView(22.0, 9.0, _focal(), W, H)
    image, board = render_board_photo(scene, view, camera, noise_sigma_dn=1.5, seed=11)
    return image, board, view, camera


def test_board_photo_corners_are_the_views_projection_of_its_truth(board_photo):
    image, board, view, camera = board_photo
    assert image.dtype == np.uint8 and image.shape == (H, W, 3)
    assert board["inner_corners"] == [9, 6] and board["squares"] == [10, 7]
    assert board["square_mm"] == pytest.approx(board["square_px"] * PLANE_MM_PER_PX)
    gray = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    found, corners = cv2.findChessboardCorners(gray, (9, 6))
    assert found
    corners = cv2.cornerSubPix(gray, corners, (5, 5), (-1, -1),
                               (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)).reshape(-1, 2)
    plane = board_corners_plane_px(board)
    truth = camera.distort_points(view.apply(plane))
    # OpenCV may start from either end of the 9×6 board.
    if np.abs(corners[::-1] - truth).max() < np.abs(corners - truth).max():
        corners = corners[::-1]
    assert np.abs(corners - truth).max() < 0.1
    # With the lens undone, the corners give back the view's homography (to the corners' noise).
    ideal = camera.undistort_points(corners)[0]
    h, _ = cv2.findHomography(plane, ideal, 0)
    assert np.abs(cv2.perspectiveTransform(plane[None], h)[0] - view.apply(plane)).max() < 0.1
    # The sheet fills a good part of the picture and stays inside it, with its white margin.
    span = truth.max(axis=0) - truth.min(axis=0)
    assert span[0] > 0.4 * W and span[1] > 0.3 * H
    assert gray[int(truth[:, 1].mean()), 4] < 200  # background left of the sheet


def test_board_photo_is_deterministic_and_refuses_what_does_not_fit(board_photo):
    image, board, view, camera = board_photo
    again, board2 = render_board_photo(Scene.for_size(W, H, background_seed=2), view, camera, noise_sigma_dn=1.5,
                                       seed=11)
    assert again.tobytes() == image.tobytes() and board2 == board
    other, _ = render_board_photo(Scene.for_size(W, H, background_seed=2), view, camera, noise_sigma_dn=1.5, seed=12)
    assert other.tobytes() != image.tobytes()
    with pytest.raises(ServoscopeError, match="does not fit"):
        render_board_photo(Scene.for_size(W, H), view, camera, square_px=4 * board["square_px"])
    with pytest.raises(ServoscopeError, match="inner corners"):
        render_board_photo(Scene.for_size(W, H), view, camera, inner=(1, 6))


@pytest.mark.parametrize("args", [(80.0, 0.0, 500.0), (0.0, -85.0, 500.0), (math.nan, 0.0, 500.0),
                                  (10.0, 0.0, 0.0), (10.0, 0.0, -3.0), (10.0, 0.0, math.inf),
                                  (70.0, 0.0, 100.0)])  # the last: the plane's horizon in the picture
def test_bad_views_are_refused(args):
    with pytest.raises(ServoscopeError, match="^view: ") as err:
        ObliqueView(*args, W, H)
    assert "\n" not in str(err.value)


def test_bad_campaign_views_are_refused_before_writing(tmp_path):
    with pytest.raises(ServoscopeError, match="view"):
        _preset(view_yaw_deg=90.0)
    with pytest.raises(ServoscopeError, match="view"):
        simulate_campaign(tmp_path, "quick", view_tilt_deg=-80.0, width=W, height=H)
    assert not any(tmp_path.iterdir())


def test_campaign_through_a_view_says_it_and_photographs_the_board(tmp_path):
    small = dict(width=240, height=192, codec="raw", frequencies_hz=(3.0, 5.0), min_dwell_s=0.2, settle_s=0.1,
                 pre_roll_s=0.1, include_step=False, noise_sigma_dn=0.0)
    simulate_campaign(tmp_path / "square", "quick", seed=1, **small)
    assert not (tmp_path / "square" / "board.png").exists()
    truth = json.loads((tmp_path / "square" / "truth.json").read_text())
    assert "view" not in truth and "board" not in truth and "view_yaw_deg" not in truth["video"]

    simulate_campaign(tmp_path / "oblique", "quick", seed=1, view_yaw_deg=22, view_tilt_deg=9, **small)
    truth = json.loads((tmp_path / "oblique" / "truth.json").read_text())
    preset = replace(get_preset("quick"), **small, view_yaw_deg=22, view_tilt_deg=9)
    view = preset.view()
    assert view.focal_px == preset.camera().camera_matrix[0, 0]
    assert {k: truth["view"][k] for k in view.to_dict()} == view.to_dict()
    assert truth["view"]["plane_mm_per_px"] == PLANE_MM_PER_PX
    assert truth["board"]["file"] == "board.png"
    photo = cv2.imread(str(tmp_path / "oblique" / "board.png"))
    assert photo.shape == (192, 240, 3)
    # Truth stays in the plane; the footage is seen through the view: the lead sticker's red blob
    # sits where the view and the lens put truth's centre.
    test = truth["tests"][0]
    lead = np.array(test["lead_xy_px"][0])
    camera = preset.camera()
    expected = camera.distort_points(view.apply(lead)[None])[0]
    rgb = next(iter(iter_frames(tmp_path / "oblique" / test["video"]))).rgb.astype(np.float64)
    red = np.clip((rgb[..., 0] - rgb[..., 1]) / 150.0, 0.0, 1.0)
    assert np.hypot(*(_moments_centroid(red, expected, half=12) - expected)) < 0.5
    assert np.hypot(*(lead - expected)) > 3.0

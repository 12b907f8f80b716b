"""The blade's plane from a chessboard held against it, against independent oracles.

Oracles: OpenCV's own :func:`cv2.findHomography` on the same corners of OpenCV's real
sample photos; boards projected with :func:`cv2.projectPoints` from a known pose
(the true view angle, the true in-plane angles and positions, the true placements of a
board moved about in the plane); repeated noisy fits (the bootstrap's uncertainty);
finite differences (the analytic Jacobian).
"""

from __future__ import annotations

import json
import math
from fractions import Fraction
from pathlib import Path

import av
import cv2
import numpy as np
import pytest

from servoscope.camera import CameraModel, Plane, calibrate_plane, fit_plane
from servoscope.camera.calibrate import detect_corners
from servoscope.camera.plane import refine_plane_corners
from servoscope.errors import ServoscopeError

from support import CHESSBOARD
from support import cli as _run  # (exit status, stdout, stderr)

PHOTOS = sorted(CHESSBOARD.glob("left*.jpg"))
needs_photos = pytest.mark.skipif(
    len(PHOTOS) != 13, reason=f"OpenCV sample chessboard photos (left01..left14.jpg) not found in {CHESSBOARD}"
)
BOARD = (9, 6)
SQUARE = 20.0
BOARD_MM = SQUARE * np.mgrid[0:9, 0:6].T.reshape(-1, 2).astype(float)
W, H = 1280, 960
DIST = np.array([-0.25, 0.08, 0.001, -0.0005, -0.01])
#: What servoscope.calibrate finds for OpenCV's sample photos (used where a camera.json is needed fast).
SAMPLE_K = np.array([[533.085, 0.0, 342.288], [0.0, 533.163, 234.010], [0.0, 0.0, 1.0]])
SAMPLE_D = np.array([-0.28521, 0.062441, 0.0010730, -0.00011269, 0.082276])


# -- synthetic boards -----------------------------------------------------------------


def _k(calibrated: bool) -> np.ndarray:
    # With a calibration the principal point is off the image centre: the plane must use the calibration's.
    cx, cy = (652.0, 471.0) if calibrated else ((W - 1) / 2, (H - 1) / 2)
    return np.array([[1100.0, 0.0, cx], [0.0, 1100.0, cy], [0.0, 0.0, 1.0]])


def _pose(tilt_deg: float, dist_mm: float = 500.0) -> tuple[np.ndarray, np.ndarray]:
    """The plane's pose: tilted about an oblique axis, spun in itself, the board's centre a little off-axis."""
    axis = math.radians(30.0)
    r = cv2.Rodrigues(math.radians(tilt_deg) * np.array([math.cos(axis), math.sin(axis), 0.0]))[0]
    r = r @ cv2.Rodrigues(np.array([0.0, 0.0, math.radians(10.0)]))[0]
    c = BOARD_MM.mean(axis=0)
    return r, np.array([20.0, -15.0, dist_mm]) - r @ np.array([c[0], c[1], 0.0])


def _project(r, t, k, dist, pts_mm):
    obj = np.column_stack([pts_mm, np.zeros(len(pts_mm))])
    return cv2.projectPoints(obj, cv2.Rodrigues(r)[0], t, k, dist)[0].reshape(-1, 2)


def _true_view_angle(r, t, centre_mm) -> float:
    sight = r @ np.array([centre_mm[0], centre_mm[1], 0.0]) + t
    return math.degrees(math.acos(abs(r[:, 2] @ sight) / np.linalg.norm(sight)))


def _placed(angle_deg: float, offset_mm) -> np.ndarray:
    a = math.radians(angle_deg)
    return BOARD_MM @ np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]]).T + offset_mm


def _in_plane_angle_error(plane: Plane, r, t, k, pts_mm) -> float:
    """Largest difference (rad) between the rectified and the true angles of lines, after their mean offset."""
    rect = plane.to_rectified(_project(r, t, k, np.zeros(5), pts_mm))  # ideal image points
    i, j = np.triu_indices(len(pts_mm), 1)
    true = np.arctan2(*(pts_mm[j] - pts_mm[i]).T[::-1])
    got = np.arctan2(*(rect[j] - rect[i]).T[::-1])
    diff = np.angle(np.exp(1j * (got - true)))
    diff = np.angle(np.exp(1j * (diff - diff[0])))
    return float(np.max(np.abs(diff - diff.mean())))


# -- OpenCV's photos ----------------------------------------------------------------------


@needs_photos
@pytest.mark.parametrize("photo", [p.name for p in PHOTOS])
def test_each_photo_fits_no_worse_than_opencv_findhomography(photo):
    path = CHESSBOARD / photo
    plane = calibrate_plane(path, BOARD, square_mm=25.0)
    gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    corners = refine_plane_corners(gray, detect_corners(gray, BOARD, fast=False), BOARD).reshape(-1, 2).astype(float)
    board = 25.0 * np.mgrid[0:9, 0:6].T.reshape(-1, 2).astype(float)
    g, _ = cv2.findHomography(board, corners, 0)
    opencv_rms = np.sqrt(np.mean(np.sum((cv2.perspectiveTransform(board[None], g)[0] - corners) ** 2, axis=1)))
    # Our own reprojection, recomputed here from the stored map (not the number it reports).
    ours = np.sqrt(np.mean(np.sum((plane.from_mm(board) - corners) ** 2, axis=1)))
    assert plane.rms_px == pytest.approx(ours, rel=1e-6)
    assert ours <= 1.5 * opencv_rms
    assert ours <= opencv_rms * (1 + 1e-6)  # refined from OpenCV's answer, kept only where lower
    assert plane.n_views == 1 and plane.views[0].name == photo and plane.camera is None


@needs_photos
def test_a_calibration_undistorts_the_corners_first():
    camera = CameraModel((640, 480), SAMPLE_K, SAMPLE_D)
    bare = calibrate_plane(PHOTOS[0], "9x6", square_mm=25.0)
    cal = calibrate_plane(PHOTOS[0], "9x6", square_mm=25.0, camera=camera)
    # The lens's barrel distortion is most of the bare homography's misfit.
    assert cal.rms_px < 0.3 < 0.8 < bare.rms_px
    assert cal.view_angle_source == "calibration" and cal.camera is camera
    assert cal.focal_px == pytest.approx(533.1, abs=0.1)


# -- synthetic truth -------------------------------------------------------------------------


@pytest.mark.parametrize("calibrated", [False, True])
@pytest.mark.parametrize("tilt_deg", [0.0, 20.0, 35.0])
def test_known_pose_gives_the_view_angle_and_in_plane_angles(tilt_deg, calibrated):
    rng = np.random.default_rng(int(tilt_deg) + 100 * calibrated)
    k = _k(calibrated)
    dist = DIST if calibrated else np.zeros(5)
    r, t = _pose(tilt_deg)
    seen = _project(r, t, k, dist, BOARD_MM) + rng.normal(0.0, 0.05, (54, 2))
    camera = CameraModel((W, H), k, dist) if calibrated else None
    plane = fit_plane([seen], BOARD, square_mm=SQUARE, image_size=(W, H), camera=camera)

    truth = _true_view_angle(r, t, BOARD_MM.mean(axis=0))
    if calibrated:
        assert plane.view_angle_source == "calibration"
        assert abs(plane.view_angle_deg - truth) < 0.5
    elif tilt_deg == 0.0:
        # Fronto-parallel: the homography says nothing of f; the tilt against the optical axis is 0.
        assert plane.view_angle_source == "affine" and math.isnan(plane.focal_px)
        assert plane.view_angle_deg < 1.0
    else:
        assert plane.view_angle_source == "homography"
        assert plane.focal_px == pytest.approx(1100.0, rel=0.02)
        assert abs(plane.view_angle_deg - truth) < 0.5
    assert math.isnan(plane.view_angle_std_deg)

    # The plane's frame is the board's: the ideal image of a board point maps back onto it.
    inside = rng.uniform([0.0, 0.0], [160.0, 100.0], (40, 2))
    ideal = _project(r, t, k, np.zeros(5), inside)
    assert np.max(np.abs(plane.to_mm(ideal) - inside)) < 0.1
    assert _in_plane_angle_error(plane, r, t, k, inside) < 1e-3
    assert plane.rms_px < 0.1 and plane.rms_mm < 0.05
    assert 0 < plane.angle_gain_std < 1e-3


def test_the_rectified_frame_is_pinned_at_the_centre():
    r, t = _pose(35.0)
    k = _k(False)
    plane = fit_plane([_project(r, t, k, np.zeros(5), BOARD_MM)], BOARD, square_mm=SQUARE, image_size=(W, H))
    c = np.array([[(W - 1) / 2, (H - 1) / 2]])
    assert np.allclose(plane.to_rectified(c), c, atol=1e-9)
    jac = plane.rectified_jacobian(c)[0]
    assert np.linalg.det(jac) == pytest.approx(1.0, abs=1e-9)
    assert abs(jac[1, 0]) < 1e-12 and jac[0, 0] > 0  # +x stays +x
    # Analytic Jacobian against central differences, away from the centre too.
    pts = np.array([[100.0, 80.0], [640.0, 480.0], [1100.0, 900.0]])
    step = 1e-3
    for p, j in zip(pts, plane.rectified_jacobian(pts)):
        num = np.column_stack([(plane.to_rectified(p + e) - plane.to_rectified(p - e))[0] / (2 * step)
                               for e in (np.array([step, 0.0]), np.array([0.0, step]))])
        assert np.allclose(j, num, rtol=1e-6, atol=1e-9)
    assert np.allclose(plane.from_rectified(plane.to_rectified(pts)), pts, atol=1e-8)
    # s is the image's area scale at the centre in px per mm: the plane's local area per pixel, inverted.
    e = 1e-3
    jm = np.column_stack([(plane.to_mm(c + d) - plane.to_mm(c - d))[0] / (2 * e) for d in ([e, 0.0], [0.0, e])])
    assert plane.scale_px_per_mm == pytest.approx(1 / math.sqrt(abs(np.linalg.det(jm))), rel=1e-6)
    # Counter-clockwise in the image stays counter-clockwise.
    tri = np.array([[600.0, 400.0], [700.0, 400.0], [650.0, 300.0]])

    def turn(q):
        (ax, ay), (bx, by) = q[1] - q[0], q[2] - q[0]
        return ax * by - ay * bx

    assert np.sign(turn(plane.to_rectified(tri))) == np.sign(turn(tri))


@pytest.mark.parametrize("calibrated", [False, True])
def test_a_board_moved_in_the_plane_gives_one_consensus(calibrated):
    rng = np.random.default_rng(5 + calibrated)
    k = _k(calibrated)
    dist = DIST if calibrated else np.zeros(5)
    r, t = _pose(25.0, dist_mm=700.0)
    moves = [(0.0, (0.0, 0.0)), (40.0, (120.0, 30.0)), (-25.0, (-60.0, 80.0))]
    seen = [_project(r, t, k, dist, _placed(a, o)) + rng.normal(0.0, 0.05, (54, 2)) for a, o in moves]
    camera = CameraModel((W, H), k, dist) if calibrated else None
    plane = fit_plane(seen, BOARD, square_mm=SQUARE, image_size=(W, H), camera=camera, names=["a", "b", "c"])

    assert plane.n_views == 3 and [v.name for v in plane.views] == ["a", "b", "c"]
    centre = np.mean([_placed(a, o).mean(axis=0) for a, o in moves], axis=0)
    assert abs(plane.view_angle_deg - _true_view_angle(r, t, centre)) < 0.5
    assert plane.view_angle_std_deg < 0.2
    for view, (a, o) in zip(plane.views, moves):
        assert view.rotation_deg == pytest.approx(a, abs=0.05)
        assert np.allclose(view.offset_mm, o, atol=0.2)
        assert not view.mirrored and view.consensus_rms_px < 0.1
    pts = rng.uniform([-60.0, -20.0], [260.0, 200.0], (40, 2))
    assert _in_plane_angle_error(plane, r, t, k, pts) < 1e-3
    assert np.max(np.abs(plane.to_mm(_project(r, t, k, np.zeros(5), pts)) - pts)) < 0.2


def test_the_photos_spread_is_part_of_the_angle_gain_uncertainty():
    """Several photos: the consensus's own bootstrap, plus how far each photo's own plane strays from it."""
    rng = np.random.default_rng(21)
    k = _k(False)
    r, t = _pose(25.0, dist_mm=700.0)
    moves = [(0.0, (0.0, 0.0)), (40.0, (120.0, 30.0)), (-25.0, (-60.0, 80.0))]
    seen = [_project(r, t, k, np.zeros(5), _placed(a, o)) + rng.normal(0.0, 0.2, (54, 2)) for a, o in moves]
    plane = fit_plane(seen, BOARD, square_mm=SQUARE, image_size=(W, H))
    alone = [fit_plane([s], BOARD, square_mm=SQUARE, image_size=(W, H)) for s in seen]
    c = np.array([[(W - 1) / 2, (H - 1) / 2]])
    phi = np.linspace(0, np.pi, 180, endpoint=False)
    u = np.column_stack([np.cos(phi), np.sin(phi)])

    def rate(p):  # dθ/dφ of lines through the centre, in the rectified frame (det J = 1 there)
        return 1.0 / np.sum((u @ p.rectified_jacobian(c)[0].T) ** 2, axis=1)

    spread = math.sqrt(sum(np.mean((rate(plane) / rate(a) - 1) ** 2) for a in alone) / (len(alone) - 1))
    single = max(a.angle_gain_std for a in alone)
    assert spread <= plane.angle_gain_std <= math.sqrt(spread**2 + single**2)


def test_a_board_whose_corners_came_mirrored_still_joins_the_consensus():
    rng = np.random.default_rng(9)
    k = _k(False)
    r, t = _pose(25.0, dist_mm=700.0)
    first = _project(r, t, k, np.zeros(5), BOARD_MM) + rng.normal(0.0, 0.05, (54, 2))
    second = _project(r, t, k, np.zeros(5), _placed(40.0, (120.0, 30.0))) + rng.normal(0.0, 0.05, (54, 2))
    second = second.reshape(6, 9, 2)[:, ::-1].reshape(-1, 2)  # each row's corners in the other order
    plane = fit_plane([first, second], BOARD, square_mm=SQUARE, image_size=(W, H))
    assert plane.views[1].mirrored and plane.rms_px < 0.1
    assert _in_plane_angle_error(plane, r, t, k, rng.uniform(0, 150, (30, 2))) < 1e-3


def test_a_board_frame_mirrored_against_the_image_is_reflected_back():
    """Corners given right-to-left: the board's frame is a mirror image of what the camera sees."""
    k = _k(False)
    r, t = _pose(20.0)
    seen = _project(r, t, k, np.zeros(5), BOARD_MM).reshape(6, 9, 2)[:, ::-1].reshape(-1, 2)
    plane = fit_plane([seen], BOARD, square_mm=SQUARE, image_size=(W, H))
    c = np.array([[(W - 1) / 2, (H - 1) / 2]])
    assert np.linalg.det(plane.rectified_jacobian(c)[0]) == pytest.approx(1.0, abs=1e-9)
    # Rectified angles are the plane's as the camera sees it (not the mirrored frame's).
    assert _in_plane_angle_error(plane, r, t, k, np.random.default_rng(2).uniform(0, 150, (30, 2))) < 1e-3


def test_the_camera_moving_between_photos_is_refused():
    k = _k(False)
    seen = [_project(*_pose(a), k, np.zeros(5), BOARD_MM) for a in (10.0, 30.0)]
    with pytest.raises(ServoscopeError, match="the camera moved"):
        fit_plane(seen, BOARD, square_mm=SQUARE, image_size=(W, H))


def test_the_angle_gain_uncertainty_matches_repeated_fits():
    """The bootstrap's 1σ against the scatter of fits to fresh noise, each gain taken against the true map."""
    k = _k(False)
    r, t = _pose(30.0)
    exact = _project(r, t, k, np.zeros(5), BOARD_MM)
    truth = fit_plane([exact], BOARD, square_mm=SQUARE, image_size=(W, H))  # noise-free: the true map
    c = np.array([[(W - 1) / 2, (H - 1) / 2]])
    u = np.stack([np.cos(np.linspace(0, np.pi, 90, endpoint=False)), np.sin(np.linspace(0, np.pi, 90, endpoint=False))], 1)

    def rate(plane):
        j = plane.rectified_jacobian(c)[0]
        return np.linalg.det(j) / np.sum((u @ j.T) ** 2, axis=1)

    rng = np.random.default_rng(3)
    claimed, dev = [], []
    for _ in range(40):
        plane = fit_plane([exact + rng.normal(0.0, 0.2, exact.shape)], BOARD, square_mm=SQUARE, image_size=(W, H))
        claimed.append(plane.angle_gain_std)
        # Rectified frames differ by a similarity, which leaves dθ/dφ unchanged only once both
        # are pinned at the same point with det 1: the ratio of rates is the gain.
        dev.append(rate(truth) / rate(plane) - 1.0)
    scatter = float(np.sqrt(np.mean(np.square(dev))))
    assert 0.6 < np.mean(claimed) / scatter < 1.6, (np.mean(claimed), scatter)


# -- videos, files, mistakes ---------------------------------------------------------------------


@pytest.fixture(scope="module")
def still_video(tmp_path_factory) -> Path:
    """Lossless FFV1: left01.jpg filmed still for 12 frames, then 4 blank frames."""
    path = tmp_path_factory.mktemp("plane") / "still.mkv"
    gray = cv2.imread(str(PHOTOS[0]), cv2.IMREAD_GRAYSCALE)
    blank = np.full_like(gray, 128)
    with av.open(str(path), "w") as out:
        stream = out.add_stream("ffv1", rate=Fraction(30))
        stream.width, stream.height, stream.pix_fmt = 640, 480, "gray"
        for i, img in enumerate([gray] * 12 + [blank] * 4):
            frame = av.VideoFrame.from_ndarray(img, format="gray")
            frame.pts = i
            out.mux(stream.encode(frame))
        out.mux(stream.encode(None))
    return path


@needs_photos
def test_a_board_filmed_still_gives_frames_that_agree(still_video):
    video = calibrate_plane(still_video, BOARD, square_mm=25.0)
    photo = calibrate_plane(PHOTOS[0], BOARD, square_mm=25.0)
    assert video.n_views == 5 and all(v.name.startswith("still.mkv#frame=") for v in video.views)
    frames = [int(v.name.split("=")[1]) for v in video.views]
    assert frames[0] == 0 and frames[-1] == 11 and frames == sorted(frames)  # spread over the frames with the board
    assert video.view_angle_std_deg < 1e-6
    assert video.view_angle_deg == pytest.approx(photo.view_angle_deg, abs=1e-6)
    assert video.rms_px == pytest.approx(photo.rms_px, rel=1e-6)
    assert video.skipped == (("still.mkv", "no 9x6 chessboard found in 4 of 16 sampled frames"),)


@pytest.mark.parametrize("calibrated", [False, True])
def test_save_and_load_round_trip(tmp_path, calibrated):
    k = _k(calibrated)
    dist = DIST if calibrated else np.zeros(5)
    r, t = _pose(20.0)
    camera = CameraModel((W, H), k, dist, 0.2) if calibrated else None
    plane = fit_plane([_project(r, t, k, dist, BOARD_MM)], BOARD, square_mm=SQUARE, image_size=(W, H),
                      camera=camera, skipped=[("x.jpg", "no 9x6 chessboard found")])
    saved = plane.save(tmp_path / "plane.json")
    assert saved.source == str(tmp_path / "plane.json") and plane.source == ""
    data = json.loads((tmp_path / "plane.json").read_text())
    assert data["format"] == "servoscope-plane" and data["version"] == 1 and data["view_angle_std_deg"] is None
    assert (data["camera"] is None) == (not calibrated)
    back = Plane.load(tmp_path / "plane.json")
    assert back.to_dict() == plane.to_dict() == data
    assert back.source == str(tmp_path / "plane.json")
    pts = np.array([[10.0, 20.0], [900.0, 700.0]])
    assert np.array_equal(back.to_rectified(pts), plane.to_rectified(pts))
    if calibrated:
        assert np.array_equal(back.camera.dist_coeffs, dist) and back.camera.rms_reprojection_error_px == 0.2
    json.dumps(plane.summary(), allow_nan=False)
    assert "Plane" in plane._repr_html_()


@pytest.mark.parametrize("content, expected", [
    ("{not json", "not a readable JSON plane file"),
    ('{"format": "servoscope-camera"}', 'no "format": "servoscope-plane"'),
    ('{"format": "servoscope-plane", "version": 7}', "version 7"),
    ('{"format": "servoscope-plane", "version": 1}', "missing field 'views'"),
])
def test_load_of_a_bad_file_says_what_is_wrong(tmp_path, content, expected):
    path = tmp_path / "plane.json"
    path.write_text(content)
    with pytest.raises(ServoscopeError) as err:
        Plane.load(path)
    assert str(path) in str(err.value) and expected in str(err.value) and "\n" not in str(err.value)


def test_load_refuses_a_singular_homography(tmp_path):
    r, t = _pose(20.0)
    plane = fit_plane([_project(r, t, _k(False), np.zeros(5), BOARD_MM)], BOARD, square_mm=SQUARE, image_size=(W, H))
    data = plane.to_dict()
    data["homography_mm"] = [[1, 0, 0], [2, 0, 0], [0, 0, 1]]
    (tmp_path / "plane.json").write_text(json.dumps(data))
    with pytest.raises(ServoscopeError, match="invertible"):
        Plane.load(tmp_path / "plane.json")


def test_bad_boards_and_corners_are_refused():
    r, t = _pose(20.0)
    seen = _project(r, t, _k(False), np.zeros(5), BOARD_MM)
    with pytest.raises(ServoscopeError, match="at least 3"):
        fit_plane([seen], "2x6", square_mm=SQUARE, image_size=(W, H))
    with pytest.raises(ServoscopeError, match="square size"):
        fit_plane([seen], BOARD, square_mm=0.0, image_size=(W, H))
    with pytest.raises(ServoscopeError, match="expected 54"):
        fit_plane([seen[:50]], BOARD, square_mm=SQUARE, image_size=(W, H))
    bent = seen + np.random.default_rng(0).normal(0.0, 4.0, seen.shape)
    with pytest.raises(ServoscopeError, match="not flat"):
        fit_plane([bent], BOARD, square_mm=SQUARE, image_size=(W, H), names=["bent.jpg"])
    with pytest.raises(ServoscopeError, match="calibration is for 640x480"):
        fit_plane([seen], BOARD, square_mm=SQUARE, image_size=(W, H), camera=CameraModel((640, 480), SAMPLE_K))


@needs_photos
def test_inputs_without_the_board_or_of_another_size(tmp_path):
    blank = tmp_path / "wall.png"
    cv2.imwrite(str(blank), np.full((480, 640), 90, np.uint8))
    plane = calibrate_plane([PHOTOS[0], blank], BOARD, square_mm=25.0)
    assert plane.n_views == 1 and plane.skipped == (("wall.png", "no 9x6 chessboard found"),)
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), cv2.resize(cv2.imread(str(PHOTOS[0])), (320, 240)))
    with pytest.raises(ServoscopeError, match="differs from 640x480"):
        calibrate_plane([PHOTOS[0], small], BOARD, square_mm=25.0)
    dark = tmp_path / "dark.png"
    cv2.imwrite(str(dark), np.zeros((480, 640), np.uint8))
    with pytest.raises(ServoscopeError, match=r"no 9x6 chessboard found in any of the 2 inputs \(wall.png, dark.png\); "
                                              r"check --board counts inner corners \(COLSxROWS\)"):
        calibrate_plane([blank, dark], BOARD, square_mm=25.0)


# -- the command line ---------------------------------------------------------------------------


@needs_photos
def test_command_writes_plane_json(tmp_path, capsys):
    out = tmp_path / "sub" / "plane.json"
    code, printed, err = _run(capsys, "plane", PHOTOS[0], "--board", "9x6", "--square", "25", "--out", out)
    assert code == 0, err
    plane = Plane.load(out)
    assert plane.to_dict() == calibrate_plane(PHOTOS[0], BOARD, square_mm=25.0).to_dict()
    assert "image 640x480 px, 1 view(s) of a 9x6 board" in printed
    assert f"view angle {plane.view_angle_deg:.2f} deg (from the homography: focal length" in printed
    assert f"reprojection RMS {plane.rms_px:.3f} px, {plane.rms_mm:.3f} mm" in printed
    assert f"angle gain uncertainty {100 * plane.angle_gain_std:.3f} %" in printed
    assert f"wrote {out}" in printed and err == ""


@needs_photos
def test_command_with_a_calibration_and_a_skipped_photo(tmp_path, capsys):
    CameraModel((640, 480), SAMPLE_K, SAMPLE_D).save(tmp_path / "camera.json")
    cv2.imwrite(str(tmp_path / "wall.png"), np.full((480, 640), 90, np.uint8))
    out = tmp_path / "plane.json"
    code, printed, err = _run(capsys, "plane", PHOTOS[0], tmp_path / "wall.png", "--board", "9x6", "--square", "25",
                              "--calibration", tmp_path / "camera.json", "--out", out)
    assert code == 0, err
    plane = Plane.load(out)
    assert plane.camera is not None and np.allclose(plane.camera.camera_matrix, SAMPLE_K)
    assert "view(s) of a 9x6 board (25 mm squares)" in printed
    assert "deg (from the board's pose, with the camera's calibration)" in printed
    assert err == "skipped wall.png: no 9x6 chessboard found\n"


def _bad_cases(tmp_path: Path) -> dict[str, tuple[list, str]]:
    cv2.imwrite(str(tmp_path / "wall.png"), np.full((480, 640), 90, np.uint8))
    CameraModel((320, 240), SAMPLE_K * [[0.5], [0.5], [1]]).save(tmp_path / "small_camera.json")
    return {
        "wrong board": ([PHOTOS[0], "--board", "7x7"], f"no 7x7 chessboard found in {PHOTOS[0]}; check --board"),
        "something else": ([tmp_path / "wall.png", "--board", "9x6"], "no 9x6 chessboard found in"),
        "other size": ([PHOTOS[0], "--board", "9x6", "--calibration", tmp_path / "small_camera.json"],
                       "image size 640x480, but the calibration is for 320x240 images"),
        "missing": ([tmp_path / "gone.jpg", "--board", "9x6"], f"{tmp_path / 'gone.jpg'}: file not found"),
        "camera moved": ([PHOTOS[0], PHOTOS[1], "--board", "9x6"], "the camera moved"),
        "small board": ([PHOTOS[0], "--board", "2x6"], "at least 3"),
    }


@needs_photos
@pytest.mark.parametrize("case", ["wrong board", "something else", "other size", "missing", "camera moved", "small board"])
def test_command_bad_input_is_one_line_and_writes_nothing(tmp_path, capsys, case):
    args, expected = _bad_cases(tmp_path)[case]
    out = tmp_path / "out" / "plane.json"
    code, printed, err = _run(capsys, "plane", *args, "--square", "25", "--out", out)
    assert code == 2 and printed == ""
    assert len(err.strip().splitlines()) == 1 and err.startswith("servoscope: error: ") and expected in err, err
    assert not out.parent.exists()

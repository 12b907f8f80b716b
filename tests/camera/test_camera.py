"""Camera calibration and point (un)distortion, against independent oracles.

Oracles: OpenCV's tutorial calibration pipeline run here on the same real
photos, ``cv2.undistortPoints``, a NumPy transcription of the Brown–Conrady
forward model, and closed-form fold radii.
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

from servoscope.camera import CalibrationResult, CameraModel, calibrate, parse_board
from servoscope.errors import ServoscopeError

from support import CHESSBOARD as DATA
PHOTOS = sorted(DATA.glob("left*.jpg"))
BOARD = (9, 6)

needs_photos = pytest.mark.skipif(
    len(PHOTOS) != 13, reason=f"OpenCV sample chessboard photos (left01..left14.jpg) not found in {DATA}"
)


# -- fixtures -----------------------------------------------------------------


@pytest.fixture(scope="module")
def ours() -> CalibrationResult:
    return calibrate(PHOTOS, BOARD)


@pytest.fixture(scope="module")
def opencv_reference() -> tuple[float, np.ndarray, np.ndarray]:
    """OpenCV's tutorial pipeline (findChessboardCorners + cornerSubPix 11x11, 30 it / 1e-3)."""
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)
    objp = np.zeros((BOARD[0] * BOARD[1], 3), np.float32)
    objp[:, :2] = np.mgrid[0 : BOARD[0], 0 : BOARD[1]].T.reshape(-1, 2)
    obj, img = [], []
    for p in PHOTOS:
        gray = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
        ok, corners = cv2.findChessboardCorners(gray, BOARD, None)
        assert ok, p
        img.append(cv2.cornerSubPix(gray, corners, (11, 11), (-1, -1), criteria))
        obj.append(objp)
    rms, k, d, _, _ = cv2.calibrateCamera(obj, img, gray.shape[::-1], None, None)
    return float(rms), k, d.ravel()


@pytest.fixture(scope="module")
def photo_video(tmp_path_factory) -> tuple[Path, dict[int, str]]:
    """Lossless FFV1 video: each photo for 3 frames, then 1 blank frame.

    Returns the path and {first frame index of each photo: photo name}.
    """
    path = tmp_path_factory.mktemp("video") / "clip.mkv"
    first: dict[int, str] = {}
    blank = np.full((480, 640), 128, np.uint8)
    with av.open(str(path), "w") as out:
        stream = out.add_stream("ffv1", rate=Fraction(30))
        stream.width, stream.height, stream.pix_fmt = 640, 480, "gray"
        index = 0
        for p in PHOTOS:
            gray = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
            first[index] = p.name
            for img in (gray, gray, gray, blank):
                frame = av.VideoFrame.from_ndarray(img, format="gray")
                frame.pts = index
                out.mux(stream.encode(frame))
                index += 1
        out.mux(stream.encode(None))
    return path, first


# -- calibration from photos --------------------------------------------------


@needs_photos
def test_photos_match_opencv_reference(ours, opencv_reference):
    ref_rms, ref_k, _ = opencv_reference
    assert 0.35 < ref_rms < 0.45  # the documented ≈0.41 px of OpenCV's tutorial
    assert ours.rms_reprojection_error_px <= ref_rms + 0.01
    k = ours.camera.camera_matrix
    for (i, j) in [(0, 0), (1, 1), (0, 2), (1, 2)]:
        assert k[i, j] == pytest.approx(ref_k[i, j], rel=0.01), (i, j)
    assert k[0, 1] == 0.0 and np.array_equal(k[2], [0, 0, 1])
    assert ours.camera.image_size == (640, 480)
    assert ours.camera.dist_coeffs.shape == (5,)
    assert ours.camera.rms_reprojection_error_px == ours.rms_reprojection_error_px


@needs_photos
def test_photos_result_bookkeeping(ours):
    names = [p.name for p in PHOTOS]
    assert ours.views_used == names
    assert list(ours.per_view_error_px) == names
    assert ours.skipped == []
    assert ours.board == BOARD and ours.square_size == 1.0
    # Every view has 54 corners, so the overall RMS is the RMS of the per-view RMS.
    per_view = np.array(list(ours.per_view_error_px.values()))
    assert math.sqrt(np.mean(per_view**2)) == pytest.approx(ours.rms_reprojection_error_px, rel=1e-6)
    s = ours.summary()
    json.dumps(s)  # plain types only
    assert s["fx"] == ours.camera.camera_matrix[0, 0] and s["board"] == [9, 6]
    assert s["worst_view"] in names


@needs_photos
def test_square_size_scales_nothing_intrinsic(ours):
    scaled = calibrate(PHOTOS, "9x6", square_size=24.5)
    np.testing.assert_allclose(scaled.camera.camera_matrix, ours.camera.camera_matrix, rtol=1e-6)
    np.testing.assert_allclose(scaled.camera.dist_coeffs, ours.camera.dist_coeffs, rtol=1e-5, atol=1e-8)
    assert scaled.square_size == 24.5


@needs_photos
def test_deterministic(ours):
    again = calibrate(PHOTOS, BOARD)
    assert np.array_equal(again.camera.camera_matrix, ours.camera.camera_matrix)
    assert np.array_equal(again.camera.dist_coeffs, ours.camera.dist_coeffs)


@needs_photos
def test_save_load_round_trip(ours, tmp_path):
    path = tmp_path / "camera.json"
    ours.save(path)
    loaded = CameraModel.load(path)
    assert np.array_equal(loaded.camera_matrix, ours.camera.camera_matrix)
    assert np.array_equal(loaded.dist_coeffs, ours.camera.dist_coeffs)
    assert loaded.image_size == ours.camera.image_size
    assert loaded.rms_reprojection_error_px == ours.rms_reprojection_error_px
    data = json.loads(path.read_text())
    assert data["board"] == [9, 6]
    assert data["views_used"] == ours.views_used
    assert data["per_view_error_px"] == ours.per_view_error_px


# -- calibration from a video -------------------------------------------------


@needs_photos
def test_video_matches_photos(ours, photo_video):
    path, first = photo_video
    res = calibrate([path], BOARD)
    # One view per photo: the other 2 frames of each are duplicates, never chosen twice.
    assert len(res.views_used) == 13
    chosen = {int(n.split("#frame=")[1]) for n in res.views_used}
    assert all(n.startswith("clip.mkv#frame=") for n in res.views_used)
    assert {min(i for i in first if i <= f and f - i < 3) for f in chosen} == set(first)
    # The 13 blank frames were candidates without a board.
    assert len(res.skipped) == 13 and all(n.startswith("clip.mkv#frame=") for n, _ in res.skipped)
    assert {int(n.split("=")[1]) % 4 for n, _ in res.skipped} == {3}
    k, k0 = res.camera.camera_matrix, ours.camera.camera_matrix
    for (i, j) in [(0, 0), (1, 1), (0, 2), (1, 2)]:
        assert k[i, j] == pytest.approx(k0[i, j], rel=0.02), (i, j)
    assert res.rms_reprojection_error_px == pytest.approx(ours.rms_reprojection_error_px, abs=0.02)


@needs_photos
def test_video_frame_budget_picks_varied_views(photo_video):
    path, first = photo_video
    res = calibrate(path, BOARD, max_video_frames=5)
    assert len(res.views_used) == 5
    # 20 candidates spread over 52 frames; the 5 chosen show 5 different photos.
    photos = {max(i for i in first if i <= int(n.split("=")[1])) for n in res.views_used}
    assert len(photos) == 5
    assert res.rms_reprojection_error_px < 0.5


# -- point (un)distortion -----------------------------------------------------


def _numpy_distort(model: CameraModel, pts: np.ndarray) -> np.ndarray:
    """Brown–Conrady forward model written out (OpenCV's documented equations)."""
    k = model.camera_matrix
    k1, k2, p1, p2, k3 = model.dist_coeffs
    x = (pts[:, 0] - k[0, 2]) / k[0, 0]
    y = (pts[:, 1] - k[1, 2]) / k[1, 1]
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.stack([xd * k[0, 0] + k[0, 2], yd * k[1, 1] + k[1, 2]], axis=1)


def _image_grid(w: int = 640, h: int = 480, n: int = 25) -> np.ndarray:
    xs, ys = np.meshgrid(np.linspace(0, w - 1, n), np.linspace(0, h - 1, n))
    return np.stack([xs.ravel(), ys.ravel()], axis=1)


@pytest.fixture(scope="module")
def model(ours) -> CameraModel:
    return ours.camera


@needs_photos
def test_distort_matches_numpy_model(model):
    pts = _image_grid()
    np.testing.assert_allclose(model.distort_points(pts), _numpy_distort(model, pts), atol=1e-9)


@needs_photos
def test_undistort_matches_opencv(model):
    pts = _image_grid()
    ours_pts, converged = model.undistort_points(pts)
    assert converged.all()
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    ref = cv2.undistortPoints(
        pts.reshape(-1, 1, 2), model.camera_matrix, model.dist_coeffs, P=model.camera_matrix, criteria=criteria
    ).reshape(-1, 2)
    assert np.abs(ours_pts - ref).max() < 1e-6


@needs_photos
def test_distort_undistort_round_trip(model):
    ideal = _image_grid()
    back, converged = model.undistort_points(model.distort_points(ideal))
    assert converged.all()
    assert np.abs(back - ideal).max() < 1e-6
    # And the other way: the undistorted point re-distorts onto the numpy model.
    rec = _image_grid()
    und, _ = model.undistort_points(rec)
    assert np.abs(_numpy_distort(model, und) - rec).max() < 1e-6


@needs_photos
def test_valid_region(model):
    inside = _image_grid()
    assert model.in_valid_region(inside).all()
    far = np.array([[-5000.0, -5000.0], [1e5, 240.0], [320.0, 480 + 0.2 * 480], [np.nan, 0.0]])
    assert not model.in_valid_region(far).any()
    # Margin: 10 % of the width beyond the left edge is in, 11 % is out.
    assert model.in_valid_region(np.array([[-0.09 * 640, 240.0], [-0.11 * 640, 240.0]])).tolist() == [True, False]


def test_strong_barrel_without_k3_does_not_converge_past_its_fold():
    # r_d = r (1 + k1 r²) with k1 = -0.4 folds at r = 1/sqrt(3·0.4), where r_d peaks
    # at (2/3) r_fold; distorted points farther out have no preimage at all.
    k1, f = -0.4, 500.0
    cam = CameraModel((640, 480), [[f, 0, 320], [0, f, 240], [0, 0, 1]], [k1, 0, 0, 0, 0])
    r_fold = 1 / math.sqrt(-3 * k1)
    assert cam.monotonic_radius == pytest.approx(r_fold, rel=1e-12)
    rd_max_px = f * (2 / 3) * r_fold
    pts = np.array([[320 + 0.9 * rd_max_px, 240.0], [320 + 1.05 * rd_max_px, 240.0]])
    und, converged = cam.undistort_points(pts)
    assert converged.tolist() == [True, False]
    assert cam.in_valid_region(pts).tolist() == [True, False]
    assert np.abs(_numpy_distort(cam, und[:1]) - pts[:1]).max() < 1e-6


def test_monotonic_radius_cases():
    def cam(d):
        return CameraModel((640, 480), [[500, 0, 320], [0, 500, 240], [0, 0, 1]], d)

    assert cam([0, 0, 0, 0, 0]).monotonic_radius == math.inf
    assert cam([0.1, 0.01, 0, 0, 0]).monotonic_radius == math.inf
    # 1 + 7 k3 u³ = 0 → u = (-1 / (7 k3))^(1/3)
    assert cam([0, 0, 0, 0, -0.5]).monotonic_radius == pytest.approx((1 / 3.5) ** (1 / 6), rel=1e-9)


# -- bad input ----------------------------------------------------------------


def test_text_file_named_jpg(tmp_path):
    bad = tmp_path / "notes.jpg"
    bad.write_text("this is not a photo\n")
    with pytest.raises(ServoscopeError, match="notes.jpg") as exc:
        calibrate([bad], BOARD)
    assert "\n" not in str(exc.value)


def test_text_file_with_no_known_ending(tmp_path):
    bad = tmp_path / "notes.txt"
    bad.write_text("this is not a video either\n")
    with pytest.raises(ServoscopeError, match="notes.txt.*not an image or video"):
        calibrate([bad], BOARD)


def test_missing_file(tmp_path):
    with pytest.raises(ServoscopeError, match="nowhere.jpg.*not found"):
        calibrate([tmp_path / "nowhere.jpg"], BOARD)


def _boardless_folder(tmp_path: Path) -> Path:
    folder = tmp_path / "empty_boards"
    folder.mkdir()
    rng = np.random.default_rng(0)
    for i in range(4):
        img = cv2.GaussianBlur(rng.integers(0, 256, (480, 640), dtype=np.uint8), (0, 0), 8)
        cv2.imwrite(str(folder / f"view{i}.png"), img)
    return folder


def test_folder_without_board(tmp_path):
    folder = _boardless_folder(tmp_path)
    with pytest.raises(ServoscopeError, match=r"only 0 view\(s\).*9x6"):
        calibrate([folder], BOARD)
    with pytest.raises(ServoscopeError, match=r"only 0 view\(s\)"):
        calibrate(sorted(folder.glob("*.png")), BOARD)


@needs_photos
def test_too_few_views_says_how_many(tmp_path):
    folder = _boardless_folder(tmp_path)
    with pytest.raises(ServoscopeError, match=r"only 2 view\(s\).*need at least 3; 4 skipped"):
        calibrate(PHOTOS[:2] + sorted(folder.glob("*.png")), BOARD)


@needs_photos
def test_mixed_sizes_name_the_file(tmp_path):
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), cv2.resize(cv2.imread(str(PHOTOS[0])), (320, 240)))
    with pytest.raises(ServoscopeError, match=r"small.png: image size 320x240 differs from 640x480"):
        calibrate(PHOTOS[:3] + [small], BOARD)


def test_empty_folder(tmp_path):
    with pytest.raises(ServoscopeError, match="holds no image or video"):
        calibrate([tmp_path], BOARD)


@pytest.mark.parametrize("bad", [{"square_size": 0}, {"square_size": float("nan")}, {"max_video_frames": 0}])
def test_bad_options(tmp_path, bad):
    with pytest.raises(ServoscopeError):
        calibrate([tmp_path], BOARD, **bad)


def test_parse_board():
    assert parse_board("9x6") == (9, 6)
    assert parse_board(" 7 X 5 ") == (7, 5)
    assert parse_board("9×6") == (9, 6)
    for bad in ["9", "9x", "x6", "9x6x2", "2x6", "nine by six", "-9x6", "9.5x6"]:
        with pytest.raises(ServoscopeError, match="board"):
            parse_board(bad)

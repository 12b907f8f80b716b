"""The blade's plane, calibrated with a chessboard held flat against it.

A camera that is not square-on to the blade's plane distorts the angle of the
line joining the two stickers. :func:`calibrate_plane` finds the chessboard in
photos or videos (read, detected and refined exactly as
:func:`~servoscope.camera.calibrate` does), fits the homography from the
(ideal, undistorted) image to the plane in mm and returns a :class:`Plane`,
which maps image points to the plane and to the *rectified frame* the tracker
measures in. The fitting itself is in :mod:`servoscope.camera.plane_fit`.

Several photos may show the board at different places in the plane (the camera
still): their consensus is one homography and a rigid motion of the board per
photo, fitted to all corners at once; the spread of the photos' own fits is part
of the uncertainty.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from ..errors import ServoscopeError
from ..results import html_rows, html_table, jsonable, readonly
from .._io import write_json_atomic
from .calibrate import detect_corners, expand_inputs, is_image, read_gray_image, view_names
from .model import CameraModel
from .plane_corners import (check_board, check_consensus, check_image_size, fit_view, ideal_corners,
                            refine_plane_corners, video_corners)
from .plane_fit import (angle_gain_std, apply_homography, fit_consensus, homography_jacobian, image_to_plane,
                        rectifying_map, view_angles)

__all__ = ["Plane", "PlaneView", "calibrate_plane", "fit_plane", "refine_plane_corners"]

#: plane.json's ``format`` and ``version``.
FORMAT = "servoscope-plane"
VERSION = 1
#: Parametric bootstrap of the corners: draws and seed (fixed: the same inputs, the same numbers).
BOOTSTRAP_DRAWS = 200
BOOTSTRAP_SEED = 20240615
VIEW_ANGLE_SOURCES = ("calibration", "homography", "affine")


@dataclass(frozen=True)
class PlaneView:
    """One photo or video frame of the board.

    Attributes
    ----------
    name : str
        ``"left01.jpg"`` or ``"clip.mp4#frame=12"``.
    view_angle_deg : float
        Its own estimate of the plane's view angle (from its own pose or homography, to
        the same point as :attr:`Plane.view_angle_deg`).
    rms_px : float
        RMS reprojection error of its own homography, px.
    consensus_rms_px : float
        RMS reprojection error of its corners in the plane's consensus, px.
    rotation_deg : float
        Its board's rotation in the plane's frame (the first view's board), degrees.
    offset_mm : (float, float)
        Where its board's first corner lies in the plane's frame, mm.
    mirrored : bool
        The detector gave its corners in mirrored order (a reflection, not a rotation).
    """

    name: str
    view_angle_deg: float
    rms_px: float
    consensus_rms_px: float
    rotation_deg: float = 0.0
    offset_mm: tuple[float, float] = (0.0, 0.0)
    mirrored: bool = False

    def summary(self) -> dict:
        """Plain-typed fields (NaN as None)."""
        return jsonable(dataclasses.asdict(self))


@dataclass(frozen=True, eq=False)
class Plane:
    """The blade's plane as the camera sees it: a homography from the ideal image to the plane in mm.

    Attributes
    ----------
    image_size : (int, int)
        Width and height of the photos, px.
    homography_mm : ndarray (3, 3)
        Ideal (undistorted) image px → plane mm (the first view's board frame: x along
        the board's rows of corners, origin at its first corner). Scaled to unit norm.
    camera : CameraModel or None
        The calibration the corners were undistorted with (None: taken as distortion-free).
    board : (int, int)
        Inner corners (cols, rows).
    square_mm : float
        Side of one square, mm.
    n_views : int
        Photos or frames used.
    views : tuple of PlaneView
    rms_px, rms_mm : float
        RMS reprojection error of the consensus: in the image (px) and in the plane (mm).
    view_angle_deg : float
        Angle between the plane's normal and the camera's line of sight to the board's
        centre (the mean of the boards' centres with several views).
    view_angle_std_deg : float
        Spread (standard deviation) of the views' own estimates of it; NaN with one view.
    view_angle_source : str
        ``"calibration"``: from :func:`cv2.solvePnP` with the camera's intrinsics;
        ``"homography"``: principal point at the image centre, square pixels, the focal
        length from the homography's orthogonality constraints; ``"affine"``: where those
        do not determine it, the foreshortening at the image centre (arccos of the ratio
        of the Jacobian's singular values; the tilt seen along the optical axis).
    focal_px : float
        The focal length the view angle used, px (NaN for ``"affine"``).
    angle_gain_std : float
        Relative 1σ uncertainty of an angle measured in this plane (0.001 = 0.1 %).
    skipped : tuple of (str, str)
        Inputs (or frames) without the board, and why.
    source : str
        The file this plane was loaded from or written to ("" until then).
    """

    image_size: tuple[int, int]
    homography_mm: np.ndarray
    camera: CameraModel | None
    board: tuple[int, int]
    square_mm: float
    n_views: int
    views: tuple[PlaneView, ...]
    rms_px: float
    rms_mm: float
    view_angle_deg: float
    view_angle_std_deg: float
    view_angle_source: str
    focal_px: float
    angle_gain_std: float
    skipped: tuple[tuple[str, str], ...] = ()
    source: str = ""
    _rectify: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        h = np.asarray(self.homography_mm, dtype=float)
        if h.shape != (3, 3) or not np.all(np.isfinite(h)) or abs(np.linalg.det(h)) < 1e-300:
            raise ValueError("homography_mm: need an invertible, finite 3x3 matrix")
        size = (int(self.image_size[0]), int(self.image_size[1]))
        if min(size) < 1:
            raise ValueError(f"image_size {size}: must be positive")
        if self.view_angle_source not in VIEW_ANGLE_SOURCES:
            raise ValueError(f"view_angle_source {self.view_angle_source!r}: one of {', '.join(VIEW_ANGLE_SOURCES)}")
        if int(self.n_views) != len(self.views) or min(int(self.board[0]), int(self.board[1])) < 3:
            raise ValueError("n_views must count views, board needs at least 3x3 inner corners")
        if not (float(self.square_mm) > 0):
            raise ValueError(f"square_mm {self.square_mm!r}: must be positive")
        set_ = object.__setattr__
        set_(self, "homography_mm", readonly(h))
        set_(self, "image_size", size)
        set_(self, "board", (int(self.board[0]), int(self.board[1])))
        set_(self, "views", tuple(self.views))
        set_(self, "skipped", tuple((str(n), str(r)) for n, r in self.skipped))
        set_(self, "_rectify", readonly(rectifying_map(h, size)))

    # -- maps ------------------------------------------------------------------
    @property
    def centre_px(self) -> tuple[float, float]:
        """The image centre ``((w − 1)/2, (h − 1)/2)``, px: where the rectified frame matches the photo."""
        return (self.image_size[0] - 1) / 2.0, (self.image_size[1] - 1) / 2.0

    @property
    def rectified_homography(self) -> np.ndarray:
        """3 × 3, ideal image px → rectified px (``S ∘ H``; see :meth:`to_rectified`)."""
        return self._rectify

    @property
    def scale_px_per_mm(self) -> float:
        """s: rectified px per plane mm (the area scale of the image at its centre, kept)."""
        a = np.asarray(self._rectify) @ np.linalg.inv(self.homography_mm)
        return float(math.sqrt(abs(np.linalg.det(a[:2, :2] / a[2, 2]))))

    def to_rectified(self, points_px: np.ndarray) -> np.ndarray:
        """Ideal image px (n, 2) → rectified px (n, 2).

        The rectified frame is the plane seen square-on: ``S(H(p))`` with ``S`` a
        similarity of the plane (``s`` px per mm, a rotation, a reflection only where the
        plane's frame is mirrored against the image's, a translation) chosen so that at
        the image centre ``c``: ``S(H(c)) = c``; the whole map's Jacobian there has
        determinant +1 (areas and the sense of rotation kept) and takes the image's +x
        direction onto +x. Near the centre the rectified picture is the photo, un-tilted;
        angles of lines in it are angles in the plane, up to one constant.
        """
        return apply_homography(self._rectify, _points(points_px))

    def from_rectified(self, points: np.ndarray) -> np.ndarray:
        """Rectified px (n, 2) → ideal image px (n, 2); the inverse of :meth:`to_rectified`."""
        return apply_homography(np.linalg.inv(self._rectify), _points(points))

    def rectified_jacobian(self, points_px: np.ndarray) -> np.ndarray:
        """Jacobian of :meth:`to_rectified` at ideal image points: (n, 2, 2), ``J[k, a, b] = ∂rect_a/∂img_b``."""
        return homography_jacobian(self._rectify, _points(points_px))

    def to_mm(self, points_px: np.ndarray) -> np.ndarray:
        """Ideal image px (n, 2) → plane mm (n, 2)."""
        return apply_homography(self.homography_mm, _points(points_px))

    def from_mm(self, points_mm: np.ndarray) -> np.ndarray:
        """Plane mm (n, 2) → ideal image px (n, 2)."""
        return apply_homography(np.linalg.inv(self.homography_mm), _points(points_mm))

    # -- files and tables --------------------------------------------------------
    def summary(self) -> dict:
        """Plain-typed summary (NaN as None): the scalars, the views and what was skipped (not :attr:`source`)."""
        return jsonable({
            "image_size": self.image_size, "board": self.board, "square_mm": self.square_mm,
            "n_views": self.n_views, "view_angle_deg": self.view_angle_deg,
            "view_angle_std_deg": self.view_angle_std_deg, "view_angle_source": self.view_angle_source,
            "focal_px": self.focal_px, "rms_px": self.rms_px, "rms_mm": self.rms_mm,
            "angle_gain_std": self.angle_gain_std, "scale_px_per_mm": self.scale_px_per_mm,
            "calibrated": self.camera is not None, "views": [v.summary() for v in self.views],
            "skipped": self.skipped,
        })

    def to_dict(self) -> dict:
        """The content of plane.json (plain types; see docs/formats.md)."""
        data = {"format": FORMAT, "version": VERSION, **self.summary()}
        data.pop("calibrated")  # the camera says so
        data["homography_mm"] = self.homography_mm.tolist()
        data["rectified_homography"] = self._rectify.tolist()  # derived: for readers in other languages
        data["camera"] = None if self.camera is None else self.camera.to_dict()
        return jsonable(data)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, source: str = "") -> "Plane":
        """A plane from :meth:`to_dict`'s form (KeyError, TypeError or ValueError when it is not one)."""
        views = tuple(
            PlaneView(str(v["name"]), _float(v["view_angle_deg"]), _float(v["rms_px"]), _float(v["consensus_rms_px"]),
                      _float(v.get("rotation_deg", 0.0)), _pair(v.get("offset_mm", (0.0, 0.0))),
                      bool(v.get("mirrored", False)))
            for v in data["views"]
        )
        return cls(
            image_size=_int_pair(data["image_size"]), homography_mm=np.asarray(data["homography_mm"], dtype=float),
            camera=_camera(data["camera"]), board=_int_pair(data["board"]), square_mm=_float(data["square_mm"]),
            n_views=int(data["n_views"]), views=views, rms_px=_float(data["rms_px"]), rms_mm=_float(data["rms_mm"]),
            view_angle_deg=_float(data["view_angle_deg"]), view_angle_std_deg=_float(data["view_angle_std_deg"]),
            view_angle_source=str(data["view_angle_source"]), focal_px=_float(data["focal_px"]),
            angle_gain_std=_float(data["angle_gain_std"]),
            skipped=tuple((str(n), str(r)) for n, r in data.get("skipped", [])), source=source,
        )

    def save(self, path: str | Path) -> "Plane":
        """Write plane.json whole or not at all; returns this plane with ``source`` set to ``path``.

        Raises
        ------
        ServoscopeError
            When the file cannot be written.
        """
        path = Path(path)
        try:
            write_json_atomic(path, self.to_dict())
        except OSError as exc:
            raise ServoscopeError(f"{path}: cannot write the plane ({exc.strerror or exc})") from None
        return dataclasses.replace(self, source=str(path))

    @classmethod
    def load(cls, path: str | Path) -> "Plane":
        """Read plane.json; a missing or bad file raises ServoscopeError (one line, naming it)."""
        path = Path(path)
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise ServoscopeError(f"{path}: plane file not found") from None
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ServoscopeError(f"{path}: not a readable JSON plane file ({_one_line(exc)})") from None
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise ServoscopeError(f'{path}: not a plane file (no "format": "{FORMAT}"); make one with `servoscope plane`')
        if data.get("version") != VERSION:
            raise ServoscopeError(f"{path}: plane file version {data.get('version')!r}, this servoscope reads {VERSION}")
        try:
            return cls.from_dict(data, source=str(path))
        except KeyError as exc:
            raise ServoscopeError(f"{path}: bad plane file: missing field {exc}; make it again with `servoscope plane`") from None
        except (TypeError, ValueError, IndexError, AttributeError) as exc:
            raise ServoscopeError(f"{path}: bad plane file ({_one_line(exc)}); make it again with `servoscope plane`") from None

    def describe(self) -> list[str]:
        """What ``servoscope plane`` prints: size, views, view angle (± spread, source), RMS, angle-gain uncertainty."""
        spread = "" if self.n_views < 2 else f" ± {self.view_angle_std_deg:.2f}"
        how = {"calibration": "from the board's pose, with the camera's calibration",
               "homography": f"from the homography: focal length {self.focal_px:.0f} px, principal point at the centre",
               "affine": "from the foreshortening at the image centre: focal length not determined"}
        return [f"image {self.image_size[0]}x{self.image_size[1]} px, {self.n_views} view(s) of a "
                f"{self.board[0]}x{self.board[1]} board ({self.square_mm:g} mm squares)",
                f"view angle {self.view_angle_deg:.2f}{spread} deg ({how[self.view_angle_source]})",
                f"reprojection RMS {self.rms_px:.3f} px, {self.rms_mm:.3f} mm",
                f"angle gain uncertainty {100 * self.angle_gain_std:.3f} % (1 sigma)"]

    def _repr_html_(self) -> str:
        scalars = {k: v for k, v in self.summary().items() if k not in ("views", "skipped")}
        rows = [(v.name, f"{v.view_angle_deg:.2f}", f"{v.rms_px:.3f}", f"{v.consensus_rms_px:.3f}") for v in self.views]
        return html_table(scalars, "Plane") + html_rows(
            ["view", "view angle (deg)", "own RMS (px)", "consensus RMS (px)"], rows)


# -- fitting ------------------------------------------------------------------------


def fit_plane(
    corners_px: Sequence[np.ndarray],
    board: tuple[int, int] | str,
    *,
    square_mm: float,
    image_size: tuple[int, int],
    camera: CameraModel | None = None,
    names: Sequence[str] | None = None,
    skipped: Iterable[tuple[str, str]] = (),
) -> Plane:
    """The plane from chessboard corners already found (what :func:`calibrate_plane` does after detection).

    Parameters
    ----------
    corners_px : sequence of ndarray (cols × rows, 2)
        Per view, the board's inner corners in the *recorded* image, px, in OpenCV's
        order (along a row first).
    board : (int, int) or str
        Inner corners ``(cols, rows)`` or ``"9x6"``.
    square_mm : float
        Side of one square, mm.
    image_size : (int, int)
        The photos' width and height, px.
    camera : CameraModel, optional
        Its lens model undistorts the corners first and its intrinsics give the view angle.
    names : sequence of str, optional
        The views' names (default ``"view 1"``, …).
    skipped : iterable of (str, str), optional
        Passed through to :attr:`Plane.skipped`.

    Returns
    -------
    Plane

    Raises
    ------
    ServoscopeError
        Bad board or square, corners of the wrong count, an image size other than the
        camera's, a board whose corners miss a plane by more than 2 px RMS.
    """
    board, square = check_board(board, square_mm)
    size = (int(image_size[0]), int(image_size[1]))
    names = [f"view {i + 1}" for i in range(len(corners_px))] if names is None else [str(n) for n in names]
    if not corners_px or len(names) != len(corners_px):
        raise ServoscopeError("no views to fit (or not one name per view)")
    if camera is not None and tuple(camera.image_size) != size:
        raise ServoscopeError(f"{names[0]}: image size {size[0]}x{size[1]}, but the calibration is for "
                              f"{camera.image_size[0]}x{camera.image_size[1]} images; use the camera.json of this camera mode")
    obs = [ideal_corners(c, name, board, camera) for c, name in zip(corners_px, names)]
    board_mm = square * np.mgrid[0:board[0], 0:board[1]].T.reshape(-1, 2).astype(np.float64)
    own = [fit_view(board_mm, c, name, camera) for c, name in zip(obs, names)]
    fit = own[0] if len(obs) == 1 else fit_consensus(board_mm, obs, own)
    check_consensus(fit, names)

    h = image_to_plane(fit.homography, size)
    centre = np.array([(size[0] - 1) / 2.0, (size[1] - 1) / 2.0])
    draws = fit.bootstrap(BOOTSTRAP_DRAWS, np.random.default_rng(BOOTSTRAP_SEED))
    angle, per_view, source, focal = view_angles(fit, own, obs, board_mm, camera, centre, draws)
    view_rms = fit.view_rms_px()
    views = []
    for i, name in enumerate(names):
        place = fit.placements[i]
        mirrored = bool(np.linalg.det(place[:2, :2]) < 0)
        rot = place[:2, :2] @ np.diag([1.0, -1.0 if mirrored else 1.0])
        views.append(PlaneView(name, per_view[i], own[i].rms_px, float(view_rms[i]),
                               math.degrees(math.atan2(rot[1, 0], rot[0, 0])),
                               (float(place[0, 2]), float(place[1, 2])), mirrored))
    plane_err = [apply_homography(h, c) - apply_homography(p, board_mm) for c, p in zip(obs, fit.placements)]
    return Plane(
        image_size=size, homography_mm=h, camera=camera, board=board, square_mm=square, n_views=len(obs),
        views=tuple(views), rms_px=fit.rms_px, rms_mm=float(np.sqrt(np.mean(np.sum(np.square(plane_err), axis=-1)))),
        view_angle_deg=angle, view_angle_std_deg=float(np.std(per_view, ddof=1)) if len(obs) > 1 else float("nan"),
        view_angle_source=source, focal_px=focal, angle_gain_std=angle_gain_std(h, draws, own, centre),
        skipped=tuple(skipped),
    )


def calibrate_plane(
    paths: str | Path | Iterable[str | Path],
    board: tuple[int, int] | str,
    *,
    square_mm: float,
    camera: CameraModel | None = None,
    max_video_frames: int = 5,
) -> Plane:
    """Calibrate the blade's plane from photos or videos of a chessboard held flat against it.

    Parameters
    ----------
    paths : path or iterable of paths
        Image files, video files and folders (their image and video files), read as
        :func:`~servoscope.camera.calibrate` reads them. All of one size, from one camera
        position; the board may sit at a different place in the plane in each.
    board : (int, int) or str
        Inner corners ``(cols, rows)`` or ``"9x6"``.
    square_mm : float
        Side of one square, mm.
    camera : CameraModel, optional
        The lens calibration (camera.json): the corners are undistorted first and the
        view angle comes from the board's pose. Without one the camera is taken as
        distortion-free.
    max_video_frames : int, optional
        From a video, at most this many frames with the board, spread evenly through the
        frames where it was found (among ``4 × max_video_frames`` sampled evenly).

    Returns
    -------
    Plane

    Raises
    ------
    ServoscopeError
        A missing or unreadable file, inputs of different sizes or of another size than
        the camera's, no board in any input, a board that is not flat (over 2 px RMS).
    """
    board, square = check_board(board, square_mm)
    if isinstance(max_video_frames, bool) or not isinstance(max_video_frames, int) or max_video_frames < 1:
        raise ServoscopeError(f"max_video_frames {max_video_frames!r}: must be a positive integer")
    files = expand_inputs(paths)
    sizes: dict[tuple[int, int], Path] = {}
    corners: list[np.ndarray] = []
    names: list[str] = []
    skipped: list[tuple[str, str]] = []
    no_board = f"no {board[0]}x{board[1]} chessboard found"
    for path, name in zip(files, view_names(files)):
        if is_image(path):
            gray = read_gray_image(path)
            check_image_size(path, gray.shape, sizes, camera)
            found = detect_corners(gray, board, fast=False)
            if found is None:
                skipped.append((name, no_board))
            else:
                corners.append(refine_plane_corners(gray, found, board))
                names.append(name)
        else:
            frames, missed = video_corners(path, board, max_video_frames, sizes, camera)
            corners += [c for _, c in frames]
            names += [f"{name}#frame={i}" for i, _ in frames]
            if missed:
                skipped.append((name, f"{no_board} in {missed[0]} of {missed[1]} sampled frames"))
    if not corners:
        where = str(files[0]) if len(files) == 1 else f"any of the {len(files)} inputs ({_first_names(files)})"
        raise ServoscopeError(f"{no_board} in {where}; check --board counts inner corners (COLSxROWS)")
    (size,) = sizes
    return fit_plane([c.reshape(-1, 2) for c in corners], board, square_mm=square, image_size=size,
                     camera=camera, names=names, skipped=skipped)


# -- helpers ------------------------------------------------------------------------
# (Finding, refining and checking the board's corners: :mod:`servoscope.camera.plane_corners`.)


def _points(points: np.ndarray) -> np.ndarray:
    pts = np.asarray(points, dtype=np.float64)
    if pts.shape[-1:] != (2,):
        raise ValueError(f"points: expected shape (n, 2), got {pts.shape}")
    return pts.reshape(-1, 2)


def _float(value: Any) -> float:
    """A JSON number, null read as NaN (plane.json writes NaN as null)."""
    if isinstance(value, bool):
        raise TypeError("expected a number, got a boolean")
    return float("nan") if value is None else float(value)


def _pair(value: Any) -> tuple[float, float]:
    a, b = value
    return _float(a), _float(b)


def _int_pair(value: Any) -> tuple[int, int]:
    a, b = value
    if int(a) != a or int(b) != b:
        raise ValueError(f"expected two integers, got {value!r}")
    return int(a), int(b)


def _camera(data: Any) -> CameraModel | None:
    """camera.json's dict (CameraModel.to_dict) as a CameraModel, or None."""
    if data is None:
        return None
    k = np.asarray(data["camera_matrix"], dtype=float)
    d = np.asarray(data.get("dist_coeffs", [0.0] * 5), dtype=float)
    if k.shape != (3, 3) or d.size > 5 or not (np.all(np.isfinite(k)) and np.all(np.isfinite(d))):
        raise ValueError("camera: need camera_matrix 3x3 and dist_coeffs [k1,k2,p1,p2,k3], finite")
    rms = data.get("rms_reprojection_error_px")
    return CameraModel(_int_pair(data["image_size"]), k, d, None if rms is None else float(rms))


def _first_names(files: Sequence[Path], n: int = 3) -> str:
    shown = ", ".join(f.name for f in files[:n])
    return shown + (", …" if len(files) > n else "")


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__

"""Camera calibration from photos or videos of a chessboard.

OpenCV does the real work: :func:`cv2.findChessboardCorners` (with
:func:`cv2.findChessboardCornersSB` as a fallback) finds the board,
:func:`cv2.cornerSubPix` refines its corners and
:func:`cv2.calibrateCamera` fits OpenCV's default 5-coefficient
Brown–Conrady model ``[k1, k2, p1, p2, k3]``.

Videos are read with PyAV. A video holds many near-identical views, so
candidate frames are sampled evenly through it, the board is detected on
them, and a *varied* subset is kept: greedy farthest-point selection on a
small descriptor of the board's layout in the image (centre position,
apparent size, tilt). Exact or near duplicates (a board held still) are
never chosen twice.

Corner refinement window
------------------------
:func:`cv2.cornerSubPix` assumes every gradient in its window belongs to the
two edges through *this* corner. OpenCV's tutorial uses a fixed half-window
of 11 px (a 23 × 23 px window), which on OpenCV's own sample photos
(squares 22–37 px) reaches the neighbouring corners and biases them: RMS
reprojection error 0.41 px. Here the half-window is 0.3 × the smallest
corner spacing of that view (clipped to 2–15 px), which keeps the window
inside the four squares around the corner: 0.18 px on the same photos.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Iterator, Sequence

import av
import cv2
import numpy as np

from ..errors import ServoscopeError
from ..video.reader import quarter_turns
from .model import CameraModel
from .._io import write_text_atomic

__all__ = ["CalibrationResult", "calibrate", "parse_board"]

#: File name endings taken as still images (what :func:`cv2.imread` reads).
IMAGE_SUFFIXES = frozenset(
    ".jpg .jpeg .jpe .png .bmp .dib .tif .tiff .webp .pgm .ppm .pbm .pnm .pxm "
    ".sr .ras .exr .hdr .pic .jp2 .avif".split()
)
#: File name endings taken as videos when a folder is expanded.
VIDEO_SUFFIXES = frozenset(
    ".mp4 .m4v .mov .mkv .webm .avi .mts .m2ts .ts .mpg .mpeg .wmv .flv .mxf .3gp .nut .y4m".split()
)

_MIN_VIEWS = 3
#: Descriptor distance below which two board views count as the same view.
_MIN_SEPARATION = 0.02
_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-4)


# -- public API ---------------------------------------------------------------


def parse_board(text: str) -> tuple[int, int]:
    """Parse a board size such as ``"9x6"``.

    Parameters
    ----------
    text : str
        ``COLSxROWS``: the number of *inner* corners along and across the
        board (a board of 10 × 7 squares has 9 × 6 inner corners). ``x``,
        ``X``, ``×`` and ``,`` are accepted as separators.

    Returns
    -------
    (int, int)
        ``(cols, rows)``, both at least 3.

    Raises
    ------
    ServoscopeError
        When the text is not two integers ≥ 3.
    """
    m = re.fullmatch(r"\s*(\d+)\s*[xX×,]\s*(\d+)\s*", str(text))
    if m is None:
        raise ServoscopeError(f"board {text!r}: expected COLSxROWS inner corners, e.g. 9x6")
    cols, rows = int(m.group(1)), int(m.group(2))
    if cols < 3 or rows < 3:
        raise ServoscopeError(f"board {text!r}: need at least 3 inner corners each way, e.g. 9x6")
    return cols, rows


@dataclass(frozen=True)
class CalibrationResult:
    """What :func:`calibrate` found.

    Attributes
    ----------
    camera : CameraModel
        Intrinsics and distortion, with ``rms_reprojection_error_px`` set.
    rms_reprojection_error_px : float
        RMS over all corners of all views of the distance between detected
        and reprojected corners, pixels (the value
        :func:`cv2.calibrateCamera` returns).
    per_view_error_px : dict of str to float
        RMS reprojection error of each view used, pixels. Views are named
        ``"left01.jpg"`` or ``"clip.mp4#frame=120"`` (decoded-frame index,
        from 0); the full path is used when two inputs share a file name.
    views_used : list of str
        Names of the views used, in input order.
    skipped : list of (str, str)
        ``(name, reason)`` of views without a detectable board.
    board : (int, int)
        Inner corners ``(cols, rows)``.
    square_size : float
        Side of one square, in the user's unit (does not affect intrinsics).
    """

    camera: CameraModel
    rms_reprojection_error_px: float
    per_view_error_px: dict[str, float]
    views_used: list[str]
    skipped: list[tuple[str, str]]
    board: tuple[int, int]
    square_size: float

    def summary(self) -> dict:
        """Plain-typed summary (JSON-serialisable).

        Returns
        -------
        dict
            ``image_size`` (px), ``fx``, ``fy``, ``cx``, ``cy`` (px),
            ``dist_coeffs`` ``[k1, k2, p1, p2, k3]``,
            ``rms_reprojection_error_px``, ``worst_view`` and its error,
            ``per_view_error_px``, ``views_used``, ``skipped``, ``board``,
            ``square_size``.
        """
        k = self.camera.camera_matrix
        worst = max(self.per_view_error_px, key=self.per_view_error_px.__getitem__)
        return {
            "image_size": list(self.camera.image_size),
            "fx": float(k[0, 0]),
            "fy": float(k[1, 1]),
            "cx": float(k[0, 2]),
            "cy": float(k[1, 2]),
            "dist_coeffs": self.camera.dist_coeffs.tolist(),
            "rms_reprojection_error_px": float(self.rms_reprojection_error_px),
            "worst_view": worst,
            "worst_view_error_px": float(self.per_view_error_px[worst]),
            "per_view_error_px": {k_: float(v) for k_, v in self.per_view_error_px.items()},
            "views_used": list(self.views_used),
            "skipped": [[n, r] for n, r in self.skipped],
            "board": list(self.board),
            "square_size": float(self.square_size),
        }

    def save(self, path: str | Path) -> None:
        """Write ``camera.json``.

        The content is :meth:`CameraModel.to_dict` plus the keys
        ``per_view_error_px``, ``board`` and ``views_used``;
        :meth:`CameraModel.load` reads it back.

        Raises
        ------
        ServoscopeError
            When the file cannot be written.
        """
        path = Path(path)
        data = self.camera.to_dict()
        data["per_view_error_px"] = {k: float(v) for k, v in self.per_view_error_px.items()}
        data["board"] = list(self.board)
        data["views_used"] = list(self.views_used)
        try:
            write_text_atomic(path, json.dumps(data, indent=2) + "\n")
        except OSError as exc:
            raise ServoscopeError(f"{path}: cannot write calibration ({exc.strerror or exc})") from None


def calibrate(
    paths: str | Path | Iterable[str | Path],
    board: tuple[int, int] | str = (9, 6),
    *,
    square_size: float = 1.0,
    max_video_frames: int = 25,
) -> CalibrationResult:
    """Calibrate a camera from chessboard photos and/or videos.

    Parameters
    ----------
    paths : path or iterable of paths
        Image files (anything :func:`cv2.imread` reads), video files (anything
        PyAV/FFmpeg decodes) and folders (their image and video files, by
        name ending, sorted; not recursive). All views must have one size.
    board : (int, int) or str
        Inner corners ``(cols, rows)``, e.g. ``(9, 6)`` or ``"9x6"``.
    square_size : float, optional
        Side of one square in any unit (mm, m…). Intrinsics and distortion
        do not depend on it; it only scales the board's coordinates.
    max_video_frames : int, optional
        At most this many views are taken from each video, chosen among
        ``4 × max_video_frames`` candidate frames spread evenly through it.

    Returns
    -------
    CalibrationResult

    Raises
    ------
    ServoscopeError
        A missing or unreadable file, a file that is neither image nor video,
        views of different sizes, fewer than 3 views with a detectable board,
        or a calibration OpenCV cannot solve.

    Notes
    -----
    Deterministic: the same inputs give the same result. Views without a
    detectable board are listed in ``skipped``, not fatal.

    Long because OpenCV's calibration is a sequence (find the corners, refine them,
    calibrate, check the reprojection and the coverage, say what is wrong) whose steps
    share the views' lists.
    """
    if isinstance(board, str):
        board = parse_board(board)
    try:
        cols, rows = (int(board[0]), int(board[1]))
    except (TypeError, ValueError, IndexError):
        raise ServoscopeError(f"board {board!r}: expected (cols, rows) inner corners, e.g. (9, 6)") from None
    if len(tuple(board)) != 2 or cols < 3 or rows < 3 or (cols, rows) != tuple(board):
        raise ServoscopeError(f"board {board!r}: need two integers ≥ 3 (inner corners), e.g. (9, 6)")
    try:
        square = float(square_size)
    except (TypeError, ValueError):
        square = float("nan")
    if isinstance(square_size, bool) or not (math.isfinite(square) and square > 0):
        raise ServoscopeError(f"square size {square_size!r}: must be a positive number")
    if isinstance(max_video_frames, bool) or not isinstance(max_video_frames, int) or max_video_frames < 1:
        raise ServoscopeError(f"max_video_frames {max_video_frames!r}: must be a positive integer")
    board = (cols, rows)

    files = expand_inputs(paths)
    names = view_names(files)

    views: list[tuple[str, np.ndarray]] = []  # (name, refined corners (n, 1, 2) float32)
    skipped: list[tuple[str, str]] = []
    size: tuple[int, int] | None = None
    size_from = ""
    no_board = f"no {cols}x{rows} chessboard found"

    def check_size(path: Path, shape: tuple[int, ...]) -> None:
        nonlocal size, size_from
        wh = (int(shape[1]), int(shape[0]))
        if size is None:
            size, size_from = wh, str(path)
        elif wh != size:
            raise ServoscopeError(
                f"{path}: image size {wh[0]}x{wh[1]} differs from {size[0]}x{size[1]} of {size_from}"
                " (all views must come from one camera mode)"
            )

    for path, name in zip(files, names):
        if is_image(path):
            gray = read_gray_image(path)
            check_size(path, gray.shape)
            corners = detect_corners(gray, board, fast=False)
            if corners is None:
                skipped.append((name, no_board))
            else:
                views.append((name, refine_corners(gray, corners, board)))
        else:
            found: list[tuple[int, np.ndarray]] = []
            for index, gray in video_candidates(path, 4 * max_video_frames):
                check_size(path, gray.shape)
                corners = detect_corners(gray, board, fast=True)
                if corners is None:
                    skipped.append((f"{name}#frame={index}", no_board))
                else:
                    found.append((index, refine_corners(gray, corners, board)))
            if found:
                assert size is not None
                desc = np.array([_layout_descriptor(c, board, size) for _, c in found])
                for i in _select_diverse(desc, max_video_frames):
                    views.append((f"{name}#frame={found[i][0]}", found[i][1]))

    if len(views) < _MIN_VIEWS:
        where = f"{len(files)} file(s)" if len(files) != 1 else str(files[0])
        raise ServoscopeError(
            f"{where}: only {len(views)} view(s) with a detectable {cols}x{rows} chessboard "
            f"(need at least {_MIN_VIEWS}; {len(skipped)} skipped); check --board counts inner corners"
        )

    assert size is not None
    obj = np.zeros((cols * rows, 3), np.float32)
    obj[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * square
    # OpenCV's multithreaded solver sums in a varying order (results differ
    # in the 10th digit from run to run); one thread makes it reproducible.
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        rms, k, d, _r, _t, _si, _se, per_view = cv2.calibrateCameraExtended(
            [obj] * len(views), [c for _, c in views], size, None, None
        )
    except cv2.error as exc:
        msg = str(exc).strip().splitlines()[-1] if str(exc).strip() else "failed"
        raise ServoscopeError(f"{len(views)} views: calibration failed ({msg}); use more varied views") from None
    finally:
        cv2.setNumThreads(threads)
    if not (np.all(np.isfinite(k)) and np.all(np.isfinite(d)) and math.isfinite(rms)):
        raise ServoscopeError(f"{len(views)} views: calibration diverged; use more varied, tilted views")

    rms = float(rms)
    camera = CameraModel(size, k, np.asarray(d, float).ravel()[:5], rms)
    return CalibrationResult(
        camera=camera,
        rms_reprojection_error_px=rms,
        per_view_error_px={n: float(e) for (n, _), e in zip(views, np.ravel(per_view))},
        views_used=[n for n, _ in views],
        skipped=skipped,
        board=board,
        square_size=square,
    )


# -- inputs -------------------------------------------------------------------
# Public (not in __all__) because camera/plane.py reads its inputs and finds its
# corners exactly as calibration does: one reading, one detector, one refinement.


def expand_inputs(paths: str | Path | Iterable[str | Path]) -> list[Path]:
    """Paths as given, folders replaced by their image/video files; duplicates dropped."""
    if isinstance(paths, (str, Path)):
        paths = [paths]
    out: list[Path] = []
    seen: set[Path] = set()
    for p in map(Path, paths):
        if not p.exists():
            raise ServoscopeError(f"{p}: file not found")
        if p.is_dir():
            inside = sorted(
                q for q in p.iterdir() if q.is_file() and q.suffix.lower() in IMAGE_SUFFIXES | VIDEO_SUFFIXES
            )
            if not inside:
                raise ServoscopeError(f"{p}: folder holds no image or video files")
            members = inside
        else:
            members = [p]
        for q in members:
            key = q.resolve()
            if key not in seen:
                seen.add(key)
                out.append(q)
    if not out:
        raise ServoscopeError("no calibration images or videos given")
    return out


def view_names(files: Sequence[Path]) -> list[str]:
    """File names, or the full paths given when two files share a name."""
    counts: dict[str, int] = {}
    for f in files:
        counts[f.name] = counts.get(f.name, 0) + 1
    return [f.name if counts[f.name] == 1 else str(f) for f in files]


def is_image(path: Path) -> bool:
    """Whether ``path`` is to be read as a still image (OpenCV knows its signature or name)."""
    return path.suffix.lower() in IMAGE_SUFFIXES or cv2.haveImageReader(str(path))


def read_gray_image(path: Path) -> np.ndarray:
    """Grayscale uint8 image, shape (height, width)."""
    if path.stat().st_size == 0:
        raise ServoscopeError(f"{path}: empty file, not an image")
    gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE) if cv2.haveImageReader(str(path)) else None
    if gray is None or gray.size == 0:
        raise ServoscopeError(f"{path}: not a readable image (OpenCV does not recognise its content)")
    return gray


def video_candidates(path: Path, n_candidates: int) -> Iterator[tuple[int, np.ndarray]]:
    """Yield ``(frame index, grayscale frame)`` for frames spread evenly through a video.

    Frame indices count decoded frames from 0. The number of frames is taken
    from the number of demuxed video packets (one pass without decoding),
    since containers' announced counts are often missing.
    """
    if path.stat().st_size == 0:
        raise ServoscopeError(f"{path}: empty file, not an image or video")
    try:
        with av.open(str(path), mode="r") as container:
            if not container.streams.video:
                raise ServoscopeError(f"{path}: no video stream (not an image or video)")
            stream = container.streams.video[0]
            n_frames = sum(1 for pkt in container.demux(stream) if pkt.size)
        if n_frames == 0:
            raise ServoscopeError(f"{path}: video holds no frames")
        wanted = np.unique(np.round(np.linspace(0, n_frames - 1, min(n_frames, n_candidates))).astype(int))
        wanted_set = set(wanted.tolist())
        last = int(wanted[-1])
        decoded = 0
        with av.open(str(path), mode="r") as container:
            stream = container.streams.video[0]
            stream.thread_type = "AUTO"
            for index, frame in enumerate(container.decode(stream)):
                decoded += 1
                if index in wanted_set:
                    # Upright, as the tracker reads the footage (a phone's rotation tag), so that the
                    # calibration's image size and principal point are the tracked images'.
                    try:
                        turns = quarter_turns(frame)
                    except ServoscopeError as exc:
                        raise ServoscopeError(f"{path}: {exc}") from None
                    gray = frame.to_ndarray(format="gray")
                    yield index, np.ascontiguousarray(np.rot90(gray, turns)) if turns else gray
                if index >= last:
                    break
        if decoded == 0:
            raise ServoscopeError(f"{path}: no frame could be decoded")
    except ServoscopeError:
        raise
    except (av.error.FFmpegError, UnicodeDecodeError, ValueError) as exc:
        raise ServoscopeError(f"{path}: not an image or video that OpenCV or FFmpeg can read ({exc})") from None


# -- detection ----------------------------------------------------------------


def detect_corners(gray: np.ndarray, board: tuple[int, int], *, fast: bool) -> np.ndarray | None:
    """Chessboard inner corners, shape (n, 1, 2) float32, or None.

    The classic detector first (``fast`` adds ``CALIB_CB_FAST_CHECK``, which
    rejects board-less frames cheaply), then the sector-based one.
    """
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    if fast:
        flags |= cv2.CALIB_CB_FAST_CHECK
    ok, corners = cv2.findChessboardCorners(gray, board, flags=flags)
    if not ok:
        ok, corners = cv2.findChessboardCornersSB(gray, board)
    if not ok or corners is None or len(corners) != board[0] * board[1]:
        return None
    return np.ascontiguousarray(corners, dtype=np.float32).reshape(-1, 1, 2)


def _min_spacing_px(corners: np.ndarray, board: tuple[int, int]) -> float:
    """Smallest distance between neighbouring corners of the grid, pixels."""
    g = corners.reshape(board[1], board[0], 2).astype(np.float64)
    along = np.hypot(*np.diff(g, axis=1).reshape(-1, 2).T)
    across = np.hypot(*np.diff(g, axis=0).reshape(-1, 2).T)
    return float(min(along.min(), across.min()))


def refine_corners(gray: np.ndarray, corners: np.ndarray, board: tuple[int, int]) -> np.ndarray:
    """Sub-pixel corners (cornerSubPix), half-window 0.3 × smallest spacing, 2–15 px."""
    half = int(np.clip(math.floor(0.3 * _min_spacing_px(corners, board)), 2, 15))
    return cv2.cornerSubPix(gray, corners.copy(), (half, half), (-1, -1), _SUBPIX_CRITERIA)


# -- choosing varied video frames ---------------------------------------------


def _layout_descriptor(corners: np.ndarray, board: tuple[int, int], size: tuple[int, int]) -> np.ndarray:
    """Where and how the board lies in the image, as 5 dimensionless numbers.

    ``[centre x / width, centre y / height, sqrt(board area) / sqrt(image
    area), gx, gy]`` where ``(gx, gy)`` is the gradient of the log of the
    local corner spacing per image diagonal: zero for a board facing the
    camera, growing with tilt, pointing to where the board is nearer. All
    are invariant to the detector's choice of corner order.
    """
    cols, rows = board
    w, h = size
    g = corners.reshape(rows, cols, 2).astype(np.float64)
    centre = g.reshape(-1, 2).mean(axis=0)
    quad = np.array([g[0, 0], g[0, -1], g[-1, -1], g[-1, 0]])
    x, y = quad[:, 0], quad[:, 1]
    area = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
    diag = math.hypot(w, h)
    # Local spacing of neighbouring corners, at the midpoint between them.
    segs = []
    for axis in (1, 0):
        d = np.diff(g, axis=axis).reshape(-1, 2)
        mid = (g[:, 1:] + g[:, :-1]) / 2 if axis == 1 else (g[1:] + g[:-1]) / 2
        segs.append((np.log(np.maximum(np.hypot(*d.T), 1e-6)), (mid.reshape(-1, 2) - centre) / diag))
    # log s = a_along·[along] + a_across·[across] + gx·x + gy·y  (least squares)
    n1, n2 = len(segs[0][0]), len(segs[1][0])
    a = np.zeros((n1 + n2, 4))
    a[:n1, 0] = 1.0
    a[n1:, 1] = 1.0
    a[:, 2:] = np.vstack([segs[0][1], segs[1][1]])
    b = np.concatenate([segs[0][0], segs[1][0]])
    coef, *_ = np.linalg.lstsq(a, b, rcond=None)
    return np.array([centre[0] / w, centre[1] / h, math.sqrt(area / (w * h)), coef[2], coef[3]])


def _select_diverse(desc: np.ndarray, k: int, min_separation: float = _MIN_SEPARATION) -> list[int]:
    """Greedy farthest-point choice of up to ``k`` rows of ``desc``; sorted indices.

    Starts from the view farthest from the mean, then repeatedly adds the
    view farthest from all those chosen (ties: earliest). Stops early when
    every remaining view is within ``min_separation`` of a chosen one
    (duplicates of a view add weight, not information).
    """
    n = len(desc)
    if n == 0:
        return []
    first = int(np.argmax(np.linalg.norm(desc - desc.mean(axis=0), axis=1)))
    chosen = [first]
    nearest = np.linalg.norm(desc - desc[first], axis=1)
    while len(chosen) < min(k, n):
        nxt = int(np.argmax(nearest))
        if nearest[nxt] < min_separation:
            break
        chosen.append(nxt)
        nearest = np.minimum(nearest, np.linalg.norm(desc - desc[nxt], axis=1))
    return sorted(chosen)

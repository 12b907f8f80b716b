"""The twin's board photo: a printed chessboard lying in the blade's plane, seen by the oblique camera.

A camera that looks at the blade from the side sees its plane through a homography
(:class:`~servoscope.simulate.view.ObliqueView`). Real users photograph a printed chessboard
laid where the blade turns to find that homography; :func:`render_board_photo` renders that
photo with a known answer: the board's corners in the plane (in plane px and, through
:data:`PLANE_MM_PER_PX`, in mm), drawn through the same view and lens as the footage, with
exact area coverage and the frames' sensor noise.
"""

from __future__ import annotations

import math

import numpy as np

from ..camera.model import CameraModel
from ..errors import ServoscopeError
from .coverage import accumulated, composite
from .render import FrameRenderer
from .scene import Scene, colour_rgb
from .view import ObliqueView, densify_closed

__all__ = ["PLANE_MM_PER_PX", "BOARD_INNER", "render_board_photo", "board_corners_plane_px"]

#: The twin's plane scale: one plane px is 0.1 mm on the blade (its 720 px picture spans 72 mm,
#: a model helicopter's blade section), so that the board's squares have a size in mm.
PLANE_MM_PER_PX = 0.1

#: Inner corners of the printed board, (along its rows, along its columns): 10×7 squares.
BOARD_INNER = (9, 6)

# A printed sheet's white and black (ink is not 0 DN, paper not 255: no clipping under the noise).
_PAPER, _INK = "#ebebeb", "#1c1c1c"
# The white margin around the squares, in squares (a chessboard detector needs a quiet border).
_MARGIN_SQUARES = 1
# How far inside the picture the sheet must stay, as a fraction of its shorter side.
_EDGE_FRACTION = 0.03


def board_corners_plane_px(board: dict) -> np.ndarray:
    """The inner corners of a board described by :func:`render_board_photo`'s truth, plane px, shape (n, 2).

    Row-major: corner ``(i, j)`` (i along the first axis, j along the second) is row ``j·nx + i``.
    """
    nx, ny = board["inner_corners"]
    first = np.asarray(board["first_corner_plane_px"], dtype=np.float64)
    ax, ay = (np.asarray(a, dtype=np.float64) for a in board["axes_plane_px"])
    j, i = np.mgrid[0:ny, 0:nx]
    return first + i.reshape(-1, 1) * ax + j.reshape(-1, 1) * ay


def _recorded(xy: np.ndarray, view: ObliqueView, camera: CameraModel | None, step_px: float) -> np.ndarray:
    """A plane polygon where the camera records it: densified (the lens bends edges), the view, the lens."""
    xy = view.apply(densify_closed(xy, step_px))
    return xy if camera is None else camera.distort_points(xy)


def _square(corner: np.ndarray, size: np.ndarray) -> np.ndarray:
    """An axis-aligned rectangle from ``corner`` spanning ``size`` (plane px), counter-clockwise on screen."""
    x0, y0 = corner
    x1, y1 = corner + size
    return np.array([[x0, y0], [x0, y1], [x1, y1], [x1, y0]], dtype=np.float64)


def _fits(sheet: np.ndarray, view: ObliqueView, camera: CameraModel | None, step_px: float) -> bool:
    xy = _recorded(sheet, view, camera, step_px)
    edge = _EDGE_FRACTION * min(view.width, view.height)
    return bool(np.all(xy >= edge) and np.all(xy[:, 0] <= view.width - 1 - edge)
                and np.all(xy[:, 1] <= view.height - 1 - edge))


def _layout(centre: np.ndarray, inner: tuple[int, int], square_px: float) -> tuple[np.ndarray, np.ndarray]:
    """(first inner corner, sheet outline) of a board of ``inner`` corners centred on ``centre``, plane px."""
    first = centre - 0.5 * (np.array(inner, dtype=np.float64) - 1.0) * square_px
    # The squares span one square before the first inner corner to one after the last; the sheet a margin more.
    lo = first - (1 + _MARGIN_SQUARES) * square_px
    span = (np.array(inner, dtype=np.float64) + 1 + 2 * _MARGIN_SQUARES) * square_px
    return first, _square(lo, span)


def _square_px(centre: np.ndarray, inner: tuple[int, int], view: ObliqueView, camera: CameraModel | None,
               step_px: float) -> int:
    """The largest whole number of plane px per square with which the sheet fits in the picture.

    The sheets of growing squares are nested about one centre: whether one fits is monotone in
    the square's size, so a bisection finds the largest.
    """
    def fits(s: int) -> bool:
        return _fits(_layout(centre, inner, s)[1], view, camera, step_px)

    lo = 4
    if not fits(lo):
        raise ServoscopeError("board photo: no chessboard with squares of 4 px or more fits in this view's picture")
    sheet_squares = np.array(inner) + 1 + 2 * _MARGIN_SQUARES
    hi = int(2 * min(view.width / sheet_squares[0], view.height / sheet_squares[1])) + 1  # never fits
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if fits(mid) else (lo, mid)
    return lo


def render_board_photo(scene: Scene, view: ObliqueView, camera: CameraModel | None = None, *,
                       inner: tuple[int, int] = BOARD_INNER, square_px: float | None = None,
                       noise_sigma_dn: float = 1.5, seed: int = 0) -> tuple[np.ndarray, dict]:
    """A photo of a printed chessboard lying in the blade's plane, seen through ``view`` and the lens.

    The board (``inner`` inner corners, so ``inner + 1`` squares, black where the square's
    indices' sum is even, on white paper with a margin of one square) is centred on the
    chord's midpoint at zero pitch, its axes along the plane's x and y. Drawn with exact area
    coverage over the scene's static picture (background and clutter, without the blade),
    with frame 0's sensor noise of a renderer seeded by ``seed`` (deterministic).

    Parameters
    ----------
    scene : Scene
        The scene whose plane and background the board lies in.
    view : ObliqueView
        The camera's view of the plane (its picture size the scene's).
    camera : CameraModel, optional
        The lens; None: none.
    inner : (int, int)
        Inner corners along the board's rows and columns (OpenCV's ``patternSize``).
    square_px : float, optional
        A square's side, plane px; None: the largest whole number with which the sheet stays
        inside the picture (3 % of its shorter side from every edge).
    noise_sigma_dn : float
        Sensor noise, DN.
    seed : int
        Seed of the noise.

    Returns
    -------
    image : ndarray of uint8, shape (height, width, 3)
        The RGB photo.
    board : dict
        ``inner_corners``, ``squares``, ``square_px``, ``square_mm``, ``plane_mm_per_px``,
        ``margin_squares``, ``first_corner_plane_px`` and ``axes_plane_px`` (two vectors of one
        square's length): inner corner ``(i, j)`` is ``first + i·axes[0] + j·axes[1]``
        (:func:`board_corners_plane_px`).

    Raises
    ------
    ServoscopeError
        Fewer than 2 inner corners either way, a square that is not positive, or a board that
        does not fit in the picture.
    """
    nx, ny = (int(v) for v in inner)
    if (nx, ny) != tuple(inner) or nx < 2 or ny < 2:
        raise ServoscopeError(f"board photo: inner corners must be two whole numbers >= 2, not {inner!r}")
    step = scene.max_segment_px
    renderer = FrameRenderer(scene, camera, noise_sigma_dn=noise_sigma_dn, noise_seed=seed, view=view)
    lens = renderer.camera  # None for a lens without distortion
    centre = scene.to_image(np.mean(scene.sticker_centres_uv(), axis=0), 0.0)
    if square_px is None:
        square_px = _square_px(centre, (nx, ny), view, lens, step)
    elif not (square_px > 0 and math.isfinite(square_px)):
        raise ServoscopeError(f"board photo: square_px must be positive, not {square_px!r}")
    first, sheet = _layout(centre, (nx, ny), float(square_px))
    if not _fits(sheet, view, lens, step):
        raise ServoscopeError(f"board photo: a board of {square_px:g} px squares does not fit in the picture")
    image = renderer.static_picture()
    w, h = scene.width, scene.height
    acc, x0, y0, sign = accumulated(_recorded(sheet, view, lens, step), w, h)
    composite(image, acc, x0, y0, colour_rgb(_PAPER), sign)
    # The black squares meet at their corners: their coverages are summed into one picture-sized
    # accumulator (disjoint areas add) and composited once, where compositing each in turn would
    # blend a corner pixel twice.
    total = np.zeros((h, w + 1))
    size = np.array([square_px, square_px], dtype=np.float64)
    for b in range(ny + 1):
        for a in range(nx + 1):
            if (a + b) % 2:
                continue
            corner = first + (np.array([a, b], dtype=np.float64) - 1.0) * square_px
            acc, x0, y0, sign = accumulated(_recorded(_square(corner, size), view, lens, step), w, h)
            ry, rx = acc.shape[0], acc.shape[1] - 1
            # The window's last column carries what spills past it: kept, so that the running sum
            # along the picture's row returns to 0 right of the square.
            total[y0:y0 + ry, x0:x0 + rx + 1] += sign * acc
    composite(image, total, 0, 0, colour_rgb(_INK), 1.0)
    board = {"inner_corners": [nx, ny], "squares": [nx + 1, ny + 1], "square_px": float(square_px),
             "square_mm": float(square_px) * PLANE_MM_PER_PX, "plane_mm_per_px": PLANE_MM_PER_PX,
             "margin_squares": _MARGIN_SQUARES, "first_corner_plane_px": first.tolist(),
             "axes_plane_px": [[float(square_px), 0.0], [0.0, float(square_px)]]}
    return renderer.add_noise(image, 0), board

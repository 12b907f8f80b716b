"""The geometry behind :mod:`servoscope.camera.plane`: homographies fitted to chessboard corners.

Conventions: ``G`` (3 × 3) maps the plane (mm) to the ideal image (px), the
direction in which the reprojection error is measured; its inverse ``H`` maps
the image to the plane. A *placement* (3 × 3) is the rigid motion that puts one
photo's board (its corners at ``square × (i, j)`` mm) into the plane's frame,
which is the first photo's board.

The least-squares problems are solved in Hartley-normalised coordinates (image
and board centred, mean distance √2) so that the eight homography parameters
have comparable scales; residuals are always image pixels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import cv2
import numpy as np
from ..errors import ServoscopeError
from .model import CameraModel

#: The homography determines f when the bootstrap's spread of f² is below this fraction of it (f to ~10 %).
FOCAL_MAX_REL_SPREAD = 0.2

__all__ = [
    "FOCAL_MAX_REL_SPREAD",
    "HomographyFit",
    "angle_gain_std",
    "angle_gain_deviation",
    "apply_homography",
    "board_pose",
    "fit_consensus",
    "fit_homography",
    "focal_squared",
    "homography_jacobian",
    "image_to_plane",
    "rectifying_map",
    "view_angle_affine_deg",
    "view_angle_focal_deg",
    "view_angle_pose_deg",
    "view_angles",
]


# -- homographies as maps ----------------------------------------------------


def apply_homography(h: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Map points (n, 2) through the 3 × 3 homography ``h``; returns (n, 2)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    q = pts @ h[:, :2].T + h[:, 2]
    return q[:, :2] / q[:, 2:3]


def homography_jacobian(h: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Jacobian of the map ``p ↦ h(p)`` at each point: shape (n, 2, 2), ``J[k, a, b] = ∂out_a/∂in_b``.

    ``h`` may also be a stack (k, 3, 3) with one point (1, 2): then one Jacobian per homography.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    hs = np.asarray(h, dtype=np.float64)
    if hs.ndim == 2:
        hs = hs[None]
    q = np.einsum("kij,nj->kni", hs[:, :, :2], pts) + hs[:, None, :, 2]  # (k, n, 3)
    w = q[..., 2]
    xy = q[..., :2] / w[..., None]
    jac = (hs[:, None, :2, :2] - xy[..., :, None] * hs[:, None, 2, None, :2]) / w[..., None, None]
    return jac.reshape(-1, 2, 2)


def _normaliser(points: np.ndarray) -> np.ndarray:
    """Hartley's similarity: the points' centroid to 0, their mean distance from it to √2."""
    m = points.mean(axis=0)
    d = float(np.mean(np.hypot(*(points - m).T)))
    s = math.sqrt(2.0) / d if d > 0 else 1.0
    return np.array([[s, 0.0, -s * m[0]], [0.0, s, -s * m[1]], [0.0, 0.0, 1.0]])


def _rotation(alpha: float) -> np.ndarray:
    c, s = math.cos(alpha), math.sin(alpha)
    return np.array([[c, -s], [s, c]])


# -- the joint model ------------------------------------------------------------


class _JointModel:
    """One homography shared by all views, a rigid placement of the board per view after the first.

    Parameters: the normalised homography's eight free entries (its [2, 2] is 1), then
    ``(angle, tx, ty)`` per further view. A board whose corner order the detector gave
    mirrored keeps that reflection fixed (``mirrored``): a rigid motion cannot undo it.
    """

    def __init__(self, board_mm: np.ndarray, corners: Sequence[np.ndarray], mirrored: Sequence[bool]):
        self.t_obj = _normaliser(board_mm)
        self.t_img = _normaliser(np.vstack(corners))
        self.scale = self.t_img[0, 0]  # normalised units per pixel
        self.board_n = apply_homography(self.t_obj, board_mm)
        self.obs_n = [apply_homography(self.t_img, c) for c in corners]
        self.flip = [np.diag([1.0, -1.0 if m else 1.0]) for m in mirrored]
        self.n_params = 8 + 3 * (len(corners) - 1)

    def unpack(self, p: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
        """Normalised homography and normalised placements (3 × 3 each) from the parameters."""
        g = np.append(p[:8], 1.0).reshape(3, 3)
        places = [np.eye(3)]
        for i in range(1, len(self.obs_n)):
            a, tx, ty = p[8 + 3 * (i - 1): 11 + 3 * (i - 1)]
            m = np.eye(3)
            m[:2, :2] = _rotation(a) @ self.flip[i]
            m[:2, 2] = (tx, ty)
            places.append(m)
        return g, places

    def pack(self, g_mm: np.ndarray, places_mm: Sequence[np.ndarray]) -> np.ndarray:
        """Parameters from a homography (plane mm → image px) and placements (board mm → plane mm)."""
        g = self.t_img @ g_mm @ np.linalg.inv(self.t_obj)
        p = list((g / g[2, 2]).ravel()[:8])
        for i, place in enumerate(places_mm[1:], start=1):
            m = self.t_obj @ place @ np.linalg.inv(self.t_obj)
            rot = m[:2, :2] @ self.flip[i]
            p += [math.atan2(rot[1, 0], rot[0, 0]), m[0, 2], m[1, 2]]
        return np.array(p)

    def to_mm(self, p: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
        """The homography (plane mm → image px) and placements (board mm → plane mm) in real units."""
        g, places = self.unpack(p)
        inv_obj = np.linalg.inv(self.t_obj)
        return np.linalg.inv(self.t_img) @ g @ self.t_obj, [inv_obj @ m @ self.t_obj for m in places]

    def residuals(self, p: np.ndarray) -> np.ndarray:
        """Model minus observed corners, image px, all views (flattened)."""
        g, places = self.unpack(p)
        out = [apply_homography(g @ m, self.board_n) - obs for m, obs in zip(places, self.obs_n)]
        return np.concatenate(out).ravel() / self.scale

    def jacobian(self, p: np.ndarray) -> np.ndarray:
        """Analytic ∂residuals/∂parameters (the bootstrap reuses it, so no finite differences)."""
        g, places = self.unpack(p)
        n = len(self.board_n)
        jac = np.zeros((2 * n * len(places), self.n_params))
        for i, m in enumerate(places):
            plane = apply_homography(m, self.board_n)  # normalised plane coordinates
            q = plane @ g[:, :2].T + g[:, 2]
            w = q[:, 2]
            xy = q[:, :2] / w[:, None]
            rows = slice(2 * n * i, 2 * n * (i + 1))
            block = np.zeros((n, 2, self.n_params))
            hom = np.column_stack([plane, np.ones(n)]) / w[:, None]
            block[:, 0, 0:3] = hom
            block[:, 1, 3:6] = hom
            block[:, :, 6] = -xy * hom[:, 0:1]
            block[:, :, 7] = -xy * hom[:, 1:2]
            if i > 0:
                a_loc = homography_jacobian(g, plane)  # ∂image/∂plane, (n, 2, 2)
                a = p[8 + 3 * (i - 1)]
                d_rot = np.array([[-math.sin(a), -math.cos(a)], [math.cos(a), -math.sin(a)]]) @ self.flip[i]
                d_plane = self.board_n @ d_rot.T  # ∂plane/∂angle
                col = 8 + 3 * (i - 1)
                block[:, :, col] = np.einsum("nab,nb->na", a_loc, d_plane)
                block[:, :, col + 1: col + 3] = a_loc
            jac[rows] = block.reshape(2 * n, self.n_params)
        return jac / self.scale


@dataclass(frozen=True)
class HomographyFit:
    """A least-squares fit of one homography (and the boards' placements) to corners.

    Attributes
    ----------
    homography : ndarray (3, 3)
        Plane mm → ideal image px.
    placements : list of ndarray (3, 3)
        Per view, its board mm → plane mm (the first is the identity).
    residuals_px : ndarray (n_views, n_corners, 2)
        Reprojected minus observed corners, px.
    jacobian : ndarray
        ∂residuals/∂parameters at the solution (for the bootstrap).
    """

    homography: np.ndarray
    placements: list[np.ndarray]
    residuals_px: np.ndarray
    jacobian: np.ndarray
    model: _JointModel = field(repr=False)
    params: np.ndarray = field(repr=False)

    @property
    def rms_px(self) -> float:
        """RMS distance between reprojected and observed corners, px."""
        return float(np.sqrt(np.mean(np.sum(self.residuals_px**2, axis=-1))))

    def view_rms_px(self) -> np.ndarray:
        """The same RMS, per view."""
        return np.sqrt(np.mean(np.sum(self.residuals_px**2, axis=-1), axis=1))

    def noise_px(self) -> float:
        """The corners' noise per coordinate, px: residual sum of squares over its degrees of freedom."""
        dof = self.residuals_px.size - len(self.params)
        return float(np.sqrt(np.sum(self.residuals_px**2) / max(dof, 1)))

    def bootstrap(self, draws: int, rng: np.random.Generator) -> np.ndarray:
        """Homographies (draws, 3, 3), plane mm → image px, re-fitted to corners with fresh noise.

        Parametric bootstrap: each draw adds independent normal noise of :meth:`noise_px`
        to every corner coordinate and re-fits by one Gauss–Newton step from the solution.
        At the solution Jᵀr = 0, so that step is ``−J⁺e``: exact to first order in the
        noise (a fraction of a pixel against a board hundreds of pixels wide), and it keeps
        200 re-fits to one pseudo-inverse.
        """
        noise = rng.normal(0.0, self.noise_px(), size=(draws, self.residuals_px.size))
        steps = -noise @ np.linalg.pinv(self.jacobian).T
        return np.array([self.model.to_mm(self.params + s)[0] for s in steps])


def _solve(model: _JointModel, p0: np.ndarray) -> np.ndarray:
    """Levenberg–Marquardt from ``p0``; the start is kept if the solver does not lower the cost."""
    from scipy.optimize import least_squares  # deferred: `import servoscope.camera` stays light

    start = float(np.sum(model.residuals(p0) ** 2))
    sol = least_squares(model.residuals, p0, jac=model.jacobian, method="lm", xtol=1e-12, ftol=1e-12, gtol=1e-12)
    better = np.all(np.isfinite(sol.x)) and float(np.sum(sol.fun**2)) <= start
    return sol.x if better else p0


def _finish(model: _JointModel, p: np.ndarray) -> HomographyFit:
    g, places = model.to_mm(p)
    res = model.residuals(p).reshape(len(places), -1, 2)
    return HomographyFit(g / np.linalg.norm(g), places, res, model.jacobian(p), model, p)


def fit_homography(board_mm: np.ndarray, corners_px: np.ndarray) -> HomographyFit:
    """One view: :func:`cv2.findHomography` (method 0), refined on the image reprojection error.

    Parameters
    ----------
    board_mm : ndarray (n, 2)
        The board's corners in its own frame, mm.
    corners_px : ndarray (n, 2)
        Where they are in the ideal image, px.

    Returns
    -------
    HomographyFit

    Raises
    ------
    ServoscopeError
        When OpenCV finds no homography (corners in a line).
    """
    g, _ = cv2.findHomography(board_mm.astype(np.float64), corners_px.astype(np.float64), 0)
    if g is None or not np.all(np.isfinite(g)):
        raise ServoscopeError("the board's corners determine no homography (are they in a line?)")
    model = _JointModel(board_mm, [corners_px], [False])
    return _finish(model, _solve(model, model.pack(g, [np.eye(3)])))


def _place(board_mm: np.ndarray, plane_mm: np.ndarray) -> tuple[np.ndarray, bool]:
    """The rigid motion (3 × 3, possibly mirrored) best taking ``board_mm`` onto ``plane_mm`` (Kabsch)."""
    mb, mp = board_mm.mean(axis=0), plane_mm.mean(axis=0)
    u, _, vt = np.linalg.svd((board_mm - mb).T @ (plane_mm - mp))
    rot = vt.T @ u.T
    out = np.eye(3)
    out[:2, :2] = rot
    out[:2, 2] = mp - rot @ mb
    return out, bool(np.linalg.det(rot) < 0)


def fit_consensus(board_mm: np.ndarray, corners_px: Sequence[np.ndarray], own: Sequence[HomographyFit]) -> HomographyFit:
    """Several views of a board moved about in one plane: one homography, one placement per view.

    Starts from the first view's own homography, each other board placed where that
    homography puts its corners, then fits all corners jointly on the image
    reprojection error.
    """
    g0 = own[0].homography
    h0 = np.linalg.inv(g0)
    places, mirrored = [np.eye(3)], [False]
    for c in corners_px[1:]:
        place, flip = _place(board_mm, apply_homography(h0, c))
        places.append(place)
        mirrored.append(flip)
    model = _JointModel(board_mm, corners_px, mirrored)
    return _finish(model, _solve(model, model.pack(g0, places)))


# -- what a fit says ---------------------------------------------------------------


def angle_gain_deviation(h_nominal: np.ndarray, h_others: np.ndarray, point: np.ndarray,
                         n_directions: int = 180) -> np.ndarray:
    """How far other maps' angle gains stray from the nominal's, for lines through ``point``.

    A line through ``point`` at direction φ in the image has angle θ(φ) after a map
    with Jacobian J there, and dθ/dφ = det J / |J u(φ)|². The gain of the nominal
    against another map is the ratio of their dθ/dφ: how much a rotation seen
    through the other map is magnified by the nominal one.

    Parameters
    ----------
    h_nominal : ndarray (3, 3)
        Image → plane.
    h_others : ndarray (k, 3, 3)
        Image → plane, each compared with the nominal.
    point : ndarray (2,)
        Image px.
    n_directions : int, optional
        Directions φ spread over [0, π).

    Returns
    -------
    ndarray (k, n_directions)
        gain − 1.
    """
    phi = np.linspace(0.0, np.pi, n_directions, endpoint=False)
    u = np.column_stack([np.cos(phi), np.sin(phi)])

    def rate(jac: np.ndarray) -> np.ndarray:
        ju = np.einsum("kab,nb->kna", jac, u)
        # |det|: a view whose corners came mirrored has the opposite orientation, not another gain.
        return np.abs(np.linalg.det(jac))[:, None] / np.sum(ju**2, axis=-1)

    nominal = rate(homography_jacobian(h_nominal, point))
    return nominal / rate(homography_jacobian(np.asarray(h_others), point)) - 1.0


def focal_squared(g: np.ndarray, principal_px: Sequence[float]) -> np.ndarray:
    """f² (px²) from a homography's orthogonality constraints, square pixels, known principal point.

    With ``K = [[f, 0, cx], [0, f, cy], [0, 0, 1]]`` the columns r1, r2 of ``K⁻¹G`` are
    orthogonal and of one length (Zhang's constraints); each is linear in f²:
    ``A + f² B = 0``. Both solved together in the least-squares sense. A fronto-parallel
    plane has B = 0: f is then not determined (NaN returned).

    Parameters
    ----------
    g : ndarray (3, 3) or (k, 3, 3)
        Plane → image.
    principal_px : (float, float)

    Returns
    -------
    ndarray, shape () or (k,)
        f², px² (may be ≤ 0 where noise dominates: then it is no focal length).
    """
    gs = np.asarray(g, dtype=np.float64)
    shift = np.array([[1.0, 0.0, -principal_px[0]], [0.0, 1.0, -principal_px[1]], [0.0, 0.0, 1.0]])
    gp = shift @ gs
    a = np.stack([gp[..., 0, 0] * gp[..., 0, 1] + gp[..., 1, 0] * gp[..., 1, 1],
                  gp[..., 0, 0] ** 2 + gp[..., 1, 0] ** 2 - gp[..., 0, 1] ** 2 - gp[..., 1, 1] ** 2])
    b = np.stack([gp[..., 2, 0] * gp[..., 2, 1], gp[..., 2, 0] ** 2 - gp[..., 2, 1] ** 2])
    bb = np.sum(b * b, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(bb > 0, -np.sum(a * b, axis=0) / bb, np.nan)


def _angle_deg(normal: np.ndarray, sight: np.ndarray) -> float:
    cos = abs(float(normal @ sight)) / (float(np.linalg.norm(normal)) * float(np.linalg.norm(sight)))
    return math.degrees(math.acos(min(1.0, cos)))


def view_angle_focal_deg(g: np.ndarray, focal_px: float, principal_px: Sequence[float],
                         centre_mm: Sequence[float]) -> float:
    """Angle between the plane's normal and the line of sight to ``centre_mm``, from G and f.

    The columns of ``K⁻¹G`` are the plane's axes and origin in the camera's frame (up to one
    scale), whether or not noise left them exactly orthonormal: the normal is their cross product.
    """
    k = np.array([[focal_px, 0.0, principal_px[0]], [0.0, focal_px, principal_px[1]], [0.0, 0.0, 1.0]])
    r1, r2, t = (np.linalg.inv(k) @ g).T
    return _angle_deg(np.cross(r1, r2), r1 * centre_mm[0] + r2 * centre_mm[1] + t)


def view_angle_affine_deg(h: np.ndarray, point_px: Sequence[float]) -> float:
    """The plane's tilt from the foreshortening at ``point_px``: arccos of the Jacobian's singular values' ratio.

    ``h`` maps image → plane. Under a locally affine (weak-perspective) view, a circle in the
    plane is seen as an ellipse whose axes' ratio is the cosine of the tilt.
    """
    sv = np.linalg.svd(homography_jacobian(h, np.asarray(point_px, float))[0], compute_uv=False)
    return math.degrees(math.acos(min(1.0, float(sv[1] / sv[0]))))


def board_pose(object_mm: np.ndarray, image_px: np.ndarray, camera_matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`cv2.solvePnP` of plane points (z = 0) seen at ideal image points: ``(rvec, tvec)``."""
    obj = np.column_stack([object_mm, np.zeros(len(object_mm))]).astype(np.float64)
    ok, rvec, tvec = cv2.solvePnP(obj, np.asarray(image_px, np.float64).reshape(-1, 1, 2), camera_matrix, None)
    if not ok:
        raise ServoscopeError("OpenCV found no pose of the board (solvePnP failed)")
    return rvec.ravel(), tvec.ravel()


def view_angle_pose_deg(rvec: np.ndarray, tvec: np.ndarray, centre_mm: Sequence[float]) -> float:
    """Angle between the plane's normal and the line of sight to ``centre_mm`` (plane z = 0), from a pose."""
    rot = cv2.Rodrigues(np.asarray(rvec, np.float64))[0]
    return _angle_deg(rot[:, 2], rot @ np.array([centre_mm[0], centre_mm[1], 0.0]) + np.asarray(tvec))


# -- what the plane is made of ------------------------------------------------------


def image_to_plane(g: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """H = G⁻¹ at unit norm, signed so that the image centre's homogeneous weight is positive."""
    h = np.linalg.inv(g)
    h /= np.linalg.norm(h)
    w = h[2] @ np.array([(size[0] - 1) / 2.0, (size[1] - 1) / 2.0, 1.0])
    return -h if w < 0 else h


def rectifying_map(h: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``S ∘ H`` (3 × 3), image px → rectified px, at unit norm.

    S is the plane's similarity fixed by three conditions at the image centre c (see
    :meth:`servoscope.camera.Plane.to_rectified`): S(H(c)) = c, det J = +1 and
    J[1, 0] = 0 with J[0, 0] > 0, where J is the Jacobian of ``S ∘ H`` at c.
    """
    c = np.array([(size[0] - 1) / 2.0, (size[1] - 1) / 2.0])
    jac = homography_jacobian(h, c)[0]
    det = float(np.linalg.det(jac))
    flip = np.diag([1.0, math.copysign(1.0, det)])  # a reflection only when the plane's frame is mirrored
    s = 1.0 / math.sqrt(abs(det))
    v = s * flip @ jac[:, 0]  # where the image's +x goes, before the rotation
    a = -math.atan2(v[1], v[0])
    lin = s * np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]]) @ flip
    sim = np.eye(3)
    sim[:2, :2] = lin
    sim[:2, 2] = c - lin @ apply_homography(h, c)[0]
    m = sim @ h
    return m / np.linalg.norm(m)


def view_angles(fit: HomographyFit, own: Sequence[HomographyFit], obs: Sequence[np.ndarray], board_mm: np.ndarray,
                 camera: CameraModel | None, centre: np.ndarray, draws: np.ndarray
                 ) -> tuple[float, list[float], str, float]:
    """(plane's view angle, each view's own, source, focal px): see :attr:`servoscope.camera.Plane.view_angle_source`.

    Every view's own estimate looks at the same point, the boards' mean centre (each
    board's own centre with one view): boards moved about in the plane are seen along
    different lines of sight, and that geometry is not a disagreement between them.
    """
    board_centre = board_mm.mean(axis=0)
    plane_centre = np.mean([apply_homography(p, board_centre)[0] for p in fit.placements], axis=0)
    # The common point in each view's own board frame.
    centres = [apply_homography(np.linalg.inv(p), plane_centre)[0] for p in fit.placements]
    if camera is not None:
        k = camera.camera_matrix
        placed = np.vstack([apply_homography(p, board_mm) for p in fit.placements])
        overall = view_angle_pose_deg(*board_pose(placed, np.vstack(obs), k), plane_centre)
        per_view = [view_angle_pose_deg(*board_pose(board_mm, c, k), m) for c, m in zip(obs, centres)]
        return overall, per_view, "calibration", float((k[0, 0] + k[1, 1]) / 2)
    f2 = float(focal_squared(fit.homography, centre))
    f2_draws = focal_squared(draws, centre)
    # The data determine f when the corners' own noise moves f² by well under itself.
    if f2 > 0 and np.all(np.isfinite(f2_draws)) and float(np.std(f2_draws)) <= FOCAL_MAX_REL_SPREAD * f2:
        f = math.sqrt(f2)
        overall = view_angle_focal_deg(fit.homography, f, centre, plane_centre)
        per_view = [view_angle_focal_deg(o.homography, f, centre, m) for o, m in zip(own, centres)]
        return overall, per_view, "homography", f
    overall = view_angle_affine_deg(np.linalg.inv(fit.homography), centre)
    per_view = [view_angle_affine_deg(np.linalg.inv(o.homography), centre) for o in own]
    return overall, per_view, "affine", float("nan")


def angle_gain_std(h: np.ndarray, draws: np.ndarray, own: Sequence[HomographyFit], centre: np.ndarray) -> float:
    """Relative 1σ of a measured angle: the bootstrap's RMS of (gain − 1) over draws and directions.

    With several views, their spread is added in quadrature: each view's own homography's
    gain against the consensus, RMS over directions, summed over views / (n − 1). That is
    one view's scatter, not the consensus's standard error (÷ n): the views' disagreement
    is as likely a model error shared by all of them (a bent board, a lens left
    uncorrected) as independent noise, so it is not averaged away.
    """
    boot = angle_gain_deviation(h, np.linalg.inv(draws), centre)
    var = float(np.mean(boot**2))
    if len(own) > 1:
        dev = angle_gain_deviation(h, np.linalg.inv(np.array([o.homography for o in own])), centre)
        var += float(np.sum(np.mean(dev**2, axis=1)) / (len(own) - 1))
    return math.sqrt(var)

"""How far off square the camera looks at the blade's plane, told by the footage alone (issue 27).

A camera that does not face the blade's plane square-on changes the angles it sees. Near the
blade, the view is an affine map ``A`` of the plane (the local Jacobian of the plane's
homography): the vector from the trail to the lead sticker, a fixed length ``L`` on the
blade, is seen as ``v = A·u(θ)``, so the vectors of every frame lie on the ellipse
``vᵀ·M·v = L²`` with ``M = A⁻ᵀA⁻¹``. A square-on camera's ellipse is a circle. The
difference ``v`` of two points placed symmetrically about their midpoint is the Jacobian at
the midpoint times their difference, up to third order: perspective across the blade cancels.

What does not cancel is the midpoint's own depth: as the blade pitches, the midpoint moves on
an arc about the pivot, nearer and farther, and the whole picture of the blade scales with it.
A scale leaves angles alone but changes the separation in step with the angle, as an oblique
view would. The stickers' soft areas tell that scale (a sticker's area is its Jacobian's
determinant times its own, whatever its orientation): ``log(area_lead·area_trail)`` is fitted as
a linear function of the midpoint's position and the separation vectors are divided by the
scale it gives before the ellipse is fitted.

The ellipse is fitted by linear least squares (``a·vx² + 2b·vx·vy + c·vy² = 1``); the
parameters' covariance from the residuals, inflated for their correlation from frame to frame
(an AR(1) long-run variance), is sampled (seeded) to give the view angle's and the angle
gain's intervals. A blade that turns little draws a short arc of the ellipse, which does not
determine it: the intervals then say so, and :attr:`ObliqueView.determined` is False.

From ``M`` (scaled to determinant 1, ``Mₙ``):

* the view angle α off square: ``cos α = √(λmin/λmax)``;
* the angle gain of the image near the blade's direction ``d`` (a unit vector): an angle seen
  in the image is ``dᵀMₙd`` times the angle in the plane (less than 1: the camera looks across
  the blade and angles read small);
* the affine correction ``Mₙ^½`` (symmetric, determinant 1): image points mapped by it lie in
  a copy of the plane up to a rotation; perspective is not corrected by it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["ObliqueView", "oblique_view", "OBLIQUE_MIN_FRAMES"]

#: Fewer valid frames than this and the view is not estimated.
OBLIQUE_MIN_FRAMES = 30
#: Draws of the ellipse's parameters for the intervals (seeded: the same footage, the same answer).
_DRAWS = 4000
_SEED = 27


@dataclass(frozen=True)
class ObliqueView:
    """The camera's view of the blade's plane, as the markers' separation tells it.

    Attributes
    ----------
    view_angle_deg : float
        The angle between the plane's normal and the camera's line of sight (0: square-on).
    view_angle_ci95_deg : (float, float)
        Its 95 % interval (from the fit's sampled covariance).
    axis_deg : float
        The image direction the view foreshortens, counter-clockwise from +x as seen (deg).
    angle_gain : float
        Angles seen in the image per angle in the plane, near the blade's mean direction
        (1: square-on; 0.94: the image reads angles 6 % small).
    angle_gain_ci95 : (float, float)
        Its 95 % interval.
    swing_deg : float
        How far the blade turned over the frames used (the ellipse's arc, deg).
    n_frames : int
        Frames the fit used.
    determined : bool
        Whether the footage tells the view: the view angle's interval narrower than 10° and
        the angle gain's than 2 % (a longer arc is needed otherwise).
    correction : ndarray, shape (2, 2)
        ``Mₙ^½``: image vectors to the plane's, up to a rotation (determinant 1).
    scale_gradient_per_px : (float, float)
        The picture's relative scale change per px of the midpoint's motion (from the stickers'
        areas), taken out before the ellipse was fitted.
    """

    view_angle_deg: float
    view_angle_ci95_deg: tuple[float, float]
    axis_deg: float
    angle_gain: float
    angle_gain_ci95: tuple[float, float]
    swing_deg: float
    n_frames: int
    determined: bool
    correction: np.ndarray
    scale_gradient_per_px: tuple[float, float]

    def summary(self) -> dict:
        """Plain-typed fields, as result.json and ``servoscope track --json`` hold them."""
        return {
            "view_angle_deg": self.view_angle_deg,
            "view_angle_ci95_deg": list(self.view_angle_ci95_deg),
            "axis_deg": self.axis_deg,
            "angle_gain": self.angle_gain,
            "angle_gain_ci95": list(self.angle_gain_ci95),
            "swing_deg": self.swing_deg,
            "n_frames": self.n_frames,
            "determined": self.determined,
            "correction": self.correction.tolist(),
            "scale_gradient_per_px": list(self.scale_gradient_per_px),
        }

    @classmethod
    def from_summary(cls, data: dict) -> "ObliqueView":
        """Read back :meth:`summary`'s dict (result.json's ``view``)."""
        return cls(view_angle_deg=float(data["view_angle_deg"]),
                   view_angle_ci95_deg=tuple(float(v) for v in data["view_angle_ci95_deg"]),  # type: ignore[arg-type]
                   axis_deg=float(data["axis_deg"]), angle_gain=float(data["angle_gain"]),
                   angle_gain_ci95=tuple(float(v) for v in data["angle_gain_ci95"]),  # type: ignore[arg-type]
                   swing_deg=float(data["swing_deg"]), n_frames=int(data["n_frames"]),
                   determined=bool(data["determined"]), correction=np.asarray(data["correction"], dtype=np.float64),
                   scale_gradient_per_px=tuple(float(v) for v in data["scale_gradient_per_px"]))  # type: ignore[arg-type]

    def describe(self) -> str:
        """One sentence: the view angle, its interval, what it does to angles."""
        lo, hi = self.view_angle_ci95_deg
        gain = self.angle_gain - 1.0
        sense = "small" if gain < 0 else "large"
        return (f"the camera looks at the blade {self.view_angle_deg:.0f}° off square (95 %: {lo:.0f}–{hi:.0f}°, "
                f"from the markers' separation over a {self.swing_deg:.1f}° swing): angles read about "
                f"{abs(100.0 * gain):.1f} % {sense}")


def _ar1_inflation(resid: np.ndarray, segments: np.ndarray) -> float:
    """Long-run over white variance of residuals correlated from frame to frame (AR(1): (1+ρ)/(1−ρ))."""
    same = segments[1:] == segments[:-1]
    r = resid - resid.mean()
    den = float(r @ r)
    if den <= 0 or not same.any():
        return 1.0
    rho = float(np.sum(r[1:][same] * r[:-1][same])) / den * (r.size / max(int(same.sum()), 1))
    rho = min(max(rho, 0.0), 0.98)
    return (1.0 + rho) / (1.0 - rho)


def _square_on_within_95(m: np.ndarray, cov: np.ndarray) -> bool:
    """Whether a circle (a = c, b = 0) lies inside the fit's 95 % region (χ² with 2 degrees of freedom)."""
    # The anisotropy (a − c, 2b) is linear in the parameters: its covariance follows exactly.
    t = np.array([[1.0, 0.0, -1.0], [0.0, 2.0, 0.0]])
    e = t @ m
    ce = t @ cov @ t.T
    try:
        d2 = float(e @ np.linalg.solve(ce, e))
    except np.linalg.LinAlgError:
        return True
    return d2 <= 5.991


def _normalised(m: np.ndarray) -> np.ndarray | None:
    """``[a, b, c]`` rows as 2×2 matrices scaled to determinant 1; None where not positive definite."""
    a, b, c = m[..., 0], m[..., 1], m[..., 2]
    det = a * c - b * b
    ok = (det > 0) & (a > 0)
    s = np.where(ok, 1.0 / np.sqrt(np.where(ok, det, 1.0)), np.nan)
    return np.stack([np.stack([a * s, b * s], -1), np.stack([b * s, c * s], -1)], -2)


def _angle_and_gain(mn: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """View angle (deg) and angle gain ``dᵀMₙd`` of determinant-1 matrices (…, 2, 2)."""
    tr = mn[..., 0, 0] + mn[..., 1, 1]
    # Eigenvalues λ and 1/λ of a determinant-1 matrix: λ + 1/λ = trace.
    lam_max = 0.5 * (tr + np.sqrt(np.maximum(tr * tr - 4.0, 0.0)))
    cos_a = np.clip(1.0 / lam_max, 0.0, 1.0)  # √(λmin/λmax) = 1/λmax
    gain = np.einsum("i,...ij,j->...", d, mn, d)
    return np.degrees(np.arccos(cos_a)), gain


def oblique_view(lead_xy_px: np.ndarray, trail_xy_px: np.ndarray, valid: np.ndarray, *,
                 lead_area_px: np.ndarray | None = None, trail_area_px: np.ndarray | None = None,
                 segment: np.ndarray | None = None) -> ObliqueView | None:
    """Estimate the camera's view of the blade's plane from the markers' separation.

    Parameters
    ----------
    lead_xy_px, trail_xy_px : ndarray, shape (n, 2)
        Centroids (undistorted when a lens model is known), px.
    valid : ndarray of bool, shape (n,)
    lead_area_px, trail_area_px : ndarray, shape (n,), optional
        The stickers' soft areas (px²), to take out the picture's scale change as the blade's
        midpoint moves nearer and farther (see the module's notes); None: not taken out.
    segment : ndarray of int, shape (n,), optional
        Which recording each frame comes from (several tracks pooled): frame-to-frame
        correlation is measured within a segment only.

    Returns
    -------
    ObliqueView or None
        None with fewer than :data:`OBLIQUE_MIN_FRAMES` valid frames.
    """
    lead = np.asarray(lead_xy_px, dtype=np.float64).reshape(-1, 2)
    trail = np.asarray(trail_xy_px, dtype=np.float64).reshape(-1, 2)
    ok = np.asarray(valid, dtype=bool) & np.all(np.isfinite(lead), axis=1) & np.all(np.isfinite(trail), axis=1)
    seg = np.zeros(lead.shape[0], dtype=np.int64) if segment is None else np.asarray(segment)
    if np.count_nonzero(ok) < OBLIQUE_MIN_FRAMES:
        return None
    v = (lead - trail)[ok]
    mid = 0.5 * (lead + trail)[ok]
    seg = seg[ok]
    grad = np.zeros(2)
    if lead_area_px is not None and trail_area_px is not None:
        log_area = np.log(np.asarray(lead_area_px, dtype=np.float64)[ok] * np.asarray(trail_area_px)[ok])
        use = np.isfinite(log_area)
        dm = mid - mid[use].mean(axis=0) if use.any() else mid * 0.0
        if np.count_nonzero(use) >= OBLIQUE_MIN_FRAMES and float(np.ptp(dm[use], axis=0).max()) > 1.0:
            design = np.c_[np.ones(int(use.sum())), dm[use]]
            coef = np.linalg.lstsq(design, log_area[use], rcond=None)[0]
            # log(area_l·area_t) ≈ 4·log(scale): the separation scales by exp(g·dm/4).
            grad = coef[1:] / 4.0
            v = v * np.exp(-(dm @ grad))[:, None]
    q = np.c_[v[:, 0] ** 2, 2.0 * v[:, 0] * v[:, 1], v[:, 1] ** 2]
    scale = float(np.mean(np.sum(v * v, axis=1)))
    qn = q / scale  # well conditioned: ~1 per row
    m, *_ = np.linalg.lstsq(qn, np.ones(len(qn)), rcond=None)
    resid = qn @ m - 1.0
    dof = max(len(qn) - 3, 1)
    sigma2 = float(resid @ resid) / dof * _ar1_inflation(resid, seg)
    cov = sigma2 * np.linalg.pinv(qn.T @ qn)
    theta = np.unwrap(np.arctan2(-v[:, 1], v[:, 0]))
    d_angle = float(np.median(theta))
    d = np.array([math.cos(d_angle), -math.sin(d_angle)])
    mn = _normalised(m[None])[0]
    if not np.all(np.isfinite(mn)):
        return None
    angle, gain = (float(x) for x in _angle_and_gain(mn, d))
    rng = np.random.default_rng(_SEED)
    draws = rng.multivariate_normal(m, cov, size=_DRAWS, method="eigh")
    mns = _normalised(draws)
    a_d, g_d = _angle_and_gain(mns, d)
    fine = np.isfinite(a_d) & np.isfinite(g_d)
    # A draw that is no ellipse at all (an arc too short to tell) counts as "anything".
    a_d = np.where(fine, a_d, 90.0)
    a_lo, a_hi = (float(x) for x in np.percentile(a_d, [2.5, 97.5]))
    if _square_on_within_95(m, cov):
        a_lo = 0.0  # the angle is a magnitude: its draws never reach 0, but a circle is not excluded
    if fine.mean() > 0.975:
        g_lo, g_hi = (float(x) for x in np.percentile(g_d[fine], [2.5, 97.5]))
    else:
        g_lo, g_hi = 0.0, math.inf
    w, vecs = np.linalg.eigh(mn)
    root = (vecs * np.sqrt(w)) @ vecs.T
    axis = vecs[:, 1]  # the largest eigenvalue's: the image direction that came out shortest
    return ObliqueView(
        view_angle_deg=angle,
        view_angle_ci95_deg=(min(a_lo, angle), max(a_hi, angle)),
        axis_deg=float(np.degrees(np.arctan2(-axis[1], axis[0])) % 180.0),
        angle_gain=gain,
        angle_gain_ci95=(min(g_lo, gain), max(g_hi, gain)),
        swing_deg=float(np.degrees(np.ptp(theta))),
        n_frames=int(len(v)),
        determined=bool(a_hi - a_lo < 10.0 and g_hi - g_lo < 0.02),
        correction=root,
        scale_gradient_per_px=(float(grad[0]), float(grad[1])),
    )

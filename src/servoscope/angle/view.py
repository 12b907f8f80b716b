"""How the camera sees the blade's plane, told by the stickers themselves (issue 27).

A camera that does not face the blade's plane square-on changes the angles it sees: by
foreshortening (the cosine of the view angle across the blade) and by perspective (the nearer
sticker looks bigger and moves more: with the twin's default stickers 600 px apart at a focal
length of 1100 px, 10° of yaw changes the angles' scale by −1.3 %, where foreshortening alone
would say +1.5 %). Both are in the map ``G`` from the image to the plane, a homography.

The stickers measure ``G`` where they are, in every frame: a round (or square) sticker has
isotropic second moments in the plane, so the ellipse its image draws (the soft membership's
second moments, :attr:`~servoscope.markers.Track.lead_shape_px2`) is the local Jacobian of the
view, and its area is that Jacobian's determinant times the sticker's own area. Two stickers
a chord apart, each seen in many frames, give the Jacobian at two places, which tells the
affine part (foreshortening: 2 numbers) and the projective part (perspective: 2 numbers) of
``G`` up to a similarity of the plane, which does not change angles. The fit:

* ``G = U·P`` in image coordinates centred on the blade and scaled by the stickers' separation,
  ``P(x) = x / (1 + g·x)`` and ``U = [[p, q], [0, 1]]`` (4 parameters), plus the stickers' common
  area in the plane (the stickers are assumed to be the same size, as one punch cuts them);
* per sticker and frame, three residuals: the anisotropy of ``J·M·Jᵀ`` (2 numbers, 0 for a round
  sticker) and the log of its area in the plane less the common one;
* frames where a sticker moved less than :data:`SLOW_PX` between frames (motion blur stretches
  the moments along the motion), each residual kind weighted by its own scatter; the
  covariance inflated for the residuals' correlation from frame to frame, and sampled (seeded)
  for the intervals, to which the systematic errors measured on the twin are added
  (:data:`VIEW_SYSTEMATIC_DEG`, :data:`GAIN_SYSTEMATIC`, :data:`GAIN_SYSTEMATIC_FRACTION`): the
  tracker's moments carry a small anisotropy of their own (a square-on camera reads 4°), and the
  perspective's share of the gain read 13 % short at 30° off square.

From ``G``: the view angle at the blade, ``arccos(σmin/σmax)`` of its Jacobian; the angle gain,
the slope of the image's angles against the plane's over the frames; the correction, ``G``
followed by the similarity that keeps the blade's midpoint, its scale and the image's +x
(a homography from image px to the plane's rectified px, as a board photo's plane gives).

Stickers that are not isotropic (strips, rectangles) carry their own anisotropy, which turns
with the blade: the fit's anisotropy residuals then follow the blade's angle, and the view is
reported as not told (:attr:`ObliqueView.determined` False).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ..camera.plane_fit import apply_homography, homography_jacobian
from ..parameters import interval95

__all__ = ["ObliqueView", "OBLIQUE_MIN_FRAMES", "SLOW_PX", "oblique_view"]

#: Fewer usable frames than this and the view is not estimated.
OBLIQUE_MIN_FRAMES = 30
#: A sticker that moved less than this between neighbouring frames (px) is taken as sharp: a
#: blur of 0.3 px adds 0.3²/12 px² to a 26 px sticker's 42 px² second moment (0.02 %).
SLOW_PX = 0.3
#: Frames the fit uses at most (spread evenly over those that qualify).
_MAX_FRAMES = 3000
#: Systematic errors of the estimate, measured on the twin's raw footage (480×384, quick preset, round
#: stickers; docs/accuracy.md "Oblique views"): a square-on camera read 4° (3–5°) off square, 23.7° read
#: 23.0°, 30.4° read 28°; the angle gain's effect read 13 % short at 30° off square (+20.1 % for +23 %)
#: and 0.2 % off square-on. The intervals add them to the fit's own (in quadrature).
VIEW_SYSTEMATIC_DEG = 4.0
GAIN_SYSTEMATIC = 0.003
GAIN_SYSTEMATIC_FRACTION = 0.2
#: The stickers' radius (px) those were measured at (17 and 26 px stickers read alike); a smaller
#: sticker's moments carry more of the pixel grid's anisotropy (the monochrome twin's 12 px dots
#: read 9–12° square-on): the two additive systematics grow as (this / radius)².
SYSTEMATIC_RADIUS_PX = 8.7
#: Frames the angle gain's slope is taken over, for each draw (draws × frames stay a few MB).
_GAIN_FRAMES = 400
#: Draws of the fitted parameters for the intervals (seeded: the same footage, the same answer).
_DRAWS = 1000
_SEED = 27


@dataclass(frozen=True)
class ObliqueView:
    """The camera's view of the blade's plane, as the stickers' shapes and sizes tell it.

    Attributes
    ----------
    view_angle_deg : float
        The angle between the plane's normal and the line of sight at the blade (0: square-on).
    view_angle_ci95_deg : (float, float)
        Its 95 % interval.
    axis_deg : float
        The image direction the view foreshortens most, counter-clockwise from +x (deg).
    angle_gain : float
        Angles seen in the image per angle in the plane where the blade spends its time (its
        median angle; 1: square-on; 0.94: the image reads angles 6 % small), foreshortening and
        perspective together.
    angle_gain_ci95 : (float, float)
        Its 95 % interval.
    swing_deg : float
        How far the blade turned over the frames used (deg).
    n_frames : int
        Frames the fit used.
    determined : bool
        Whether the footage tells the view: enough sharp frames, and stickers that look alike
        in the plane whatever the blade's angle (round or square ones).
    correction : ndarray, shape (3, 3)
        The homography from image px to the plane's rectified px (the blade's midpoint kept,
        its scale and the image's +x direction kept).
    why : str
        What the estimate rests on, or why it is not told.
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
    why: str = ""

    def summary(self) -> dict:
        """Plain-typed fields, as result.json holds them."""
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
            "why": self.why,
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
                   why=str(data.get("why", "")))

    def describe(self) -> str:
        """One sentence: the view angle, its interval, what it does to angles."""
        lo, hi = self.view_angle_ci95_deg
        gain = self.angle_gain - 1.0
        glo, ghi = (100.0 * (g - 1.0) for g in self.angle_gain_ci95)
        sense = "small" if gain < 0 else "large"
        return (f"the camera looks at the blade {self.view_angle_deg:.0f}° off square (95 %: {lo:.0f}–{hi:.0f}°, "
                f"from the stickers' shapes and sizes): angles read about {abs(100.0 * gain):.1f} % {sense} "
                f"(95 %: {glo:+.1f} to {ghi:+.1f} %)")


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


def _square_on_within_95(theta: np.ndarray, cov: np.ndarray) -> bool:
    """Whether the square-on view (p = 1, q = g1 = g2 = 0) lies inside the fit's 95 % region (χ², 4 d.o.f.)."""
    e = theta - np.array([1.0, 0.0, 0.0, 0.0])
    try:
        d2 = float(e @ np.linalg.solve(cov, e))
    except np.linalg.LinAlgError:
        return True
    return d2 <= 9.488


def _map(theta: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``G(x)`` and its Jacobian (…, 2, 2) for parameters ``(p, q, g1, g2)`` at normalised points (…, 2)."""
    # Parameters broadcast against the points' leading shape (a row per draw, or one set for all).
    p, q, g1, g2 = theta[..., 0], theta[..., 1], theta[..., 2], theta[..., 3]
    w = 1.0 + g1 * x[..., 0] + g2 * x[..., 1]
    px, py = x[..., 0] / w, x[..., 1] / w
    out = np.stack([p * px + q * py, py], axis=-1)
    # J_P = (I·w − x·gᵀ)/w², then J = U·J_P.
    jp = np.empty(x.shape[:-1] + (2, 2))
    jp[..., 0, 0] = (w - x[..., 0] * g1) / w**2
    jp[..., 0, 1] = (-x[..., 0] * g2) / w**2
    jp[..., 1, 0] = (-x[..., 1] * g1) / w**2
    jp[..., 1, 1] = (w - x[..., 1] * g2) / w**2
    jac = np.empty_like(jp)
    jac[..., 0, :] = p[..., None] * jp[..., 0, :] + q[..., None] * jp[..., 1, :]
    jac[..., 1, :] = jp[..., 1, :]
    return out, jac


def _residuals(params: np.ndarray, x: np.ndarray, moments: np.ndarray, log_area: np.ndarray,
               scale: np.ndarray) -> np.ndarray:
    """Per observation: the anisotropy of the sticker in the plane (2) and its log area less the common one.

    (The tracker's soft membership adds about 1 px² of isotropic spread in the recorded picture,
    which an oblique view turns anisotropic in the plane; fitted as a parameter it traded with the
    view's own anisotropy and doubled a square-on camera's reading, 4° to 8°: it is left to the
    systematics.)
    """
    _, jac = _map(params[:4], x)
    m = jac @ moments @ np.swapaxes(jac, -1, -2)
    tr = m[:, 0, 0] + m[:, 1, 1]
    det = np.abs(jac[:, 0, 0] * jac[:, 1, 1] - jac[:, 0, 1] * jac[:, 1, 0])
    return np.concatenate([((m[:, 0, 0] - m[:, 1, 1]) / tr) / scale[0], (2.0 * m[:, 0, 1] / tr) / scale[0],
                           (log_area + np.log(det) - params[4]) / scale[1]])


def _points(theta: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``G(x)`` alone (no Jacobian: the draws × frames arrays stay small), parameters broadcast as in :func:`_map`."""
    p, q, g1, g2 = theta[..., 0], theta[..., 1], theta[..., 2], theta[..., 3]
    w = 1.0 + g1 * x[..., 0] + g2 * x[..., 1]
    return np.stack([(p * x[..., 0] + q * x[..., 1]) / w, x[..., 1] / w], axis=-1)


def _angles(theta: np.ndarray, lead_n: np.ndarray, trail_n: np.ndarray) -> np.ndarray:
    """The blade's angle in the plane for each parameter row (d, 4) and frame (n): shape (d, n)."""
    d = _points(theta[:, None, :], lead_n[None]) - _points(theta[:, None, :], trail_n[None])
    return np.unwrap(np.arctan2(d[..., 1], d[..., 0]), axis=-1)  # y up in the normalised frame


def _slow(xy: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """Frames where the sticker moved less than :data:`SLOW_PX` from both neighbours (same recording)."""
    step = np.full(len(xy), np.inf)
    d = np.hypot(*np.diff(xy, axis=0).T)
    d = np.where(ok[1:] & ok[:-1], d, np.inf)
    step[1:] = d
    after = np.full(len(xy), np.inf)
    after[:-1] = d
    return ok & (np.maximum(step, after) < SLOW_PX)


def _correction(theta: np.ndarray, c0: np.ndarray, s0: float, mid_px: np.ndarray) -> np.ndarray:
    """The homography image px → rectified px: normalise, ``G``, then the similarity that keeps the blade's midpoint."""
    p, q, g1, g2 = theta
    norm = np.array([[1.0 / s0, 0.0, -c0[0] / s0], [0.0, -1.0 / s0, c0[1] / s0], [0.0, 0.0, 1.0]])
    g = np.array([[p, q, 0.0], [0.0, 1.0, 0.0], [g1, g2, 1.0]]) @ norm
    at = apply_homography(g, mid_px)[0]
    jac = homography_jacobian(g, mid_px)[0]  # image px in, plane units with y up out
    flip = np.diag([1.0, -1.0])  # back to y down
    qm, r = np.linalg.qr(flip @ jac)
    signs = np.sign(np.diag(r))
    qm, r = qm * signs, signs[:, None] * r
    s = 1.0 / math.sqrt(abs(r[0, 0] * r[1, 1]))
    lin = s * qm.T @ flip
    t = mid_px - lin @ at
    return np.array([[lin[0, 0], lin[0, 1], t[0]], [lin[1, 0], lin[1, 1], t[1]], [0.0, 0.0, 1.0]]) @ g


def _intervals(theta: np.ndarray, cov: np.ndarray, lead_n: np.ndarray, trail_n: np.ndarray, seen: np.ndarray,
               where: np.ndarray, at: float, small: float = 1.0
               ) -> tuple[tuple[float, float, float], tuple[float, float, float], np.ndarray]:
    """The view angle at ``where`` and the angle gain, each (value, 95 % low, high), from sampled parameters.

    The fit's covariance is sampled (seeded); the measured systematics are added to the sampled
    half-widths in quadrature (``small`` times the additive ones: small stickers). Also returns the
    Jacobian at ``where`` for every draw (the first row the fit's own).
    """
    rng = np.random.default_rng(_SEED)
    draws = np.vstack([theta[:4], rng.multivariate_normal(theta[:4], cov[:4, :4], size=_DRAWS, method="eigh")])
    # The gain is a slope over the swing: a few hundred frames spread over it tell it as well as all.
    pick = np.linspace(0, len(seen) - 1, min(len(seen), _GAIN_FRAMES)).astype(int)
    lead_n, trail_n, seen = lead_n[pick], trail_n[pick], seen[pick]
    in_plane = _angles(draws, lead_n, trail_n)
    span = float(np.ptp(seen))
    # The gain changes along the swing (perspective): taken where the blade spends its time (``at``,
    # the median image angle of every valid frame: the dwells about the rest angle, whose amplitudes
    # give K), as the slope there of a quadratic through the sharp frames.
    # One least-squares solve for every draw at once (a column each): the per-draw fits cost ~0.1 s.
    gains = 1.0 / np.polyfit(seen - at, in_plane.T, 2)[1] if span > 1e-4 else np.ones(draws.shape[0])
    _, jmid = _map(draws[:, None, :], np.broadcast_to(where, (draws.shape[0], 1, 2)))
    sv = np.linalg.svd(jmid[:, 0], compute_uv=False)
    angles = np.degrees(np.arccos(np.clip(sv[:, 1] / sv[:, 0], 0.0, 1.0)))
    a_lo, a_hi = (float(v) for v in np.percentile(angles[1:], [2.5, 97.5]))
    a0 = float(angles[0])
    # A systematic error σ widens each half width by its own 95 % half width (the normal interval's).
    a_sys = interval95(0.0, small * VIEW_SYSTEMATIC_DEG, "normal")[1]
    a_lo = a0 - math.hypot(a0 - a_lo, a_sys)
    a_hi = a0 + math.hypot(a_hi - a0, a_sys)
    if a_lo <= 0.0 or _square_on_within_95(theta[:4], cov[:4, :4]):
        a_lo = 0.0  # the angle is a magnitude: its draws never reach 0, but a square-on view is not excluded
    g_lo, g_hi = (float(v) for v in np.percentile(gains[1:], [2.5, 97.5]))
    g0 = float(gains[0])
    sys_gain = small * GAIN_SYSTEMATIC + GAIN_SYSTEMATIC_FRACTION * abs(g0 - 1.0)
    g_sys = interval95(0.0, sys_gain, "normal")[1]
    g_lo = g0 - math.hypot(g0 - g_lo, g_sys)
    g_hi = g0 + math.hypot(g_hi - g0, g_sys)
    return (a0, a_lo, a_hi), (g0, g_lo, g_hi), jmid


def oblique_view(lead_xy_px: np.ndarray, trail_xy_px: np.ndarray, lead_moments_px2: np.ndarray,
                 trail_moments_px2: np.ndarray, lead_area_px: np.ndarray, trail_area_px: np.ndarray,
                 valid: np.ndarray, *, segment: np.ndarray | None = None,
                 centre_px: tuple[float, float] | None = None, lead_to_frame: np.ndarray | None = None,
                 trail_to_frame: np.ndarray | None = None) -> ObliqueView | None:
    """Estimate the camera's view of the blade's plane from the stickers' shapes and sizes.

    Parameters
    ----------
    lead_xy_px, trail_xy_px : ndarray, shape (n, 2)
        Centroids, in the frame the moments are given in (y down).
    lead_moments_px2, trail_moments_px2 : ndarray, shape (n, 2, 2)
        Each sticker's central second moments over its area (px²), as the tracker measured them
        in the recorded picture.
    lead_area_px, trail_area_px : ndarray, shape (n,)
        Their areas (px²), in that frame.
    valid : ndarray of bool, shape (n,)
    segment : ndarray of int, shape (n,), optional
        Which recording each frame comes from (several tracks pooled): neighbours and the
        residuals' correlation are taken within a recording only.
    lead_to_frame, trail_to_frame : ndarray, shape (n, 2, 2), optional
        The local Jacobian from the recorded picture to the centroids' frame at each sticker
        (the lens's inverse, the plane's map); None: the identity.
    centre_px : (float, float), optional
        The principal point (the picture's centre when no calibration says otherwise), in the
        centroids' frame: the view angle is the one there (the optical axis's with the plane's
        normal, what a tripod's yaw and tilt set). None: at the blade's midpoint.

    Returns
    -------
    ObliqueView or None
        None with fewer than :data:`OBLIQUE_MIN_FRAMES` sharp frames.
    """
    lead = np.asarray(lead_xy_px, dtype=np.float64).reshape(-1, 2)
    trail = np.asarray(trail_xy_px, dtype=np.float64).reshape(-1, 2)
    n = lead.shape[0]
    seg = np.zeros(n, dtype=np.int64) if segment is None else np.asarray(segment)
    mom = [np.asarray(m, dtype=np.float64).reshape(-1, 2, 2) for m in (lead_moments_px2, trail_moments_px2)]
    area = [np.asarray(a, dtype=np.float64).reshape(-1) for a in (lead_area_px, trail_area_px)]
    ok = np.asarray(valid, dtype=bool) & np.all(np.isfinite(lead), axis=1) & np.all(np.isfinite(trail), axis=1)
    for m, a in zip(mom, area):
        ok &= np.all(np.isfinite(m), axis=(1, 2)) & np.isfinite(a) & (a > 0) & (m[:, 0, 0] > 0) & (m[:, 1, 1] > 0)
    cut = np.r_[True, seg[1:] != seg[:-1]]
    ok_n = ok & ~cut & ~np.r_[cut[1:], True]  # a recording's ends have one neighbour only
    use = _slow(lead, ok_n) & _slow(trail, ok_n)
    if np.count_nonzero(use) < OBLIQUE_MIN_FRAMES:
        return None
    idx = np.flatnonzero(use)
    idx = idx[np.linspace(0, idx.size - 1, min(idx.size, _MAX_FRAMES)).astype(int)]
    mid = 0.5 * (lead[idx] + trail[idx])
    c0 = np.median(mid, axis=0)
    s0 = float(np.median(np.hypot(*(lead[idx] - trail[idx]).T)))
    flip = np.diag([1.0, -1.0])

    def norm(xy):
        return ((xy - c0) / s0) * np.array([1.0, -1.0])

    x = np.concatenate([norm(lead[idx]), norm(trail[idx])])
    to = [np.tile(np.eye(2), (n, 1, 1)) if t is None else np.asarray(t, dtype=np.float64).reshape(-1, 2, 2)
          for t in (lead_to_frame, trail_to_frame)]
    # The moments carried into the positions' frame, y up.
    moments = np.concatenate([flip @ t[idx] @ m[idx] @ np.swapaxes(t[idx], -1, -2) @ flip for m, t in zip(mom, to)])
    log_area = np.log(np.concatenate([area[0][idx], area[1][idx]]))
    start = np.array([1.0, 0.0, 0.0, 0.0, float(np.mean(log_area))])
    scale = np.ones(2)
    sol = least_squares(_residuals, start, args=(x, moments, log_area, scale), method="lm")
    r = sol.fun
    k = idx.size
    aniso, size = r[:4 * k], r[4 * k:]
    # Each kind of residual weighted by its own scatter (robust), then fitted again.
    scale = np.array([max(1.4826 * float(np.median(np.abs(aniso - np.median(aniso)))), 1e-6),
                      max(1.4826 * float(np.median(np.abs(size - np.median(size)))), 1e-6)])
    sol = least_squares(_residuals, sol.x, args=(x, moments, log_area, scale), method="lm")
    theta = sol.x
    # Six blocks of residuals (two kinds of anisotropy and the size, for each sticker): neighbours within one.
    seg_obs = np.concatenate([seg[idx] + b * (int(seg.max()) + 1) for b in range(6)])
    inflation = _ar1_inflation(sol.fun, seg_obs)
    jtj = sol.jac.T @ sol.jac
    dof = max(sol.fun.size - theta.size, 1)
    cov = np.linalg.pinv(jtj) * float(sol.fun @ sol.fun) / dof * inflation
    seen = np.unwrap(np.arctan2(trail[idx, 1] - lead[idx, 1], lead[idx, 0] - trail[idx, 0]))
    span = float(np.ptp(seen))
    where = norm(np.asarray(centre_px, dtype=np.float64)[None] if centre_px is not None else c0[None])[0]
    radius = math.sqrt(float(np.median(np.concatenate([area[0][idx], area[1][idx]]))) / math.pi)
    small = max(1.0, (SYSTEMATIC_RADIUS_PX / radius) ** 2)
    every = np.unwrap(np.arctan2(trail[ok, 1] - lead[ok, 1], lead[ok, 0] - trail[ok, 0]))
    # On the sharp frames' branch of the unwrapped angle.
    at = float(np.median(every)) + 2.0 * np.pi * round((float(np.median(seen)) - float(np.median(every))) / (2 * np.pi))
    (a0, a_lo, a_hi), (g0, g_lo, g_hi), jmid = _intervals(theta, cov, norm(lead[idx]), norm(trail[idx]), seen, where,
                                                          at, small)
    _, vecs = np.linalg.eigh(jmid[0, 0].T @ jmid[0, 0])
    axis = flip @ vecs[:, 1]  # the image direction the plane stretches most: the one the view shortened
    # Stickers that are not isotropic in the plane turn their anisotropy with the blade: it follows the angle.
    both = np.r_[seen, seen]
    turning = max(abs(float(np.corrcoef(both, sol.fun[j * 2 * k:(j + 1) * 2 * k])[0, 1])) for j in (0, 1)) \
        if span > 1e-3 else 0.0
    fine = turning < 0.5
    why = (f"{k} sharp frames of both stickers (the stickers taken as round or square, one size)"
           if fine else "the stickers' shapes change with the blade's angle: not round or square stickers")
    return ObliqueView(
        view_angle_deg=a0,
        view_angle_ci95_deg=(a_lo, a_hi),
        axis_deg=float(np.degrees(np.arctan2(-axis[1], axis[0])) % 180.0),
        angle_gain=g0,
        angle_gain_ci95=(g_lo, g_hi),
        swing_deg=float(np.degrees(span)),
        n_frames=int(k),
        determined=bool(fine),
        correction=_correction(theta[:4], c0, s0, np.median(mid, axis=0)),
        why=why,
    )

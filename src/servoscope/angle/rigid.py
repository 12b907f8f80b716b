"""The blade's rigid motion fitted to any number of markers, and each marker's bending from it (issue 18).

Two markers give the pitch as the angle of the line joining them
(:func:`~servoscope.angle.geometry.blade_angle`). More markers along the blade
give more: their *template* (each marker's place in the blade's frame: along
the lead–trail line and across it, the median over the valid frames) is fitted
to every frame by a weighted 2-D Procrustes fit (rotation and translation, no
scale), each marker weighted by its centroid's noise. The fit's rotation is the
pitch; its translation carries the heave; what it leaves at each marker, across
the fitted chord line, is that marker's *bending*.

The tracker fits the motion to the lead and trail markers alone (``fit_markers=2``):
the chord line through them, as the paper measured it, so that the pitch and the
heave are the two-marker ones bit for bit and a bending mode cannot leak into the
pitch. Fitted to all markers, the twin's 9 Hz bending mode (a marker at a quarter of
the chord moving 62 % of the heave) turned the pitch by 1.9e-4 rad RMS against 3.6e-5
from the chord, for 8 % less noise on a rigid blade (markers between the two have
little lever arm).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ServoscopeError

__all__ = ["RigidMotion", "rigid_motion"]


@dataclass(frozen=True)
class RigidMotion:
    """The rigid motion of m markers per frame, and their residual bending.

    Attributes
    ----------
    angle_rad : ndarray, shape (n,)
        The fitted rotation, the angle of the template's lead–trail line (as
        :func:`~servoscope.angle.geometry.angle_rad_from_centroids`), unwrapped
        over the valid frames; NaN where invalid.
    angle_sigma_rad : ndarray, shape (n,)
        Its standard uncertainty from the markers' centroid noise,
        ``1/√(Σ wᵢ·|qᵢ − q̄|²)``; NaN where invalid.
    chord_xy_px : ndarray, shape (n, 2, 2)
        Where the fitted rigid motion puts the lead and the trail marker (image
        px): the chord line the heave is measured on.
    bending_px : ndarray, shape (n, m)
        Each marker's distance from its rigidly moved place across the fitted
        chord line (px, up positive: the line's normal turned a quarter turn
        counter-clockwise from trail to lead); NaN where invalid.
    along_px : ndarray, shape (n, m)
        The same residual along the line (a rigid sticker's is noise; a marker
        that slid or a wrong blob is not).
    template_uv_px : ndarray, shape (m, 2)
        Each marker's place in the blade's frame: along the line from the trail
        marker towards the lead, and across it (up positive).
    """

    angle_rad: np.ndarray
    angle_sigma_rad: np.ndarray
    chord_xy_px: np.ndarray
    bending_px: np.ndarray
    along_px: np.ndarray
    template_uv_px: np.ndarray


def _up(xy: np.ndarray) -> np.ndarray:
    """Image points (y down) as points with y up."""
    out = np.array(xy, dtype=np.float64)
    out[..., 1] = -out[..., 1]
    return out


def rigid_motion(points_xy_px: np.ndarray, sigma_px: np.ndarray, valid: np.ndarray, *,
                 fit_markers: int | None = None) -> RigidMotion:
    """Fit the blade's rigid motion to m markers in every valid frame.

    Parameters
    ----------
    points_xy_px : ndarray, shape (n, m, 2)
        Centroids (undistorted when a lens model is known); marker 0 is the
        lead, marker 1 the trail, then any others.
    sigma_px : ndarray, shape (n, m)
        Each centroid coordinate's standard uncertainty (px); it weighs the
        marker (``1/σ²``).
    valid : ndarray of bool, shape (n,)
        Frames where every marker was measured.
    fit_markers : int, optional
        Fit the motion to the first ``fit_markers`` markers only (2: the chord line
        through the lead and trail markers, whose angle is then the two-marker
        angle); the others get their bending from it. None: all markers.

    Returns
    -------
    RigidMotion

    Raises
    ------
    ServoscopeError
        With no valid frame, or when the markers' template is degenerate (the
        lead and trail markers in one point).
    """
    p = _up(points_xy_px)
    n, m, _ = p.shape
    valid = np.asarray(valid, dtype=bool) & np.all(np.isfinite(p), axis=(1, 2)) & np.all(
        np.asarray(sigma_px, float) > 0, axis=1)
    if not valid.any():
        raise ServoscopeError("no frame has every marker measured: the rigid motion cannot be fitted")
    # The template: each marker in the frame of the lead–trail line, median over the valid frames.
    d = p[valid, 0] - p[valid, 1]
    length = np.hypot(d[:, 0], d[:, 1])
    if not np.median(length) > 0:
        raise ServoscopeError("the lead and trail markers are in one point: no chord line to fit")
    e = d / length[:, None]
    rel = p[valid] - p[valid, 1][:, None, :]
    u = rel[..., 0] * e[:, None, 0] + rel[..., 1] * e[:, None, 1]
    v = rel[..., 1] * e[:, None, 0] - rel[..., 0] * e[:, None, 1]
    template = np.stack([np.median(u, axis=0), np.median(v, axis=0)], axis=1)
    template[1] = 0.0  # the trail marker is the origin, the lead on the u axis: exactly, not by median
    template[0, 1] = 0.0

    w = np.where(valid[:, None], 1.0 / np.square(np.where(valid[:, None], sigma_px, 1.0)), 0.0)
    if fit_markers is not None:
        if not 2 <= fit_markers <= m:
            raise ServoscopeError(f"fit_markers must be from 2 to {m}, not {fit_markers}")
        w[:, fit_markers:] = 0.0
    wsum = w.sum(axis=1)
    safe = np.where(valid, wsum, 1.0)
    pc = np.einsum("nm,nmk->nk", w, np.nan_to_num(p)) / safe[:, None]
    qc = (w @ template) / safe[:, None]
    pp = np.nan_to_num(p) - pc[:, None, :]
    qq = template[None, :, :] - qc[:, None, :]
    a = np.sum(w * (qq[..., 0] * pp[..., 0] + qq[..., 1] * pp[..., 1]), axis=1)
    b = np.sum(w * (qq[..., 0] * pp[..., 1] - qq[..., 1] * pp[..., 0]), axis=1)
    phi = np.arctan2(b, a)
    c, s = np.cos(phi), np.sin(phi)
    rq = np.stack([c[:, None] * qq[..., 0] - s[:, None] * qq[..., 1],
                   s[:, None] * qq[..., 0] + c[:, None] * qq[..., 1]], axis=-1)
    fitted = pc[:, None, :] + rq
    resid = np.nan_to_num(p) - fitted
    normal = np.stack([-s, c], axis=1)
    bending = np.einsum("nmk,nk->nm", resid, normal)
    along = np.einsum("nmk,nk->nm", resid, np.stack([c, s], axis=1))
    lever = np.sum(w * (qq[..., 0] ** 2 + qq[..., 1] ** 2), axis=1)

    angle = np.where(valid, phi, np.nan)
    angle[valid] = np.unwrap(angle[valid])
    chord = _up(fitted[:, :2, :])
    nan = ~valid
    chord[nan] = np.nan
    bending[nan] = np.nan
    along[nan] = np.nan
    sigma = np.where(valid, 1.0 / np.sqrt(np.where(lever > 0, lever, np.inf)), np.nan)
    return RigidMotion(angle, sigma, chord, bending, along, template)

"""The blade's flapping fitted to the heave's whole traces (issue 32): each mode driven by the measured pitch.

A dwell's heave fitted as a sine over its steady window (:func:`servoscope.sysid.heave.dwell_heave`)
is right only when the window shows the steady state: near the blade's mode, which takes
``4/(ζω)`` to settle, a 2-second dwell shows the transient and a sine fitted to it reads low.
Here the heave model (each mode ``−κ·s²/(s² + 2ζω·s + ω²)`` driven by the pitch each frame
measured, from rest at the test's start) is simulated over every test's whole trace, dwells
and step alike, and fitted to all of them at once: a dwell too short to settle still counts for
what it shows.

Beside the modes the model has one more term, the pitch itself times a constant ``e`` (px/rad):
the apparent heave of an axis found ``e`` px off along the chord. A blade turning by θ about its
true axis keeps its markers' line at one distance from it; measured from a point ``e`` px along
the chord away, the distance changes by ``e·sin θ``, in phase with the pitch at every frequency,
where the flapping's heave grows as ω². The term takes that out of the flapping (and of every
dwell's heave, :func:`servoscope.campaign.blade.heave_response`).

Method: variable projection. For given mode frequencies and damping ratios the model is linear
in the κs, ``e`` and one level per test (least squares); scipy's ``least_squares`` fits the
frequencies and damping ratios. The covariance of all parameters is Newey–West's over the
residuals of each test (κ's with :data:`~servoscope.sysid.heave.HEAVE_SYSTEMATIC_REL` of it added, f's and ζ's with
:data:`~servoscope.sysid.modes.MODE_SYSTEMATIC`) (:func:`servoscope.sysid.hac.hac_covariance` with ``groups``): the
tracker's errors are correlated from frame to frame, not from one test to the next.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import cont2discrete, lfilter, resample_poly

from .hac import hac_covariance
from .heave import HEAVE_SYSTEMATIC_REL, HeaveModel
from .modes import MAX_MODE_DAMPING, MODE_SYSTEMATIC, ModeFit

__all__ = ["HeaveTrace", "fit_heave_traces", "mode_response_px"]


@dataclass(frozen=True)
class HeaveTrace:
    """One test's heave and pitch per frame, and when its input started.

    Attributes
    ----------
    label : str
    time_s : ndarray
        The frames' times.
    pitch_rad, heave_px : ndarray
        The measured pitch and heave per frame (NaN where a frame is not valid).
    start_s : float
        The input's start (t0): the pitch before it is the blade at rest.
    """

    label: str
    time_s: np.ndarray
    pitch_rad: np.ndarray
    heave_px: np.ndarray
    start_s: float

    def pitch_from_rest(self) -> np.ndarray:
        """The pitch less its level at rest (the valid frames' median before the start), gaps interpolated."""
        t, p = np.asarray(self.time_s, float), np.asarray(self.pitch_rad, float)
        ok = np.isfinite(p)
        if np.count_nonzero(ok) < 2:
            return np.zeros_like(t)
        before = ok & (t < self.start_s)
        rest = float(np.median(p[before])) if np.any(before) else float(p[ok][0])
        return np.interp(t, t[ok], p[ok]) - rest


#: The pitch is upsampled this many times (band-limited, scipy's ``resample_poly``) before the mode is
#: simulated: a first-order hold at the frame rate joins the frames by straight lines, which takes
#: sinc²(f/fps) off a sine (0.7 % at 9.3 Hz and 200 frames/s, 14 of the fit's standard errors of κ).
UPSAMPLE = 4


@functools.lru_cache(maxsize=256)
def _discrete(frequency_hz: float, damping_ratio: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``−s²/(s² + 2ζω·s + ω²)`` discretised with a first-order hold at ``dt`` (numerator, denominator)."""
    w = 2.0 * math.pi * frequency_hz
    num, den, _ = cont2discrete(([-1.0, 0.0, 0.0], [1.0, 2.0 * damping_ratio * w, w * w]), dt, method="foh")
    return np.ravel(num), np.asarray(den)


def mode_response_px(time_s: np.ndarray, pitch_rad: np.ndarray, frequency_hz: float,
                     damping_ratio: float) -> np.ndarray:
    """A mode's heave per unit κ, ``−s²/(s² + 2ζω·s + ω²)`` driven by ``pitch_rad`` (from rest, 0 at the first frame).

    Simulated on a uniform grid at the frames' median interval, upsampled :data:`UPSAMPLE` times
    (band-limited), with a first-order hold (scipy's ``cont2discrete``), and read back at each
    frame's time.
    """
    t = np.asarray(time_s, float)
    u = np.asarray(pitch_rad, float)
    if t.size < 2:
        return np.zeros_like(t)
    dt = float(np.median(np.diff(t)))
    grid = t[0] + dt * np.arange(int(round((t[-1] - t[0]) / dt)) + 1)
    fine = resample_poly(np.interp(grid, t, u), UPSAMPLE, 1, padtype="line")
    num, den = _discrete(float(frequency_hz), float(damping_ratio), dt / UPSAMPLE)
    out = lfilter(num, den, fine)[::UPSAMPLE]
    return np.interp(t, grid, out[:grid.size])


def _columns(traces, pitches, modes) -> list[np.ndarray]:
    """Each mode's unit-κ heave over every trace, concatenated (valid heave samples only)."""
    cols = []
    for fm, zeta in modes:
        cols.append(np.concatenate([mode_response_px(tr.time_s, p, fm, zeta)[m]
                                    for tr, p, m in zip(traces, pitches, _masks(traces))]))
    return cols


def _masks(traces) -> list[np.ndarray]:
    return [np.isfinite(np.asarray(tr.heave_px, float)) for tr in traces]


def _mode_derivatives(traces, pitches, x: list[float], kappas: np.ndarray) -> list[np.ndarray]:
    """The Jacobian's columns of each mode's frequency and damping ratio: κ times the unit response's derivative
    (central differences); the linear parameters' columns are the design itself."""
    cols = []
    for j, kappa in enumerate(kappas):
        for k, step in ((2 * j, 1e-5 * x[2 * j]), (2 * j + 1, 1e-4 * max(x[2 * j + 1], 1e-3))):
            up, down = list(x), list(x)
            up[k] += step
            down[k] -= step
            diff = (_columns(traces, pitches, [(up[2 * j], up[2 * j + 1])])[0]
                    - _columns(traces, pitches, [(down[2 * j], down[2 * j + 1])])[0])
            cols.append(kappa * diff / (2.0 * step))
    return cols


def _model(x: list[float], beta: np.ndarray, cov: np.ndarray, r: np.ndarray, n_lin: int, n_params: int,
           n_dwells: int, gain_systematic_rel: float) -> HeaveModel | None:
    """The fitted :class:`HeaveModel` from the parameters (frequencies and damping ratios ``x``; levels, axis term
    and κs ``beta``), their covariance and the residuals; None where a damping ratio sits at its bound."""
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    # The heave's noise: its frame-to-frame scatter, for the fit's reduced χ².
    noise = np.std(np.diff(r)) / math.sqrt(2.0)
    dof = max(r.size - n_params, 1)
    chi2 = float(r @ r) / dof / noise**2 if noise > 0 else math.nan
    gains, gain_se, fits, order = [], [], [], []
    for j in range(len(x) // 2):
        fm, zeta = x[2 * j], x[2 * j + 1]
        if not 0.0 < zeta < MAX_MODE_DAMPING * 0.999:
            return None
        ik, jf, jz = n_lin + j, n_lin + len(x) // 2 + 2 * j, n_lin + len(x) // 2 + 2 * j + 1
        kappa = float(beta[ik])
        gains.append(kappa)
        # The per-dwell heave's relative floor (a resonant heave on raw footage read 0.13 % low) holds
        # for κ, which scales every dwell's heave alike.
        gain_se.append(math.hypot(float(se[ik]), gain_systematic_rel * abs(kappa)))
        fits.append(ModeFit(fm, math.hypot(float(se[jf]), MODE_SYSTEMATIC["frequency"] * fm), zeta,
                            math.hypot(float(se[jz]), MODE_SYSTEMATIC["damping"] * zeta), abs(kappa),
                            "heave_traces"))
        order += [ik, jf, jz]
    sub = cov[np.ix_(order, order)] if order else np.zeros((0, 0))
    # The systematic parts of f and ζ (MODE_SYSTEMATIC) in the covariance too: the per-dwell
    # values made from it carry them.
    for j, m in enumerate(fits):
        sub[3 * j, 3 * j] = gain_se[j] ** 2
        sub[3 * j + 1, 3 * j + 1] = m.frequency_stderr_hz ** 2
        sub[3 * j + 2, 3 * j + 2] = m.damping_ratio_stderr ** 2
    return HeaveModel(tuple(gains), tuple(gain_se), tuple(fits), chi2, n_dwells,
                      method="whole traces", axis_px_per_rad=float(beta[n_lin - 1]),
                      axis_stderr_px_per_rad=float(se[n_lin - 1]),
                      covariance=tuple(tuple(float(v) for v in row) for row in sub))


def fit_heave_traces(traces: list[HeaveTrace], modes: list[tuple[float, float]], *,
                     n_dwells: int | None = None, gain_systematic_rel: float = HEAVE_SYSTEMATIC_REL) -> HeaveModel | None:
    """Fit the flapping model to the heave's whole traces: each mode's κ, frequency and damping, and the axis term.

    Parameters
    ----------
    traces : list of HeaveTrace
        Every test's heave and pitch (dwells, steps, sweeps).
    modes : list of (frequency_hz, damping_ratio)
        Where to start each mode (the step's ring-down, or the dwells' ratios). Empty: only the
        axis term and the levels (a rigid blade's heave, or none that rings).
    n_dwells : int, optional
        How many of the traces are dwells (stated in the result); default all.
    gain_systematic_rel : float
        κ's relative systematic, added to its error: :data:`~servoscope.sysid.heave.HEAVE_SYSTEMATIC_REL`
        for frames coded on their own, :data:`~servoscope.sysid.heave.HEAVE_SYSTEMATIC_REL_PREDICTED`
        where the codec predicts frames.

    Returns
    -------
    HeaveModel or None
        ``method = "whole traces"``, with ``axis_px_per_rad`` and the covariance of
        (κ, f, ζ) per mode; None with fewer than 20 samples, or when the fit fails or puts a mode's
        damping outside (0, ``MAX_MODE_DAMPING``].
    """
    from scipy.optimize import least_squares

    traces = [tr for tr in traces if np.count_nonzero(np.isfinite(np.asarray(tr.heave_px, float))) >= 10]
    masks = _masks(traces)
    n = sum(int(np.count_nonzero(m)) for m in masks)
    if not traces or n < 20:
        return None
    pitches = [tr.pitch_from_rest() for tr in traces]
    h = np.concatenate([np.asarray(tr.heave_px, float)[m] for tr, m in zip(traces, masks)])
    groups = np.concatenate([np.full(int(np.count_nonzero(m)), k) for k, m in enumerate(masks)])
    levels = (groups[:, None] == np.arange(len(traces))[None, :]).astype(float)
    axis = np.concatenate([p[m] for p, m in zip(pitches, masks)])
    fixed = np.column_stack([levels, axis])
    n_lin = fixed.shape[1]

    def design(x) -> np.ndarray:
        pairs = [(x[2 * j], x[2 * j + 1]) for j in range(len(modes))]
        return np.column_stack([fixed, *_columns(traces, pitches, pairs)]) if pairs else fixed

    counts = np.bincount(groups).astype(float)

    def demeaned(a: np.ndarray) -> np.ndarray:
        # Each test's level taken off (the levels' columns projected out, Frisch–Waugh): the same
        # residual as with them, at a fraction of the cost.
        return a - (np.bincount(groups, weights=a) / counts)[groups]

    h_dm = demeaned(h)
    axis_dm = demeaned(axis)

    def resid(x) -> np.ndarray:
        pairs = [(x[2 * j], x[2 * j + 1]) for j in range(len(modes))]
        d = np.column_stack([axis_dm, *(demeaned(c) for c in _columns(traces, pitches, pairs))])
        beta, *_ = np.linalg.lstsq(d, h_dm, rcond=None)
        return d @ beta - h_dm

    x0 = [float(v) for fm, z in modes for v in (fm, min(max(z, 2e-3), 0.5 * MAX_MODE_DAMPING))]
    if modes:
        lo = [v for fm, _ in modes for v in (fm / 1.5, 1e-4)]
        hi = [v for fm, _ in modes for v in (fm * 1.5, MAX_MODE_DAMPING)]
        try:
            sol = least_squares(resid, x0, bounds=(lo, hi), x_scale=[v for fm, z in modes for v in (fm * 1e-3, 1e-3)])
        except (ValueError, np.linalg.LinAlgError):
            return None
        if not sol.success:
            return None
        x = [float(v) for v in sol.x]
    else:
        x = []
    d = design(x)
    beta, *_ = np.linalg.lstsq(d, h, rcond=None)
    r = h - d @ beta
    J = np.column_stack([d, *_mode_derivatives(traces, pitches, x, beta[n_lin:])])
    cov = hac_covariance(J, r, groups=groups)
    if not np.all(np.isfinite(np.diag(cov))):
        return None
    return _model(x, beta, cov, r, n_lin, J.shape[1], len(traces) if n_dwells is None else n_dwells,
                  gain_systematic_rel)

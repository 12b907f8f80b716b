"""The step test read from a turning rotor's passes: :func:`analyse_pass_step`.

The passes (one pitch a blade a revolution, :mod:`servoscope.sysid.pass_sine`) sample the
step at N·Ω, irregularly as the engine's speed drifts, each blade with its own offset. The
offsets are measured where the pitch stands still (before the step and in its last quarter,
each blade's mean against the blades' mean) and taken off; the passes of every blade, merged
in time order, go to :func:`~servoscope.sysid.step.analyse_step` as one trace.

What the spacing allows
-----------------------
The passes are ``h = 1/(N·Ω)`` apart (25 ms at 2 blades × 20 rev/s): the threshold dead time
(the first pass beyond the threshold) is known to ``h/√12`` (a uniform place within one
spacing), and the rise time's crossings are interpolated across passes one spacing apart.
The rise time's stated error is the two crossings' noise (the noise over the response's
slope there) and their interpolation's, measured as the difference between the cubic
crossing ``analyse_step`` takes and the straight line's, both in quadrature: a bound more
than a standard error, since the cubic's error falls faster with the spacing than the
line's (the paper's servo, 0.01° noise, 100 rotor phases each: at 15 rev/s × 2 blades the
errors' RMS is 4.2 ms against a stated 5.7 ms, at 20 × 2 1.8 against 3.4, at 30 × 3 0.2
against 1.0; the cubic reads late by up to 3.7 ms at 33 ms spacing). A dead time of
1 ms cannot be read by counting passes 25 ms apart: the analysis says so, and the dead time
stays the dwells' phases' and the LED's (``servoscope identify``'s, as for a static blade).
With a model, ``analyse_step``'s fit of the model's step to the passes does locate it (the
paper's servo, 20 rev/s × 2 blades, 0.01° noise, 20 rotors: 85.007 ± 0.065 ms against the
true 85 ms, its stated error 0.068 ms), but only as far as the model's shape between passes
is right; the warning gives it as a check, not the answer.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import control
import numpy as np
from numpy.typing import ArrayLike, NDArray

from servoscope.errors import ServoscopeError
from servoscope.results import jsonable
from servoscope.sysid.pass_result import readonly_int
from servoscope.sysid.step import analyse_step
from servoscope.sysid.step_result import StepAnalysis

__all__ = ["PassStepAnalysis", "analyse_pass_step", "blade_offsets_at_rest"]

_RISE_LIMITS = (0.1, 0.9)


@dataclass(frozen=True)
class PassStepAnalysis(StepAnalysis):
    """A step read from a rotor's passes (:func:`analyse_pass_step`): a :class:`StepAnalysis` and the sampling's limits.

    Its samples (``time_s``, ``y``) are the passes of every blade in time order, each blade's
    offset taken off (``y`` = pitch − ``blade_offsets_rad[blade]``).

    Attributes
    ----------
    pass_spacing_s : float
        Median time between passes, 1/(N·Ω), s.
    rise_time_stderr_s : float
        The rise time's error given the spacing and the noise (module docstring), s.
    dead_time_threshold_stderr_s : float
        The threshold dead time's: ``h/√12`` and the input start's, in quadrature, s.
    blades : tuple of int
        The blades seen.
    blade_offsets_rad, blade_offset_stderrs_rad : tuple of float
        Each blade's constant minus the blades' mean, and its standard error, rad (blade order).
    blade : numpy.ndarray of int
        Each sample's blade.
    """

    pass_spacing_s: float = float("nan")
    rise_time_stderr_s: float = float("nan")
    dead_time_threshold_stderr_s: float = float("nan")
    blades: tuple[int, ...] = ()
    blade_offsets_rad: tuple[float, ...] = ()
    blade_offset_stderrs_rad: tuple[float, ...] = ()
    blade: NDArray[np.int_] = field(default_factory=lambda: readonly_int([]), repr=False, compare=False)

    def fit_statistics(self) -> dict[str, Any]:
        """The step's metrics, plus the pass spacing and the errors it sets."""
        out = super().fit_statistics()
        out.update({"pass_spacing_s": float(self.pass_spacing_s), "rise_time_stderr_s": float(self.rise_time_stderr_s),
                    "dead_time_threshold_stderr_s": float(self.dead_time_threshold_stderr_s)})
        return out

    def summary(self) -> dict[str, Any]:
        """The :class:`StepAnalysis` summary, plus ``passes``: spacing, the errors it sets, the blades' offsets."""
        out = super().summary()
        out["passes"] = jsonable({
            "pass_spacing_s": self.pass_spacing_s, "rise_time_stderr_s": self.rise_time_stderr_s,
            "dead_time_threshold_stderr_s": self.dead_time_threshold_stderr_s, "blades": list(self.blades),
            "blade_offsets_rad": list(self.blade_offsets_rad),
            "blade_offset_stderrs_rad": list(self.blade_offset_stderrs_rad)})
        return out


def blade_offsets_at_rest(time_s: NDArray[np.float64], blade: NDArray[np.int_], pitch_rad: NDArray[np.float64],
                          t0_s: float) -> tuple[NDArray[np.int_], NDArray[np.float64], NDArray[np.float64]]:
    """Each blade's constant minus the blades' mean, where the pitch stands still.

    Before `t0_s`, and in the last quarter of the record after it: in each, each blade's mean
    minus the mean of the blades' means; the two combined weighted by their variances (the
    scatter of each blade's passes there).

    Returns
    -------
    blades, offsets_rad, stderrs_rad : numpy.ndarray
        The blades seen (sorted), their offsets and standard errors (rad).
    """
    blades = np.unique(blade)
    t_end = float(np.max(time_s))
    segments = [time_s < t0_s, time_s >= t_end - 0.25 * (t_end - t0_s)]
    est, var = [], []
    for seg in segments:
        means, vars_ = [], []
        for k in blades:
            v = pitch_rad[seg & (blade == k)]
            if v.size < 2:
                break
            means.append(float(np.mean(v)))
            vars_.append(float(np.var(v, ddof=1)) / v.size)
        else:
            m = np.array(means)
            est.append(m - m.mean())
            # The blades' mean is itself uncertain: (1 − 2/k)·var_i + Σvar/k² for blade i.
            vk = np.array(vars_)
            var.append((1.0 - 2.0 / blades.size) * vk + vk.sum() / blades.size**2)
    if not est:
        return blades, np.zeros(blades.size), np.full(blades.size, np.nan)
    e, v = np.array(est), np.maximum(np.array(var), 1e-300)
    w = 1.0 / v
    return blades, (w * e).sum(axis=0) / w.sum(axis=0), np.sqrt(1.0 / w.sum(axis=0))


def analyse_pass_step(
    time_s: ArrayLike,
    blade: ArrayLike,
    pitch_rad: ArrayLike,
    *,
    t0_s: float,
    step_size: float,
    valid: ArrayLike | None = None,
    model: control.TransferFunction | None = None,
    t0_stderr_s: float | None = None,
) -> PassStepAnalysis:
    """Measure a step from a rotor's passes: every blade's, each blade's offset taken off.

    Parameters
    ----------
    time_s, blade, pitch_rad : array_like, shape (n,)
        Each pass's time (ψ = 0, s), blade (0 first) and pitch (rad); NaN pitches excluded.
    t0_s : float
        The step's time (the LED's switch), s; passes before it give the baseline.
    step_size : float
        Input step, input units (≠ 0).
    valid : array_like of bool, optional
        False marks passes to leave out.
    model : control.TransferFunction, optional
        Delay-free model for :func:`~servoscope.sysid.step.analyse_step`'s dead-time fit.
    t0_stderr_s : float, optional
        Standard uncertainty of `t0_s`, s.

    Returns
    -------
    PassStepAnalysis

    Raises
    ------
    ServoscopeError
        Mismatched inputs, or what :func:`~servoscope.sysid.step.analyse_step` refuses.
    """
    t = np.asarray(time_s, dtype=float).ravel()
    b = np.asarray(blade).ravel()
    y = np.asarray(pitch_rad, dtype=float).ravel()
    if not (t.size == b.size == y.size) or (valid is not None and np.asarray(valid).size != t.size):
        raise ServoscopeError(f"analyse_pass_step: time_s, blade, pitch_rad (and valid) must have one length, got "
                              f"{t.size}, {b.size}, {y.size}")
    mask = np.isfinite(t) & np.isfinite(y)
    if valid is not None:
        mask &= np.asarray(valid, dtype=bool).ravel()
    order = np.argsort(t[mask], kind="stable")
    t, b, y = t[mask][order], b[mask][order].astype(int), y[mask][order]
    if t.size < 2:
        raise ServoscopeError(f"analyse_pass_step: only {t.size} usable passes")
    blades, offsets, offset_se = blade_offsets_at_rest(t, b, y, float(t0_s))
    aligned = y - offsets[np.searchsorted(blades, b)]
    sa = analyse_step(t, aligned, t0_s=t0_s, step_size=step_size, model=model, t0_stderr_s=t0_stderr_s)
    h = float(np.median(np.diff(t)))
    rise_se = _rise_time_stderr(sa, h)
    thr_se = math.hypot(h / math.sqrt(12.0), t0_stderr_s or 0.0)
    warns = list(sa.warnings)
    # The value only: its error grows with the model's own (a campaign adds it, campaign/step_test.py).
    fitted = (f"; the model's step fitted to the passes puts it at {1000 * sa.dead_time_s:.2f} ms, resting on "
              f"the model's shape between them" if model is not None and sa.dead_time_s is not None else "")
    warns.append(
        f"passes {1000 * h:.1f} ms apart: the step's rise time is read to ±{1000 * rise_se:.1f} ms and its threshold "
        f"dead time to ±{1000 * thr_se:.1f} ms: a dead time cannot be read to 1 ms by counting passes, it comes from "
        f"the dwells' phases and the LED{fitted}")
    fields = {f.name: getattr(sa, f.name) for f in dataclasses.fields(StepAnalysis)}
    fields["warnings"] = tuple(warns)
    return PassStepAnalysis(**fields, pass_spacing_s=h, rise_time_stderr_s=rise_se, dead_time_threshold_stderr_s=thr_se,
                            blades=tuple(int(k) for k in blades), blade_offsets_rad=tuple(float(v) for v in offsets),
                            blade_offset_stderrs_rad=tuple(float(v) for v in offset_se), blade=readonly_int(b))


def _rise_time_stderr(sa: StepAnalysis, h: float) -> float:
    """The rise time's error: each crossing's noise over the slope, and cubic minus linear interpolation."""
    if not (math.isfinite(sa.rise_time_s) and sa.change != 0):
        return float("nan")
    post = sa.time_s >= sa.t0_s
    tp, r = sa.time_s[post], (sa.y[post] - sa.initial_value) / sa.change
    k = int(np.argmin(np.abs(tp - (sa.t0_s + sa.peak_time_s))))
    seg, tseg = r[: k + 1], tp[: k + 1]
    crossings, noise = [], []
    for level in _RISE_LIMITS:
        below = np.nonzero(seg < level)[0]
        if below.size == 0 or below[-1] + 1 >= seg.size:
            return float("nan")
        i = int(below[-1])
        dr = float(seg[i + 1] - seg[i])
        dt = float(tseg[i + 1] - tseg[i])
        crossings.append(float(tseg[i]) + (level - float(seg[i])) / dr * dt)
        # A crossing's noise: the level's error over the slope, from the samples either side.
        noise.append(sa.noise_sigma / abs(sa.change) * dt / dr * math.sqrt(0.5))
    linear = crossings[1] - crossings[0]
    return math.sqrt(sum(n * n for n in noise) + (linear - sa.rise_time_s) ** 2)

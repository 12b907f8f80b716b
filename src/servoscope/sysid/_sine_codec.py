"""The codec check of a sine dwell: the fundamental fitted to the intra-coded frames alone.

A step of :func:`~servoscope.sysid.fit_sine` (:mod:`servoscope.sysid.sine`, "The codec check").
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from servoscope.errors import ServoscopeError
from servoscope.sysid import hac
from servoscope.sysid._sine_harmonics import design_matrix
from servoscope.sysid.hac import hac_covariance
from servoscope.sysid.sine_result import wrap_pi

__all__ = ["codec_check"]

#: Intra-coded frames in the window needed for the codec check.
_MIN_INTRA = 8
#: The intra fit replaces the all-frame fit unless its amplitude error is this many times larger.
_INTRA_SE_RATIO = 4.0


def codec_check(intra: ArrayLike | None, t_all: NDArray[np.float64], y_all: NDArray[np.float64],
                 mask: NDArray[np.bool_], n: int, flat: bool, f_hat: float, tc: float, amp: float, amp_se: float,
                 phase: float | None, f_var: float | None, t0_s: float | None,
                 t0_stderr_s: float | None) -> dict[str, Any] | None:
    """The fundamental fitted to the intra-coded frames alone, and its difference from all frames'.

    Returns None when the check does not apply (:mod:`servoscope.sysid.sine`), else the
    SineFit fields (``estimator``, ``n_intra``, ``all_frames_*``,
    ``codec_*``) plus the intra fit's ``amplitude``, ``phase_rad`` and their
    standard errors, and ``warnings`` and ``flags`` to add.
    """
    if intra is None:
        return None
    i_all = np.asarray(intra, dtype=bool).ravel()
    if i_all.shape != t_all.shape:
        raise ServoscopeError(f"fit_sine: intra has {i_all.size} entries but time_s has {t_all.size}")
    sel = mask & i_all
    n_i = int(np.count_nonzero(sel))
    if flat or n_i == n:
        return None
    out: dict[str, Any] = {"estimator": "all frames", "n_intra": n_i, "warnings": [], "flags": []}
    if n_i < _MIN_INTRA:
        return out
    ti, yi = t_all[sel], y_all[sel]
    X = design_matrix(ti, f_hat, tc)
    if np.linalg.cond(X) > 1e3:
        # Every intra frame at (nearly) one phase of the sine: cos and sin are (almost) constant there.
        out["warnings"].append(
            f"codec check impossible: the {n_i} intra-coded frames all fall at one phase of the sine (the "
            "I-frame rate is the dwell's frequency or a multiple of it); gain and phase from all frames"
        )
        return out
    coef, *_ = np.linalg.lstsq(X, yi, rcond=None)
    r = yi - X @ coef
    if hac.USE_HAC:
        # Errors that depend on where the sticker sits on the pixel grid change slowly on slow
        # dwells: correlated from one intra frame to the next too.
        order = np.argsort(ti, kind="stable")
        cov = hac_covariance(X[order], r[order])
    else:
        # X is well conditioned here (checked above).
        cov = np.linalg.inv(X.T @ X) * (float(r @ r) / (n_i - 3))
    a, b = float(coef[1]), float(coef[2])
    amp_i = math.hypot(a, b)
    if not amp_i > 0:
        return out
    g = np.array([0.0, a / amp_i, b / amp_i])
    amp_i_se = math.sqrt(max(float(g @ cov @ g), 0.0))
    phase_i = phase_i_se = None
    gp = np.array([0.0, b / amp_i**2, -a / amp_i**2])
    var_at_tc = max(float(gp @ cov @ gp), 0.0)  # the intra fit's phase at tc
    if t0_s is not None:
        lever = float(t0_s) - tc
        phase_i = wrap_pi(math.atan2(a, b) + 2.0 * math.pi * f_hat * lever)
        var = var_at_tc
        if f_var is not None:
            var += (2.0 * math.pi * lever) ** 2 * f_var
        if t0_stderr_s is not None:
            var += (2.0 * math.pi * f_hat * float(t0_stderr_s)) ** 2
        phase_i_se = math.sqrt(var)
    # The two fits share the intra frames, so their difference is less uncertain than this: conservative.
    diff_se = math.hypot(amp_se, amp_i_se)
    out.update(
        all_frames_amplitude=amp, all_frames_phase_rad=phase,
        codec_gain_bias=amp / amp_i - 1.0, codec_gain_bias_stderr=diff_se / amp_i,
        amplitude=amp_i, amplitude_stderr=amp_i_se, phase_rad=phase_i, phase_stderr_rad=phase_i_se,
    )
    if phase is not None and phase_i is not None:
        # t0 and the frequency are common to both fits: the difference's error is that of the
        # phases at tc (the all-frame one ≈ its amplitude's relative error).
        out["codec_phase_bias_rad"] = wrap_pi(phase - phase_i)
        out["codec_phase_bias_stderr_rad"] = math.hypot(math.sqrt(var_at_tc), amp_se / amp)
    if amp_i_se > _INTRA_SE_RATIO * amp_se:
        out["warnings"].append(
            f"codec check inconclusive: the {n_i} intra-coded frames fall at nearly one phase of the sine "
            f"(amplitude error {amp_i_se / amp_se:.0f}x the all-frame fit's); gain and phase from all frames"
        )
        return out
    out["estimator"] = "intra frames"
    big_gain = abs(amp - amp_i) > 3.0 * diff_se
    big_phase = ("codec_phase_bias_rad" in out
                 and abs(out["codec_phase_bias_rad"]) > 3.0 * out["codec_phase_bias_stderr_rad"])
    if big_gain or big_phase:
        out["warnings"].append(
            f"video compression: the frames the codec predicted from others move {100 * (amp / amp_i - 1.0):+.2f} % "
            f"(± {100 * diff_se / amp_i:.2f} %) against its {n_i} intra-coded frames"
            + (f", {math.degrees(out['codec_phase_bias_rad']):+.2f}° in phase" if "codec_phase_bias_rad" in out else "")
            + "; gain and phase taken from the intra-coded frames"
        )
        out["flags"].append("codec")
    return out

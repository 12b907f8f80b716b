"""The measured points a transfer function is fitted to, in fitting units, with their weights.

Part of the transfer-function fit (:mod:`servoscope.sysid.tf_fit` describes the model, the
weights and the uncertainty). :func:`prepare_fit_data` turns a
:class:`~servoscope.sysid.FrequencyResponse` into a :class:`FitData` (usable points, sorted by
frequency; ln gain and phase with floored standard errors) and the warnings the data earn;
:func:`identifiability_problem` says whether they can determine a model of a given structure.
Both the fit and the order selection start here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from servoscope.defaults import DISTORTED_THD_UNTESTED, LOW_FIDELITY
from servoscope.errors import ServoscopeError
from servoscope.sysid._rational import Structure
from servoscope.sysid.frequency_response import FrequencyResponse

__all__ = ["FitData", "Mode", "Zeros", "floored_sigma", "identifiability_problem", "prepare_fit_data", "wrap_rad"]

Mode = Literal["magnitude", "complex"]
Zeros = Literal["minimum_phase", "free"]

_SIGMA_FLOOR = 1e-3


def floored_sigma(values: NDArray[np.float64]) -> NDArray[np.float64]:
    """Floored standard errors: NaN -> median; floor at max(0.5*median, 1e-3)."""
    s = np.asarray(values, dtype=float).copy()
    ok = np.isfinite(s) & (s > 0)
    if not np.any(ok):
        return np.ones_like(s)
    med = float(np.median(s[ok]))
    s[~ok] = med
    return np.maximum(s, max(0.5 * med, _SIGMA_FLOOR))


def wrap_rad(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """Angles wrapped to [-pi, pi) (phase residuals are known modulo a turn)."""
    return (x + np.pi) % (2.0 * np.pi) - np.pi


@dataclass(frozen=True)
class FitData:
    """Usable points, sorted by frequency, in fitting units (ln gain; phase in rad)."""

    w: NDArray[np.float64]  # rad/s
    lng: NDArray[np.float64]  # ln gain
    sig_ln: NDArray[np.float64]
    ph: NDArray[np.float64]  # rad, NaN where unknown
    has_ph: NDArray[np.bool_]
    sig_ph: NDArray[np.float64]  # rad, NaN where unknown
    fid: NDArray[np.float64]
    labels: tuple[str, ...]
    #: Whether the response came with standard errors (else the weights are
    #: arbitrary and only the scatter can give the scale).
    stated: bool = True

    @property
    def n(self) -> int:
        return int(self.w.size)

    def take(self, idx: NDArray[np.intp]) -> FitData:
        return FitData(
            self.w[idx], self.lng[idx], self.sig_ln[idx], self.ph[idx], self.has_ph[idx],
            self.sig_ph[idx], self.fid[idx], tuple(self.labels[i] for i in idx), self.stated,
        )


def prepare_fit_data(fr: FrequencyResponse, mode: str, who: str) -> tuple[FitData, list[str]]:
    """The usable points of `fr` as :class:`FitData`, and the warnings they earn.

    Points without a usable gain are left out (a warning names them); low fidelity and
    harmonic distortion are reported. `who` names the caller in error messages.
    """
    warns: list[str] = []
    w_all = fr.omega_rad_s
    g_all = fr.gain
    use = np.isfinite(w_all) & np.isfinite(g_all) & (g_all > 0) & (w_all > 0)
    dropped = [fr.labels[i] for i in np.nonzero(~use)[0]]
    if dropped:
        warns.append(
            f"{len(dropped)} dwell(s) without a usable gain left out: {', '.join(dropped)}"
        )
    idx = np.nonzero(use)[0]
    idx = idx[np.argsort(w_all[idx], kind="stable")]
    w = w_all[idx]
    lng = np.log(g_all[idx])
    sig_ln = floored_sigma(fr.gain_stderr[idx] / fr.gain[idx]) if idx.size else np.zeros(0)
    ph = fr.phase_rad[idx]
    has_ph = np.isfinite(ph) & (mode == "complex")
    if mode == "complex" and idx.size and not np.any(has_ph):
        raise ServoscopeError(f"{who}: mode='complex' needs phases (t0 unknown for all dwells); use mode='magnitude'")
    sig_ph = np.full(idx.size, np.nan)
    if np.any(has_ph):
        sig_ph[has_ph] = floored_sigma(np.radians(fr.phase_stderr_deg[idx][has_ph]))
    if mode == "complex":
        missing = [fr.labels[i] for i, h in zip(idx, has_ph) if not h]
        if missing:
            warns.append(f"no phase for {', '.join(missing)}: magnitude only there")
    fid = fr.fidelity[idx]
    labels = tuple(fr.labels[i] for i in idx)
    low = [lab for lab, f in zip(labels, fid) if math.isfinite(f) and f < LOW_FIDELITY]
    if low:
        warns.append(
            f"low sinusoidal fidelity (< {LOW_FIDELITY:g}) at {', '.join(low)}: the response there is "
            "not a clean sine (nonlinearity or noise); a linear model describes it only approximately"
        )
    thd_u = np.asarray(fr.thd, dtype=float)[idx]
    flagged = [("distorted" in fr.flags[i]) for i in idx]
    if any(fr.flags[i] for i in idx):
        # fit_sine tested the harmonics' significance: trust its flag.
        high = [f"{lab} ({100 * v:.1f} %)" for lab, v, fl in zip(labels, thd_u, flagged) if fl]
    else:
        high = [f"{lab} ({100 * v:.1f} %)" for lab, v in zip(labels, thd_u) if math.isfinite(v) and v > DISTORTED_THD_UNTESTED]
    if high:
        warns.append(
            f"harmonic distortion at {', '.join(high)}: nonlinear response "
            "(rate limit, backlash, saturation?); the fit describes the fundamental only"
        )
    se_g = fr.gain_stderr[idx]
    se_p = fr.phase_stderr_deg[idx]
    stated = bool(np.any(np.isfinite(se_g) & (se_g > 0)) or np.any(np.isfinite(se_p) & (se_p > 0)))
    return FitData(w, lng, sig_ln, ph, has_ph, sig_ph, fid, labels, stated), warns


def _distinct(w: NDArray[np.float64]) -> int:
    return int(np.unique(np.round(np.log(w), 9)).size) if w.size else 0


def identifiability_problem(d: FitData, st: Structure, mode: str) -> str | None:
    """None when the data can determine the model, else what is missing."""
    p = st.n_params
    nd = _distinct(d.w)
    nd_ph = _distinct(d.w[d.has_ph]) if mode == "complex" else 0
    order = f"order ({st.nb}, {st.na}) in mode {mode!r} has {p} parameters"
    if d.n == 0:
        return f"{order} but no dwell has a usable gain"
    if nd < 2:
        return (
            f"{order} but all {d.n} usable dwell(s) are at one frequency "
            f"({d.w[0] / (2 * math.pi):.4g} Hz): measure at more frequencies"
        )
    if mode == "magnitude":
        if d.n < p:
            return f"{order} but only {d.n} dwell(s) are usable: measure at least {p} frequencies"
        if nd < p:
            return f"{order} but the dwells cover only {nd} distinct frequencies: measure at least {p}"
    else:
        if nd + nd_ph < p:
            return (
                f"{order} but the dwells give only {nd} magnitude(s) and {nd_ph} phase(s) at distinct "
                f"frequencies: measure at more frequencies"
            )
    return None

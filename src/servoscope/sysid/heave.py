"""A signal's sine at a dwell's known frequency, against the input: the blade's heave per dwell (issue 18).

The heave (px) is not an angle and has no rigid-motion null channel or codec check, so it
gets the plain part of :func:`servoscope.sysid.fit_sine`: sin, cos and a level at the
input's frequency over the dwell's steady window, errors from the Newey–West covariance.
"""

from __future__ import annotations

import math

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..parameters import FitResult, Parameter, Parameters, interval95
from ..results import jsonable
from .hac import hac_covariance
from .modes import MAX_MODE_DAMPING, MODE_SYSTEMATIC, ModeFit, ringdown_columns

__all__ = ["BENDING_SYSTEMATIC_PX", "HEAVE_FLOOR_MIN_INTRA_PX", "HEAVE_FLOOR_MIN_PX", "HEAVE_SYSTEMATIC_IFRAME_PX",
           "HEAVE_SYSTEMATIC_INTRA_PX", "HEAVE_SYSTEMATIC_PX",
           "HEAVE_SYSTEMATIC_REL", "HEAVE_SYSTEMATIC_REL_PREDICTED", "HeaveModel", "HeaveRow",
           "coded_alone", "dwell_heave", "fit_heave_model", "heave_systematic_px"]

#: Systematic uncertainty of a dwell's heave amplitude, px, added to the fit's, on footage whose
#: codec predicts frames from others (H.264, MPEG-2): the codec holds each sticker's motion across
#: the line back, and the heave (the line's place at the axis, a lever beyond the markers) shows it
#: 90–130° behind the pitch, whatever the amplitude. Rigid blades on the twin (issue 32; 480×384 and
#: 800×600, 200 frames/s) read 0.03–0.06 px at 8–20 Mbit/s, 0.06–0.08 px at 8 Mbit/s and 800×600,
#: up to 0.096 px at 4 Mbit/s; MPEG-2 at 15 Mbit/s 0.012–0.017 px. (It was 0.05 px, from one
#: 720×576 campaign: an 800×600 camera's dwells then read 1.7–2.5 stated errors high, all alike.)
HEAVE_SYSTEMATIC_PX = 0.1
#: The same where a dwell's heave is fitted to its I-frames alone (a camcorder's GOP, 8 or more in the
#: window): H.264 with an I-frame every 12 read ≤ 0.007 px on rigid blades (issue 32).
HEAVE_SYSTEMATIC_IFRAME_PX = 0.01
#: The least floor the footage's own (the dwells' scatter about the flapping model fitted to the whole
#: traces, :func:`servoscope.campaign.blade.flapping`) may state, where the codec predicts frames: the
#: I-frames' (an estimate from a few dwells can fall well short of the codec's bias).
HEAVE_FLOOR_MIN_PX = HEAVE_SYSTEMATIC_IFRAME_PX
#: The same on frames coded alone: what rigid blades with disc stickers read at worst on raw twin footage
#: (0.0009–0.0029 px).
HEAVE_FLOOR_MIN_INTRA_PX = 0.003
#: κ's relative systematic on footage whose codec predicts frames: the flapping's heave held back or
#: carried on by the codec alike at every dwell (twin, issue 32: 9.3 Hz mode at 800×600 H.264, κ 0.8 % low).
HEAVE_SYSTEMATIC_REL_PREDICTED = 0.015
#: The same on footage of frames coded on their own (raw, image sequences, intra-only codecs): rigid
#: blades (quick preset, raw, 720×576 and 480×384) showed 0.0009–0.0029 px, flapping ones
#: 0.001–0.0035 px off the renderer's heave.
HEAVE_SYSTEMATIC_INTRA_PX = 0.005
#: ...plus this share of the amplitude: a 5.5 px heave at resonance (paper-bend, raw) read 0.13 % low.
HEAVE_SYSTEMATIC_REL = 0.003


#: A marker's bending per dwell where the codec predicts frames: the bending is one marker against
#: the line through two others, three centroids' codec errors. The twin's (quick preset, H.264,
#: 480×384 seed 1 and 720×576 seed 2) read 0.09–0.14 px at 1 Hz where 0.004 px was rendered.
BENDING_SYSTEMATIC_PX = 0.1


def coded_alone(intra: np.ndarray | None) -> bool:
    """Whether a track's every frame was coded on its own (``Track.intra`` all true; unknown counts as predicted)."""
    return intra is not None and len(intra) > 0 and bool(np.all(intra))


def heave_systematic_px(intra: np.ndarray | None, *, bending: bool = False) -> float:
    """The heave's (or a marker's bending's) systematic floor for a track: :data:`HEAVE_SYSTEMATIC_INTRA_PX` when
    every frame was coded on its own (``Track.intra`` all true), else :data:`HEAVE_SYSTEMATIC_PX`
    (:data:`BENDING_SYSTEMATIC_PX` for bending; unknown counts as predicted)."""
    if coded_alone(intra):
        return HEAVE_SYSTEMATIC_INTRA_PX
    return BENDING_SYSTEMATIC_PX if bending else HEAVE_SYSTEMATIC_PX


@dataclass(frozen=True)
class HeaveRow:
    """One dwell's heave at its input frequency: gain (px per input unit) and phase against the input.

    Attributes
    ----------
    label : str
    frequency_hz : float
    gain, gain_stderr : float
        Heave amplitude over input amplitude, px per input unit.
    phase_deg, phase_stderr_deg : float
        Against the input's sine (0 before its start), degrees in (−180, 180].
    amplitude_px : float
    marker : str
        Whose motion: ``""`` for the blade's heave (the chord line's), a marker's
        name (``"extra1"`` …) for that marker's bending across the line.
    colour : str
        That marker's colour as given (``""`` for the heave).
    source : str
        ``"measured"``: the sine fitted to the dwell's own window; ``"model"``: the flapping model's
        steady state at the dwell (fitted to the whole traces), where the dwell's window starts before
        the blade's mode has settled and cannot show it (:func:`servoscope.campaign.blade.heave_response`).
    """

    label: str
    frequency_hz: float
    gain: float
    gain_stderr: float
    phase_deg: float
    phase_stderr_deg: float
    amplitude_px: float
    marker: str = ""
    colour: str = ""
    source: str = "measured"

    def summary(self) -> dict[str, Any]:
        """Plain types, a row of result.json's ``heave_response`` (or, with a marker, ``bending_response``)."""
        return jsonable({**({"marker": self.marker, "colour": self.colour} if self.marker else {}),
                         "video": self.label, "frequency_hz": self.frequency_hz, "gain": self.gain,
                         "gain_stderr": self.gain_stderr, "phase_deg": self.phase_deg,
                         "phase_stderr_deg": self.phase_stderr_deg, "amplitude_px": self.amplitude_px,
                         "units": "px per input unit", "source": self.source})

    @classmethod
    def from_summary(cls, d: dict[str, Any]) -> "HeaveRow":
        """The row back from :meth:`summary`'s dict."""
        return cls(d["video"], d["frequency_hz"], d["gain"], d["gain_stderr"], d["phase_deg"], d["phase_stderr_deg"],
                   d["amplitude_px"], d.get("marker", ""), d.get("colour", ""), d.get("source", "measured"))


def dwell_heave(time_s: np.ndarray, heave: np.ndarray, frequency_hz: float, t0_s: float, amplitude: float,
                window_s: tuple[float, float], label: str = "", marker: str = "", colour: str = "", *,
                systematic_px: float = HEAVE_SYSTEMATIC_PX,
                mode: tuple[float, float] | list[tuple[float, float]] | None = None) -> HeaveRow | None:
    """The heave's sine at ``frequency_hz`` in a dwell's steady window, by least squares with HAC errors.

    ``mode`` (frequency Hz, damping ratio), or a list of them: the blade's modes, whose free
    ring-downs from the dwell's start are still in the window; fitted beside the sine (two
    decaying columns each), not left in the residual, where they swelled the quick preset's
    errors 10-fold. A mode within a line width (1/window) of the dwell's frequency is left
    out: there the two cannot be told apart in the window. The errors include ``systematic_px`` and
    :data:`HEAVE_SYSTEMATIC_REL` of the amplitude (in phase as that much displacement across
    the amplitude); None with fewer than 10 samples in the window.
    """
    t, h = np.asarray(time_s, float), np.asarray(heave, float)
    inside = np.isfinite(h) & (t >= window_s[0]) & (t <= window_s[1])
    if np.count_nonzero(inside) < 10:
        return None
    w = 2.0 * math.pi * frequency_hz * (t[inside] - t0_s)
    columns = [np.sin(w), np.cos(w), np.ones_like(w)]
    span = float(window_s[1] - window_s[0])
    modes = [] if mode is None else [mode] if np.isscalar(mode[0]) else list(mode)
    for fm, z in modes:
        if span > 0 and abs(fm - frequency_hz) > 1.0 / span:
            columns += ringdown_columns(t[inside] - window_s[0], fm, z)
    design = np.column_stack(columns)
    coef, *_ = np.linalg.lstsq(design, h[inside], rcond=None)
    cov = hac_covariance(design, h[inside] - design @ coef)
    a, b = float(coef[0]), float(coef[1])
    amp = math.hypot(a, b)
    if not amp > 0:
        return None
    # Amplitude and phase of a·sin + b·cos = amp·sin(w + φ), by the delta method.
    ga = np.array([a, b]) / amp
    gp = np.array([-b, a]) / amp**2
    c2 = cov[:2, :2]
    floor = math.hypot(systematic_px, HEAVE_SYSTEMATIC_REL * amp)
    se_amp = math.hypot(math.sqrt(max(float(ga @ c2 @ ga), 0.0)), floor)
    se_phase = math.hypot(math.sqrt(max(float(gp @ c2 @ gp), 0.0)), floor / amp)
    return HeaveRow(label, float(frequency_hz), amp / abs(amplitude), se_amp / abs(amplitude),
                    math.degrees(math.atan2(b, a)), math.degrees(se_phase), amp, marker, colour)


@dataclass(frozen=True)
class HeaveModel(FitResult):
    """The flapping frequency response fitted: heave over pitch as modes driven by the pitch's acceleration.

    ``Q/Θ(jω) = Σⱼ κⱼ·ω² / (ωⱼ² − ω² + 2j·ζⱼ·ωⱼ·ω)`` (``−κ s²`` over each mode's denominator, as
    a blade whose inertia the pitch's acceleration throws across its chord), fitted to each
    dwell's heave over its pitch (complex ratios, px per rad).

    Attributes
    ----------
    gains_px_per_rad, gain_stderrs_px_per_rad : tuple of float
        Each κⱼ: a mode's heave per rad of pitch well above it.
    modes : tuple of ModeFit
        Each mode's frequency and damping with their errors (source ``"heave_response"``), or,
        for a mode the dwells cannot tell, the step's, held (source ``"held"``, errors NaN).
    chi2_reduced : float
        The fit's χ² over its degrees of freedom (errors widened by its square root when above 1).
    n_dwells : int
    method : str
        ``"dwell ratios"``: fitted to each dwell's heave over its pitch (:func:`fit_heave_model`);
        ``"whole traces"``: to every test's heave per frame, each mode driven by the measured pitch
        (:func:`servoscope.sysid.heave_traces.fit_heave_traces`).
    axis_px_per_rad, axis_stderr_px_per_rad : float
        The whole traces' axis term: heave in phase with the pitch at every frequency, px per rad
        (an axis found that far off along the chord); 0 and NaN for the dwell ratios' fit.
    covariance : tuple of tuple of float, or None
        Covariance of (κ, frequency, damping ratio) of each mode in turn (the whole traces' fit):
        the per-dwell heave made from the model carries it (:meth:`ratio_stderr`).
    floor_px : float
        The per-dwell heave's systematic floor as the dwells' scatter about this model showed it
        (:func:`servoscope.campaign.blade.flapping`); NaN where it was not measured (fewer than 3
        degrees of freedom among the dwells away from the modes: the constants stand).
    """

    gains_px_per_rad: tuple[float, ...]
    gain_stderrs_px_per_rad: tuple[float, ...]
    modes: tuple[ModeFit, ...]
    chi2_reduced: float
    n_dwells: int
    method: str = "dwell ratios"
    axis_px_per_rad: float = 0.0
    axis_stderr_px_per_rad: float = math.nan
    covariance: tuple[tuple[float, ...], ...] | None = None
    floor_px: float = math.nan

    model_name = "heave/pitch = Σ κ·ω²/(ωm² − ω² + 2j·ζ·ωm·ω) (the blade's flapping modes)"

    @property
    def parameters(self) -> Parameters:
        """Each mode's κ (``gain_px_per_rad``, px/rad, normal interval: it has either sign), frequency (Hz)
        and damping ratio (log-normal intervals, as :attr:`ModeFit.parameters`): the first mode's
        unnumbered as in :meth:`summary`, the others' names ending ``_2``, ``_3`` …; a mode held at
        the step's has its frequency and damping ratio fixed (errors NaN).
        """
        out = []
        for j, (kappa, se, m) in enumerate(zip(self.gains_px_per_rad, self.gain_stderrs_px_per_rad, self.modes)):
            suffix = "" if j == 0 else f"_{j + 1}"
            out.append(Parameter(f"gain_px_per_rad{suffix}", float(kappa), float(se), interval95(kappa, se, "normal"),
                                 unit="px/rad"))
            out += [Parameter(f"{p.name}{suffix}", p.value, p.stderr, p.ci95, vary=p.vary, min=p.min, unit=p.unit,
                              interval=p.interval) for p in m.parameters.values()]
        if self.method == "whole traces":
            e, se = self.axis_px_per_rad, self.axis_stderr_px_per_rad
            out.append(Parameter("axis_px_per_rad", float(e), float(se), interval95(e, se, "normal"), unit="px/rad"))
        return Parameters(out)

    def fit_statistics(self) -> dict[str, Any]:
        """Dwells fitted, the fit's reduced χ² and what it was fitted to."""
        return {"fitted to": self.method, "dwells": int(self.n_dwells), "reduced chi-square": float(self.chi2_reduced)}

    @property
    def gain_px_per_rad(self) -> float:
        """The first mode's κ."""
        return self.gains_px_per_rad[0]

    @property
    def gain_stderr_px_per_rad(self) -> float:
        return self.gain_stderrs_px_per_rad[0]

    @property
    def mode(self):
        """The first (strongest) mode."""
        return self.modes[0]

    def ratio(self, frequency_hz: np.ndarray) -> np.ndarray:
        """The fitted heave over pitch (complex, px per rad) at ``frequency_hz``."""
        w = 2.0 * math.pi * np.asarray(frequency_hz, dtype=float)
        out = np.zeros(w.shape, dtype=complex)
        for kappa, m in zip(self.gains_px_per_rad, self.modes):
            out = out + _mode_term(w, kappa, m.frequency_hz, m.damping_ratio)
        return out

    def ratio_stderr(self, frequency_hz: float) -> float:
        """The standard error of :meth:`ratio`'s modulus at ``frequency_hz`` (px per rad), from :attr:`covariance`
        by the delta method (central differences); NaN without a covariance."""
        if self.covariance is None:
            return math.nan
        x = np.array([v for k, m in zip(self.gains_px_per_rad, self.modes) for v in (k, m.frequency_hz, m.damping_ratio)])
        w = np.array([2.0 * math.pi * float(frequency_hz)])

        def modulus(v):
            return float(abs(sum(_mode_term(w, v[3 * j], v[3 * j + 1], v[3 * j + 2]) for j in range(len(self.modes)))[0]))
        grad = np.zeros(x.size)
        for k in range(x.size):
            step = 1e-6 * max(abs(x[k]), 1e-3)
            up, down = x.copy(), x.copy()
            up[k] += step
            down[k] -= step
            grad[k] = (modulus(up) - modulus(down)) / (2.0 * step)
        cov = np.asarray(self.covariance, dtype=float)
        return math.sqrt(max(float(grad @ cov @ grad), 0.0))

    def summary(self) -> dict[str, Any]:
        """Plain types, result.json's ``heave_model``: the first mode's terms, and every mode's in ``modes``."""
        def terms(kappa, se, m):
            return {"gain_px_per_rad": kappa, "gain_stderr_px_per_rad": se, "frequency_hz": m.frequency_hz,
                    "damping_ratio": m.damping_ratio,
                    "stderr": {"frequency_hz": m.frequency_stderr_hz, "damping_ratio": m.damping_ratio_stderr},
                    **({"held": True} if m.source == "held" else {})}
        all_terms = [terms(*x) for x in zip(self.gains_px_per_rad, self.gain_stderrs_px_per_rad, self.modes)]
        return jsonable({"model": "heave/pitch = sum of kappa*w^2/(wm^2 - w^2 + 2j*zeta*wm*w)", **all_terms[0],
                         **({"modes": all_terms} if len(all_terms) > 1 else {}),
                         "chi2_reduced": self.chi2_reduced, "n_dwells": self.n_dwells, "method": self.method,
                         **({"axis_px_per_rad": self.axis_px_per_rad,
                             "axis_stderr_px_per_rad": self.axis_stderr_px_per_rad,
                             "covariance": [list(r) for r in self.covariance or ()],
                             "floor_px": self.floor_px}
                            if self.method == "whole traces" else {})})

    @classmethod
    def from_summary(cls, d: dict[str, Any]) -> "HeaveModel":
        """The model back from :meth:`summary`'s dict."""
        terms = d.get("modes") or [d]
        def nan_if_none(v):
            return math.nan if v is None else v
        modes = tuple(ModeFit(t["frequency_hz"], nan_if_none(t["stderr"]["frequency_hz"]), t["damping_ratio"],
                              nan_if_none(t["stderr"]["damping_ratio"]), abs(t["gain_px_per_rad"]),
                              "held" if t.get("held") else "heave_response") for t in terms)
        method = d.get("method", "dwell ratios")
        if method == "whole traces":
            modes = tuple(replace(m, source="heave_traces") if m.source != "held" else m for m in modes)
        cov = d.get("covariance")
        return cls(tuple(t["gain_px_per_rad"] for t in terms), tuple(t["gain_stderr_px_per_rad"] for t in terms), modes,
                   nan_if_none(d["chi2_reduced"]), d["n_dwells"], method, d.get("axis_px_per_rad", 0.0),
                   nan_if_none(d.get("axis_stderr_px_per_rad")),
                   None if not cov else tuple(tuple(float(nan_if_none(v)) for v in row) for row in cov),
                   nan_if_none(d.get("floor_px")))


def _mode_term(w: np.ndarray, kappa: float, frequency_hz: float, damping_ratio: float) -> np.ndarray:
    """One mode's heave over pitch at ω (rad/s): ``κ·ω² / (ωm² − ω² + 2j·ζ·ωm·ω)``."""
    wm = 2.0 * math.pi * frequency_hz
    return kappa * w**2 / (wm**2 - w**2 + 2j * damping_ratio * wm * w)


def _heave_over_pitch(rows: list[HeaveRow], pitch: dict[str, tuple[float, float, float, float]]):
    """Each dwell's heave over its pitch: frequencies, complex ratios (px/rad) and their errors; None under 3 dwells.

    A ratio's error is isotropic in the complex plane: its modulus times the larger of its
    relative gain error and its phase error.
    """
    data = [(r, pitch[r.label]) for r in rows if r.label in pitch and pitch[r.label][0] > 0]
    if len(data) < 3:
        return None
    f = np.array([r.frequency_hz for r, _ in data])
    z = np.array([r.gain / p[0] * np.exp(1j * (math.radians(r.phase_deg) - p[2])) for r, p in data])
    rel = np.array([max(math.hypot(r.gain_stderr / r.gain if r.gain > 0 else np.inf, p[1] / p[0]),
                        math.hypot(math.radians(r.phase_stderr_deg), p[3])) for r, p in data])
    return f, z, np.abs(z) * np.minimum(rel, 1e6) + 1e-12


def fit_heave_model(rows: list[HeaveRow], pitch: dict[str, tuple[float, float, float, float]],
                    start_hz: float | list[float] | None = None) -> HeaveModel | None:
    """Fit :class:`HeaveModel` to the dwells' heave over their pitch; None when it cannot be told.

    Parameters
    ----------
    rows : list of HeaveRow
        Each dwell's heave (gain per input unit, phase against the input).
    pitch : dict of label → (gain, gain_stderr, phase_rad, phase_stderr_rad)
        Each dwell's pitch against the same input (rad per input unit).
    start_hz : float, or list of frequencies or (frequency, damping ratio) pairs, optional
        The modes found elsewhere (the step's): one term each, started there; a mode beyond what
        the dwells can tell (3 dwells per mode) keeps its frequency and damping, only its κ is
        fitted. None: one mode, started from a grid over the dwells' range.

    Each ratio's error is isotropic in the complex plane: its modulus times the larger of its
    relative gain error and its phase error. The covariance is the Jacobian's, widened by the
    reduced χ² when above 1, then the modes' systematic part (:data:`~servoscope.sysid.modes.MODE_SYSTEMATIC`)
    is added. None with fewer than 3 dwells, a fit that fails, a damping ratio
    outside (0, ``MAX_MODE_DAMPING``], or a mode outside the dwells' frequencies (where nothing
    shows it).
    """
    from scipy.optimize import least_squares

    ratios = _heave_over_pitch(rows, pitch)
    if ratios is None:
        return None
    f, z, sd = ratios
    n_dwells = f.size
    w = 2.0 * math.pi * f
    known = [tuple(float(u) for u in np.atleast_1d(v)) for v in
             ([start_hz] if np.isscalar(start_hz) else (start_hz or []))]
    n = max(len(known), 1)
    # Modes beyond what the dwells can tell (3 parameters each, 3 dwells per mode) keep the
    # step's frequency and damping; only their κ is fitted, so that they do not bend the first.
    free = n if n_dwells >= 3 * n else 1
    held = [(k[0], k[1] if len(k) > 1 else 0.05) for k in known[free:]]

    def unpack(x):
        terms = [tuple(x[3 * j:3 * j + 3]) for j in range(free)]
        return terms + [(x[3 * free + j], fm, zeta) for j, (fm, zeta) in enumerate(held)]

    def model(x):
        out = np.zeros(w.shape, dtype=complex)
        for kappa, fm, zeta in unpack(x):
            out = out + _mode_term(w, kappa, fm, zeta)
        return out

    def resid(x):
        d = (model(x) - z) / sd
        return np.concatenate([d.real, d.imag])

    start_sets = [[k[0] for k in known[:free]]] if known else [[fm0] for fm0 in np.geomspace(f.min(), f.max(), 12)]
    best = None
    for fms in start_sets:
        x0, lo, hi = [], [], []
        for fm0 in fms:
            shape = _mode_term(w, 1.0, fm0, 0.05)
            kappa0 = float(np.real(np.vdot(shape / sd, z / sd)) / np.real(np.vdot(shape / sd, shape / sd)))
            x0 += [kappa0, fm0, 0.05]
            lo += [-np.inf, 0.2 * f.min(), 1e-4]
            hi += [np.inf, 5.0 * f.max(), 0.9]
        x0 += [0.0] * len(held)
        lo += [-np.inf] * len(held)
        hi += [np.inf] * len(held)
        try:
            sol = least_squares(resid, x0, bounds=(lo, hi))
        except (ValueError, np.linalg.LinAlgError):
            continue
        if sol.success and (best is None or sol.cost < best.cost):
            best = sol
    if best is None:
        return None
    x = [float(v) for v in best.x]
    dof = max(2 * n_dwells - len(x), 1)
    chi2 = 2.0 * float(best.cost) / dof
    try:
        cov = np.linalg.inv(best.jac.T @ best.jac) * max(chi2, 1.0)
    except np.linalg.LinAlgError:
        return None
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    terms = []
    if not np.all(np.isfinite(se)):
        return None
    for j, (kappa, fm, zeta) in enumerate(unpack(x)):
        if j < free:
            if not (0.0 < zeta <= MAX_MODE_DAMPING and f.min() <= fm <= f.max()):
                return None
            mode = ModeFit(fm, math.hypot(float(se[3 * j + 1]), MODE_SYSTEMATIC["frequency"] * fm), zeta,
                           math.hypot(float(se[3 * j + 2]), MODE_SYSTEMATIC["damping"] * zeta), abs(kappa),
                           "heave_response")
            terms.append((kappa, float(se[3 * j]), mode))
        else:
            # Held at the step's: a mode of the model, not a finding of the heave's (source "held").
            terms.append((kappa, float(se[3 * free + j - free]), ModeFit(fm, math.nan, zeta, math.nan, abs(kappa),
                                                                         "held")))
    return HeaveModel(tuple(t[0] for t in terms), tuple(t[1] for t in terms), tuple(t[2] for t in terms), chi2,
                      n_dwells)

"""The camera's exposure (shutter), from what the footage shows of it: the LED's switches and motion blur.

The rig switches the LED at a time that has nothing to do with the camera's
frame clock, so the switch falls inside an exposure with probability
exposure / frame interval, and then one frame is partly lit; otherwise it
falls in the unexposed gap between two exposures and every frame is clean.
Over a campaign's videos the share of switches that lit a frame partly
estimates the exposure's share of the frame interval (a binomial
proportion, with its Wilson interval).

A campaign of a handful of videos gives the exposure only coarsely (7
videos: ±35 % of the interval); the estimate is reported with that
interval, and "unknown" when no switch lit a frame partly (the shutter is
then short, and how short the footage cannot tell). The LED timing never
relies on it: a switch no frame dated is placed in the widest gap the
footage allows (see :mod:`servoscope.markers.led_timing`).

Motion blur measures the exposure directly. A sticker that moves at
velocity v during an exposure e is smeared along a segment of length |v|·e:
its image is the still sticker convolved with that segment, so its second
moments (the tracker's soft membership, :attr:`Track.lead_shape_px2`) grow
by ``(e²/12)·v·vᵀ`` whatever its shape. :func:`blur_evidence` regresses
each sticker's moments, turned into the markers' own frame (so that a strip
that turns with the blade keeps one shape), on its velocity's outer product
(from a cubic spline through the centroids), with one intercept per sticker
and component (its still shape), and :func:`estimate_exposure` pools the
slopes k = e²/12 of a campaign's videos. The tracker measures a sticker over
a support a little larger than its still outline, which cuts the ends off a
long smear: the growth then falls short of k·|v|² at the highest speeds. A
second regressor, |v|²·v·vᵀ, takes that curvature, so that k is the growth
where the smear is short (on the twin, a full-frame shutter: 10.0 ms read as
8.2 ms without it, 9.3 ms with it). Frames are grouped in blocks of
:data:`BLUR_BLOCK_FRAMES` and the slope's uncertainty is the blocks'
scatter (a cluster-robust sandwich), because tracking errors are correlated
from frame to frame. Blur is *seen* when the slope is at least
:data:`BLUR_MIN_Z` standard errors above 0; otherwise the footage bounds the
exposure from above (stickers that move slowly show little blur at any
shutter, and the bound says how much the motion could tell).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Iterable

import numpy as np

from ..parameters import FitResult, Parameter, Parameters, interval95

if TYPE_CHECKING:  # the camera stage reads a track; it never calls the markers stage
    from ..markers.track import Track

__all__ = ["BLUR_BLOCK_FRAMES", "BLUR_MIN_Z", "BLUR_SYSTEMATIC", "BlurEvidence", "ExposureEstimate", "blur_evidence",
           "estimate_exposure", "pool_blur"]

#: Frames per block of the blur regression's cluster-robust uncertainty: longer than the
#: tracking errors' correlation (a few frames; a codec's GOP), short enough for many blocks.
BLUR_BLOCK_FRAMES = 25
#: Blur is taken as seen when its slope is this many standard errors above zero (the
#: exposure's statistical uncertainty is then at most 1/(2·z) = 12.5 % of it). At 3 a
#: quarter-frame shutter's faint blur read 4.2 ms for 2.5 (the twin, raw video).
BLUR_MIN_Z = 4.0
#: Relative systematic uncertainty of an exposure read from blur, added to the statistical
#: one: what is left of the support's cut after its correction term, the twin's finite
#: sub-exposure samples and a lens's scale (measured on the twin: −7 % raw, −13 % H.264 at a
#: full-frame shutter).
BLUR_SYSTEMATIC = 0.10


@dataclass(frozen=True)
class ExposureEstimate(FitResult):
    """The exposure of a campaign's camera and where it came from.

    A :class:`~servoscope.parameters.FitResult`: :attr:`parameters` holds ``exposure_s`` with
    `stderr_s` and `ci95_s` as they are (``fit_report()``, ``to_pandas()`` and the notebook's
    table show them). Its interval: held at the given value ("given"); the LED's Wilson score
    interval of the share of switches that lit a frame partly, times the frame interval
    (interval kind ``"wilson"``: given, not made from the error); from blur, or both combined,
    normal from the error, stopped at 0 (kind ``"normal"``, ``min`` 0; a blur seen has a
    relative error of at most 16 %, so the stop is only a guard).

    Attributes
    ----------
    value_s : float or None
        The exposure (s); None when unknown.
    stderr_s : float or None
        Its standard uncertainty (s); 0 when given.
    ci95_s : (float, float) or None
        95 % interval (s).
    source : str
        "given" (``[camera] exposure_s``), "LED" (partly lit frames at the
        switches) or "unknown".
    detail : str
        One line a person reads: the evidence.
    frame_interval_s : float or None
        The frame interval it is a share of.
    switches : int
        LED switches found (videos).
    partly_lit : int
        Of those, switches that lit a frame partly.
    """

    value_s: float | None
    stderr_s: float | None
    ci95_s: tuple[float, float] | None
    source: str
    detail: str
    frame_interval_s: float | None = None
    switches: int = 0
    partly_lit: int = 0
    blur: "BlurEvidence | None" = None

    @property
    def known(self) -> bool:
        return self.value_s is not None

    @property
    def model_name(self) -> str:  # type: ignore[override]
        return f"camera exposure (source: {self.source})"

    @property
    def parameters(self) -> Parameters:
        """``exposure_s`` (s) with its error and interval as held (NaN when unknown; fixed when given)."""
        nan = math.nan
        if self.value_s is None:
            return Parameters([Parameter("exposure_s", nan, nan, (nan, nan), min=0.0, unit="s")])
        se = nan if self.stderr_s is None else float(self.stderr_s)
        ci = (nan, nan) if self.ci95_s is None else (float(self.ci95_s[0]), float(self.ci95_s[1]))
        kind = "wilson" if self.source == "LED" else "normal"
        return Parameters([Parameter("exposure_s", float(self.value_s), se, ci, vary=self.source != "given", min=0.0,
                                     unit="s", interval=kind)])

    def fit_statistics(self) -> dict[str, Any]:
        """The evidence: source, frame interval, LED switches (and those partly lit), the blur's."""
        out: dict[str, Any] = {"source": self.source, "frame_interval_s": self.frame_interval_s,
                               "led_switches": self.switches, "led_switches_partly_lit": self.partly_lit}
        if self.blur is not None:
            out.update({"blur seen": self.blur.seen, "blur z": float(self.blur.z)})
            if not self.blur.seen and self.blur.upper_bound_s is not None:
                out["blur upper_bound_s"] = float(self.blur.upper_bound_s)
        out["evidence"] = self.detail
        return out

    @classmethod
    def from_summary(cls, data: dict) -> "ExposureEstimate":
        """Rebuild the estimate from its :meth:`summary` (result.json's ``exposure``)."""
        ci = data.get("ci95_s")
        blur = data.get("blur")
        return cls(data.get("value_s"), data.get("stderr_s"), None if ci is None else (ci[0], ci[1]),
                   data["source"], data.get("detail", ""), data.get("frame_interval_s"),
                   int(data.get("led_switches", 0)), int(data.get("led_switches_partly_lit", 0)),
                   None if blur is None else BlurEvidence.from_summary(blur))

    def summary(self) -> dict:
        """Plain types, for result.json."""
        return {
            "value_s": self.value_s,
            "stderr_s": self.stderr_s,
            "ci95_s": None if self.ci95_s is None else list(self.ci95_s),
            "fraction_of_frame_interval": (None if self.value_s is None or not self.frame_interval_s
                                           else self.value_s / self.frame_interval_s),
            "source": self.source,
            "detail": self.detail,
            "frame_interval_s": self.frame_interval_s,
            "led_switches": self.switches,
            "led_switches_partly_lit": self.partly_lit,
            "blur": None if self.blur is None else self.blur.summary(),
        }


@dataclass(frozen=True)
class BlurEvidence:
    """What the stickers' motion blur says of the exposure (one video, or a campaign's pooled).

    Attributes
    ----------
    slope_s2 : float
        k in ``moments = still shape + k·v·vᵀ`` (px² per (px/s)² = s²);
        e = √(12·k). NaN when no frame could be used.
    slope_stderr_s2 : float
        Its standard uncertainty (the blocks' scatter).
    frames : int
        Sticker-frames used (each sticker in each frame counts once).
    blocks : int
        Blocks of :data:`BLUR_BLOCK_FRAMES` frames they fell in.
    max_speed_px_s : float
        The fastest sticker motion seen (px/s): how much blur there was to see.
    sxx, sxy : tuple of tuple of float
        Each block's sums of x·xᵀ (4 numbers, row by row) and x·y (2), x the
        regressors (v·vᵀ and its truncation term) and y the moment, both less
        their sticker's means: what pooling needs.
    """

    slope_s2: float
    slope_stderr_s2: float
    frames: int
    blocks: int
    max_speed_px_s: float
    sxx: tuple[tuple[float, ...], ...] = ()
    sxy: tuple[tuple[float, ...], ...] = ()
    frame_interval_s: float | None = None

    @property
    def z(self) -> float:
        """The slope in standard errors (how clearly blur is seen)."""
        if not (self.slope_stderr_s2 > 0 and math.isfinite(self.slope_s2)):
            return 0.0
        return self.slope_s2 / self.slope_stderr_s2

    @property
    def _raw_exposure_s(self) -> float:
        return math.sqrt(12.0 * self.slope_s2) if self.slope_s2 > 0 else 0.0

    @property
    def too_long(self) -> bool:
        """Whether the blur reads an exposure longer than the frame interval beyond doubt (not blur, then)."""
        if self.frame_interval_s is None or not self.z >= BLUR_MIN_Z:
            return False
        e = self._raw_exposure_s
        return self._interval(e)[0] > self.frame_interval_s

    @property
    def seen(self) -> bool:
        """Whether blur is seen: the slope :data:`BLUR_MIN_Z` standard errors above zero, and possible."""
        return self.z >= BLUR_MIN_Z and not self.too_long

    def _stderr(self, e: float) -> float:
        # The delta method (σ_e = 6·σ_k / e) and the systematic part, in quadrature.
        return math.hypot(6.0 * self.slope_stderr_s2 / e, BLUR_SYSTEMATIC * e)

    def _interval(self, e: float) -> tuple[float, float]:
        # Normal, stopped at 0 (a guard: where blur is seen the relative error is at most
        # hypot(1/(2·BLUR_MIN_Z), BLUR_SYSTEMATIC) = 16 %, and the normal interval stays above 0).
        lo, hi = interval95(e, self._stderr(e), "normal")
        return max(lo, 0.0), hi

    @property
    def exposure_s(self) -> float | None:
        """e = √(12·k) (s), when blur is seen; else None."""
        return self._raw_exposure_s if self.seen else None

    @property
    def exposure_stderr_s(self) -> float | None:
        """σ_e (s): statistical and systematic (:data:`BLUR_SYSTEMATIC`), when blur is seen."""
        e = self.exposure_s
        return None if e is None else self._stderr(e)

    @property
    def ci95_s(self) -> tuple[float, float] | None:
        """95 % interval of e (s), when blur is seen."""
        e = self.exposure_s
        return None if e is None else self._interval(e)

    @property
    def upper_bound_s(self) -> float | None:
        """The longest exposure the footage allows (95 %, s); None without evidence."""
        if not (self.blocks >= 3 and math.isfinite(self.slope_s2) and self.slope_stderr_s2 > 0):
            return None
        # The slope's upper 95 % limit, then the systematic part's (a relative error: on a scale of 1).
        k_high = interval95(max(self.slope_s2, 0.0), self.slope_stderr_s2, "normal")[1]
        return math.sqrt(12.0 * k_high) * interval95(1.0, BLUR_SYSTEMATIC, "normal")[1]

    def summary(self) -> dict:
        """Plain types, for result.json and the track summary."""
        f = (lambda v: None if v is None or not math.isfinite(v) else float(v))
        return {
            "exposure_s": self.exposure_s,
            "exposure_stderr_s": self.exposure_stderr_s,
            "ci95_s": None if self.ci95_s is None else list(self.ci95_s),
            "upper_bound_s": None if self.seen else self.upper_bound_s,
            "seen": self.seen,
            "longer_than_frame_interval": self.too_long,
            "z": f(self.z),
            "slope_s2": f(self.slope_s2),
            "slope_stderr_s2": f(self.slope_stderr_s2),
            "frames": self.frames,
            "blocks": self.blocks,
            "max_speed_px_s": f(self.max_speed_px_s),
            "frame_interval_s": self.frame_interval_s,
        }

    @classmethod
    def from_summary(cls, data: dict) -> "BlurEvidence":
        """Rebuild the evidence from its :meth:`summary` (the blocks' sums are not in it: it cannot be pooled again)."""
        nan = (lambda v: math.nan if v is None else float(v))
        return cls(nan(data.get("slope_s2")), nan(data.get("slope_stderr_s2")), int(data.get("frames", 0)),
                   int(data.get("blocks", 0)), nan(data.get("max_speed_px_s")),
                   frame_interval_s=data.get("frame_interval_s"))

    def describe(self) -> str:
        """One line a person reads."""
        if self.too_long:
            return (f"the stickers' shapes change with their speed as no shutter does (a blur of "
                    f"{1e3 * self._raw_exposure_s:.3g} ms, longer than the frame interval): not read as blur")
        if self.seen:
            lo, hi = self.ci95_s
            return (f"motion blur: exposure {1e3 * self.exposure_s:.3g} ms (95 % {1e3 * lo:.3g}–{1e3 * hi:.3g} ms; "
                    f"blur seen at {self.z:.0f} σ over {self.frames} sticker-frames)")
        bound = self.upper_bound_s
        if bound is None:
            return "motion blur: too few moving frames to tell"
        return (f"no motion blur seen (stickers up to {self.max_speed_px_s:.0f} px/s): exposure ≤ "
                f"{1e3 * bound:.3g} ms (95 %)")


def _velocity(time_s: np.ndarray, xy: np.ndarray, usable: np.ndarray) -> np.ndarray:
    """Centroid velocity (px/s) by a cubic spline through each run of usable frames; NaN elsewhere.

    A spline's derivative stays accurate where the motion is fast against the
    frame rate (a central difference reads a 15 Hz sine at 100 frames/s 14 %
    slow); each run's two end frames, where the spline is least sure, are left out.
    """
    from scipy.interpolate import CubicSpline  # deferred: only the exposure estimate needs it

    v = np.full(xy.shape, np.nan)
    idx = np.flatnonzero(usable)
    if idx.size < 7:
        return v
    breaks = np.flatnonzero(np.diff(idx) != 1) + 1
    for run in np.split(idx, breaks):
        if run.size < 7 or np.any(np.diff(time_s[run]) <= 0):
            continue
        spline = CubicSpline(time_s[run], xy[run], axis=0)
        inner = run[2:-2]
        v[inner] = spline(time_s[inner], 1)
    return v


def _sticker_rows(track: "Track", name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """One sticker's regression rows: frame index, x (n, 3, 2) and y (n, 3), less their means; and its top speed."""
    xy = np.asarray(getattr(track, f"{name}_xy_px"), dtype=float)
    shape = np.asarray(getattr(track, f"{name}_shape_px2"), dtype=float)
    d = np.asarray(track.lead_xy_px, dtype=float) - np.asarray(track.trail_xy_px, dtype=float)
    length = np.hypot(d[:, 0], d[:, 1])
    time_s = np.asarray(track.time_s, dtype=float)
    usable = (np.asarray(track.valid, dtype=bool) & np.all(np.isfinite(shape), axis=1)
              & np.all(np.isfinite(xy), axis=1) & (length > 0))
    v = _velocity(time_s, xy, usable)
    use = usable & np.all(np.isfinite(v), axis=1)
    if np.count_nonzero(use) < 3:
        return np.zeros(0, int), np.zeros((0, 3, 2)), np.zeros((0, 3)), 0.0
    # The markers' own frame: u along the line joining them, n across it.
    u = d[use] / length[use, None]
    n = np.stack([-u[:, 1], u[:, 0]], axis=1)
    s20, s11, s02 = shape[use].T
    suu = u[:, 0] ** 2 * s20 + 2 * u[:, 0] * u[:, 1] * s11 + u[:, 1] ** 2 * s02
    snn = n[:, 0] ** 2 * s20 + 2 * n[:, 0] * n[:, 1] * s11 + n[:, 1] ** 2 * s02
    sun = u[:, 0] * n[:, 0] * s20 + (u[:, 0] * n[:, 1] + u[:, 1] * n[:, 0]) * s11 + u[:, 1] * n[:, 1] * s02
    vu = np.sum(v[use] * u, axis=1)
    vn = np.sum(v[use] * n, axis=1)
    outer = np.stack([vu * vu, vn * vn, vu * vn], axis=1)
    # Regressors per component: v·vᵀ (the blur) and |v|²·v·vᵀ (the support's cut, see the module).
    x = np.stack([outer, outer * (vu * vu + vn * vn)[:, None]], axis=2)  # (n, 3 components, 2)
    y = np.stack([suu, snn, sun], axis=1)
    # The still sticker's shape (and the velocity noise's own variance) are this
    # sticker's intercepts: taken out by its means.
    return np.flatnonzero(use), x - x.mean(axis=0), y - y.mean(axis=0), float(np.max(np.hypot(vu, vn)))


def blur_evidence(track: "Track") -> BlurEvidence:
    """What one video's stickers' blur says of the exposure.

    Parameters
    ----------
    track : Track
        A tracked video with its stickers' second moments
        (:attr:`~servoscope.markers.Track.lead_shape_px2`).

    Returns
    -------
    BlurEvidence
        The slope k = e²/12 and its blocks' sums (for :func:`pool_blur`).

    Notes
    -----
    The moments are in the recorded image's pixels and the velocity in the
    centroids' (the ideal image's when a lens model was given): where the
    lens scales the image by s, k reads s² times too large, a few per cent
    at most for the lenses servoscope calibrates.
    """
    sums: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    frames, top = 0, 0.0
    for name in ("lead", "trail"):
        index, x, y, speed = _sticker_rows(track, name)
        frames += index.size
        top = max(top, speed)
        block = index // BLUR_BLOCK_FRAMES
        for b in np.unique(block):
            xs, ys = x[block == b].reshape(-1, 2), y[block == b].reshape(-1)
            a, c = sums.get(int(b), (np.zeros((2, 2)), np.zeros(2)))
            sums[int(b)] = (a + xs.T @ xs, c + xs.T @ ys)
    keys = sorted(sums)
    period = float(np.median(np.diff(track.time_s))) if np.size(track.time_s) > 1 else None
    return _pooled(tuple(tuple(sums[k][0].ravel().tolist()) for k in keys),
                   tuple(tuple(sums[k][1].tolist()) for k in keys), frames, top, period)


def _pooled(sxx, sxy, frames: int, top: float, period: float | None) -> BlurEvidence:
    """The slope and its cluster-robust uncertainty from blocks' sums."""
    g = len(sxx)
    a = np.asarray(sxx, dtype=float).reshape(g, 2, 2)
    b = np.asarray(sxy, dtype=float).reshape(g, 2)
    total = a.sum(axis=0)
    if g < 3 or not (np.all(np.isfinite(total)) and np.linalg.det(total) > 0):
        return BlurEvidence(math.nan, math.nan, frames, g, top, tuple(sxx), tuple(sxy), period)
    inv = np.linalg.inv(total)
    beta = inv @ b.sum(axis=0)
    scores = b - a @ beta  # each block's Σ x·residual
    cov = inv @ (scores.T @ scores) @ inv * (g / (g - 1))
    return BlurEvidence(float(beta[0]), math.sqrt(max(float(cov[0, 0]), 0.0)), frames, g, top, tuple(sxx), tuple(sxy),
                        period)


def pool_blur(evidence: Iterable[BlurEvidence]) -> BlurEvidence | None:
    """One campaign's blur evidence from its videos' (each block a cluster); None without any."""
    items = [e for e in evidence if e is not None and e.frames]
    if not items:
        return None
    sxx = tuple(v for e in items for v in e.sxx)
    sxy = tuple(v for e in items for v in e.sxy)
    periods = sorted(e.frame_interval_s for e in items if e.frame_interval_s)
    return _pooled(sxx, sxy, sum(e.frames for e in items), max(e.max_speed_px_s for e in items),
                   periods[len(periods) // 2] if periods else None)


def _wilson(k: int, n: int) -> tuple[float, float]:
    """The Wilson score 95 % interval of a binomial proportion k/n."""
    p = k / n
    # A score interval, not a parameter's: it needs the normal 97.5 % point itself, taken from
    # the one function that makes intervals (the upper limit of 0 ± 1 standard error).
    z = interval95(0.0, 1.0, "normal")[1]
    z2 = z**2
    centre = (p + z2 / (2 * n)) / (1 + z2 / n)
    half = z * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n)) / (1 + z2 / n)
    return max(0.0, centre - half), min(1.0, centre + half)


def estimate_exposure(switches: Iterable[tuple[int, float]], given_s: float | None = None,
                      blur: BlurEvidence | None = None) -> ExposureEstimate:
    """Estimate the exposure from the LED switches and the motion blur of a campaign's videos.

    Parameters
    ----------
    switches : iterable of (partly_lit_frames, frame_interval_s)
        One per video whose LED switch was found: how many frames at the
        switch were partly lit (0, 1 or 2; see
        :attr:`servoscope.markers.led_timing.SwitchTime.partial_frames`) and
        the video's frame interval.
    given_s : float, optional
        The exposure the user gave (``[camera] exposure_s``): it wins.
    blur : BlurEvidence, optional
        The stickers' motion blur (:func:`blur_evidence`, pooled by :func:`pool_blur`).

    Returns
    -------
    ExposureEstimate
        Source "given", "LED", "blur", "LED+blur" (the two combined by their
        inverse variances) or "unknown"; the blur evidence rides along in
        every case.
    """
    switches = [(int(k), float(p)) for k, p in switches if p and p > 0]
    period = None
    if switches:
        period = sorted(p for _, p in switches)[len(switches) // 2]
    n = len(switches)
    partly = sum(1 for k, _ in switches if k > 0)
    if given_s is not None:
        return ExposureEstimate(float(given_s), 0.0, (float(given_s), float(given_s)), "given",
                                "[camera] exposure_s", period, n, partly, blur)
    led = _from_led(n, partly, period)
    seen = blur is not None and blur.seen
    blur_note = "" if blur is None else f"; {blur.describe()}"
    if led is None and not seen:
        if n == 0 or period is None:
            why = "no LED switch found: nothing shows the shutter"
        else:
            high = _wilson(partly, n)[1]
            why = (f"no LED switch of {n} lit a frame partly: a shutter shorter than the frame "
                   f"interval (≤ {high:.0%} of it, 95 %), how short the footage cannot tell")
        return ExposureEstimate(None, None, None, "unknown", why + blur_note, period, n, partly, blur)
    if not seen:
        value, se, ci, detail = led
        return ExposureEstimate(value, se, ci, "LED", detail + blur_note, period, n, partly, blur)
    b_value, b_se, b_ci = blur.exposure_s, blur.exposure_stderr_s, blur.ci95_s
    if led is None:
        return ExposureEstimate(b_value, b_se, b_ci, "blur", blur.describe(), period, n, partly, blur)
    value, se, ci, detail = led
    # Two independent measurements of one exposure: their inverse-variance mean.
    w_led, w_blur = 1.0 / se**2, 1.0 / b_se**2
    mean = (w_led * value + w_blur * b_value) / (w_led + w_blur)
    both_se = 1.0 / math.sqrt(w_led + w_blur)
    lo, hi = interval95(mean, both_se, "normal")
    return ExposureEstimate(mean, both_se, (max(lo, 0.0), hi), "LED+blur",
                            f"{detail}; {blur.describe()}", period, n, partly, blur)


def _from_led(n: int, partly: int, period: float | None) -> tuple[float, float, tuple[float, float], str] | None:
    """The exposure from the share of LED switches that lit a frame partly: (value, σ, 95 %, detail); None when none did."""
    if n == 0 or period is None or partly == 0:
        return None
    low, high = _wilson(partly, n)
    share = partly / n
    se = math.sqrt(share * (1 - share) / n) * period or (high - low) * period / 4
    return (share * period, se, (low * period, high * period),
            f"{partly} of {n} LED switches lit a frame partly: exposure {share:.0%} of the frame "
            f"interval (95 %: {low:.0%}–{high:.0%})")

"""The LED found by what only an LED does: it switches (issue 28, build 2; issue 29, build 3).

The engines follow one LED, the largest blob of its colour by the blade
(:func:`~servoscope.markers.led_level.locate_led`). Where that blob never
switches (a hub's glint, an LED fixed to the stand), every blob of the LED's
colour (or brightness) in the first frame with both markers is a candidate:
each one's level is followed through the video twice, fixed in the picture
and carried in the markers' frame (an LED on the blade). The LED is the one
whose level steps down once, sharply against its own noise, and stays down
(a light that leaves the picture in the last frames, or ends with the
video, is not a switch); where several step at the same frame it is the
lighting, not an LED. ``led_near`` pins it by position.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from ..errors import ServoscopeError
from .led_level import LED_PEAK_FRAMES, LED_STAY_FRAMES, InputStart, disks_native, input_start
from .moments import Moments

__all__ = ["LED_STAY_FRAMES", "LedCandidate", "LedSearch", "led_input_start", "switch_of"]

#: Most candidates followed (the largest blobs; a pinned one always).
LED_MAX_CANDIDATES = 8
#: A switch's step against the level's own noise (robust σ of the settled frames each side).
LED_SHARPNESS = 8.0
#: Smallest step (DN of 8-bit luma) that counts, as :func:`~servoscope.markers.led_level.input_start`'s.
LED_MIN_STEP_DN = 10.0


@dataclass
class LedCandidate:
    """One blob of the LED's colour: where it was, and its level per frame fixed and carried by the blade."""

    x_px: float
    y_px: float
    radius_px: float
    local: np.ndarray
    fixed: list[float] = field(default_factory=list)
    borne: list[float] = field(default_factory=list)
    peak_fixed: list[float] = field(default_factory=list)
    peak_borne: list[float] = field(default_factory=list)

    def where(self) -> str:
        return f"({self.x_px:.0f}, {self.y_px:.0f})"


def _axes(lead: Moments, trail: Moments):
    origin = np.array([trail.x_px, trail.y_px])
    axis = np.array([lead.x_px, lead.y_px]) - origin
    length = float(np.hypot(*axis))
    e = axis / length
    return origin, e, np.array([-e[1], e[0]]), length


def _rgb_disk(image: np.ndarray, cx: float, cy: float, r: float) -> float:
    """Mean BT.601 luma of an RGB image in a disk; NaN off the picture."""
    if not (math.isfinite(cx) and math.isfinite(cy)):
        return math.nan
    h, w = image.shape[:2]
    x0, x1 = int(max(0, math.floor(cx - r))), int(min(w, math.floor(cx + r) + 1))
    y0, y1 = int(max(0, math.floor(cy - r))), int(min(h, math.floor(cy + r) + 1))
    if x1 <= x0 or y1 <= y0:
        return math.nan
    yy, xx = np.mgrid[y0:y1, x0:x1]
    inside = (xx - cx) ** 2 + (yy - cy) ** 2 <= r * r
    px = np.asarray(image[y0:y1, x0:x1])[inside]
    if px.size == 0:
        return math.nan
    # BT.601 luma, as the YUV engines read it (a lit yellow LED's red clips at 255; its luma does not).
    return float((px.astype(np.float64) @ np.array([0.299, 0.587, 0.114])).mean())


class LedSearch:
    """The candidates for the LED, and their levels frame by frame (:meth:`measure`)."""

    def __init__(self, candidates: list[LedCandidate], first_frame: int, near: tuple[float, float] | None):
        self.candidates = candidates
        self.first_frame = first_frame
        self.near = near
        self._native: tuple | None = None  # measure_native's arrays, made on its first call

    @classmethod
    def find(cls, rgb: np.ndarray, model, lead: Moments, trail: Moments, first_frame: int,
             near: tuple[float, float] | None = None) -> "LedSearch":
        """The blobs of ``model``'s colour in ``rgb`` (the markers' disks masked out), largest first."""
        mask = model.mask(rgb).astype(np.uint8)
        for m in (lead, trail):
            r = 1.5 * math.sqrt(max(m.m00, 0.0) / math.pi) + 3.0
            cv2.circle(mask, (int(round(m.x_px)), int(round(m.y_px))), int(math.ceil(r)), 0, -1)
        n, _, stats, cents = cv2.connectedComponentsWithStats(mask, connectivity=8)
        areas = stats[1:, cv2.CC_STAT_AREA].astype(np.float64)
        order = [int(i) for i in np.argsort(-areas, kind="stable") if areas[i] >= 3][:LED_MAX_CANDIDATES]
        if near is not None and areas.size:
            pinned = int(np.argmin(np.hypot(*(cents[1:] - np.asarray(near)).T)))
            if pinned not in order:
                order.append(pinned)
        origin, e, nrm, length = _axes(lead, trail)
        found: list[LedCandidate] = []
        for i in order:
            if any(math.hypot(*(cents[1 + i] - (c.x_px, c.y_px))) <= 1.5 * c.radius_px + 2.0 for c in found):
                continue  # a piece of a larger blob (a light split by the codec or its housing's rim)
            d = cents[1 + i] - origin
            found.append(LedCandidate(float(cents[1 + i][0]), float(cents[1 + i][1]), math.sqrt(areas[i] / math.pi),
                                      np.array([d @ e, d @ nrm]) / length))
        return cls(found, first_frame, near)

    def measure_native(self, samples: np.ndarray, packed: bool, width: int, lead: Moments | None,
                       trail: Moments | None) -> None:
        """:meth:`measure` on a monochrome frame's native samples, every candidate's disks in one compiled call.

        The same levels to the bit as :meth:`measure` on the samples (or their
        unpacking). A packed 12-bit frame is read where the disks are, not
        unpacked whole each frame (a 1024×1024 packed MRAW with an LED: the whole
        track 2.1× faster); on 16-bit words one call instead of two a candidate
        (one candidate: 4.4 against 5.2 µs a frame).

        Parameters
        ----------
        samples, packed, width
            A :class:`~servoscope.video.native.NativeFrame`'s.
        lead, trail : Moments or None
        """
        if self._native is None:
            cs = self.candidates
            self._native = (np.array([c.x_px for c in cs], np.float64), np.array([c.y_px for c in cs], np.float64),
                            np.array([1.5 * c.radius_px + 1.0 for c in cs], np.float64),
                            np.array([float(c.local[0]) for c in cs]), np.array([float(c.local[1]) for c in cs]),
                            np.zeros(6), np.empty((len(cs), 4)))
        xs, ys, rs, us, vs, axes, out = self._native
        both = lead is not None and trail is not None
        if both:
            ox, oy = trail.x_px, trail.y_px  # type: ignore[union-attr]
            ax, ay = lead.x_px - ox, lead.y_px - oy  # type: ignore[union-attr]
            length = math.hypot(ax, ay)  # Python's hypot, as measure's
            axes[:] = (ox, oy, ax / length, ay / length, length, 1.0)
        else:
            axes[5] = 0.0
        disks_native(samples, packed, width, xs, ys, rs, us, vs, axes, out)
        for c, (level, peak, borne, borne_peak) in zip(self.candidates, out.tolist()):
            c.fixed.append(level)
            if len(c.peak_fixed) < LED_PEAK_FRAMES:
                c.peak_fixed.append(peak)
            if not both:
                c.borne.append(math.nan)
                continue
            c.borne.append(borne)
            if len(c.peak_borne) < LED_PEAK_FRAMES:
                c.peak_borne.append(borne_peak)

    def measure(self, image: np.ndarray, lead: Moments | None, trail: Moments | None) -> None:
        """Each candidate's level in this frame (``image``: luma, or RGB), fixed and carried by the markers.

        A 2-D image (a luma plane, samples) is :meth:`measure_native`'s, in one compiled call;
        an RGB image (the reference engine's) is measured disk by disk in its BT.601 luma,
        without peaks.
        """
        if image.ndim == 2:
            self.measure_native(image, False, image.shape[1], lead, trail)
            return
        axes = None
        if lead is not None and trail is not None:
            # Python floats: NumPy's 2-vectors cost more than the disk itself.
            ox, oy = trail.x_px, trail.y_px
            ax, ay = lead.x_px - ox, lead.y_px - oy
            length = math.hypot(ax, ay)
            axes = (ox, oy, ax / length, ay / length, length)
        for c in self.candidates:
            r = 1.5 * c.radius_px + 1.0
            c.fixed.append(_rgb_disk(image, c.x_px, c.y_px, r))
            if axes is None:
                c.borne.append(math.nan)
                continue
            ox, oy, ex, ey, length = axes
            u, v = float(c.local[0]), float(c.local[1])
            # Along the axis e and across it (−e_y, e_x), as LedSearch.find placed it.
            c.borne.append(_rgb_disk(image, ox + length * (u * ex - v * ey), oy + length * (u * ey + v * ex), r))

    def signals(self, n: int):
        """(candidate, "fixed" or "blade", levels over all ``n`` frames, peaks) for each candidate and mode."""
        pad = [math.nan] * self.first_frame
        for c in self.candidates:
            for how, level, peak in (("fixed", c.fixed, c.peak_fixed), ("blade", c.borne, c.peak_borne)):
                yield c, how, np.asarray((pad + level)[:n] + [math.nan] * max(0, n - len(pad) - len(level))), peak


@dataclass(frozen=True)
class Switch:
    """A level's one sharp step down: the first frame below half-way, the step (DN) and step / noise."""

    frame: int
    step_dn: float
    sharpness: float


def switch_of(level: np.ndarray) -> tuple[Switch | None, str]:
    """The one sharp step down of ``level`` that stays down, or None and why not.

    Lit and dark are the medians of the first and last five measured frames; the
    step is the first frame under half-way. It must be at least
    :data:`LED_MIN_STEP_DN` and :data:`LED_SHARPNESS` times the level's robust
    noise, take at most two frames (a partly lit frame each side), and the level
    must stay under half-way from there to the end, at least
    :data:`LED_STAY_FRAMES` frames, having been above it before.
    """
    ok = np.flatnonzero(np.isfinite(level))
    if ok.size < 2 * LED_STAY_FRAMES:
        return None, "too few frames"
    values = level[ok]
    on, off = float(np.median(values[:5])), float(np.median(values[-5:]))
    step = on - off
    if not step > LED_MIN_STEP_DN:
        return None, "no step down"
    below = values < on - 0.5 * step
    k = int(np.argmax(below))
    if k < 2 or below[:k].any() or not below[k:].all():
        return None, "not one step that stays down"
    if ok.size - k < LED_STAY_FRAMES:
        return None, "dark only in the video's last frames"
    if abs(values[k - 2] - on) > 0.25 * step or (k + 1 < values.size and abs(values[k + 1] - off) > 0.25 * step):
        return None, "not sharp (a slow fade)"
    settled = np.concatenate([values[:k - 1] - on, values[k + 2:] - off])
    mad = 1.4826 * float(np.median(np.abs(settled - np.median(settled))))
    noise = max(mad, float(np.std(settled[np.abs(settled) <= 5 * mad])) if mad > 0 else 0.0, 0.5)
    if step / noise < LED_SHARPNESS:
        return None, f"step {step:.0f} DN is under {LED_SHARPNESS:g}× its noise ({noise:.1f} DN)"
    return Switch(int(ok[k]), step, step / noise), ""


def _pin_hint(spec: str) -> str:
    key = "brightness" if spec.strip().lower() in ("bright", "dark") else "colour"
    return (f"pin it: led = {{{key} = \"{spec}\", near = [x, y]}} in campaign.toml's [markers], or "
            f"--led '{spec}@x,y'")


def _looked_at(search: LedSearch) -> str:
    parts = []
    for c in search.candidates:
        level = np.asarray(c.fixed, dtype=np.float64)
        finite = level[np.isfinite(level)]
        span = f"level {finite.min():.0f}-{finite.max():.0f}" if finite.size else "not measured"
        parts.append(f"{c.where()} {span}")
    return "; ".join(parts)


def _pinned(search: LedSearch, spec: str) -> LedCandidate:
    """The candidate at ``search.near``; ServoscopeError (naming those there are) when none is by it."""
    x, y = search.near
    best = min(search.candidates, key=lambda c: math.hypot(c.x_px - x, c.y_px - y), default=None)
    if best is None or math.hypot(best.x_px - x, best.y_px - y) > 3.0 * best.radius_px + 10.0:
        seen = _looked_at(search) or "none"
        raise ServoscopeError(f"LED pinned at ({x:g}, {y:g}): no blob of the LED's colour ({spec}) there in the "
                              f"first frame (blobs of it: {seen}); check the position with `servoscope markers`")
    return best


def led_input_start(search: LedSearch | None, engine_start: InputStart, own_warnings: list[str], args: dict,
                    spec: str, warnings: list[str]) -> InputStart:
    """The input's start from the engine's LED, or, where that does not switch or the LED is pinned, by its switch.

    ``engine_start`` and ``own_warnings`` are what :func:`input_start` made of the
    engine's LED; ``args`` the rest of :func:`input_start`'s arguments (all but the
    level, the peaks, ``warnings`` and ``led_xy``). Among the candidates the LED is
    the one whose level :func:`switch_of` finds one sharp step in (fixed in the
    picture or carried by the blade, whichever is sharper); where several step at
    the same frame (the lighting) or none does, no t0, and one warning naming the
    candidates and how to pin it.
    """
    if search is None or (search.near is None and engine_start.t0_s is not None):
        warnings.extend(own_warnings)
        return engine_start
    n = int(np.size(args["time_s"]))
    pinned = _pinned(search, spec) if search.near is not None else None
    best: dict[int, tuple[Switch, LedCandidate, str, np.ndarray, list[float]]] = {}
    for c, how, level, peak in search.signals(n):
        if pinned is not None and c is not pinned:
            continue
        sw, _ = switch_of(level)
        if sw is not None and (id(c) not in best or sw.sharpness > best[id(c)][0].sharpness):
            best[id(c)] = (sw, c, how, level, peak)
    # The engine's own complaints about its blob are superseded by the search's verdict.
    warnings[:] = [w for w in warnings if not w.startswith("LED not found in the first frames")]
    found = sorted(best.values(), key=lambda b: -b[0].sharpness)
    if len(found) > 1 and max(b[0].frame for b in found) - min(b[0].frame for b in found) <= 1:
        warnings.append(f"LED not found: {len(found)} lights step down together at frame {found[0][0].frame} "
                        f"(the lighting, not an LED): {_looked_at(search)}; {_pin_hint(spec)}")
        return InputStart(np.full(n, np.nan))
    if not search.candidates:
        warnings.append(f"LED not found: no blob of its colour ({spec}) beside the markers in the first frame with "
                        f"both; no input start (t0); check its colour with `servoscope markers`, or {_pin_hint(spec)}")
        return InputStart(np.full(n, np.nan))
    if not found:
        what = "the pinned blob" if pinned is not None else f"none of the {len(search.candidates)} blobs of its colour"
        looked = _looked_at(LedSearch([pinned], 0, None)) if pinned is not None else _looked_at(search) or "none"
        warnings.append(f"LED not found by its switch: {what} steps down once, sharply, and stays down "
                        f"(looked at {looked}); no input start (t0); {_pin_hint(spec)}")
        return InputStart(np.full(n, np.nan))
    sw, c, how, level, peak = found[0]
    if len(found) > 1:
        warnings.append(f"LED: {len(found)} blobs switch; took the sharpest, {c.where()} (step {sw.step_dn:.0f} DN); "
                        f"if that is not the LED, {_pin_hint(spec)}")
    return input_start(list(level), list(peak), warnings=warnings, led_xy=(c.x_px, c.y_px), **args)


def follow_candidates(log, image: np.ndarray, rgb, model, found: dict, near: tuple[float, float] | None,
                      row_offset: int = 0, row_step: int = 1) -> None:
    """An engine's step for one frame, before it is logged: the candidates found in the first frame with both
    markers (``rgb()`` gives its RGB image; ``near`` in frame px), then measured in ``image`` every frame."""
    if log.led_search is None:
        if model is None or "lead" not in found or "trail" not in found:
            return
        pin = None if near is None else (float(near[0]), (float(near[1]) - row_offset) / row_step)
        log.led_search = LedSearch.find(rgb(), model, found["lead"].moments, found["trail"].moments, len(log), pin)
    lead, trail = found.get("lead"), found.get("trail")
    log.led_search.measure(image, None if lead is None else lead.moments, None if trail is None else trail.moments)

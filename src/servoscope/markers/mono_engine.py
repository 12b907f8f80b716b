"""The monochrome engine (``engine="mono"``): brightness markers measured on the native samples.

Monochrome footage (high-speed cameras' MRAW, CINE, 8–16-bit TIFF sequences)
with markers told by brightness. Each frame is read as the camera stored it
(:func:`~servoscope.video.native.iter_native_frames`: a view of a
memory-mapped file where the file is an array of samples) and measured by one
call of the monochrome kernel (:mod:`.kernel_mono`) over the markers' windows
and the LED's disk: no conversion to 8 bits, RGB or YUV, no 8-bit rounding.

The first frame is found as the RGB reference engine (:mod:`.rgb_engine`)
finds it (8-bit RGB, thresholds from the frame's levels, the first
detection's selection); a marker lost or implausible in its window is found
again in the whole frame's RGB image and measured by the kernel around what
was found. The RGB engine stays the oracle (tests/markers/test_mono_engine.py):
on the 12-bit twin the two agree to their estimators' difference (0.02–0.04 px
RMS: the RGB engine's nearest-ring background is itself 0.015–0.02 px noisy)
plus the rounding this one removes (0.001 px at full light, 0.016 px lit at 10 %).

Each frame's illumination gain against the first frame's
(:class:`~.illumination.NativeGain`: lamp flicker, which a high-speed camera
sees frame by frame) scales the markers' learned level and class threshold
about black, as the YUV engine scales its learned colours: the unmixing's
``α = (p − b)/(M − b)`` with the first frame's ``M`` would read a dim frame's
sticker as smaller ("partly hidden"). Within the dead band
(:data:`~.illumination.GAIN_DEADBAND`) nothing is scaled: steady footage is
tracked bit for bit as without it. The LED's level is not scaled: it emits
its own light (its unlit level follows the lamps, as in the YUV engine).

Not done here: a rolling shutter's bands (:class:`~.illumination.BandGain`,
the YUV engine's) and rectangular stickers' own support (a rectangle is
measured in a disk around it).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..errors import ServoscopeError
from ..video.native import NativeFrame, iter_native_frames
from . import kernels as K
from .centroid import SoftCentroid
from .colour import BRIGHTNESS, BrightnessModel
from .first_frame import choose_first, nothing_matches
from .frame_record import EngineInput, FrameRecord, TrackLog
from .illumination import GAIN_DEADBAND, NativeGain, varied_warning
from .kernel_mono import MONO_LED_NQ, MONO_NP, MP, mono_led_level, track_frame_mono
from .led_level import LED_PEAK_FRAMES, locate_led
from .led_search import follow_candidates
from .marker_state import Blob, MarkerTracker
from .moments import Moments
from .refind import search_window, take_markers

__all__ = ["run_mono"]

#: Recentring passes of the soft moments (as the YUV engine's: one, from the class's centroid).
MONO_ITERATIONS = 1
#: Width of the background ring (px), as the YUV engine's.
RING_PX = 4.0
#: Support beyond the sticker's reach and ``support_margin_px`` (px). Measured on the 12-bit monochrome
#: twin (121 frames, angle error's σ against truth): −1 → 0.0017°, 0 → 0.0022°, +1 → 0.0021°, −2 →
#: 0.0016° (but 0.0046° RMS from the RGB oracle, against 0.0027° at −1): a wider support takes in more
#: background noise.
MONO_EXTRA_MARGIN_PX = -1.0
#: Least |marker − background| contrast at which a pixel is unmixed, in 8-bit DN (scaled to the samples'
#: depth): the RGB engine's 10 DN of three channels' norm is 5.8 DN of gray; under it the class flag is the weight.
MIN_CONTRAST_DN8 = 5.8
#: Clip of the membership.
ALPHA_RANGE = (0.0, 1.0)
#: The class (detection, coarse centre, area, extent) is sampled every CLASS_STEP pixels each way for stickers
#: reaching at least CLASS_STEP_MIN_REACH_PX (every pixel for smaller ones, whose area a coarse grid counts
#: too roughly for the area check). Measured on a 1024×1024 12-bit MRAW: 30 % off the per-frame time (the class
#: pass over a 77×77 window was half the kernel's); angle noise on the 12-bit twin (three footages) 2.33/3.41/1.88
#: mdeg against 2.43/3.56/1.69 sampling every pixel: the same within the estimate's scatter.
CLASS_STEP = 2
CLASS_STEP_MIN_REACH_PX = 6.0


class _MonoState:
    """A marker's parameter row (:class:`~.kernel_mono.MP`) and its class area in the first frame.

    ``radius`` and ``edge`` repeat the row's support radius and the class's last
    sampled offset (1 + STEP) as Python floats: :func:`_blob` reads them twice a
    frame, and arithmetic on NumPy scalars costs several times more.
    """

    def __init__(self) -> None:
        self.prm = np.zeros(MONO_NP)
        self.class_area: float | None = None
        self.radius = 0.0
        self.edge = 1.0


def _core(frame: NativeFrame, m: Moments, r: float) -> np.ndarray:
    """The samples within ``r`` px of the blob's centroid (the sticker's interior), as float64."""
    h, w = frame.shape
    x0, x1 = int(max(0, math.floor(m.x_px - r))), int(min(w, math.ceil(m.x_px + r) + 1))
    y0, y1 = int(max(0, math.floor(m.y_px - r))), int(min(h, math.ceil(m.y_px + r) + 1))
    yy, xx = np.mgrid[y0:y1, x0:x1]
    inside = (xx - m.x_px) ** 2 + (yy - m.y_px) ** 2 <= r * r
    # As stored, the kernel's levels (``gray`` shifts a word's high-bit samples down: 16x below them for 12 bits).
    return frame.stored(slice(y0, y1))[:, x0:x1][inside].astype(np.float64)


def _learn(tracker: MarkerTracker, frame: NativeFrame, m: Moments, margin_px: float) -> None:
    """The marker's kernel row from the first detection: level, threshold, noise in the samples' DN; support."""
    model = tracker.model
    reach = float(tracker.reach_px or tracker.extent_px)
    core = _core(frame, m, max(1.5, 0.6 * (reach - 1.5)))
    level = float(np.median(core))
    mad = float(np.median(np.abs(core - level)))
    dn8 = (frame.white - frame.black) / 255.0  # samples' DN per 8-bit DN
    prm = tracker.mono.prm
    prm[MP.LEVEL] = level
    prm[MP.THRESHOLD] = frame.from_8bit(model.threshold_dn)
    prm[MP.SIGN] = 1.0 if model.bright else -1.0
    prm[MP.STEP] = CLASS_STEP if reach >= CLASS_STEP_MIN_REACH_PX else 1
    prm[MP.RADIUS] = reach + margin_px + MONO_EXTRA_MARGIN_PX
    prm[MP.RING] = RING_PX
    prm[MP.ITER] = MONO_ITERATIONS
    prm[MP.ENABLED] = 1.0
    # Robust σ² of the interior, and at least the samples' own quantisation (1/12 DN²).
    prm[MP.VAR] = (1.4826 * mad) ** 2 + 1.0 / 12.0
    prm[MP.ALPHA_LO], prm[MP.ALPHA_HI] = ALPHA_RANGE
    prm[MP.MIN_CONTRAST] = MIN_CONTRAST_DN8 * dn8
    tracker.mono.radius = float(prm[MP.RADIUS])
    tracker.mono.edge = 1.0 + float(prm[MP.STEP])


def _blob(tracker: MarkerTracker, row: np.ndarray, window, shape) -> Blob | None:
    """The marker's blob from its kernel output row, or None when the window's class is implausible.

    The YUV engine's checks (:mod:`.yuv_engine`): a class of the first frame's area,
    not cut by the window's edge, its soft centroid near its binary one.
    """
    Q = K.Q
    row = row.tolist()  # Python floats: indexing and arithmetic on NumPy scalars cost more
    n = row[Q.N]
    if not n > 0 or not row[Q.M00] > 0:
        return None
    area = tracker.mono.class_area
    if area is not None and not (0.4 * area <= n <= 2.5 * area):
        return None
    h, w = shape
    x0, y0, x1, y1 = window
    last = tracker.mono.edge  # the class's last sampled column (row) may be STEP − 1 from the edge
    if ((row[Q.XMIN] < x0 + 1 and x0 > 0) or (row[Q.YMIN] < y0 + 1 and y0 > 0)
            or (row[Q.XMAX] > x1 - last and x1 < w) or (row[Q.YMAX] > y1 - last and y1 < h)):
        return None  # cut by the window (not the image): part of something larger, look wider
    if math.hypot(row[Q.X] - row[Q.BX], row[Q.Y] - row[Q.BY]) > 0.5 * tracker.extent_px + 2.0:
        return None
    m = Moments(row[Q.M00], row[Q.X], row[Q.Y], row[Q.MU20], row[Q.MU11], row[Q.MU02])
    radius = tracker.mono.radius
    support_out = m.x_px - radius < 0 or m.y_px - radius < 0 or m.x_px + radius > w - 1 or m.y_px + radius > h - 1
    at_border = bool(support_out or row[Q.RING_N] < 8)
    soft = SoftCentroid(m, math.sqrt(0.5 * (row[Q.VAR_X] + row[Q.VAR_Y])), radius, row[Q.CONTRAST], 0.0, at_border)
    return Blob(m, soft.sigma_px, tracker.flaw(soft))


def _apply_gain(prm: np.ndarray, gain: float, black: float) -> None:
    """Scale a marker's learned level and class threshold in its kernel row (:class:`~.kernel_mono.MP`) to this
    frame's light, about the samples' black level.

    The threshold too: the whole scene's light scales, so the class (the coarse
    centre, the area check, the ring's exclusion of the marker's pixels) keeps the
    first frame's cut between sticker and background. Within
    :data:`~servoscope.markers.illumination.GAIN_DEADBAND` of 1 the row is left as it is.
    """
    if abs(gain - 1.0) <= GAIN_DEADBAND:
        return
    prm[MP.LEVEL] = black + gain * (prm[MP.LEVEL] - black)
    prm[MP.THRESHOLD] = black + gain * (prm[MP.THRESHOLD] - black)


@njit(cache=True, nogil=True)
def _same_samples(a, b, start) -> bool:
    """Whether two frames' samples are equal, from row ``start`` on (a differing frame differs there at once)."""
    if a.shape != b.shape:
        return False
    h = a.shape[0]
    for k in range(h):
        i = (start + k) % h
        for j in range(a.shape[1]):
            if a[i, j] != b[i, j]:
                return False
    return True


def _candidates_in_8bit(search, frame: NativeFrame) -> None:
    """The LED candidates' levels, measured on the samples, as 8-bit levels (the RGB engine's units).

    The LED's search (:mod:`.led_search`) reads a 2-D image's disks compiled; it
    is handed the samples as they are (no whole-frame conversion a frame), and
    its levels are mapped to 8-bit levels once, at the end (the map is linear).
    """
    if search is None:
        return
    for c in search.candidates:
        for name in ("fixed", "borne", "peak_fixed", "peak_borne"):
            setattr(c, name, [frame.to_8bit(float(v)) for v in getattr(c, name)])


def run_mono(job: EngineInput, log: TrackLog) -> None:
    """Track ``job``'s monochrome footage with the monochrome kernel, one record a frame into ``log``.

    The first frame: brightness models from its levels, the first detection and
    each marker's kernel row (:func:`_learn`); then each frame is one kernel call
    for both markers and the LED, a marker lost or implausible there found again
    in the whole frame (RGB) and measured by the kernel around what was found.
    LED levels are 8-bit levels (the samples scaled, unrounded), as the RGB engine's.
    Long because its steps share the kernel's buffers and the per-frame state.

    Raises
    ------
    ServoscopeError
        When a marker is not found in the first frame, or a marker is given by colour.
    """
    path, settings, lead, trail, led_model = job.path, job.settings, job.lead, job.trail, job.led_model
    specs = (job.lead_spec, job.trail_spec)
    if not all(isinstance(s, str) and s in BRIGHTNESS for s in specs):
        raise ServoscopeError("engine \"mono\" tracks markers told by brightness (\"bright\", \"dark\"); markers "
                              "told by colour are tracked by engine \"numba\" (or \"auto\")")
    trackers = (lead, trail)
    for t in trackers:
        t.mono = _MonoState()
    params = np.zeros((2, MONO_NP))
    out = np.zeros((2, K.NQ))
    led_prm = np.zeros(K.LED_NP)
    led_out = np.zeros(MONO_LED_NQ)
    led_local = None
    prev = None
    learned = False
    first: dict[str, Blob] = {}
    progress = job.progress
    gain_of = NativeGain()
    gain = 1.0  # this frame's illumination against the first frame's (see illumination.py)
    gains: list[float] = []

    def measure_one(k: int, frame: NativeFrame, window, centre=None) -> Blob | None:
        one = np.zeros((2, MONO_NP))
        one[k] = trackers[k].mono.prm
        _apply_gain(one[k], gain, frame.black)
        one[k, MP.X0:MP.Y1 + 1] = window
        if centre is not None:
            one[k, MP.CX], one[k, MP.CY], one[k, MP.USE_CENTRE] = centre[0], centre[1], 1.0
        tmp = np.zeros((2, K.NQ))
        track_frame_mono(frame.samples, frame.packed, frame.width, one, np.zeros(K.LED_NP), tmp,
                         np.zeros(MONO_LED_NQ))
        out[k] = tmp[k]
        return _blob(trackers[k], tmp[k], window, frame.shape)

    for frame in iter_native_frames(path):
        shape = frame.shape
        samples = frame.samples
        gain = gain_of(frame)
        gains.append(gain)
        found: dict[str, Blob] = {}
        slow = False
        if not learned:
            rgb = frame.rgb
            # Markers (and an LED) told by brightness: their thresholds from this frame's levels, once a
            # brightness (the frame's percentiles cost ~25 ms a megapixel; "bright" markers and LED share one).
            models = {spec: BrightnessModel.from_frame(rgb, spec)
                      for spec in {*specs, *([job.led_brightness] if job.led_brightness else [])}}
            for tracker, spec in zip(trackers, specs):
                tracker.model = models[spec]
            if job.led_brightness is not None:
                led_model = models[job.led_brightness]
            log.warnings.extend(choose_first(path, rgb, trackers, settings, frame.row_offset, frame.row_step))
            for tracker in trackers:
                blob, why = tracker.find(rgb)
                if blob is None:
                    raise ServoscopeError(nothing_matches(path, tracker, rgb))
                tracker.learn(rgb, blob)
                blob = tracker.find(rgb)[0] or blob
                first[tracker.name] = blob
                _learn(tracker, frame, blob.moments, settings.support_margin_px)
            for k, tracker in enumerate(trackers):
                m = first[tracker.name].moments
                measure_one(k, frame, search_window(tracker, shape, (m.x_px, m.y_px)))
                tracker.mono.class_area = float(out[k, K.Q.N]) if out[k, K.Q.N] > 0 else None
            learned = True
            slow = True
        windows = []
        for k, tracker in enumerate(trackers):
            params[k] = tracker.mono.prm
            window = search_window(tracker, shape) if tracker.has_position or not slow else None
            if window is None and slow:
                m = first[tracker.name].moments  # the first frame: around the found blob
                window = search_window(tracker, shape, (m.x_px, m.y_px))
            windows.append(window)
            if window is None:
                params[k, MP.ENABLED] = 0.0
            else:
                _apply_gain(params[k], gain, frame.black)
                params[k, MP.X0:MP.Y1 + 1] = window
        led_prm[0] = 1.0 if led_local is not None else 0.0
        track_frame_mono(samples, frame.packed, frame.width, params, led_prm, out, led_out)
        # A duplicated frame: the same samples under a new timestamp. Compared from a row the kernel has just
        # read: a memory-mapped frame's pages are mapped on their first read, and the middle row's may be
        # one no window touches (a differing frame differs in its first row compared, whichever it is).
        start = windows[0][1] if windows[0] is not None else shape[0] // 2
        repeated = prev is not None and _same_samples(prev, samples, start)
        prev = samples
        reason, took_slow = take_markers(trackers, windows, out, shape, _blob, lambda: frame.rgb,
                                         lambda k, window, centre: measure_one(k, frame, window, centre), found)
        slow = slow or took_slow
        led_level = led_peak = None
        if log.led_search is not None:
            # Every candidate's disks in one compiled call on the samples as stored (packed ones too).
            lead_b, trail_b = found.get("lead"), found.get("trail")
            log.led_search.measure_native(samples, frame.packed, frame.width,
                                          None if lead_b is None else lead_b.moments,
                                          None if trail_b is None else trail_b.moments)
        elif led_model is not None:
            # Found in the first frame with both markers (and measured there): packed samples unpacked, once.
            follow_candidates(log, frame.gray if frame.packed else samples, lambda: frame.rgb, led_model, found,
                              settings.led_near)
        if led_model is not None:
            both = len(found) == 2
            if led_local is None and both:
                led_local, led_radius = locate_led(frame.rgb, led_model, found["lead"].moments,
                                                   found["trail"].moments)
                if led_local is None:
                    log.warnings.append("LED not found in the first frames: no input start (t0)")
                    led_model = None
                else:
                    led_prm[:] = (1.0, led_local[0], led_local[1], 1.5 * led_radius + 1.0)
                    slow = True
            if led_local is not None and slow:
                mono_led_level(samples, frame.packed, frame.width, led_prm, out, led_out)
            led_level = frame.to_8bit(float(led_out[0])) if led_local is not None and both else math.nan
            if led_local is not None and both and len(log.led_peak_dn) < LED_PEAK_FRAMES:
                led_peak = frame.to_8bit(float(led_out[4]))
        log.add(FrameRecord(frame.index, frame.time_s, frame.intra, 0, 1, found, reason, repeated,
                            lambda frame=frame: frame.rgb, led_level, led_peak))
        if progress is not None and frame.index % 50 == 0:
            progress(frame.index + 1)
    if prev is not None:
        _candidates_in_8bit(log.led_search, frame)
    varied = varied_warning(gains, "the markers' levels")
    if varied:
        log.warnings.append(varied)

"""The YUV engines (``"numba"``, ``"numpy"``): the fused kernel on the decoder's planes.

Each marker's kernel row (:mod:`.kernels`) is learned from the first frame (its
colour, hue cone, noise; a rectangular sticker's outline); each frame the kernel
classifies by chroma inside a window around the predicted position and unmixes
with full-resolution luma. A marker lost or implausible there is found in the
whole frame by its :class:`~.marker_state.MarkerTracker` (RGB components) and
measured by the kernel around what was found.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from ..errors import ServoscopeError
from ..video.reader import iter_yuv_frames, probe_video
from . import kernels as K
from .centroid import SoftCentroid
from .colour import AUTO, ycbcr_bt601
from .first_frame import choose_first, nothing_matches, take_auto_colours
from .frame_checks import same_image
from .frame_record import EngineInput, FrameRecord, TrackLog
from .illumination import GAIN_DEADBAND, BandGain, GlobalGain, scale_colour, varied_warning
from .led_level import LED_PEAK_FRAMES, disk_peak, locate_led
from .led_search import follow_candidates
from .marker_state import Blob, MarkerTracker
from .moments import Moments
from .refind import search_window, take_markers

__all__ = ["learn_colour_model", "run_yuv"]


#: Luma weight of the unmixing (see kernels): luma's α weighs w_Y·c_Y² against
#: chroma's |c_C|². Measured on the twin's H.264 footage, a strong luma weight
#: (16–64) is *worse* (0.0059–0.0067°) than 1 (0.0049°): around these stickers
#: the background's luma varies (blade edge, sky gradient) as much as the
#: marker/background luma contrast, and the ring's per-angle background does
#: not capture it finely enough for luma; chroma's background is flatter.
W_Y = 1.0
#: Recentring passes of the soft moments.
YUV_ITERATIONS = 1
#: Width of the background ring (px).
RING_PX = 4.0
#: Extra support margin of the YUV path over ``support_margin_px`` (px): the
#: chroma's 2-px smear must fit inside the support.
YUV_EXTRA_MARGIN_PX = -1.5
#: Largest |α_Y − α_C| at which luma still sets the weight (see kernels; compared at chroma's
#: resolution, ramp ±0.1). Where both are right they differ only by noise: ~1 DN of codec error
#: per sample (H.264 − raw, measured) over contrasts of 30–90 DN, α noise ≈ 0.01–0.03, so
#: 0.15 (full trust below 0.05, none above 0.25) is ≥ 3 σ; results are flat for 0.1–0.2.
AGREE = 0.15
#: Clip of the membership.
ALPHA_RANGE = (0.0, 1.0)
#: Under a rolling shutter, each marker's illumination gain from the band of sensor rows around
#: it (:class:`~.illumination.BandGain`), not the frame's: flicker lights the bands differently.
#: False keeps the frame's gain for every marker (the behaviour before issue 29; benchmarks).
BAND_GAIN = True


def _chroma_angle(uv: np.ndarray) -> np.ndarray:
    return np.arctan2(uv[..., 1] - 128.0, uv[..., 0] - 128.0)


class _YuvState:
    """A marker's YUV model: its kernel parameter row and class area.

    ``phi0`` is a rectangular sticker's long-side direction (rad, image
    coordinates) at the first frame, where the markers' line had direction
    ``beta0``; None for a round sticker.
    """

    def __init__(self) -> None:
        self.prm = np.zeros(K.NP)
        self.class_area: float | None = None
        self.phi0: float | None = None
        self.beta0 = 0.0


#: A sticker whose binary blob fills at least this fraction of its minimum-area bounding
#: rectangle is rectangular (a square, a tape strip): its support follows that rectangle. A
#: disk fills π/4 = 0.785 of its square (0.74–0.82 measured on pixelated 17–26 px disks, H.264).
RECT_FILL = 0.86
#: ...or at least this fraction with a half-length under this many second-moment σ along its long
#: axis (a rectangle √3 = 1.73, 1.81–1.84 measured; a disk 2, 1.91–2.05 measured).
RECT_FILL_ELONGATED = 0.83
RECT_SIGMA_RATIO = 1.86
#: Support beyond a rectangular sticker's outline (px), as a round sticker's reaches ~2 px beyond
#: its edge: the edge blur and the codec's chroma smear fit inside.
RECT_SUPPORT_PX = 2.0


def _learn_rect(tracker: MarkerTracker, frame, m: Moments) -> None:
    """Decide whether the found sticker is rectangular; if so, set its kernel row's rectangle."""
    st = tracker.yuv
    if frame.row_step != 1 or tracker.model is None:
        return  # fields: a rectangle in field rows is sheared; round support as before
    rgb = frame.rgb
    h, w = rgb.shape[:2]
    r = float(tracker.reach_px or tracker.extent_px) + 2.0
    x0, x1 = int(max(0, math.floor(m.x_px - r))), int(min(w, math.ceil(m.x_px + r) + 1))
    y0, y1 = int(max(0, math.floor(m.y_px - r))), int(min(h, math.ceil(m.y_px + r) + 1))
    mask = tracker.model.mask(rgb[y0:y1, x0:x1]).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if n <= 1:
        return
    lab = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    ys, xs = np.nonzero(labels == lab)
    if xs.size < 12:
        return
    pts = np.c_[xs + x0, ys + y0].astype(np.float32)
    (cx, cy), (rw, rh), _ = cv2.minAreaRect(pts)
    # minAreaRect spans pixel centres: a pixel more each way reaches their edges.
    fill = xs.size / ((rw + 1.0) * (rh + 1.0))
    major_ratio = 0.5 * (max(rw, rh) + 1.0) / max(m.axes_px[0], 1e-9)
    # A rectangle's half-side is √3 its second-moment σ, a disk's or an ellipse's radius 2σ.
    if not (fill >= RECT_FILL or (fill >= RECT_FILL_ELONGATED and major_ratio <= RECT_SIGMA_RATIO)):
        return
    corners = cv2.boxPoints(((cx, cy), (rw, rh), _))
    side_a, side_b = corners[1] - corners[0], corners[2] - corners[1]
    long_side = side_a if np.hypot(*side_a) >= np.hypot(*side_b) else side_b
    # The half-sides from the soft second moments (a rectangle's half-side is √3 σ), not the binary
    # extents: those grow with the edge blur and the chroma smear, and a support that reaches
    # further takes in background the ring does not describe (a blade's edge beside a strip).
    a, b = m.axes_px
    hu, hv = math.sqrt(3.0) * a, math.sqrt(3.0) * b
    prm = st.prm
    prm[K.P.RECT] = 1.0
    prm[K.P.HALF_U], prm[K.P.HALF_V] = hu, hv
    prm[K.P.RECT_MARGIN] = RECT_SUPPORT_PX
    prm[K.P.RADIUS] = math.hypot(hu, hv) + RECT_SUPPORT_PX
    st.phi0 = math.atan2(float(long_side[1]), float(long_side[0]))
    tracker.edge_factor = (hu + hv) / math.sqrt(math.pi * hu * hv)
    _orient(prm, st.phi0)


def _orient(prm: np.ndarray, phi: float) -> None:
    prm[K.P.COS], prm[K.P.SIN] = math.cos(phi), math.sin(phi)


def _line_direction(lead: MarkerTracker, trail: MarkerTracker) -> float | None:
    """Direction (rad, image coordinates) from the trail marker's predicted position to the lead's."""
    a, b = lead.predicted_xy(), trail.predicted_xy()
    if a is None or b is None:
        return None
    return math.atan2(a[1] - b[1], a[0] - b[0])


def _robust_var(x: np.ndarray) -> float:
    mad = float(np.median(np.abs(x - np.median(x))))
    return (1.4826 * mad) ** 2 + 0.25


def learn_colour_model(prm: np.ndarray, y: np.ndarray, u: np.ndarray, v: np.ndarray,
                       max_tolerance_rad: float = math.radians(20.0)) -> tuple[float, float]:
    """Set a YUV kernel row's colour model from samples of a marker's core; its hue and the cone's half-angle (rad).

    The median colour (``YM``, ``UM``, ``VM``), its chroma direction, the hue cone's half-angle
    (3 × the samples' 90th-percentile spread about it, within 10°-20° and at most
    ``max_tolerance_rad``), the saturation floor (0.45 × its saturation, at least 6) and the
    luma and chroma noise (robust variances; the chroma's at least the luma's). ``y``, ``u``, ``v``:
    the samples' luma and chroma (float arrays of one length). The half-angle returned is the
    samples' own (before ``max_tolerance_rad``).
    """
    ym, um, vm = float(np.median(y)), float(np.median(u)), float(np.median(v))
    sat = math.hypot(um - 128.0, vm - 128.0)
    mean_ang = math.atan2(vm - 128.0, um - 128.0)
    spread = np.abs(np.angle(np.exp(1j * (np.arctan2(v - 128.0, u - 128.0) - mean_ang))))
    tol = float(np.clip(3.0 * np.percentile(spread, 90), math.radians(10.0), math.radians(20.0)))
    prm[K.P.YM], prm[K.P.UM], prm[K.P.VM] = ym, um, vm
    prm[K.P.DIR_U], prm[K.P.DIR_V] = (um - 128.0) / max(sat, 1e-9), (vm - 128.0) / max(sat, 1e-9)
    prm[K.P.COS_TOL] = math.cos(min(tol, max_tolerance_rad))
    prm[K.P.SAT_MIN] = max(6.0, 0.45 * sat)
    prm[K.P.VAR_Y] = _robust_var(y)
    # A codec leaves a flat interior almost free of chroma noise while its chroma errors at the
    # edges are larger: take at least the luma's noise for the chroma.
    prm[K.P.VAR_C] = max(0.5 * (_robust_var(u) + _robust_var(v)), prm[K.P.VAR_Y])
    return mean_ang, tol


def _learn_yuv(tracker: MarkerTracker, frame, m: Moments, margin_px: float) -> None:
    """Marker colour (median), chroma direction, hue tolerance and noise from the core of the found blob."""
    reach = float(tracker.reach_px or tracker.extent_px)
    h, w = frame.y.shape
    r_core = max(1.5, 0.6 * (reach - 1.5))
    prm = tracker.yuv.prm
    rect = bool(prm[K.P.RECT])
    r_box = math.hypot(prm[K.P.HALF_U], prm[K.P.HALF_V]) if rect else r_core
    x0, x1 = int(max(0, math.floor(m.x_px - r_box))), int(min(w, math.ceil(m.x_px + r_box) + 1))
    y0, y1 = int(max(0, math.floor(m.y_px - r_box))), int(min(h, math.ceil(m.y_px + r_box) + 1))
    yy, xx = np.mgrid[y0:y1, x0:x1]
    if rect:
        # A strip's disk of radius 0.6·reach is mostly background: its rectangle, 2 px in.
        c, s = float(prm[K.P.COS]), float(prm[K.P.SIN])
        u, v = (xx - m.x_px) * c + (yy - m.y_px) * s, (yy - m.y_px) * c - (xx - m.x_px) * s
        core = ((np.abs(u) <= max(1.0, prm[K.P.HALF_U] - 2.0)) & (np.abs(v) <= max(1.0, prm[K.P.HALF_V] - 2.0)))
    else:
        core = (xx - m.x_px) ** 2 + (yy - m.y_px) ** 2 <= r_core**2
    xs, ys = xx[core].astype(np.float64), yy[core].astype(np.float64)
    Y = frame.y[y0:y1, x0:x1][core].astype(np.float64)
    U = K.chroma_np(frame.u, xs, ys, frame.row_offset, frame.row_step)
    V = K.chroma_np(frame.v, xs, ys, frame.row_offset, frame.row_step)
    _, tol = learn_colour_model(prm, Y, U, V)
    st = tracker.yuv
    prm[K.P.AGREE] = AGREE
    if not rect:  # a rectangle's support is set by its shape (see _learn_rect)
        prm[K.P.RADIUS] = reach + margin_px + YUV_EXTRA_MARGIN_PX
    prm[K.P.RING] = RING_PX
    prm[K.P.W_Y] = W_Y
    prm[K.P.ITER] = YUV_ITERATIONS
    prm[K.P.ENABLED] = 1.0
    prm[K.P.ALPHA_LO], prm[K.P.ALPHA_HI] = ALPHA_RANGE
    prm[K.P.MIN_DEN] = 100.0
    st.tolerance_rad = tol


def _separate_hues(states: list[_YuvState], led_rgb) -> None:
    """Narrow each marker's hue tolerance to under half the angle to the other colours (markers, LED)."""
    dirs = [math.atan2(st.prm[K.P.DIR_V], st.prm[K.P.DIR_U]) for st in states]
    others = list(dirs)
    if led_rgb is not None:
        y, u, v = ycbcr_bt601(led_rgb)
        others.append(math.atan2(v - 128.0, u - 128.0))
    for i, st in enumerate(states):
        gaps = [abs(math.remainder(dirs[i] - o, 2 * math.pi)) for j, o in enumerate(others) if j != i]
        tol = st.tolerance_rad
        if gaps:
            tol = min(tol, 0.45 * min(gaps))
        st.prm[K.P.COS_TOL] = math.cos(max(tol, math.radians(4.0)))


def _kernel_blob(tracker: MarkerTracker, row: np.ndarray, window, shape) -> Blob | None:
    """The marker's blob from its kernel output row, or None when the window's class is implausible."""
    st = tracker.yuv
    prm = st.prm
    row = row.tolist()  # Python floats: indexing and arithmetic on NumPy scalars cost more
    n = row[K.Q.N]
    if not n > 0 or not row[K.Q.M00] > 0:
        return None
    if st.class_area is not None and not (0.4 * st.class_area <= n <= 2.5 * st.class_area):
        return None
    h, w = shape
    x0, y0, x1, y1 = window
    # A class cut by the window's edge (not the image's) may be part of something larger: look wider.
    if ((row[K.Q.XMIN] < x0 + 1 and x0 > 0) or (row[K.Q.YMIN] < y0 + 1 and y0 > 0)
            or (row[K.Q.XMAX] > x1 - 2 and x1 < w) or (row[K.Q.YMAX] > y1 - 2 and y1 < h)):
        return None
    if math.hypot(row[K.Q.X] - row[K.Q.BX], row[K.Q.Y] - row[K.Q.BY]) > 0.5 * tracker.extent_px + 2.0:
        return None
    m = Moments(row[K.Q.M00], row[K.Q.X], row[K.Q.Y], row[K.Q.MU20], row[K.Q.MU11], row[K.Q.MU02])
    radius = float(prm[K.P.RADIUS])
    rx = ry = radius
    if prm[K.P.RECT]:
        # A rectangle's support reaches its own bounding box, not the disk around it.
        hu, hv, c, s = (float(prm[i]) for i in (K.P.HALF_U, K.P.HALF_V, K.P.COS, K.P.SIN))
        sm = float(prm[K.P.RECT_MARGIN])
        rx, ry = abs(hu * c) + abs(hv * s) + sm, abs(hu * s) + abs(hv * c) + sm
    support_out = m.x_px - rx < 0 or m.y_px - ry < 0 or m.x_px + rx > w - 1 or m.y_px + ry > h - 1
    at_border = bool(support_out or row[K.Q.RING_N] < 8)
    soft = SoftCentroid(m, math.sqrt(0.5 * (row[K.Q.VAR_X] + row[K.Q.VAR_Y])), radius, row[K.Q.CONTRAST],
                        0.0, at_border)
    return Blob(m, soft.sigma_px, tracker.flaw(soft))


def run_yuv(job: EngineInput, engine: str, log: TrackLog) -> None:
    """Track ``job``'s video with the YUV engine ``engine`` ("numba", "numpy"), one record a frame into ``log``.

    The first frame learns each marker's kernel row (:func:`_learn_rect`,
    :func:`_learn_yuv`, :func:`_separate_hues`); then each frame is one kernel call for both markers, with a marker lost or
    implausible found again in the whole frame and measured around what was
    found. The LED's level is measured by its own kernel on the frames where
    the markers' kernel took the slow path, else by the markers' call.
    Frames' illumination against the first's scales the learned colours
    (:mod:`.illumination`); under a rolling shutter each marker's by the light
    of its own band of sensor rows (:data:`BAND_GAIN`). Long because its steps share the kernels'
    buffers and the per-frame state, which is clearer in one place.

    Raises
    ------
    ServoscopeError
        When a marker is not found in the first frame.
    """
    path, settings, lead, trail, led_model = job.path, job.settings, job.lead, job.trail, job.led_model
    kernel = K.ENGINES[engine]
    led_kernel = K.LED_ENGINES[engine]
    trackers = (lead, trail)
    for t in trackers:
        t.yuv = _YuvState()
    params = np.zeros((2, K.NP))
    out = np.zeros((2, K.NQ))
    led_prm = np.zeros(K.LED_NP)
    led_out = np.zeros(K.LED_NQ)
    led_rgb = led_model.rgb if led_model is not None else None
    led_local = None
    prev = None
    learned = False
    gain_of = GlobalGain()
    gain = 1.0  # this frame's illumination against the first frame's (see illumination.py)
    gains: list[float] = []
    band_of = None
    if settings.readout_s > 0 and job.fields is None and BAND_GAIN:
        # The sensor's rows are the image's columns under a phone's quarter-turn rotation.
        band_of = BandGain(settings.readout_s, axis=1 if (probe_video(path).rotation_deg // 90) % 2 else 0)

    def gain_at(window) -> float:
        """The illumination gain for a marker measured in ``window``: its band's, else the frame's."""
        if band_of is None or window is None:
            return gain
        # The window is (x0, y0, x1, y1): the band's axis 0 (rows) is its y, axis 1 its x.
        i = 1 - band_of.axis
        along = 0.5 * (window[i] + window[i + 2] - 1)
        g = band_of.gain(along, gain)
        if abs(g - 1.0) > abs(worst[0] - 1.0):
            worst[0] = g
        return g

    def measure_one(k: int, frame, window, centre=None) -> Blob | None:
        one = np.zeros((2, K.NP))
        one[k] = trackers[k].yuv.prm
        _apply_gain(one[k], gain_at(window))
        one[k, K.P.X0:K.P.Y1 + 1] = window
        if centre is not None:
            one[k, K.P.CX], one[k, K.P.CY], one[k, K.P.USE_CENTRE] = centre[0], centre[1], 1.0
        tmp = np.zeros((2, K.NQ))
        kernel(frame.y, frame.u, frame.v, frame.row_offset, frame.row_step, one, np.zeros(K.LED_NP), tmp,
               np.zeros(K.LED_NQ))
        out[k] = tmp[k]
        return _kernel_blob(trackers[k], tmp[k], window, frame.y.shape)

    for frame in iter_yuv_frames(path, fields=job.fields):
        shape = frame.y.shape
        # A camcorder's duplicated frame: the same image under a new timestamp.
        repeated = prev is not None and same_image(prev, frame)
        prev = frame
        gain = gain_of(frame.y, frame.row_offset)
        worst = [gain]  # the gain furthest from 1 this frame took, for the warning
        if band_of is not None:
            band_of.set_frame(frame.y)
        found: dict[str, Blob] = {}
        slow = False
        if not learned:
            rgb = frame.rgb
            if AUTO in (job.lead_spec, job.trail_spec):
                take_auto_colours(path, rgb, trackers, led_model)
            log.warnings.extend(choose_first(path, rgb, trackers, settings, frame.row_offset, frame.row_step))
            first = {}
            for tracker in trackers:
                blob, why = tracker.find(rgb)
                if blob is None:
                    raise ServoscopeError(nothing_matches(path, tracker, rgb))
                tracker.learn(rgb, blob)
                blob = tracker.find(rgb)[0] or blob
                first[tracker.name] = blob
                # The shape first: a rectangle's colour is learned from its own interior.
                _learn_rect(tracker, frame, blob.moments)
                _learn_yuv(tracker, frame, blob.moments, settings.support_margin_px)
            _separate_hues([t.yuv for t in trackers], led_rgb)
            for tracker in trackers:
                if tracker.yuv.phi0 is not None:
                    # A rectangle turns with the blade: the markers' line says by how much.
                    ml, mt = first["lead"].moments, first["trail"].moments
                    tracker.yuv.beta0 = math.atan2(ml.y_px - mt.y_px, ml.x_px - mt.x_px)
            for k, tracker in enumerate(trackers):
                m = first[tracker.name].moments
                window = search_window(tracker, shape, (m.x_px, m.y_px))
                measure_one(k, frame, window)
                tracker.yuv.class_area = float(out[k, K.Q.N]) if out[k, K.Q.N] > 0 else None
            learned = True
            slow = True
        params[:] = 0.0
        windows = []
        beta = _line_direction(lead, trail)
        for k, tracker in enumerate(trackers):
            if tracker.yuv.phi0 is not None and beta is not None:
                _orient(tracker.yuv.prm, tracker.yuv.phi0 + beta - tracker.yuv.beta0)
            params[k] = tracker.yuv.prm
            window = search_window(tracker, shape) if tracker.has_position or not slow else None
            if window is None and slow:
                m = first[tracker.name].moments  # the first frame: around the found blob
                window = search_window(tracker, shape, (m.x_px, m.y_px))
            windows.append(window)
            if window is None:
                params[k, K.P.ENABLED] = 0.0
            else:
                _apply_gain(params[k], gain_at(window))
                params[k, K.P.X0:K.P.Y1 + 1] = window
        led_prm[0] = 1.0 if led_local is not None else 0.0
        kernel(frame.y, frame.u, frame.v, frame.row_offset, frame.row_step, params, led_prm, out, led_out)
        reason, took_slow = take_markers(trackers, windows, out, shape, _kernel_blob, lambda: frame.rgb,
                                         lambda k, window, centre: measure_one(k, frame, window, centre), found)
        slow = slow or took_slow
        led_level = led_peak = None
        follow_candidates(log, frame.y, lambda: frame.rgb, led_model, found, settings.led_near, frame.row_offset,
                          frame.row_step)
        if led_model is not None:
            if led_local is None and len(found) == 2:
                led_local, led_radius = locate_led(frame.rgb, led_model, found["lead"].moments, found["trail"].moments)
                if led_local is None:
                    log.warnings.append("LED not found in the first frames: no input start (t0)")
                    led_model = None
                else:
                    led_prm[:] = (1.0, led_local[0], led_local[1], 1.5 * led_radius + 1.0)
                    slow = True
            if led_local is not None and slow:
                led_kernel(frame.y, led_prm, out, led_out)
            led_level = float(led_out[0]) if led_local is not None and len(found) == 2 else math.nan
            if led_local is not None and len(found) == 2 and len(log.led_peak_dn) < LED_PEAK_FRAMES:
                led_peak = disk_peak(frame.y, led_out[2], led_out[3], led_prm[3])
        gains.append(worst[0])
        log.add(FrameRecord(frame.index, frame.time_s, frame.intra, frame.row_offset, frame.row_step, found, reason,
                            repeated, lambda frame=frame: frame.rgb, led_level, led_peak))
        if job.progress is not None and frame.index % 50 == 0:
            job.progress(frame.index + 1)
    varied = varied_warning(gains, "the markers' colours", band_of is not None)
    if varied:
        log.warnings.append(varied)


def _apply_gain(prm: np.ndarray, gain: float) -> None:
    """Scale a marker's learned colour (and saturation floor) in its kernel row to this frame's light.

    Within :data:`~servoscope.markers.illumination.GAIN_DEADBAND` of 1 the row is left as it is.
    """
    if abs(gain - 1.0) <= GAIN_DEADBAND:
        return
    prm[K.P.YM], prm[K.P.UM], prm[K.P.VM] = scale_colour((prm[K.P.YM], prm[K.P.UM], prm[K.P.VM]), gain)
    prm[K.P.SAT_MIN] *= min(gain, 1.0)

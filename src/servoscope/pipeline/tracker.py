"""Tracking two coloured markers (and a status LED) through a video: the stages run together.

In the pipeline layer (:mod:`servoscope.pipeline`): a markers engine measures the
stickers' pixel centroids, then the camera stage and the angle stage make the
angles (:func:`_finish` writes the order out).

The first frame's blobs of each marker's colour are scored and the best
pair taken, or the blobs the user pinned (:mod:`servoscope.markers.selection`).
Per frame: find each marker's blob by colour inside a window around its
predicted position (the whole frame when lost), then measure its centroid
from a *soft* membership: each pixel's colour is unmixed between the marker's
colour and the local background's, so a pixel half covered by the sticker
counts one half. That makes the centroid subpixel, where a binary threshold
(the paper's flag) moves by whole pixels as edge pixels flip (see
:mod:`servoscope.markers.centroid`). The learned colours follow the frame's
illumination (:mod:`servoscope.markers.illumination`); a rectangular sticker
is measured over a support that follows its outline.

A frame is *invalid*, with a reason, when a marker is not found, is partly
hidden (its soft area or second moments differ from the marker's own
reference), touches the image border, or its centroid lies outside the
lens model's trusted region; when the markers' separation departs from a
rigid blade's (a track where most frames do is refused); and when the frame
repeats the previous image (a duplicated frame) or its timestamp does not
advance.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Callable

import cv2
import numpy as np

from ..angle.geometry import angle_rad_from_centroids, blade_angle
from ..angle.rigid import rigid_motion
from ..angle.rigid_check import flag_nonrigid
from ..camera.plane_map import area_scale_map, centroids_in_plane, plane_camera
from ..camera.rolling_shutter import angle_sample_times, check_readout
from ..camera.undistort import undistort_centroids
from ..defaults import TIMESTAMPS
from ..errors import ServoscopeError
from ..markers.colour import AUTO, BRIGHTNESS, ColourModel, parse_colour
from ..markers.frame_checks import flag_repeated
from ..markers.frame_record import EngineInput, TrackLog
from ..markers.led_level import input_start
from ..markers.led_search import led_input_start
from ..markers.led_timing import exposure_middle_offset_s, frame_period_s
from ..markers.marker_state import MarkerTracker
from ..markers.mono_engine import run_mono
from ..markers.rgb_engine import run_rgb
from ..markers.settings import BACKENDS, ENGINES, TrackerSettings, extra_marker_problems, resolve_engine
from ..markers.timebase import frame_timing
from ..markers.track import Track
from ..markers.yuv_engine import run_yuv
from ..video.reader import VideoInfo, probe_video, thread_budget

__all__ = ["TrackerSettings", "Track", "track_video", "angle_rad_from_centroids", "resolve_engine", "ENGINES", "BACKENDS"]


def track_video(
    path: str | Path,
    settings: TrackerSettings | None = None,
    *,
    progress: Callable[[int], None] | None = None,
) -> Track:
    """Track both markers (and the LED) through one video.

    Parameters
    ----------
    path : path-like
        Any video PyAV decodes.
    settings : TrackerSettings
    progress : callable, optional
        Called with the number of frames done, now and then.

    Returns
    -------
    Track

    Raises
    ------
    ServoscopeError
        When the video cannot be read, or a marker colour matches nothing in
        the first frame (the message lists the closest coloured blobs).
    """
    settings = settings or TrackerSettings()
    path = Path(path)
    budget = thread_budget()
    if budget and cv2.getNumThreads() != budget:
        # A process given a share of the cores (a campaign's Dask worker): OpenCV's pool
        # keeps to it too, as the decoder does (see video.reader.thread_budget).
        cv2.setNumThreads(budget)
    info = probe_video(path)
    if settings.plane is not None:
        # Before any work: a plane of another camera, or of another size, is refused.
        settings = replace(settings, camera=plane_camera(settings.plane, settings.camera, (info.width, info.height),
                                                         path))
    _check_extra(settings)
    lead_spec = parse_colour(settings.lead, what="lead marker colour")
    trail_spec = parse_colour(settings.trail, what="trail marker colour")
    led_spec = parse_colour(settings.led, what="LED colour") if settings.led else None
    if led_spec == AUTO:
        raise ServoscopeError("LED colour: \"auto\" is not supported for the LED; give its colour")
    fields = {None: None, "fields": "tff", "fields-tff": "tff", "fields-bff": "bff"}.get(settings.deinterlace, "?")
    if fields == "?":
        raise ServoscopeError(f"deinterlace: {settings.deinterlace!r} is not one of 'fields', 'fields-bff' or None")
    if settings.centroid not in ("local", "projected"):
        raise ServoscopeError(f"centroid: {settings.centroid!r} is not 'local' or 'projected'")
    if not (settings.shape_tolerance > 0 and settings.support_margin_px >= 1):
        raise ServoscopeError("shape_tolerance must be > 0 and support_margin_px >= 1")
    check_readout(settings.readout_s, info.frame_rate_hz, fields is not None)
    if info.frame_rate_hz:
        # Before any work: the container's nominal frame (or field) interval.
        _check_exposure(path, settings, np.arange(2) / (info.frame_rate_hz * (2 if fields is not None else 1)))
    engine = resolve_engine(settings)
    # An oblique view (a plane given) makes a sticker bigger where the plane is nearer: the camera
    # stage's map of it, for the markers to compare their areas at the picture's centre's scale.
    area_scale = area_scale_map(settings.plane, settings.camera)
    lead = MarkerTracker("lead", lead_spec, settings, area_scale=area_scale)
    trail = MarkerTracker("trail", trail_spec, settings, area_scale=area_scale)
    _check_monochrome(path, info, (lead_spec, trail_spec))
    # A brightness LED's model comes from the first frame, as brightness markers' do.
    led_model = (ColourModel.from_seed(led_spec) if led_spec is not None and led_spec not in BRIGHTNESS
                 else None)  # type: ignore[arg-type]

    job = EngineInput(path, fields, settings, lead, trail, lead_spec, trail_spec, led_model, progress,
                      led_spec if led_spec in BRIGHTNESS else None)
    log = TrackLog()
    if engine == "reference-rgb":
        run_rgb(job, log)
    elif engine == "mono":
        run_mono(job, log)
    else:
        run_yuv(job, engine, log)
    if progress is not None:
        progress(len(log))
    track = _finish(path, settings, info, fields, led_spec, log)
    if settings.extra:
        track = _with_extras(path, settings, track)
    if settings.reference is not None:
        track = _against_reference(path, settings, track)
    return track


def _check_monochrome(path: Path, info: VideoInfo, specs) -> None:
    """Refuse colour markers on monochrome footage, saying how to give brightness markers."""
    from ..video.frame_source import is_frame_source
    from ..video.sources import open_frame_source

    if is_frame_source(path):
        source = open_frame_source(path)
        source.close()
        mono = source.header.monochrome
    else:
        mono = (info.pixel_format or "").startswith("gray")
    if mono and any(spec not in BRIGHTNESS for spec in specs):
        raise ServoscopeError(
            f"{path}: the footage is monochrome, so markers cannot be told by colour; give them by brightness: "
            "lead = {brightness = \"bright\", near = [x, y]} (and trail likewise) in [markers], or --lead "
            "'bright@x,y' --trail 'bright@x,y' (\"dark\" for dark dots on a light blade; without positions the "
            "lead is the one on the right)")


def _as_reference(text: str) -> str:
    """A message about the reference pass's markers, named as the user named them."""
    return text.replace("lead marker", "first reference marker").replace("trail marker", "second reference marker")


def _against_reference(path: Path, settings: TrackerSettings, track: Track) -> Track:
    """The blade's angle against the line joining two stickers on the airframe.

    The reference stickers are tracked by a second pass over the video, as a pair
    of markers of their own (colour models, sub-pixel moments, rigid check); the
    line's angle, less its median, is the picture's own rotation (camera roll, a
    phone's stabilisation, the airframe rocking), taken off the blade's angle frame
    by frame. A frame is valid when both pairs are; the angle's uncertainty adds
    both lines'. The reference line is taken at the blade's sample times (no
    rolling-shutter correction of its own rows).
    """
    lead_ref, trail_ref = settings.reference
    ref_settings = replace(settings, lead=lead_ref, trail=trail_ref, led=None, reference=None, lead_near=None,
                           trail_near=None)
    try:
        ref = track_video(path, ref_settings)
    except ServoscopeError as exc:
        raise ServoscopeError(_as_reference(str(exc))) from None
    if ref.n_frames != track.n_frames:  # pragma: no cover - one decoder, one video
        raise ServoscopeError(f"{path}: the reference pass decoded {ref.n_frames} frames, the blade's {track.n_frames}")
    if ref.n_valid == 0:
        why = "; ".join(_as_reference(w) for w in ref.warnings) or "no frame has both"
        raise ServoscopeError(f"{path}: the reference stickers ({lead_ref}, {trail_ref}) were not measured in any "
                              f"frame ({why}); check their colours with `servoscope markers`")
    motion = ref.angle_rad - float(np.median(ref.angle_rad[ref.valid]))
    valid = track.valid & ref.valid
    reasons = [r or ("" if ok else "reference: " + _as_reference(rr or "not measured"))
               for r, ok, rr in zip(track.reason, ref.valid, ref.reason)]
    warnings = list(track.warnings) + [f"reference: {_as_reference(w)}" for w in ref.warnings]
    return replace(track, angle_rad=np.where(valid, track.angle_rad - motion, np.nan), valid=valid, reason=reasons,
                   angle_sigma_rad=np.hypot(track.angle_sigma_rad, ref.angle_sigma_rad), warnings=warnings,
                   reference_angle_rad=np.where(ref.valid, motion, np.nan))


def _check_extra(settings: TrackerSettings) -> None:
    """Refuse extra markers that cannot be told apart: not a colour, or another marker's colour."""
    others = {"the lead marker": settings.lead, "the trail marker": settings.trail, "the LED": settings.led,
              **{f"reference sticker {i + 1}": c for i, c in enumerate(settings.reference or ())}}
    for k, why in extra_marker_problems(settings.extra, others):
        raise ServoscopeError(f"extra marker {k + 1}: {why}")


def _as_extra(text: str, names: tuple[str, str]) -> str:
    """A message about an extra-marker pass, its two markers named as the user named them."""
    text = text.replace("lead and trail markers", f"{names[0]} and {names[1]}")
    return text.replace("lead marker", names[0]).replace("trail marker", names[1])


#: An extra marker whose residual from the blade's rigid motion exceeds this many of its robust
#: spreads (and :data:`EXTRA_JUMP_MIN_PX`) in a frame is taken as a wrong blob there.
EXTRA_JUMP_SPREADS = 8.0
EXTRA_JUMP_MIN_PX = 2.0


def _with_extras(path: Path, settings: TrackerSettings, track: Track) -> Track:
    """Track the extra markers and measure each one's bending across the chord line (:func:`~servoscope.angle.rigid_motion`).

    The extra markers are tracked two at a time by passes of their own over the video,
    each pair as a pair of markers (colour models, sub-pixel moments, rigid check); an
    odd one out is paired with the lead marker (pinned where the user pinned it).
    A frame is valid when every marker is; the motion is fitted to the lead and trail
    markers (the chord line: the angle and the heave stay the two-marker ones), and each
    marker's residual across that line is its bending. A pass that finds an extra
    marker where the lead or trail marker is (a colour that matched theirs) is refused.
    """
    extras = list(settings.extra)
    n = track.n_frames
    xy = np.full((n, len(extras), 2), np.nan)
    sigma = np.full((n, len(extras)), np.nan)
    valid = track.valid.copy()
    reasons = list(track.reason)
    warnings = list(track.warnings)
    base = replace(settings, led=None, reference=None, extra=(), lead_near=None, trail_near=None)
    for start in range(0, len(extras), 2):
        ks = list(range(start, min(start + 2, len(extras))))
        names = tuple(f"extra marker {k + 1} ({extras[k]})" for k in ks)
        if len(ks) == 2:
            pass_settings = replace(base, lead=extras[ks[0]], trail=extras[ks[1]])
            names_in_pass = names
        else:
            pass_settings = replace(base, lead=settings.lead, lead_near=settings.lead_near, trail=extras[ks[0]])
            names_in_pass = ("lead marker", names[0])
        try:
            got = track_video(path, pass_settings)
        except ServoscopeError as exc:
            raise ServoscopeError(_as_extra(str(exc), names_in_pass)) from None
        if got.n_frames != n:  # pragma: no cover - one decoder, one video
            raise ServoscopeError(f"{path}: the extra markers' pass decoded {got.n_frames} frames, the blade's {n}")
        columns = ([got.lead_xy_px, got.trail_xy_px], [got.lead_sigma_px, got.trail_sigma_px]) if len(ks) == 2 \
            else ([got.trail_xy_px], [got.trail_sigma_px])
        for k, pos, sig in zip(ks, *columns):
            xy[:, k], sigma[:, k] = pos, sig
        for i in np.flatnonzero(track.valid & ~got.valid):
            valid[i] = False
            reasons[i] = reasons[i] or _as_extra(got.reason[i] or "not measured", names_in_pass)
        # The pass's own warnings, less what the first pass said already (illumination, timing).
        warnings += [w for w in (_as_extra(w, names_in_pass) for w in got.warnings
                                 if not w.startswith(("LED", "no LED"))) if w not in warnings]
    _refuse_coinciding(path, track, xy, extras)
    if settings.readout_s > 0 and track.snapshot_rgb is not None:
        # Each marker is seen at its own rows' time: the bending is not corrected for it.
        rows = np.concatenate([track.lead_xy_px[:, None, 1], track.trail_xy_px[:, None, 1], xy[..., 1]], axis=1)
        spread = float(np.nanmedian(np.nanmax(rows, axis=1) - np.nanmin(rows, axis=1)))
        skew_ms = 1e3 * settings.readout_s * spread / track.snapshot_rgb.shape[0]
        warnings.append(f"rolling shutter: the markers lie {spread:.0f} rows apart and are seen up to {skew_ms:.2g} ms "
                        "apart; their bending includes the blade's motion over that time (not corrected)")
    points = np.concatenate([track.lead_xy_px[:, None], track.trail_xy_px[:, None], xy], axis=1)
    sig = np.concatenate([track.lead_sigma_px[:, None], track.trail_sigma_px[:, None], sigma], axis=1)
    if not valid.any():
        # Nothing to fit: the track stands, every frame invalid, saying why.
        return replace(track, angle_rad=np.full(n, np.nan), angle_sigma_rad=np.full(n, np.nan), valid=valid,
                       reason=reasons, warnings=warnings + ["no frame has every marker (the extra markers included)"],
                       extra_colours=tuple(extras), extra_xy_px=xy, extra_sigma_px=sigma,
                       bending_px=np.full((n, 2 + len(extras)), np.nan))
    fit = rigid_motion(points, sig, valid, fit_markers=2)
    # A wrong blob in a frame (an extra marker's colour met elsewhere) leaves it off the rigid motion.
    resid = np.hypot(fit.bending_px, fit.along_px)
    centre = np.nanmedian(resid, axis=0)
    spread = 1.4826 * np.nanmedian(np.abs(resid - centre), axis=0)
    jumped = np.any(resid > np.maximum(EXTRA_JUMP_MIN_PX, centre + EXTRA_JUMP_SPREADS * spread), axis=1)
    if jumped.any():
        for i in np.flatnonzero(jumped):
            valid[i] = False
            reasons[i] = reasons[i] or "a marker left the blade's rigid motion (wrong blob?)"
        warnings.append(f"{int(jumped.sum())} frames had a marker off the blade's rigid motion by more than "
                        f"{EXTRA_JUMP_MIN_PX:g} px and {EXTRA_JUMP_SPREADS:g} spreads: left out")
        if valid.any():
            fit = rigid_motion(points, sig, valid, fit_markers=2)
    # The pitch and its uncertainty stay the chord line's (the fit's own, bit for bit): only frames change.
    return replace(track, angle_rad=np.where(valid, track.angle_rad, np.nan),
                   angle_sigma_rad=np.where(valid, track.angle_sigma_rad, np.nan), valid=valid, reason=reasons,
                   warnings=warnings, extra_colours=tuple(extras), extra_xy_px=xy, extra_sigma_px=sigma,
                   bending_px=np.where(valid[:, None], fit.bending_px, np.nan))


def _refuse_coinciding(path: Path, track: Track, xy: np.ndarray, extras: list[str]) -> None:
    """Refuse an extra marker found where the lead or trail marker is: its colour matched theirs, not a sticker."""
    for k, colour in enumerate(extras):
        for name, other, area in (("lead", track.lead_xy_px, track.lead_area_px),
                                  ("trail", track.trail_xy_px, track.trail_area_px)):
            gap = np.nanmedian(np.hypot(*(xy[:, k] - other).T)) if np.isfinite(xy[:, k]).any() else np.inf
            radius = np.sqrt(np.nanmedian(area) / np.pi) if np.isfinite(area).any() else 1.0
            if gap < 2.0 * radius:
                raise ServoscopeError(f"{path}: extra marker {k + 1} ({colour}) was found on the {name} marker "
                                      f"({gap:.1f} px from it): its colour matches the {name}'s; give a colour the "
                                      "other stickers do not have (check with `servoscope markers`)")


def _finish(path: Path, settings: TrackerSettings, info: VideoInfo, fields: str | None, led_spec,
            log: TrackLog) -> Track:
    """The Track from an engine's log: frame checks, then the camera stage, the angle stage and the LED's t0.

    Frame checks: timestamps that do not advance, duplicated images; the camera
    stage undistorts the centroids (a lens model given) and times the rows of a
    rolling shutter; then the rigid-blade check on the ideal centroids and the
    angle. Long because it is the pipeline's order written out, one step a few lines.
    """
    n = len(log)
    reasons, warnings = log.reasons, log.warnings
    expected = (info.frame_count or 0) * (2 if fields else 1)
    if expected and n < expected:
        warnings.append(f"decoded {n} of {expected} announced frames: the file ends early")
    time_s = np.asarray(log.time_s)
    _check_exposure(path, settings, time_s)
    lead_arr = np.asarray(log.xy["lead"], dtype=np.float64).reshape(-1, 2)
    trail_arr = np.asarray(log.xy["trail"], dtype=np.float64).reshape(-1, 2)
    lead_sigma = np.asarray(log.sigma["lead"], dtype=np.float64)
    trail_sigma = np.asarray(log.sigma["trail"], dtype=np.float64)

    timing = frame_timing(time_s)
    warnings.extend(timing.warnings)
    for i in timing.stalled:
        reasons[i] = reasons[i] or "timestamp does not advance"
    flag_repeated(np.asarray(log.repeated, dtype=bool), lead_arr, trail_arr, reasons, warnings)

    valid = np.array([r == "" for r in reasons], dtype=bool)
    # A rolling shutter exposes the rows of the *recorded* image in turn: keep
    # the recorded rows before undistortion replaces the centroids (the stored
    # picture's rows: a phone's 90° rotation makes them the upright image's columns).
    lead_row, trail_row = info.sensor_rows(lead_arr), info.sensor_rows(trail_arr)
    if settings.camera is not None:
        for name in ("lead", "trail"):
            raw = lead_arr if name == "lead" else trail_arr
            ideal, outside = undistort_centroids(settings.camera, raw, log.area[name])
            raw[:] = ideal
            for i in np.flatnonzero(outside):
                valid[i] = False
                reasons[i] = reasons[i] or f"{name} centroid outside the calibrated region"
    if settings.plane is not None:
        # Into the blade's plane: the rigid check, the angle and everything after it are the plane's.
        lead_arr, lead_sigma = centroids_in_plane(settings.plane, lead_arr, lead_sigma)
        trail_arr, trail_sigma = centroids_in_plane(settings.plane, trail_arr, trail_sigma)
    flag_nonrigid(path, lead_arr, trail_arr, valid, reasons, warnings)
    angle, angle_sigma = blade_angle(lead_arr, trail_arr, valid, lead_sigma, trail_sigma)
    # Angles and t0 on the exposures' middle clock (the LED and the stickers share each exposure).
    angle_clock_s = time_s.astype(np.float64) + exposure_middle_offset_s(settings.timestamp, settings.exposure_s)
    angle_time, why = angle_sample_times(angle_clock_s, lead_arr, trail_arr, valid, lead_row, trail_row,
                                         settings.readout_s, info.sensor_height)
    if why:
        warnings.append(why)
    invalid = n - int(valid.sum())
    if n and not valid.any():
        warnings.append("no frame has both markers")
    elif invalid:
        counts: dict[str, int] = {}
        for r in reasons:
            if r:
                key = r.split(" (")[0]
                counts[key] = counts.get(key, 0) + 1
        detail = "; ".join(f"{k}: {v}" for k, v in sorted(counts.items(), key=lambda kv: -kv[1]))
        warnings.append(f"{invalid} of {n} frames invalid ({detail})")

    own: list[str] = []
    start = input_start(log.led_signal, log.led_peak_dn, angle_clock_s, time_s, settings.exposure_s,
                        settings.readout_s, log.snapshot, led_spec, info, own)
    args = dict(clock_s=angle_clock_s, time_s=time_s, exposure_s=settings.exposure_s, readout_s=settings.readout_s,
                snapshot=log.snapshot, led_spec=led_spec, info=info)
    start = led_input_start(log.led_search, start, own, args, str(settings.led), warnings)  # type: ignore[arg-type]
    t0_window = start.t0_window

    return Track(
        video=path.name,
        frame=np.arange(n),
        time_s=time_s,
        lead_xy_px=lead_arr,
        trail_xy_px=trail_arr,
        lead_area_px=np.asarray(log.area["lead"], dtype=np.float64),
        trail_area_px=np.asarray(log.area["trail"], dtype=np.float64),
        angle_rad=angle,
        valid=valid,
        reason=reasons,
        led_level=start.led_level,
        t0_s=start.t0_s,
        t0_uncertainty_s=start.t0_uncertainty_s,
        warnings=warnings,
        snapshot_rgb=log.snapshot,
        snapshot_index=log.snapshot_index,
        lead_sigma_px=lead_sigma,
        trail_sigma_px=trail_sigma,
        angle_sigma_rad=angle_sigma,
        angle_time_s=angle_time,
        readout_s=float(settings.readout_s),
        intra=np.asarray(log.intra, dtype=bool),
        t0_earliest_s=None if t0_window is None else float(t0_window[0]),
        t0_latest_s=None if t0_window is None else float(t0_window[1]),
        led_partial_frames=start.partial_frames,
        lead_shape_px2=np.asarray(log.shape["lead"], dtype=np.float64).reshape(-1, 3),
        trail_shape_px2=np.asarray(log.shape["trail"], dtype=np.float64).reshape(-1, 3),
        plane=None if settings.plane is None else (settings.plane.source or "plane.json"),
        plane_mm_per_px=None if settings.plane is None else 1.0 / settings.plane.scale_px_per_mm,
    )


def _check_exposure(path: Path, settings: TrackerSettings, time_s: np.ndarray) -> None:
    """Refuse an exposure no camera gives: zero or negative, or longer than the frame interval."""
    if settings.timestamp not in TIMESTAMPS:
        raise ServoscopeError(f"{path}: timestamp {settings.timestamp!r}: use one of {', '.join(TIMESTAMPS)}")
    if settings.exposure_s is None:
        return
    period = frame_period_s(time_s)
    if not settings.exposure_s > 0:
        raise ServoscopeError(f"{path}: exposure {settings.exposure_s} s: an exposure must be > 0 "
                              "(leave it out when the shutter is not known)")
    if period > 0 and settings.exposure_s > 1.001 * period:
        raise ServoscopeError(f"{path}: exposure {1e3 * settings.exposure_s:.4g} ms is longer than the frame interval "
                              f"({1e3 * period:.4g} ms): a frame cannot expose longer than it lasts; give the shutter "
                              "time (e.g. 1/1000 s = 0.001), or leave it out when not known")

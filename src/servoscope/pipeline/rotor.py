"""Tracking a turning rotor: footage of the blades' passes → a :class:`~servoscope.angle.passes.PassTable`.

The stages together for one video (docs/rotor.md): the markers stage finds each blade's
stickers frame by frame and cuts the passes (:mod:`servoscope.markers.passes`); the camera
stage undistorts the centroids (a lens model given); the angle stage reads each pass's pitch
at ψ = 0 and the rotor speed (:mod:`servoscope.angle.passes`); the LED's switch (t0) is dated
by the static tracker's own LED timing (:func:`servoscope.markers.led_level.input_start`).
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Callable

import numpy as np

from ..angle.geometry import angle_rad_from_centroids
from ..angle.pass_short import (MIN_SHORT_FRAMES, fit_short_pass, pitch_rate_spread_rad_s, pooled_crossing_times,
                                pooled_slope_rad_s)
from ..angle.pass_error import pooled_frame_variance_rad2, shared_pass_errors, two_frame_variance_rad2
from ..angle.passes import (MIN_PASS_FRAMES, PassTable, centre_column, crossing_time, fit_passes, foreshortening,
                            rotor_speed)
from ..camera.undistort import undistort_centroids
from ..errors import ServoscopeError
from ..markers.colour import BRIGHTNESS, parse_colour
from ..markers.led_level import input_start
from ..markers.led_timing import exposure_middle_offset_s
from ..markers.passes import RotorSightings, blade_colours, scan_rotor_video, segment_passes
from ..markers.passes_mono import scan_rotor_mono
from ..markers.settings import TrackerSettings
from ..video.reader import probe_video

__all__ = ["CAMERA_DISTANCE_STDERR_M", "TIP_RADIUS_STDERR_M", "blades_by_order", "monochrome_blades", "passes_from_sightings",
           "pinhole_k", "scan_rotor", "track_passes"]


def track_passes(path: str | Path, settings: TrackerSettings | None = None, *, rotor,
                 progress: Callable[[int], None] | None = None) -> PassTable:
    """Every pass of every blade through one video of a turning rotor: pitch at ψ = 0, error, rotor speed, t0.

    Parameters
    ----------
    path : path-like
        Footage from a camera in the rotor's plane looking at the axis: colour (each blade its
        own pair of colours), or monochrome (every sticker ``"bright"``: the blades are then
        told apart by their order, :func:`blades_by_order`).
    settings : TrackerSettings, optional
        The LED (``led``, ``led_near``), the shutter (``exposure_s``, ``timestamp``) and the
        lens model (``camera``) as for ``servoscope track``; the marker colours in it are not
        used (each blade's are ``rotor``'s).
    rotor : RotorSpec-like
        ``blades`` (one ``(lead, trail)`` pair of colours per blade, blade 0 first), and
        optionally ``rev_per_s`` (used when no blade passes twice), ``camera_distance_m`` and
        ``tip_radius_m`` (the foreshortening's curvature when the passes do not tell it).
        Pairs alone are taken as the blades.
    progress : callable, optional
        Called with the number of frames done, now and then.

    Returns
    -------
    PassTable

    Raises
    ------
    ServoscopeError
        When the video never shows a pass (naming what the colours' cheap test saw), or the
        rotor's speed can be neither measured nor read from ``rotor``.
    """
    path = Path(path)
    settings = settings or TrackerSettings()
    info = probe_video(path)
    warnings: list[str] = []
    if settings.readout_s > 0:
        warnings.append("rolling shutter: not corrected for a rotor's passes (the tip crosses the picture in "
                        "milliseconds; use a global shutter)")
    sightings, led = scan_rotor(path, settings, rotor, progress=progress, warnings=warnings)
    table = passes_from_sightings(path, sightings, settings, rotor=rotor, warnings=warnings)
    own: list[str] = []
    clock = sightings.time_s + exposure_middle_offset_s(settings.timestamp, settings.exposure_s)
    t0_s = t0_unc = None
    if led is not None:
        start = input_start(sightings.led_level_dn, sightings.led_peak_dn, clock, sightings.time_s, settings.exposure_s,
                            0.0, sightings.snapshot_rgb, parse_colour(led), info, own, led_xy=sightings.led_xy_px)
        t0_s, t0_unc = start.t0_s, start.t0_uncertainty_s
        if sightings.led_xy_px is None:
            own.append("LED not found in a frame without a blade: no input start (t0)")
    return replace(table, t0_s=t0_s, t0_uncertainty_s=t0_unc, warnings=tuple(table.warnings) + tuple(own))


#: How well a tape gives the camera's distance from the rotor axis and the tip's radius (m, 1σ), for the pinhole's k.
CAMERA_DISTANCE_STDERR_M = 0.01
TIP_RADIUS_STDERR_M = 0.003


def pinhole_k(camera_distance_m: float, tip_radius_m: float) -> tuple[float, float]:
    """The foreshortening's k for a pinhole at D from the axis looking at a tip at R: (D + R)/(2(D − R)), and its
    standard error from :data:`CAMERA_DISTANCE_STDERR_M` and :data:`TIP_RADIUS_STDERR_M` (docs/rotor.md, "Pitch")."""
    d, r = float(camera_distance_m), float(tip_radius_m)
    k = (d + r) / (2.0 * (d - r))
    dk_dd, dk_dr = -r / (d - r) ** 2, d / (d - r) ** 2
    return k, math.hypot(dk_dd * CAMERA_DISTANCE_STDERR_M, dk_dr * TIP_RADIUS_STDERR_M)


def scan_rotor(path: str | Path, settings: TrackerSettings, rotor, *, progress: Callable[[int], None] | None = None,
               warnings: list[str] | None = None) -> tuple[RotorSightings, str | None]:
    """Every frame of a rotor's video: each blade's stickers where seen, and the LED (the scan of :func:`track_passes`).

    Monochrome footage (every sticker ``"bright"``): :func:`~servoscope.markers.passes_mono.scan_rotor_mono`,
    the blades told apart by their order; colour: :func:`~servoscope.markers.passes.scan_rotor_video`, each
    blade by its colours. An LED the footage cannot show (a coloured one on monochrome footage, a
    brightness one on colour footage) is not read, with a warning appended to ``warnings``.

    Returns
    -------
    (RotorSightings, str or None)
        The sightings, and the LED read (None: none).
    """
    warnings = [] if warnings is None else warnings
    led = settings.led
    n_mono = monochrome_blades(rotor)
    if n_mono:
        # Bright stickers on every blade: found by brightness, the blades told by their order.
        if led is not None and parse_colour(led, what="LED colour") not in BRIGHTNESS:
            warnings.append(f"LED {led!r}: a coloured LED is not read on monochrome footage; no t0")
            led = None
        sightings = blades_by_order(scan_rotor_mono(path, led=led is not None, led_near=settings.led_near,
                                                    progress=progress), n_mono)
        if n_mono > 1:
            warnings.append(f"monochrome: the {n_mono} blades are told apart by their order (blade 0 is the first "
                            "seen); give each blade its own colours to know which is which")
        return sightings, led
    if led is not None and parse_colour(led, what="LED colour") in BRIGHTNESS:
        warnings.append(f"LED {led!r}: a brightness LED is not read on colour footage of a rotor; no t0")
        led = None
    return scan_rotor_video(path, blade_colours(rotor), led=led, led_near=settings.led_near, progress=progress), led


def monochrome_blades(rotor) -> int:
    """The number of blades when every sticker is told by brightness (``"bright"``/``"dark"``, any case: a
    monochrome camera's footage, the blades told apart by their order), else 0. ``rotor``: a RotorSpec or its blades."""
    blades = getattr(rotor, "blades", rotor) or ()
    specs = []
    for b in blades:
        specs.extend((b["lead"], b["trail"]) if isinstance(b, dict) else tuple(b))
    if specs and all(isinstance(x, str) and x.strip().lower() in BRIGHTNESS for x in specs):
        return len(blades)
    return 0


def blades_by_order(sightings: RotorSightings, n_blades: int) -> RotorSightings:
    """One-column sightings (the blades not told apart) spread over ``n_blades`` columns: pass k is blade k mod N.

    The passes are cut as :func:`~servoscope.markers.passes.segment_passes` cuts them and numbered
    in time order (blade 0 the first seen). A pass missed altogether (a blade hidden for a
    revolution) would renumber those after it: the pass-to-pass interval is checked, and a
    gap of more than 1.5 intervals is refused.

    Raises
    ------
    ServoscopeError
        When a pass is missing from the sequence.
    """
    passes = segment_passes(sightings)
    n = sightings.time_s.size
    seen = np.zeros((n, n_blades), dtype=bool)
    lead = np.full((n, n_blades, 2), np.nan)
    trail = np.full((n, n_blades, 2), np.nan)
    ls = np.full((n, n_blades), np.nan)
    ts = np.full((n, n_blades), np.nan)
    starts = np.array([p.first_frame for p in passes], dtype=float)
    if starts.size > 2:
        gaps = np.diff(starts)
        if gaps.max() > 1.5 * np.median(gaps):
            k = int(np.argmax(gaps))
            raise ServoscopeError(f"monochrome footage: a pass is missing between frames {int(starts[k])} and "
                                  f"{int(starts[k + 1])}, so the blades cannot be told apart by their order; give "
                                  "each blade its own colours, or film without the gap")
    for k, p in enumerate(passes):
        b = k % n_blades
        sl = slice(p.first_frame, p.last_frame + 1)
        seen[sl, b] = sightings.seen[sl, 0]
        lead[sl, b], trail[sl, b] = sightings.lead_xy_px[sl, 0], sightings.trail_xy_px[sl, 0]
        ls[sl, b], ts[sl, b] = sightings.lead_sigma_px[sl, 0], sightings.trail_sigma_px[sl, 0]
    return replace(sightings, seen=seen, lead_xy_px=lead, trail_xy_px=trail, lead_sigma_px=ls, trail_sigma_px=ts)


def _no_pass(path: Path, sightings: RotorSightings, passes) -> ServoscopeError:
    seen = "; ".join(sightings.colours_seen)
    if passes:
        what = (f"{len(passes)} blade sightings, none with both stickers whole in {MIN_SHORT_FRAMES} frames "
                "(stickers cut by the picture's edge, or too few frames a pass)")
    else:
        what = "no blade's stickers in any frame"
    return ServoscopeError(
        f"{path}: no pass of a blade found in {sightings.time_s.size} frames ({what}). Colours seen: {seen}. "
        "Check [rotor] blades' colours against the footage and that the camera looks at the rotor's axis "
        "from its plane")


def passes_from_sightings(path: str | Path, sightings: RotorSightings, settings: TrackerSettings | None = None, *,
                          rotor=None, warnings: list[str] | None = None) -> PassTable:
    """The pass table from :func:`~servoscope.markers.passes.scan_rotor_video`'s sightings (no LED t0).

    Parameters
    ----------
    path : path-like
        The video (named in the table and in errors).
    sightings : RotorSightings
    settings : TrackerSettings, optional
        ``camera`` (undistortion), ``exposure_s`` and ``timestamp`` (the exposures' middles).
    rotor : RotorSpec-like, optional
        ``rev_per_s``, ``camera_distance_m``, ``tip_radius_m`` where known.
    warnings : list of str, optional
        Appended to the table's.

    Returns
    -------
    PassTable

    Notes
    -----
    Long because it is the angle stage's order written out: undistort, the centre column,
    the crossing times, the rotor speed, the pitches.
    """
    path = Path(path)
    settings = settings or TrackerSettings()
    warnings = list(warnings or []) + list(sightings.kernel_rows)
    lead = sightings.lead_xy_px.copy()
    trail = sightings.trail_xy_px.copy()
    nb = lead.shape[1]
    if settings.camera is not None:
        for b in range(nb):
            for arr in (lead, trail):
                ok = np.isfinite(arr[:, b, 0])
                if ok.any():
                    ideal, outside = undistort_centroids(settings.camera, arr[ok, b], np.zeros(int(ok.sum())))
                    ideal[outside] = np.nan
                    arr[ok, b] = ideal
    clock = sightings.time_s + exposure_middle_offset_s(settings.timestamp, settings.exposure_s)
    segments = segment_passes(sightings)
    good = [p for p in segments if p.whole.size >= MIN_SHORT_FRAMES]
    if not good:
        raise _no_pass(path, sightings, segments)
    if len(good) < len(segments):
        warnings.append(f"{len(segments) - len(good)} of {len(segments)} passes left out: fewer than "
                        f"{MIN_SHORT_FRAMES} frames with both stickers whole (cut by the picture's edge)")
    n_short = sum(p.whole.size < MIN_PASS_FRAMES for p in good)
    if n_short:
        warnings.append(f"{n_short} of {len(good)} passes read from fewer than {MIN_PASS_FRAMES} frames with both "
                        "stickers whole (n_whole in the table): their crossing time from the blade's path, their "
                        "own pitch rate shrunk towards 0 and its error in theirs")
    # ψ = 0's column, each blade's (its stickers' midpoint need not sit on the pitch axis).
    centres = []
    for b in range(nb):
        mine = [p for p in good if p.blade == b]
        if not mine:
            centres.append(math.nan)
            continue
        idx = np.concatenate([p.whole for p in mine])
        pid = np.concatenate([np.full(p.whole.size, j) for j, p in enumerate(mine)])
        xm = 0.5 * (lead[idx, b, 0] + trail[idx, b, 0])
        sep = lead[idx, b, 0] - trail[idx, b, 0]
        xc, xc_err = centre_column(xm, sep, pid)
        if not math.isfinite(xc) or not xc_err < 0.1 * sightings.width:
            fallback = (float(np.asarray(settings.camera.camera_matrix)[0, 2]) if settings.camera is not None
                        else 0.5 * (sightings.width - 1))
            warnings.append(f"blade {b}: the stickers' separation does not show where ψ = 0 is; "
                            f"taken at the picture's centre column ({fallback:.1f} px)")
            xc = float(fallback)
        centres.append(xc)
    t_c = np.full(len(good), np.nan)
    t_c_err = np.full(len(good), np.nan)
    for j, p in enumerate(good):
        idx = p.whole
        xm = 0.5 * (lead[idx, p.blade, 0] + trail[idx, p.blade, 0])
        t_c[j], t_c_err[j] = crossing_time(clock[idx], xm, centres[p.blade])
    for b in range(nb):
        # Short passes: their crossing from the path the blade's every pass follows.
        mine = [j for j, p in enumerate(good) if p.blade == b]
        if not any(good[j].whole.size < MIN_PASS_FRAMES for j in mine):
            continue
        idx = np.concatenate([good[j].whole for j in mine])
        pid = np.concatenate([np.full(good[j].whole.size, i) for i, j in enumerate(mine)])
        tcs, tcs_err = pooled_crossing_times(clock[idx], 0.5 * (lead[idx, b, 0] + trail[idx, b, 0]), pid, centres[b])
        for i, j in enumerate(mine):
            if good[j].whole.size < MIN_PASS_FRAMES:
                t_c[j], t_c_err[j] = tcs[i], tcs_err[i]
    blade = np.array([p.blade for p in good], dtype=np.int64)
    rate, rate_err, _ = rotor_speed(t_c, blade, t_c_err)
    given = getattr(rotor, "rev_per_s", None) if rotor is not None else None
    if not math.isfinite(rate):
        if given is None:
            raise ServoscopeError(f"{path}: no blade passes twice, so the rotor's speed is not measured; give "
                                  "[rotor] rev_per_s, or film more revolutions")
        rate, rate_err = float(given), math.nan
        warnings.append(f"rotor speed taken from [rotor] rev_per_s ({rate:g} rev/s): no blade passes twice")
    elif given is not None and abs(rate - given) > 0.01 * given:
        warnings.append(f"rotor speed measured {rate:.5g} rev/s, [rotor] rev_per_s says {given:g}: the measured one "
                        "is used")
    dist = getattr(rotor, "camera_distance_m", None) if rotor is not None else None
    tip = getattr(rotor, "tip_radius_m", None) if rotor is not None else None
    data = []
    for p in good:
        idx = p.whole
        data.append((clock[idx], angle_rad_from_centroids(lead[idx, p.blade], trail[idx, p.blade])))
    fits, k, k_err = fit_passes(data, t_c, rate, t_c_stderr_s=t_c_err, shared_error=False,
                                k_min_frames=MIN_SHORT_FRAMES, blade=blade)
    if dist and tip and dist > tip:
        # k is the camera's geometry, the same in every video: the pinhole's from [rotor]'s distance and tip radius
        # (as a tape measures them), weighed with what this video's passes tell. Short passes of colour footage
        # tell little and may tell it wrong (session 10, paper-rotor at 2,000 frames/s: 0.74 ± 0.73, 1.54 ± 1.11,
        # 6e-6 ± 0.55 and 1.12 ± 0.21 in its four videos against the geometry's 1.44 ± 0.03).
        k_geo, k_geo_err = pinhole_k(dist, tip)
        if math.isfinite(k_err) and k_err > 0:
            if abs(k - k_geo) > 3.0 * math.hypot(k_err, k_geo_err):
                warnings.append(f"foreshortening: the passes give k = {k:.3g} ± {k_err:.2g}, [rotor]'s camera "
                                f"distance and tip radius {k_geo:.3g} ± {k_geo_err:.2g}: check them (both weighed)")
            w_fit, w_geo = k_err ** -2, k_geo_err ** -2
            k, k_err = (w_fit * k + w_geo * k_geo) / (w_fit + w_geo), (w_fit + w_geo) ** -0.5
        else:
            k, k_err = k_geo, k_geo_err
            warnings.append(f"foreshortening from [rotor]'s camera distance and tip radius (k = {k:.3g}): the passes "
                            "do not tell it")
        fits, k, k_err = fit_passes(data, t_c, rate, t_c_stderr_s=t_c_err, k=k, k_stderr=k_err, shared_error=False)
    fits, fallback = _short_fits(data, fits, good, t_c, t_c_err, rate, k, k_err)
    fits = shared_pass_errors(fits, [p.blade for p in good], [p.whole for p in good], lead, trail, clock, warnings,
                              fallback, frames_share_errors=not monochrome_blades(rotor))
    rows = [(p, f) for p, f in zip(good, fits) if f is not None]
    return PassTable(
        video=path.name,
        time_s=[f.time_s for _, f in rows],
        blade=[p.blade for p, _ in rows],
        pitch_rad=[f.pitch_rad for _, f in rows],
        pitch_stderr_rad=[f.pitch_stderr_rad for _, f in rows],
        azimuth_from_rad=[f.azimuth_from_rad for _, f in rows],
        azimuth_to_rad=[f.azimuth_to_rad for _, f in rows],
        frames=[p.frames for p, _ in rows],
        rev_per_s=float(rate),
        rev_per_s_stderr=float(rate_err),
        foreshortening_k=float(k),
        foreshortening_k_stderr=float(k_err),
        centre_column_px=tuple(centres),
        first_frame=[p.first_frame for p, _ in rows],
        last_frame=[p.last_frame for p, _ in rows],
        pitch_rate_rad_s=[f.pitch_rate_rad_s for _, f in rows],
        n_whole=[f.frames_used for _, f in rows],
        warnings=tuple(warnings),
    )


def _short_fits(data, fits, good, t_c, t_c_err, rate: float, k: float, k_err: float):
    """The short passes' pitches (:func:`fit_short_pass`), and the 2-frame passes' estimate of one frame's variance.

    The rate prior is the passes' pooled slope, its spread from every pass's pitch, one frame's
    variance from the passes' lines (:func:`~servoscope.angle.pass_error.pooled_frame_variance_rad2`); a few
    rounds, the short passes first read with the rate held at the prior.
    """
    short = [j for j, p in enumerate(good) if p.whole.size < MIN_PASS_FRAMES and math.isfinite(t_c[j])]
    if not short:
        return fits, 0.0
    fits = list(fits)
    k_se = k_err if math.isfinite(k_err) else 0.0
    spread = 0.0
    seen = [j for j, f in enumerate(fits) if f is not None or j in short]
    prior, prior_var = pooled_slope_rad_s([data[j] for j in seen], t_c[seen], rate, k)
    pairs = []  # the 2-frame passes' corrected angle differences and time apart
    for j in short:
        t, phi = data[j]
        if t.size == 2:
            th = np.arctan(np.tan(phi) / foreshortening(2.0 * math.pi * rate * (t - t_c[j]), k))
            pairs.append((float(th[1] - th[0]), float(t[1] - t[0])))
    frame_var, fallback = math.inf, 0.0
    for _ in range(3):  # the spread from the pitches, the short ones' first read with none
        for j in short:
            fits[j] = fit_short_pass(*data[j], t_c[j], rate, k, rate_spread_rad_s=spread,
                                     frame_variance_rad2=frame_var, rate_prior_rad_s=prior, rate_prior_var=prior_var,
                                     t_c_stderr_s=float(np.nan_to_num(t_c_err[j])), k_stderr=k_se)
        done = [(j, f) for j, f in enumerate(fits) if f is not None]
        fallback = two_frame_variance_rad2(pairs, prior, spread)
        frame_var = pooled_frame_variance_rad2([f for _, f in done], fallback)
        spread = pitch_rate_spread_rad_s(np.array([f.time_s for _, f in done]),
                                         np.array([f.pitch_rad for _, f in done]),
                                         np.array([good[j].blade for j, _ in done]), math.sqrt(frame_var))
    return fits, fallback

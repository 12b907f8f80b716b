"""The passes drawn on a frame (issue 33, the report's "Under rotation"): one pass of a blade on the footage itself.

A pass is read from the frames its stickers cross the picture in: the stickers' line in the picture
(φ) is the pitch only at ψ = 0, and foreshortened away from it (tan φ = tan θ·F(ψ)). The figure shows
one real frame near ψ = 0 with each sticker's measured centroid, their line, the blade's pitch and
the frame's fitted azimuth; the same blade's stickers in the pass's other frames on it; φ and the
corrected θ against ψ through the pass; and each frame of the pass cropped around the tip, so that the
reader sees the foreshortening the fit removes.

The centroids are not kept in the result (its tracks' samples are the passes): the footage is read
again, by the same scan and pass fit as ``identify`` (:mod:`servoscope.markers.passes`,
:mod:`servoscope.pipeline.rotor`), which give the same table.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib import patheffects
from matplotlib.figure import Figure

from ..angle.geometry import angle_rad_from_centroids
from ..angle.passes import foreshortening
from ..camera.undistort import undistort_centroids
from ..errors import ServoscopeError
from ..markers.led_timing import exposure_middle_offset_s
from ..markers.passes import segment_passes
from ..markers.settings import TrackerSettings
from ..pipeline.rotor import passes_from_sightings, scan_rotor
from ..video import iter_frames

__all__ = ["MAX_CROPS", "PassOnFrame", "pass_frame_figure", "pass_on_frame"]

#: Frames of the pass shown as crops below the frame (evenly spaced, the drawn one among them).
MAX_CROPS = 8
_EDGE = [patheffects.withStroke(linewidth=2.5, foreground="black")]
_LEAD, _TRAIL = "#ffd92f", "#66c2ff"


@dataclass(frozen=True)
class PassOnFrame:
    """One pass of one blade, frame by frame, as the figure draws it.

    Attributes
    ----------
    video : str
    blade : int
    pass_time_s : float
        The pass's time at ψ = 0 (s, the exposures' middles).
    pitch_rad, pitch_stderr_rad, pitch_rate_rad_s : float
        The pass's pitch at ψ = 0, its error and its own change through the pass (the table's).
    rev_per_s, foreshortening_k : float
        The rotor's speed and F(ψ)'s curvature (the table's).
    frame_index : ndarray of int
        The pass's frames, first to last (the blade's stickers in the picture).
    time_s : ndarray
        Their exposures' middles (s).
    azimuth_rad : ndarray
        Each frame's fitted azimuth ψ = 2π·Ω·(t − t_c).
    lead_xy_px, trail_xy_px : ndarray, shape (n, 2)
        Each sticker's measured centroid in the recorded picture (px, pixel centres on integers);
        NaN where the sticker is cut by the picture's edge.
    image_angle_rad, corrected_rad : ndarray
        The stickers' line in the (undistorted) picture, φ, and corrected for the foreshortening,
        θ = atan(tan φ / F(ψ)); NaN where a sticker is cut.
    drawn : int
        Index (into the arrays) of the frame drawn whole: the one nearest ψ = 0.
    rgb : ndarray, shape (n, h, w, 3)
        The pass's frames as read (uint8).
    """

    video: str
    blade: int
    pass_time_s: float
    pitch_rad: float
    pitch_stderr_rad: float
    pitch_rate_rad_s: float
    rev_per_s: float
    foreshortening_k: float
    frame_index: np.ndarray
    time_s: np.ndarray
    azimuth_rad: np.ndarray
    lead_xy_px: np.ndarray
    trail_xy_px: np.ndarray
    image_angle_rad: np.ndarray
    corrected_rad: np.ndarray
    drawn: int
    rgb: np.ndarray

    @property
    def drawn_frame(self) -> int:
        """The drawn frame's index in the footage."""
        return int(self.frame_index[self.drawn])

    @property
    def whole(self) -> np.ndarray:
        """Which frames have both stickers whole (measured)."""
        return np.isfinite(self.lead_xy_px[:, 0]) & np.isfinite(self.trail_xy_px[:, 0])


def _read_frames(path, first: int, last: int) -> np.ndarray:
    frames = []
    for frame in iter_frames(path):
        if frame.index > last:
            break
        if frame.index >= first:
            frames.append(frame.rgb)
    if len(frames) != last - first + 1:
        raise ServoscopeError(f"{path}: frames {first}-{last} could not be read again")
    return np.stack(frames)


def pass_on_frame(path: str | Path, rotor, settings: TrackerSettings | None = None) -> PassOnFrame:
    """One pass of a rotor's footage, frame by frame: where each sticker was measured, ψ, φ and θ.

    Parameters
    ----------
    path : path-like
        One video of a turning rotor (colour, or a monochrome camera's file).
    rotor : RotorSpec-like
        The campaign's ``[rotor]`` (each blade's colours, or ``"bright"`` stickers).
    settings : TrackerSettings, optional
        ``camera`` (undistortion), ``exposure_s`` and ``timestamp``, as ``identify`` reads the video.

    Returns
    -------
    PassOnFrame
        Of the pass with the most frames of both stickers whole (the first such whose nearest frame is
        nearest ψ = 0), its drawn frame the one nearest ψ = 0.

    Raises
    ------
    ServoscopeError
        When the footage shows no pass (as ``identify`` would say).
    """
    path = Path(path)
    settings = settings or TrackerSettings()
    # identify's own scan (the LED's disk kept out of the stickers' search): the same passes are found.
    sightings, _ = scan_rotor(path, settings, rotor)
    table = passes_from_sightings(path, sightings, settings, rotor=rotor)
    clock = sightings.time_s + exposure_middle_offset_s(settings.timestamp, settings.exposure_s)
    segments = {(p.blade, p.first_frame): p for p in segment_passes(sightings)}

    def segment(j: int):
        return segments.get((int(table.blade[j]), int(table.first_frame[j])))

    rows = [j for j in range(len(table)) if segment(j) is not None]
    if not rows:
        raise ServoscopeError(f"{path}: no pass to draw")
    # A pass seen in the most frames, measured about as well as the others, and of the largest pitch: its
    # foreshortening shows best.
    most = max(segment(j).whole.size for j in rows)
    typical = float(np.median(table.pitch_stderr_rad[rows]))
    rows = [j for j in rows if segment(j).whole.size == most]
    rows = [j for j in rows if table.pitch_stderr_rad[j] <= 2 * typical] or rows
    j = max(rows, key=lambda j: (abs(float(table.pitch_rad[j])), -j))
    b, first, last = int(table.blade[j]), int(table.first_frame[j]), int(table.last_frame[j])
    idx = np.arange(first, last + 1)
    lead = sightings.lead_xy_px[idx, b].copy()
    trail = sightings.trail_xy_px[idx, b].copy()
    psi = 2 * np.pi * table.rev_per_s * (clock[idx] - table.time_s[j])
    ideal_lead, ideal_trail = lead.copy(), trail.copy()
    if settings.camera is not None:
        for arr in (ideal_lead, ideal_trail):
            ok = np.isfinite(arr[:, 0])
            if ok.any():
                ideal, outside = undistort_centroids(settings.camera, arr[ok], np.zeros(int(ok.sum())))
                ideal[outside] = np.nan  # as the pass fit: outside the lens model's trusted region
                arr[ok] = ideal
    phi = angle_rad_from_centroids(ideal_lead, ideal_trail)
    theta = np.arctan(np.tan(phi) / foreshortening(psi, table.foreshortening_k))
    whole = np.isfinite(lead[:, 0]) & np.isfinite(trail[:, 0])
    drawn = int(np.flatnonzero(whole)[np.argmin(np.abs(psi[whole]))])
    return PassOnFrame(
        video=path.name, blade=b, pass_time_s=float(table.time_s[j]), pitch_rad=float(table.pitch_rad[j]),
        pitch_stderr_rad=float(table.pitch_stderr_rad[j]), pitch_rate_rad_s=float(table.pitch_rate_rad_s[j]),
        rev_per_s=float(table.rev_per_s), foreshortening_k=float(table.foreshortening_k), frame_index=idx,
        time_s=clock[idx], azimuth_rad=psi, lead_xy_px=lead, trail_xy_px=trail,
        image_angle_rad=np.where(whole, phi, np.nan), corrected_rad=np.where(whole, theta, np.nan), drawn=drawn,
        rgb=_read_frames(path, first, last))


def _marks(ax, lead, trail, *, size: float, gid: str = "") -> None:
    """A frame's two stickers: + lead, × trail, and the line through them (extended a little each way)."""
    if not (np.isfinite(lead).all() and np.isfinite(trail).all()):
        return
    d = lead - trail
    ends = np.stack([trail - 0.35 * d, lead + 0.35 * d])
    ax.plot(ends[:, 0], ends[:, 1], "-", color="white", lw=0.9, path_effects=_EDGE)
    ax.plot([lead[0]], [lead[1]], "+", color=_LEAD, ms=size, mew=1.6, path_effects=_EDGE, gid=gid and f"{gid}-lead")
    ax.plot([trail[0]], [trail[1]], "x", color=_TRAIL, ms=0.8 * size, mew=1.6, path_effects=_EDGE,
            gid=gid and f"{gid}-trail")


def _crop_boxes(view: PassOnFrame) -> tuple[np.ndarray, float, float, float]:
    """Each frame's crop centre column (the stickers' midpoint, straight through the pass), its row, half sizes."""
    whole = view.whole
    mid = 0.5 * (view.lead_xy_px + view.trail_xy_px)
    sep = float(np.median(np.hypot(*(view.lead_xy_px[whole] - view.trail_xy_px[whole]).T)))
    if whole.sum() >= 2:
        slope, icpt = np.polyfit(view.time_s[whole], mid[whole, 0], 1)
        xc = slope * view.time_s + icpt
    else:
        xc = np.full(view.time_s.size, mid[whole, 0][0])
    return xc, float(np.median(mid[whole, 1])), max(0.9 * sep, 16.0), max(0.6 * sep, 10.0)


def pass_frame_figure(view: PassOnFrame, title: str = "") -> Figure:
    """The pass drawn on its frame nearest ψ = 0, φ and θ against ψ, and each frame of the pass cropped.

    The drawn frame's marks carry the gids ``drawn-lead`` and ``drawn-trail`` (one point each, the
    centroids in the recorded picture's pixels).
    """
    n = view.frame_index.size
    fig = Figure(figsize=(8.0, 5.8), layout="constrained")
    top, bottom = fig.subfigures(2, 1, height_ratios=[2.3, 1.0])
    ax, axa = top.subplots(1, 2, width_ratios=[1.5, 1.0])
    k = view.drawn
    ax.imshow(view.rgb[k], interpolation="nearest")
    whole = view.whole
    for i in np.flatnonzero(whole):
        if i == k:
            continue
        ax.plot(*np.stack([view.trail_xy_px[i], view.lead_xy_px[i]]).T, "-", color="0.85", lw=0.6, alpha=0.8)
        ax.plot(*view.lead_xy_px[i], "o", color=_LEAD, ms=3.5, mec="black", mew=0.5)
        ax.plot(*view.trail_xy_px[i], "o", color=_TRAIL, ms=3.5, mec="black", mew=0.5)
    _marks(ax, view.lead_xy_px[k], view.trail_xy_px[k], size=11, gid="drawn")
    psi_deg = math.degrees(float(view.azimuth_rad[k]))
    ax.text(0.02, 0.97, f"blade {view.blade} · frame {view.drawn_frame} · ψ = {psi_deg:+.2f}°\n"
            f"pitch at ψ = 0: {math.degrees(view.pitch_rad):.3f}° ± {math.degrees(view.pitch_stderr_rad):.3f}°\n"
            f"this frame's line φ = {math.degrees(float(view.image_angle_rad[k])):.3f}°",
            transform=ax.transAxes, va="top", ha="left", fontsize=8, color="white", path_effects=_EDGE)
    ax.set_title(title or f"{view.video}: blade {view.blade}'s pass at t = {view.pass_time_s:.5f} s", fontsize=9)
    ax.set_axis_off()
    # The fit's own curve: the pitch's line through the pass, foreshortened into the picture's angle.
    psi = np.linspace(float(np.nanmin(view.azimuth_rad)), float(np.nanmax(view.azimuth_rad)), 200)
    line = view.pitch_rad + view.pitch_rate_rad_s * psi / (2 * np.pi * view.rev_per_s)
    axa.plot(np.degrees(psi), np.degrees(np.arctan(np.tan(line) * foreshortening(psi, view.foreshortening_k))),
             "-", color="C0", lw=1, label="fit, as the picture sees it")
    axa.plot(np.degrees(psi), np.degrees(line), "--", color="C3", lw=1, label="fit: the pitch")
    axa.plot(np.degrees(view.azimuth_rad), np.degrees(view.image_angle_rad), "o", mfc="none", color="C0", ms=4,
             label="stickers' line φ")
    axa.plot(np.degrees(view.azimuth_rad), np.degrees(view.corrected_rad), "o", color="C3", ms=3.5,
             label="corrected θ = atan(tan φ / F(ψ))")
    axa.axvline(psi_deg, color="0.5", ls=":", lw=1)
    seen = np.degrees(np.r_[view.image_angle_rad, view.corrected_rad, line])
    lo, hi = float(np.nanmin(seen)), float(np.nanmax(seen))
    pad = max(0.15 * (hi - lo), 0.05)
    axa.set_ylim(lo - pad, hi + pad)  # the fitted curve's ends are not the point; the frames' angles are
    axa.set_xlabel("fitted azimuth ψ (°)")
    axa.set_ylabel("angle (°)")
    axa.set_title(f"foreshortening F(ψ) = 1/cos(√(2k)·ψ), k = {view.foreshortening_k:.3g}", fontsize=8)
    axa.legend(fontsize=7, loc="best")
    axa.grid(True, alpha=0.3)
    shown = np.round(np.linspace(0, n - 1, min(n, MAX_CROPS))).astype(int)
    shown[np.argmin(np.abs(shown - k))] = k  # the drawn frame among the crops
    shown = np.unique(shown)
    xc, yc, hw, hh = _crop_boxes(view)
    axes = np.atleast_1d(bottom.subplots(1, shown.size))
    for axc, i in zip(axes, shown):
        axc.imshow(view.rgb[i], interpolation="nearest")
        _marks(axc, view.lead_xy_px[i], view.trail_xy_px[i], size=7)
        # One size for every crop, past the picture's edge where the tip is entering or leaving it.
        axc.set_xlim(xc[i] - hw, xc[i] + hw)
        axc.set_ylim(yc + hh, yc - hh)
        axc.set_title(f"ψ {math.degrees(float(view.azimuth_rad[i])):+.1f}°" + ("" if whole[i] else " (cut)"),
                      fontsize=7, fontweight="bold" if i == k else "normal")
        axc.set_xticks([])
        axc.set_yticks([])
    return fig

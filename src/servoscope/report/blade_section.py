"""The report's section on the blade's motions beside its pitch (issues 18 and 32): its modes and their shapes,
its heave and bending per dwell, and the flapping model fitted to the heave's whole traces."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from ..camera.plane_map import recorded_points
from ..numbers import format_interval, format_value, format_with_uncertainty
from ..sysid.heave import HEAVE_SYSTEMATIC_IFRAME_PX, HEAVE_SYSTEMATIC_INTRA_PX, HEAVE_SYSTEMATIC_PX
from ..sysid.modes import MODE_SOURCES
from .figures import blade_frame_figure, heave_figure
from .html import ReportSection

if TYPE_CHECKING:  # pragma: no cover
    from ..campaign.result import IdentificationResult

__all__ = ["blade_section"]


def blade_section(result: "IdentificationResult", figures_dir) -> ReportSection:
    """The blade's motions beside its pitch (issue 18): modes, their shapes, the heave and bending per dwell."""
    s = ReportSection("Blade motions", figures_dir=figures_dir)
    s.text("Beside its pitch the blade moves across its chord: it heaves (the lead–trail line's distance from "
           "the pitch axis) and, seen by more markers, bends (each marker's distance from that line). Its "
           "structural modes ring on after the step and the dwells' starts (the paper saw it flap).")
    if result.modes:
        s.table(["blade mode, from", "frequency (Hz)", "± s.e.", "95 % interval", "damping ratio", "± s.e.",
                 "95 % interval"],
                [[MODE_SOURCES.get(m.source, m.source),
                  *format_with_uncertainty(m.frequency_hz, m.frequency_stderr_hz),
                  format_interval(*m.ci95["frequency_hz"], m.frequency_stderr_hz),
                  *format_with_uncertainty(m.damping_ratio, m.damping_ratio_stderr),
                  format_interval(*m.ci95["damping_ratio"], m.damping_ratio_stderr)]
                 for m in result.modes])
    shaped = [m for m in result.modes if m.shape is not None]
    for mode in shaped:
        sh = mode.shape
        s.table([f"marker (mode at {mode.frequency_hz:.3g} Hz)", "colour", "amplitude (px)", "± s.e.",
                 "relative to the lead", "phase against the lead (deg)", "± s.e."],
                [[m, c, *format_with_uncertainty(a, sa), format_value(r, 3), *format_with_uncertainty(p, sp)]
                 for m, c, a, sa, r, p, sp in zip(sh.markers, sh.colours, sh.amplitude_px, sh.amplitude_stderr_px,
                                                  sh.relative(), sh.phase_deg, sh.phase_stderr_deg)])
    if shaped:
        frame = _blade_frame(result, shaped)
        if frame is not None:
            s.figure(frame, "A frame of the step with every marker (squares), the chord line through the lead and "
                     "trail markers, and the mode's shape: each marker's ring-down across the chord line, drawn "
                     "exaggerated (arrows; the dashed line joins the displaced markers).", "Blade motions frame",
                     name="blade_frame")
    if result.heave_response:
        _add_heave(s, result)
    if result.bending_response:
        s.table(["marker", "dwell", "f (Hz)", "bending gain (px per input unit)", "± s.e.", "phase (deg)", "± s.e.",
                 "amplitude (px)"],
                [[f"{r.marker} ({r.colour})", r.label, format_value(r.frequency_hz, 4),
                  *format_with_uncertainty(r.gain, r.gain_stderr),
                  *format_with_uncertainty(r.phase_deg, r.phase_stderr_deg), format_value(r.amplitude_px, 3)]
                 for r in result.bending_response])
        by_marker: dict[str, list] = {}
        for r in result.bending_response:
            by_marker.setdefault(f"{r.marker} ({r.colour})", []).append(r)
        s.figure(heave_figure([], result.modes, series=by_marker, what="bending"), "Each extra marker's bending "
                 "(its distance across the lead–trail line) at each dwell's frequency, against the input. Error bars: "
                 "±1 standard error, the systematic floor included.", "Bending against frequency", name="bending")
    return s


def _add_heave(s: ReportSection, result: "IdentificationResult") -> None:
    """The heave per dwell's table, the flapping model in words and the heave's figure."""
    # The blade's heave at each dwell's frequency: a second frequency response, beside the pitch's.
    s.table(["dwell", "f (Hz)", "heave gain (px per input unit)", "± s.e.", "phase (deg)", "± s.e.",
             "amplitude (px)", "from"],
            [[r.label, format_value(r.frequency_hz, 4), *format_with_uncertainty(r.gain, r.gain_stderr),
              *format_with_uncertainty(r.phase_deg, r.phase_stderr_deg), format_value(r.amplitude_px, 3),
              "measured" if r.source == "measured" else "the model (window not settled)"]
             for r in result.heave_response])
    hm = result.heave_model
    curve = None
    if hm is not None:
        terms = "; ".join(
            f"κ = {' ± '.join(format_with_uncertainty(k, kse))} px/rad, "
            + (f"fm = {m.frequency_hz:.4g} Hz and ζ = {m.damping_ratio:.3g} held at the step's" if m.source == "held"
               else f"fm = {' ± '.join(format_with_uncertainty(m.frequency_hz, m.frequency_stderr_hz))} Hz, "
                    f"ζ = {' ± '.join(format_with_uncertainty(m.damping_ratio, m.damping_ratio_stderr))}")
            for k, kse, m in zip(hm.gains_px_per_rad, hm.gain_stderrs_px_per_rad, hm.modes))
        how = (f"to every test's heave frame by frame, each mode driven by the pitch measured in it, from the "
               f"test's start ({hm.n_dwells} dwells and the other tests; reduced χ² {hm.chi2_reduced:.3g}); "
               f"beside the modes, heave in phase with the pitch at every frequency, "
               f"{' ± '.join(format_with_uncertainty(hm.axis_px_per_rad, hm.axis_stderr_px_per_rad))} px/rad "
               f"(the pitch axis found that far off along the chord), taken off each dwell's heave above"
               if hm.method == "whole traces" else
               f"over {hm.n_dwells} dwells' heave over their pitch (reduced χ² {hm.chi2_reduced:.3g})")
        s.text(f"Fitted as {'a mode' if len(hm.modes) == 1 else f'{len(hm.modes)} modes'} thrown by the pitch's "
               f"acceleration, heave/pitch = Σ κ·ω²/(ωm² − ω² + 2jζωm·ω): {terms}; {how}.")
        f = np.geomspace(min(r.frequency_hz for r in result.heave_response) / 1.5,
                         max(r.frequency_hz for r in result.heave_response) * 1.5, 400)
        w = 2 * np.pi * f
        pitch = result.model.transfer_function(1j * w) * np.exp(-1j * w * (result.dead_time_s or 0.0))
        z = hm.ratio(f) * np.asarray(pitch).reshape(-1)
        phase = np.degrees(np.angle(z))  # wrapped, as the measured phases are: broken where it wraps
        phase[1:][np.abs(np.diff(phase)) > 180.0] = np.nan
        curve = (f, np.abs(z), phase)
    s.figure(heave_figure(result.heave_response, result.modes, curve), "The blade's heave (the lead–trail "
             "line's distance from the pitch axis) at each dwell's frequency, against the input: a blade that "
             "flaps answers most near its mode. Error bars: ±1 standard error, a systematic floor included: "
             + _floor_text(result.heave_model) + ", and 0.3 % of the amplitude.",
             "Heave against frequency", name="heave")


def _blade_frame(result: "IdentificationResult", modes):
    """The blade motions frame: the step's snapshot, every marker, the modes' shapes exaggerated; None without a step."""
    label = result.step_label
    track = result.tracks.get(label) if label else None
    if track is None or track.extra_xy_px is None:
        return None
    i = track.snapshot_index if track.snapshot_rgb is not None else int(np.argmax(track.valid))
    pts = np.concatenate([track.lead_xy_px[i][None], track.trail_xy_px[i][None], track.extra_xy_px[i]])
    if not np.all(np.isfinite(pts)):
        return None
    if track.snapshot_rgb is not None:
        pts = recorded_points(pts, result.campaign.camera, result.campaign.plane)
    span = float(np.hypot(*(pts[0] - pts[1])))
    drawn = []
    for mode in modes:
        shape = np.asarray(mode.shape.amplitude_px) * np.cos(np.radians(mode.shape.phase_deg))
        scale = 0.1 * span / max(float(np.max(np.abs(shape))), 1e-9)
        drawn.append((shape, scale, f"{mode.frequency_hz:.3g} Hz mode ×{scale:.3g}"))
    which = " and ".join(f"{m.frequency_hz:.3g} Hz" for m in modes)
    return blade_frame_figure(track.snapshot_rgb, pts, list(modes[0].shape.markers), None,
                              title=f"{label}, frame {i}: every marker and the {which} mode shapes (exaggerated)",
                              more=drawn)


def _floor_text(model) -> str:
    """The heave rows' systematic floor, in words: the one the footage showed where it did."""
    if model is not None and math.isfinite(getattr(model, "floor_px", math.nan)):
        return (f"{model.floor_px:.2g} px (what the dwells' scatter about the flapping model shows; "
                f"{HEAVE_SYSTEMATIC_IFRAME_PX:g} px where a dwell's heave is fitted to its I-frames)")
    return (f"{HEAVE_SYSTEMATIC_INTRA_PX:g} px on footage of frames coded on their own, {HEAVE_SYSTEMATIC_PX:g} px "
            f"where the codec predicts frames, {HEAVE_SYSTEMATIC_IFRAME_PX:g} px where a dwell's heave is fitted to "
            f"its I-frames")

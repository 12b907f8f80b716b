"""Figures of the report, one function each, from plain arrays.

Each function builds and returns a matplotlib Figure (drawing nothing on
screen), so that the same figure goes into the HTML report, a PNG file, or a
notebook. Figure numbers in the titles refer to the paper.
"""

from __future__ import annotations

from typing import Sequence

import matplotlib

matplotlib.use("Agg")  # no display: figures are files and embedded images
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib import patheffects  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from ..sysid.plotting import (  # noqa: E402
    on_branch_deg,
    plot_dwell,
    plot_dwell_residual,
    plot_gain,
    plot_model_gain,
    plot_model_phase,
    plot_phase,
    plot_step,
)

__all__ = ["amplitude_figure", "bode_figure", "dwell_figure", "step_figure", "overlay_figure", "segmentation_figure"]


#: White marks drawn over a black edge: seen on coloured stickers and on a monochrome camera's white dots alike.
_EDGE = [patheffects.withStroke(linewidth=3.0, foreground="black")]


def bode_figure(
    frequency_hz: np.ndarray,
    gain: np.ndarray,
    gain_stderr: np.ndarray | None,
    phase_deg: np.ndarray | None,
    model_frequency_hz: np.ndarray,
    model_gain: np.ndarray,
    model_phase_deg: np.ndarray | None = None,
    *,
    bandwidth_rad_s: float | None = None,
    truth_gain: np.ndarray | None = None,
    label: str = "fitted model",
) -> Figure:
    """Amplitude plot (paper Fig. 9) and, when phases are known, the phase plot.

    Parameters
    ----------
    frequency_hz, gain : ndarray, shape (n,)
        Measured points; gain in output units per input unit.
    gain_stderr : ndarray or None
        Standard errors of the gains, drawn as error bars.
    phase_deg : ndarray or None
        Measured phases (NaN where unknown); the phase panel is drawn when any is finite.
    model_frequency_hz, model_gain, model_phase_deg : ndarray
        The fitted model on a dense grid.
    """
    with_phase = phase_deg is not None and np.isfinite(phase_deg).any()
    fig, axes = plt.subplots(2 if with_phase else 1, 1, figsize=(7.5, 6.2 if with_phase else 4.2), sharex=True, squeeze=False)
    ax = axes[0, 0]
    omega = 2 * np.pi * np.asarray(frequency_hz)
    plot_gain(ax, omega, gain, gain_stderr)
    plot_model_gain(ax, 2 * np.pi * np.asarray(model_frequency_hz), model_gain, label=label)
    if truth_gain is not None:
        ax.semilogx(2 * np.pi * np.asarray(model_frequency_hz), 20 * np.log10(np.asarray(truth_gain)), "--", color="0.5", lw=1, label="truth")
    if bandwidth_rad_s is not None and np.isfinite(bandwidth_rad_s):
        ax.axvline(bandwidth_rad_s, color="C2", ls=":", lw=1.2, label=f"−3 dB bandwidth {bandwidth_rad_s:.1f} rad/s")
    ax.set_xscale("log")
    ax.set_ylabel("gain (dB)")
    ax.set_title("Frequency response: amplitude (paper Fig. 9)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="lower left", fontsize=8)
    if with_phase:
        axp = axes[1, 0]
        plot_phase(axp, omega, phase_deg)
        if model_phase_deg is not None:
            plot_model_phase(axp, 2 * np.pi * np.asarray(model_frequency_hz), model_phase_deg, label=label)
        axp.set_ylabel("phase (deg)")
        axp.grid(True, which="both", alpha=0.3)
        axp.legend(loc="lower left", fontsize=8)
    axes[-1, 0].set_xlabel("angular frequency ω (rad/s)")
    fig.tight_layout()
    return fig


def dwell_figure(
    time_s: np.ndarray,
    angle_rad: np.ndarray,
    valid: np.ndarray,
    fit_angle_rad: np.ndarray,
    window_s: tuple[float, float],
    *,
    t0_s: float | None = None,
    title: str = "",
) -> Figure:
    """One dwell: measured angle with the fitted sine (paper Fig. 7) and the residual (Fig. 8)."""
    time_s = np.asarray(time_s)
    valid = np.asarray(valid, bool)
    fig, (ax, axr) = plt.subplots(2, 1, figsize=(7.5, 5.4), sharex=True, gridspec_kw={"height_ratios": [2, 1]})
    plot_dwell(ax, time_s, angle_rad, fit_angle_rad, window_s, valid=valid, t0_s=t0_s)
    plot_dwell_residual(axr, time_s, angle_rad, fit_angle_rad, window_s, valid=valid, t0_s=t0_s)
    ax.set_ylabel("angle (rad)")
    ax.set_title(title or "Dwell: measured angle and fitted sine (paper Fig. 7)")
    ax.legend(loc="upper right", fontsize=8)
    axr.set_ylabel("residual (rad)")
    axr.set_xlabel("time (s)")
    axr.set_title("Residual (paper Fig. 8)", fontsize=9)
    fig.tight_layout()
    return fig


def step_figure(
    time_s: np.ndarray,
    angle_rad: np.ndarray,
    valid: np.ndarray,
    predicted_angle_rad: np.ndarray | None,
    *,
    t0_s: float | None = None,
    dead_time_s: float | None = None,
) -> Figure:
    """Step response: measured and predicted by the identified model (paper Fig. 10)."""
    time_s = np.asarray(time_s)
    valid = np.asarray(valid, bool)
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    plot_step(ax, time_s, angle_rad, predicted_angle_rad, valid=valid, t0_s=t0_s, dead_time_s=dead_time_s)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("angle (rad)")
    ax.set_title("Step response: measured and predicted (paper Fig. 10)")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    return fig


def overlay_figure(
    frame_rgb: np.ndarray,
    lead_xy_px: Sequence[float],
    trail_xy_px: Sequence[float],
    angle_rad: float,
    *,
    title: str = "",
) -> Figure:
    """A frame with the detected centroids and the joining line (paper Fig. 4).

    Centroids are in the recorded image's pixel coordinates.
    """
    h, w = frame_rgb.shape[:2]
    fig, ax = plt.subplots(figsize=(7.5, 7.5 * h / w + 0.4))
    ax.imshow(frame_rgb, interpolation="nearest")
    lx, ly = lead_xy_px
    tx, ty = trail_xy_px
    edge = _EDGE
    ax.plot([tx, lx], [ty, ly], "-", color="white", lw=1.2, path_effects=edge)
    ax.plot([tx, lx], [ty, ty], "--", color="white", lw=0.8, alpha=0.7)
    for (x, y), name in (((lx, ly), "lead"), ((tx, ty), "trail")):
        ax.plot([x], [y], "s", ms=7, mfc="none", mec="white", mew=1.5, path_effects=edge)
        ax.annotate(name, (x, y), xytext=(6, -10), textcoords="offset points", color="white", fontsize=9,
                    path_effects=edge)
    ax.set_title(title or f"Detected centroids, θ = {np.degrees(angle_rad):.3f}° (paper Fig. 4)")
    ax.set_axis_off()
    fig.tight_layout()
    return fig


def segmentation_figure(
    frame_rgb: np.ndarray,
    masks: dict[str, np.ndarray],
    colours_rgb: dict[str, tuple[float, float, float]],
    centroids_xy_px: dict[str, Sequence[float]],
    *,
    zoom_px: int = 40,
) -> Figure:
    """Segmentation by colour (paper Fig. 3): the whole frame, then each marker zoomed.

    Parameters
    ----------
    frame_rgb : ndarray, shape (h, w, 3), uint8
    masks : dict of name → bool array (h, w)
        Pixels classified as each marker.
    colours_rgb : dict of name → (r, g, b) in 0–255
    centroids_xy_px : dict of name → (x, y)
        Measured centroids in the recorded image, drawn as white squares.
    """
    h, w = frame_rgb.shape[:2]
    canvas = np.zeros((h, w, 3))
    for name, mask in masks.items():
        canvas[mask] = np.asarray(colours_rgb[name]) / 255.0
    fig, axes = plt.subplots(1, 1 + len(masks), figsize=(7.5 + 2.5 * len(masks), 3.6),
                             gridspec_kw={"width_ratios": [3] + [1] * len(masks)})
    axes[0].imshow(canvas, interpolation="nearest")
    axes[0].set_title("pixels classified as markers (paper Fig. 3)", fontsize=9)
    for ax, name in zip(axes[1:], masks):
        x, y = centroids_xy_px[name]
        x0, y0 = int(max(0, x - zoom_px)), int(max(0, y - zoom_px))
        x1, y1 = int(min(w, x + zoom_px)), int(min(h, y + zoom_px))
        ax.imshow(frame_rgb[y0:y1, x0:x1], interpolation="nearest", extent=(x0 - 0.5, x1 - 0.5, y1 - 0.5, y0 - 0.5))
        ax.contour(np.arange(x0, x1), np.arange(y0, y1), masks[name][y0:y1, x0:x1].astype(float), levels=[0.5], colors="white", linewidths=0.8)
        ax.plot([x], [y], "s", ms=6, mfc="none", mec="white", mew=1.5, path_effects=_EDGE)
        ax.set_title(f"{name}: ({x:.2f}, {y:.2f}) px", fontsize=9)
    for ax, name in zip(axes[:1], ["all"]):
        for n, (x, y) in centroids_xy_px.items():
            ax.plot([x], [y], "s", ms=5, mfc="none", mec="white", mew=1.2, path_effects=_EDGE)
    for ax in axes:
        ax.set_axis_off()
    fig.tight_layout()
    return fig


def amplitude_figure(checks) -> Figure:
    """Gain against input amplitude at each frequency measured at several (the linearity check).

    Each frequency's gains relative to their weighted mean (%, ±1 standard error): a
    linear servo's lie on 0 at every amplitude.
    """
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    for c in checks:
        g, se = np.asarray(c.gains), np.asarray(c.gain_stderrs)
        w = 1.0 / se**2
        mean = float(np.sum(w * g) / np.sum(w))
        ax.errorbar(c.amplitudes, 100.0 * (g / mean - 1.0), yerr=100.0 * se / mean, marker="o", capsize=3,
                    label=f"{c.frequency_hz:.3g} Hz" + ("" if c.linear else " (not linear)"))
    ax.axhline(0.0, color="0.5", lw=0.8)
    ax.set_xscale("log")
    ax.set_xlabel("input amplitude (input units)")
    ax.set_ylabel("gain against its mean (%)")
    ax.set_title("Gain against input amplitude (linearity check)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def servo_traces_figure(fit) -> Figure:
    """Each test's measured angle against the time-domain model's (``ServoModelFit.plot``), tests stacked."""
    fig, ax = plt.subplots(figsize=(7.5, 5.0))
    fit.plot(ax)
    fig.tight_layout()
    return fig


def describing_function_figure(candidates, measured) -> Figure:
    """Gain and phase against input amplitude at each frequency: measured, and each candidate's describing function.

    ``candidates`` are :class:`~servoscope.sysid.servo_fit.ServoModelFit` (the selected first);
    ``measured`` maps a frequency (Hz) to its dwells' ``[(amplitude, gain, gain_stderr, phase_deg)]``.
    A linear model's line is flat; the selected structure's bends where the servo does.
    """
    fig, (ax_g, ax_p) = plt.subplots(2, 1, figsize=(7.5, 6.0), sharex=True)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, (f, rows) in enumerate(sorted(measured.items())):
        colour = colours[i % len(colours)]
        a = np.array([r[0] for r in rows])
        ax_g.errorbar(a, [r[1] for r in rows], yerr=[r[2] for r in rows], fmt="o", color=colour, capsize=3,
                      label=f"{f:.3g} Hz")
        ax_p.plot(a, [r[3] for r in rows], "o", color=colour)
        grid = np.geomspace(0.5 * a.min(), 1.5 * a.max(), 12)
        for style, fit in zip(("-", ":", "--", "-."), candidates):
            df = fit.describing_function(f, grid)
            ax_g.plot(grid, np.abs(df), style, color=colour, lw=1)
            # No phase where the model hardly moves (a play wider than the swing): it would be noise.
            phase = np.where(np.abs(df) > 0.05 * np.max(np.abs(df)), np.degrees(np.angle(df)), np.nan)
            # The measured phase's branch: the model's drawn beside it, not 360° away.
            ref = rows[0][3]
            ax_p.plot(grid, on_branch_deg(phase, ref), style, color=colour, lw=1)
    ax_g.set_xscale("log")
    ax_g.set_ylabel("gain")
    ax_p.set_ylabel("phase (deg)")
    ax_p.set_xlabel("input amplitude")
    names = ", ".join(f"{st} {c.structure}" for st, c in zip(("solid:", "dotted:", "dashed:", "dash-dot:"), candidates))
    ax_g.set_title(f"Describing function per frequency ({names})", fontsize=9)
    ax_g.legend(fontsize=7, ncol=3)
    fig.tight_layout()
    return fig


def candidate_traces_figure(trace, candidates) -> Figure:
    """One test measured against every candidate's simulation (rest angles taken off)."""
    fig, ax = plt.subplots(figsize=(7.5, 4.0))
    fit0 = candidates[0]
    t = trace.time_s - trace.t0_s
    ax.plot(t, trace.angle_rad - fit0.offsets.get(trace.label, 0.0), ".", ms=3, color="0.4", label="measured")
    for c in candidates:
        ax.plot(t, c.predict(trace) - c.offsets.get(trace.label, 0.0), lw=1, label=c.structure)
    ax.set_xlabel("time after the input's start (s)")
    ax.set_ylabel("angle (rad)")
    ax.set_title(f"{trace.label}: measured and each candidate", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def heave_figure(rows, modes, curve: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None, *,
                 series: dict[str, list] | None = None, what: str = "heave") -> Figure:
    """The blade's heave per dwell against frequency (gain px per input unit, phase), its modes marked.

    A second frequency response beside the pitch's: ``rows`` are
    :class:`~servoscope.sysid.heave.HeaveRow`, ``modes`` :class:`~servoscope.sysid.modes.ModeFit`;
    ``curve`` (frequency Hz, gain, phase deg) the fitted flapping model's. ``series`` (label →
    rows) draws several, e.g. each marker's bending (``what="bending"``), instead of ``rows``.
    """
    fig, (ax_g, ax_p) = plt.subplots(2, 1, figsize=(7.5, 5.4), sharex=True)
    for k, (label, these) in enumerate((series or {"measured": rows}).items()):
        f = np.array([r.frequency_hz for r in these]) * (1.0 + 0.01 * k)  # side by side where they share a dwell
        ax_g.errorbar(f, [r.gain for r in these], yerr=[r.gain_stderr for r in these], fmt="o", capsize=3,
                      label=label)
        ax_p.errorbar(f, [r.phase_deg for r in these], yerr=[r.phase_stderr_deg for r in these], fmt="o", capsize=3)
    if series:
        ax_g.legend(fontsize=7)
    if curve is not None:
        ax_g.plot(curve[0], curve[1], "-", color="C1", lw=1.2, label="fitted mode × pitch model")
        ax_p.plot(curve[0], curve[2], "-", color="C1", lw=1.2)
        ax_g.legend(fontsize=7)
    for m in modes:
        for ax in (ax_g, ax_p):
            ax.axvspan(m.frequency_hz * (1 - m.damping_ratio), m.frequency_hz * (1 + m.damping_ratio), color="0.85")
            ax.axvline(m.frequency_hz, color="0.4", lw=0.8, ls="--")
    ax_g.set_xscale("log")
    ax_g.set_yscale("log")
    ax_g.set_ylabel(f"{what} gain (px per input unit)")
    ax_p.set_ylabel(f"{what} phase (deg)")
    ax_p.set_xlabel("frequency (Hz)")
    ax_g.set_title(f"The blade's {what} at each dwell's frequency (dashed: its modes, shaded: ±ζ)", fontsize=9)
    fig.tight_layout()
    return fig


def blade_frame_figure(frame_rgb: np.ndarray | None, points_xy_px: np.ndarray, names: Sequence[str],
                       shape: Sequence[float] | None, *, scale: float = 1.0, title: str = "",
                       more: Sequence[tuple[Sequence[float], float, str]] = ()) -> Figure:
    """A frame with every marker, the chord line through the lead and trail, and a mode's shape drawn exaggerated.

    Parameters
    ----------
    frame_rgb : ndarray (h, w, 3) or None
        The frame (None: the markers alone, image axes).
    points_xy_px : ndarray, shape (m, 2)
        The markers' centroids in that frame (lead, trail, extras), recorded image px.
    names : sequence of str
    shape : sequence of float or None
        Each marker's displacement across the chord line in the mode (px, up positive), drawn
        ``scale`` times as long, the displaced markers joined in order along the chord.
    more : sequence of (shape, scale, label)
        Other modes' shapes, drawn alike in other colours.
    """
    pts = np.asarray(points_xy_px, dtype=float)
    if frame_rgb is not None:
        h, w = frame_rgb.shape[:2]
        fig, ax = plt.subplots(figsize=(7.5, 7.5 * h / w + 0.4))
        ax.imshow(frame_rgb, interpolation="nearest")
    else:
        fig, ax = plt.subplots(figsize=(7.5, 4.0))
        ax.invert_yaxis()
        ax.set_aspect("equal")
    lead, trail = pts[0], pts[1]
    d = (lead - trail) / np.hypot(*(lead - trail))
    up = np.array([d[1], -d[0]])  # a quarter turn counter-clockwise on screen (y down) from trail to lead
    ends = np.stack([trail - 0.15 * (lead - trail), lead + 0.15 * (lead - trail)])
    ax.plot(ends[:, 0], ends[:, 1], "-", color="white", lw=1.0, label="chord line (lead–trail)")
    for (x, y), name in zip(pts, names):
        ax.plot([x], [y], "s", ms=7, mfc="none", mec="white", mew=1.5)
        ax.annotate(name, (x, y), xytext=(6, 8), textcoords="offset points", color="white", fontsize=8)
    drawn = ([(shape, scale, f"mode shape ×{scale:.3g}")] if shape is not None else []) + list(more)
    order = np.argsort((pts - trail) @ d)
    for (sh, sc, label), colour in zip(drawn, ("yellow", "cyan", "magenta")):
        moved = pts + sc * np.asarray(sh, dtype=float)[:, None] * up[None, :]
        for p, q in zip(pts, moved):
            ax.annotate("", q, p, arrowprops={"arrowstyle": "->", "color": colour, "lw": 1.2})
        ax.plot(moved[order, 0], moved[order, 1], "--", color=colour, lw=1.2, label=label)
    ax.legend(fontsize=7, loc="lower right")
    ax.set_title(title or "Every marker, the chord line and the mode's shape (exaggerated)", fontsize=9)
    ax.set_axis_off()
    fig.tight_layout()
    return fig

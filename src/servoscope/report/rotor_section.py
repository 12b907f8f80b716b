"""The report's section "Under rotation": a turning rotor's passes, speed and blade-to-blade pitch (issue 33).

Its parts: the fastest dwell's passes by blade with the fitted sine; one of that dwell's passes drawn on
its frames (:mod:`servoscope.report.rotor_frame`, the footage read again; one line instead where it is gone);
the rotor speed and blade-to-blade tables; and, after ``identify --beside``, the response beside the static
campaign's (:mod:`servoscope.report.rotor_beside`).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.figure import Figure

from ..campaign.rotor import rotor_settings
from ..errors import ServoscopeError
from ..video import is_frame_source
from ..video.frame_source import parse_frame_source
from .html import ReportSection
from .rotor_beside import beside_static_part
from .rotor_frame import pass_frame_figure, pass_on_frame

if TYPE_CHECKING:  # pragma: no cover
    from ..campaign.result import IdentificationResult

__all__ = ["footage_path", "passes_figure", "rotor_section"]

_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")


def passes_figure(time_s: np.ndarray, blade: np.ndarray, pitch_rad: np.ndarray, fit, title: str) -> Figure:
    """Each blade's pitch per pass against time (its own marker), and the fitted sine with each blade's offset.

    ``time_s``, ``blade``, ``pitch_rad``: the dwell's passes; ``fit``: its
    :class:`~servoscope.sysid.pass_result.PassSineFit` (the common sine, one offset a blade).
    """
    fig = Figure(figsize=(7.0, 3.2), layout="constrained")
    ax = fig.add_subplot()
    fine = np.linspace(float(np.min(time_s)), float(np.max(time_s)), 2000)
    common = fit.model(fine) - fit.offset
    for o in fit.blade_offsets:
        mine = blade == o.blade
        marker = _MARKERS[o.blade % len(_MARKERS)]
        points = ax.plot(time_s[mine], np.degrees(pitch_rad[mine]), marker, ms=3.5, ls="none",
                         label=f"blade {o.blade} ({int(np.count_nonzero(mine))} passes)")
        ax.plot(fine, np.degrees(common + o.offset_rad), "-", lw=0.9, color=points[0].get_color())
    lo, hi = fit.window_s
    ax.axvspan(lo, hi, color="0.9", zorder=0)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("pitch (°)")
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=8, loc="best")
    return fig


def _deg(value_rad: float | None) -> str:
    return "—" if value_rad is None or not math.isfinite(value_rad) else f"{math.degrees(value_rad):.4f}"


def rotor_section(result: "IdentificationResult", figures_dir: Path | None) -> ReportSection | None:
    """The passes of the highest dwell by blade with its fitted sine, rev/s and passes per test, each blade's pitch
    against blade 0's; None for a static blade."""
    rotor = result.rotor
    if rotor is None:
        return None
    s = ReportSection("Under rotation", figures_dir=figures_dir)
    blades = rotor["blades"]
    s.text(f"{len(blades)} blades, read once a revolution each as its tip passes the camera (ψ = 0): each pass "
           f"gives that blade's pitch then, with its error. Each dwell's sine is common to the blades, with one "
           f"constant a blade (its rigging); the pass rate bounds the dwells (its Nyquist frequency, "
           f"blades × rev/s / 2). What the method cannot see (flapping, lead-lag, cyclic away from the camera) is "
           f"in docs/rotor.md.")
    fits = {k: f for k, f in result.sine_fits.items() if getattr(f, "blade_offsets", None)}
    if fits:
        label = max(fits, key=lambda k: fits[k].frequency_hz)
        fit = fits[label]
        track = result.tracks[label]
        s.figure(passes_figure(np.asarray(fit.time_s) if len(fit.blade) else track.time_s,
                               np.asarray(fit.blade) if len(fit.blade) else np.zeros(track.n_frames, int),
                               np.asarray(fit.pitch_rad) if len(fit.blade) else track.angle_rad, fit,
                               f"{label}: each blade's pitch per pass and the fitted sine"),
                 f"{label} at {fit.frequency_hz:.4g} Hz, {100 * fit.frequency_hz / fit.pass_nyquist_hz:.0f} % of the "
                 f"passes' Nyquist frequency ({fit.pass_nyquist_hz:.4g} Hz); shaded: the steady-state window.",
                 "Passes by blade", name="rotor_passes")
        _frame_part(s, result, label)
    s.table(["test", "rotor speed (rev/s)", "passes"],
            [[t["label"], f"{t['rev_per_s']:.5f} ± {t['rev_per_s_stderr']:.1g}", t["passes"]] for t in rotor["tests"]])
    if rotor["blade_differences"]:
        s.text("Each blade's pitch against blade 0's (its rigging), pooled over the dwells:")
        s.table(["blade", "pitch − blade 0's (°)", "95 % interval (°)", "dwells"],
                [[d["blade"], _deg(d["difference_rad"]), f"[{_deg(d['ci95_rad'][0])}, {_deg(d['ci95_rad'][1])}]",
                  d["dwells"]] for d in rotor["blade_differences"]])
    rows = [[t["label"], d["blade"], _deg(d["difference_rad"]), f"[{_deg(d['ci95_rad'][0])}, {_deg(d['ci95_rad'][1])}]"]
            for t in rotor["tests"] for d in t.get("blade_differences", [])]
    if rows and rotor.get("identified_by") == "order":
        s.text("The blades look alike here (a monochrome camera's bright stickers): each video numbers them in the "
               "order they pass first, so blade 0 may be a different blade in each video, and the differences are "
               "not pooled. Give each blade its own colours to follow one blade through the campaign.")
    if rows:
        s.table(["dwell", "blade", "pitch − blade 0's (°)", "95 % interval (°)"], rows)
    beside_static_part(s, result)
    return s


def footage_path(result: "IdentificationResult", label: str) -> Path:
    """Where a test's footage is: as the campaign names it, else as its campaign.toml does (a result loaded
    back from its files names the video alone)."""
    video = Path(next(t.video for t in result.campaign.tests if t.label == label))
    if video.exists() or is_frame_source(video) and Path(parse_frame_source(video).path).exists():
        return video
    from ..campaign.manifest import load_campaign

    try:
        manifest = load_campaign(result.campaign.path, check_videos=False)
    except (ServoscopeError, OSError):
        return video
    return Path(next((t.video for t in manifest.tests if t.label == label), video))


def _frame_part(s: ReportSection, result: "IdentificationResult", label: str) -> None:
    """The passes drawn on a frame of ``label``'s footage, or one line saying why not."""
    c = result.campaign
    if c.rotor is None:
        s.text(f"The passes drawn on a frame are left out: the rotor's stickers are not known (campaign.toml "
               f"{c.path} could not be read again).")
        return
    path = footage_path(result, label)
    if not path.exists() and not is_frame_source(path):
        s.text(f"The passes drawn on a frame are left out: {label}'s footage {path} is not there any more.")
        return
    try:
        view = pass_on_frame(path, c.rotor, rotor_settings(c))
    except (ServoscopeError, OSError) as exc:
        s.text(f"The passes drawn on a frame are left out: {label}'s footage could not be read again ({exc}).")
        return
    k = view.drawn
    s.figure(pass_frame_figure(view, f"{label}: blade {view.blade}'s pass at t = {view.pass_time_s:.5f} s"),
             f"Frame {view.drawn_frame} of {label}, the pass's frame nearest ψ = 0 (ψ = "
             f"{math.degrees(float(view.azimuth_rad[k])):+.2f}°, from the rotor speed and the pass's time): each "
             f"sticker's measured centroid (+ lead, × trail) and their line; dots, the same stickers in the pass's "
             f"other frames. Right: the stickers' line in the picture (φ) against the fitted azimuth, and corrected "
             f"for the foreshortening (θ); the pass's pitch, {math.degrees(view.pitch_rad):.3f}°, is the line's "
             f"value at ψ = 0. Below: each frame of the pass around the tip (cut: a sticker at the picture's edge, "
             f"not used).", "A pass drawn on its frames", name="rotor_pass_frame")
